"""Stage 5: join the torso and the four limbs of each frame -> ``skeleton/solved``, and map the
pose onto the character rig -> ``rig/pose`` (rotations relative to the rig's T-pose; mocap_core/rig.py),
turning the source's world by the up axis its frames carry.
"""
from __future__ import annotations

import time
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from messages import LimbSolution, RigPose, SkeletonFrame
from mocap_core.ik.kernels import frames_to_quats
from mocap_core.limb_join import LIMBS, FrameJoiner, Joined
from mocap_core.rig import BONE_JOINT, BONES, default_rig_offsets, local_positions, rig_local_rotations, \
    rig_world_rotations, to_unity_position
from mocap_core.skeleton import Status
from mocap_core.world import DEFAULT_UP
from nodes.runtime import Node
from nodes.skeleton_codec import from_message, to_message


class Params(BaseModel):
    model_config = ConfigDict(extra="forbid")
    max_wait_ms: float = Field(20.0, gt=0, description="longest wait for a late limb before it is held")
    rig: Literal["unity_humanoid"] = "unity_humanoid"
    bone_positions: Literal["rig", "actor"] = Field(
        "rig", description="rig: each bone's local position is the character's own (it keeps its proportions); "
                           "actor: the actor's bones this frame (a receiver that applies positions reshapes the "
                           "character to the actor)")
    input: Literal["limbs", "whole"] = Field(
        "limbs", description="limbs: join skeleton/torso and the four skeleton/limb/* topics; whole: take "
                             "skeleton/fitted, one whole skeleton a frame (the skeleton_fit node)")


class Retarget(Node):
    kind = "retarget"
    Params = Params
    subscribes = {"skeleton/torso": SkeletonFrame, **{f"skeleton/limb/{limb}": LimbSolution for limb in LIMBS}}
    publishes = {"skeleton/solved": SkeletonFrame, "rig/pose": RigPose}
    timer_period_s = 0.005

    @classmethod
    def inputs(cls, params):
        return {"skeleton/fitted": SkeletonFrame} if params.input == "whole" else cls.subscribes

    @classmethod
    def kernels(cls, params):
        return ("rotations",)

    def setup(self) -> None:
        self.joiner = FrameJoiner(self.params.max_wait_ms / 1000)
        self.last_world = np.tile(np.eye(3), (len(BONES), 1, 1))

    def on_message(self, topic, msg) -> None:
        now = time.monotonic()
        if topic == "skeleton/fitted":  # whole already: nothing to join or wait for
            self._publish([Joined(msg.header.frame, *from_message(msg), [], msg)])
            return
        if isinstance(msg, SkeletonFrame):
            joined = self.joiner.add_torso(msg.header.frame, now, *from_message(msg), msg)
        else:
            joined = self.joiner.add_limb(msg.header.frame, now, msg.limb, *from_message(msg))
        self._publish(joined)

    def on_timer(self) -> None:
        self._publish(self.joiner.release(time.monotonic()))

    def _publish(self, joined) -> None:
        for j in joined:
            self.ctx.publish("skeleton/solved", to_message(j.positions, j.frames, j.status), source=j.source)
            if j.held_limbs:
                self.ctx.count_error("held_limb", f"frame {j.source.header.frame}: {', '.join(j.held_limbs)} late, "
                                                  "held as last solved", len(j.held_limbs))
            if self.ctx.has_subscribers("rig/pose"):  # the rig costs ~0.3 ms a frame: only when wanted
                self._publish_rig(j)

    def _publish_rig(self, j) -> None:
        up = j.source.header.up_axis or DEFAULT_UP
        world = rig_world_rotations(j.frames, up)
        unknown = ~np.isfinite(world).all(axis=(1, 2))
        world[unknown] = self.last_world[unknown]  # a bone without a frame keeps its last rotation
        self.last_world = world
        local = rig_local_rotations(world)
        if self.params.bone_positions == "rig":
            offsets = default_rig_offsets()
        else:
            offsets = np.nan_to_num(local_positions(j.positions, world, up))
        status = j.status[BONE_JOINT]
        held = (status == Status.HELD) | (status == Status.MISSING) | unknown  # (estimated: from this frame's data)
        self.ctx.publish("rig/pose", RigPose(
            header=RigPose.make_header(), rig=self.params.rig, bones=list(BONES),
            root_position=np.nan_to_num(to_unity_position(j.positions[0], up)).astype(np.float32),
            rotations=frames_to_quats(np.ascontiguousarray(local)).astype(np.float32),
            positions=offsets.astype(np.float32), held=held.astype(np.uint8)), source=j.source)

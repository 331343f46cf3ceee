"""Stage 5: join the torso and the four limbs of each frame -> ``skeleton/solved``.

(Mapping onto a character rig, ``rig/pose``, is added by the outputs issue.)
"""
from __future__ import annotations

import time

from pydantic import BaseModel, ConfigDict, Field

from messages import LimbSolution, SkeletonFrame
from mocap_core.ik.kernels import quats_to_frames
from mocap_core.limb_join import LIMBS, FrameJoiner
from mocap_core.warmup import warm_up
from nodes.runtime import Node
from nodes.skeleton_codec import from_message, to_message


class Params(BaseModel):
    model_config = ConfigDict(extra="forbid")
    max_wait_ms: float = Field(20.0, gt=0, description="longest wait for a late limb before it is held")


class Retarget(Node):
    kind = "retarget"
    Params = Params
    subscribes = {"skeleton/torso": SkeletonFrame, **{f"skeleton/limb/{limb}": LimbSolution for limb in LIMBS}}
    publishes = {"skeleton/solved": SkeletonFrame}
    timer_period_s = 0.005

    def setup(self) -> None:
        warm_up()
        self.joiner = FrameJoiner(self.params.max_wait_ms / 1000)

    def on_message(self, topic, msg) -> None:
        now = time.monotonic()
        if isinstance(msg, SkeletonFrame):
            joined = self.joiner.add_torso(msg.header.frame, now, *from_message(msg), msg)
        else:
            joined = self.joiner.add_limb(msg.header.frame, now, msg.limb, msg.positions.astype(float),
                                          quats_to_frames(msg.orientations.astype(float)), msg.status.copy())
        self._publish(joined)

    def on_timer(self) -> None:
        self._publish(self.joiner.release(time.monotonic()))

    def _publish(self, joined) -> None:
        for j in joined:
            self.ctx.publish("skeleton/solved", to_message(j.positions, j.frames, j.status), source=j.source)
            if j.held_limbs:
                self.ctx.errors["held_limb"] += len(j.held_limbs)

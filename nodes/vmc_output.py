"""Streams ``rig/pose`` as VMC (OSC over UDP, default 127.0.0.1:39539) for Unity EVMC4U, Unreal
VMC4UE, Blender VMC4B. One bundle per frame: /VMC/Ext/Root/Pos, /VMC/Ext/Bone/Pos for every
humanoid bone (local position and rotation, Unity's left-handed Y-up frame; see mocap_core/rig.py),
/VMC/Ext/T and /VMC/Ext/OK."""
from __future__ import annotations

import time

from pydantic import BaseModel, ConfigDict, Field
from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message_builder import OscMessageBuilder
from pythonosc.udp_client import SimpleUDPClient

from messages import RigPose
from nodes.runtime import Node


class Params(BaseModel):
    model_config = ConfigDict(extra="forbid")
    host: str = "127.0.0.1"
    port: int = Field(39539, ge=1, le=65535)
    max_rate_hz: float = Field(0.0, ge=0, description="send at most this often (keep the newest); 0 = every frame")


def _msg(address: str, *args) -> object:
    b = OscMessageBuilder(address=address)
    for a in args:
        b.add_arg(a)
    return b.build()


class VmcOutput(Node):
    kind = "vmc_output"
    Params = Params
    subscribes = {"rig/pose": RigPose}

    def setup(self) -> None:
        self.client = SimpleUDPClient(self.params.host, self.params.port)
        self.t0 = time.monotonic()
        self.next_send = 0.0

    def on_message(self, topic, msg: RigPose) -> None:
        if self.params.max_rate_hz:
            now = time.monotonic()
            if now < self.next_send:
                return  # engines render at display rate: a newer frame follows soon
            self.next_send = now + 1.0 / self.params.max_rate_hz
        bundle = OscBundleBuilder(IMMEDIATELY)
        bundle.add_content(_msg("/VMC/Ext/OK", 1))
        bundle.add_content(_msg("/VMC/Ext/T", float(time.monotonic() - self.t0)))
        bundle.add_content(_msg("/VMC/Ext/Root/Pos", "root", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0))
        for i, bone in enumerate(msg.bones):
            p = msg.root_position if i == 0 else msg.positions[i]
            q = msg.rotations[i]
            bundle.add_content(_msg("/VMC/Ext/Bone/Pos", bone, *map(float, p), *map(float, q)))
        self.client.send(bundle.build())

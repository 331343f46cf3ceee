"""Streams ``rig/pose`` as VMC (OSC over UDP, default 127.0.0.1:39539) for Unity EVMC4U, Unreal VMC4UE and
Blender VMC4B, as the VMC protocol (v2.5) lays it out, in Unity's left-handed Y-up frame (mocap_core/rig.py):

- ``/VMC/Ext/Root/Pos``: the avatar's root on the floor under the pelvis (it moves with the pelvis), no rotation;
- ``/VMC/Ext/Bone/Pos`` for every humanoid bone: its rotation relative to the rig's T-pose, local to its parent,
  and its local position: the pelvis's height above the floor for Hips, the rig's own bone for the others
  (retarget's ``bone_positions``);
- ``/VMC/Ext/T`` (seconds since the stream began) and ``/VMC/Ext/OK`` (loaded, calibrated, normal mode, and
  tracking good unless a bone was held this frame).

A frame goes out as bundles of at most ``max_datagram`` bytes (1472: one Ethernet frame's UDP payload, so a real
network never fragments them), OK and T in the last. ``max_rate_hz`` caps the rate: frames are sent on a schedule
of that period, each one that comes within half a period of its slot, so the rate is exactly the cap (or the
capture rate below it).
"""
from __future__ import annotations

import socket
import time

from pydantic import BaseModel, ConfigDict, Field
from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message_builder import OscMessageBuilder

from messages import RigPose
from nodes.runtime import Node

CALIBRATED, NORMAL_MODE = 3, 0   # /VMC/Ext/OK's calibration state and mode (VMC v2.5)
BUNDLE_OVERHEAD = 16             # "#bundle\0" and the time tag
ELEMENT_OVERHEAD = 4             # each element's size


class Params(BaseModel):
    model_config = ConfigDict(extra="forbid")
    host: str = "127.0.0.1"
    port: int = Field(39539, ge=1, le=65535)
    max_rate_hz: float = Field(0.0, ge=0, description="send at most this often (keep the newest); 0 = every frame")
    max_datagram: int = Field(1472, ge=256, le=65507, description="largest UDP payload; a frame is split to fit")


def _msg(address: str, *args):
    b = OscMessageBuilder(address=address)
    for a in args:
        b.add_arg(a)
    return b.build()


def frame_messages(msg: RigPose, t: float) -> list:
    """One frame's OSC messages, in the order they go out."""
    root = [float(v) for v in msg.root_position]
    out = [_msg("/VMC/Ext/Root/Pos", "root", root[0], 0.0, root[2], 0.0, 0.0, 0.0, 1.0)]
    for i, bone in enumerate(msg.bones):
        p = (0.0, root[1], 0.0) if i == 0 else tuple(map(float, msg.positions[i]))
        out.append(_msg("/VMC/Ext/Bone/Pos", bone, *p, *map(float, msg.rotations[i])))
    tracking = 0 if msg.held.any() else 1
    out += [_msg("/VMC/Ext/T", float(t)), _msg("/VMC/Ext/OK", 1, CALIBRATED, NORMAL_MODE, tracking)]
    return out


def pack(messages: list, max_bytes: int) -> list[bytes]:
    """Bundles of whole messages, each at most ``max_bytes``."""
    out, bundle, size = [], OscBundleBuilder(IMMEDIATELY), BUNDLE_OVERHEAD
    for m in messages:
        n = ELEMENT_OVERHEAD + m.size
        if size + n > max_bytes and size > BUNDLE_OVERHEAD:
            out.append(bundle.build().dgram)
            bundle, size = OscBundleBuilder(IMMEDIATELY), BUNDLE_OVERHEAD
        bundle.add_content(m)
        size += n
    out.append(bundle.build().dgram)
    return out


class RateCap:
    """Lets frames through on a schedule of ``rate_hz``; a frame up to half a period early takes its slot."""

    def __init__(self, rate_hz: float):
        self.period = 1.0 / rate_hz if rate_hz else 0.0
        self.next = -float("inf")

    def admit(self, now: float) -> bool:
        if not self.period:
            return True
        if now < self.next - 0.5 * self.period:
            return False
        # the next slot, unless the stream paused: then the schedule starts again from now
        self.next = max(self.next + self.period, now + 0.5 * self.period)
        return True


class VmcOutput(Node):
    kind = "vmc_output"
    Params = Params
    subscribes = {"rig/pose": RigPose}

    def setup(self) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.address = (self.params.host, self.params.port)
        if self.params.host in ("127.0.0.1", "localhost"):
            self.sock.bind(("127.0.0.1", 0))  # else the first send binds every interface
        self.t0 = time.monotonic()
        self.cap = RateCap(self.params.max_rate_hz)

    def on_message(self, topic, msg: RigPose) -> None:
        now = time.monotonic()
        if not self.cap.admit(now):
            return  # engines render at display rate: a newer frame follows soon
        for datagram in pack(frame_messages(msg, now - self.t0), self.params.max_datagram):
            try:
                self.sock.sendto(datagram, self.address)
            except OSError as e:  # no route to the receiver (yet): the stream goes on without it
                self.ctx.count_error("vmc_send", f"VMC to {self.address[0]}:{self.address[1]}: {e}")
                return

    def teardown(self) -> None:
        self.sock.close()

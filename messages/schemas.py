"""Pydantic schemas of every topic (docs/design.md, "Topics and messages").

Conventions shared by all messages:
- positions are float32 metres in the world frame of the source, right-handed; the header's
  ``up_axis`` says which axis is up, set by the source and carried along (mocap_core.world);
  occluded markers and missing joints are NaN;
- a joint's bone frame is a float32 rotation matrix, world from bone: its columns are the bone's x, y and z
  axes in the world (the layout mocap_core solves in, so no stage converts it); NaN where the joint has none;
- quaternions, where a consumer wants them (the rig's rotations, RigPose), are float32 in scalar-last order
  ``(x, y, z, w)`` (scipy, Unity and the thesis code use the same order);
- every message starts with a :class:`Header`. ``schema``/``version`` identify the model,
  ``seq`` counts messages per publisher and topic (a gap is a drop), ``frame`` and
  ``capture_time_s`` come from the capture system, and ``entry_time_ns`` (wall clock,
  ``time.time_ns()``) is stamped once when the frame enters the graph so that any node can
  report end-to-end latency.
"""
from __future__ import annotations

from typing import ClassVar, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from mocap_core.skeleton import N_JOINTS
from mocap_core.world import UP_AXES
from messages.arrays import Array


class Header(BaseModel):
    model_config = ConfigDict(extra="forbid")

    schema_name: str = Field(alias="schema")
    version: int
    publisher: str = ""   # node id (and replica) that sent it; seq counts per publisher and topic
    seq: int = 0
    frame: int = 0
    capture_time_s: float = 0.0
    entry_time_ns: int = 0
    up_axis: Literal[("", *UP_AXES)] = ""   # the source's world (mocap_core.world); "" = not said


class Message(BaseModel):
    """Base of every topic message. Subclasses set SCHEMA and VERSION."""

    model_config = ConfigDict(extra="forbid", arbitrary_types_allowed=True, populate_by_name=True)
    SCHEMA: ClassVar[str] = ""
    VERSION: ClassVar[int] = 1

    header: Header

    @classmethod
    def make_header(cls, frame: int = 0, capture_time_s: float = 0.0, entry_time_ns: int = 0,
                    up_axis: str = "") -> Header:
        return Header(schema=cls.SCHEMA, version=cls.VERSION, frame=frame,
                      capture_time_s=capture_time_s, entry_time_ns=entry_time_ns, up_axis=up_axis)

    # The schema name and version are checked by the codec before validation (messages/codec.py) and
    # stamped by the runtime on publish, so no model validator repeats it on the 20 us hot path.


class MarkerSet(Message):
    """The labels and metadata of a marker stream (topic ``markers/set``); the up axis is the header's."""

    SCHEMA: ClassVar[str] = "mocap.MarkerSet"
    labels: list[str]
    units: Literal["m"] = "m"
    rate_hz: float
    source: str = ""


class MarkerFrame(Message):
    """One frame of labelled markers (``markers/raw``, ``markers/filled``).

    Departure from the design card (documented in docs/graph.md): the frame carries its labels, so every frame
    is self-describing; a node that joins late or a bag cut anywhere needs no earlier MarkerSet.
    ``flags`` per marker: 0 measured, 1 interpolated, 2 missing.
    """

    SCHEMA: ClassVar[str] = "mocap.MarkerFrame"
    labels: list[str]
    positions: Array("float32", (None, 3))
    flags: Array("uint8", (None,))

    @model_validator(mode="after")
    def _check_lengths(self):
        n = len(self.labels)
        if self.positions.shape[0] != n or self.flags.shape[0] != n:
            raise ValueError(f"{n} labels but positions {self.positions.shape} and flags {self.flags.shape}")
        return self


FLAG_MEASURED, FLAG_INTERPOLATED, FLAG_MISSING = 0, 1, 2


class SkeletonFrame(Message):
    """Every joint of the skeleton model in model order (mocap_core.skeleton.JOINTS): its position, its bone
    frame (``rotations``, world from bone) and its ``status`` (mocap_core.skeleton.Status: 0 missing, 1 located,
    2 estimated, 3 held). Version 1 carried quaternions (``orientations``); the codec still reads it."""

    SCHEMA: ClassVar[str] = "mocap.SkeletonFrame"
    VERSION: ClassVar[int] = 2
    positions: Array("float32", (N_JOINTS, 3))
    rotations: Array("float32", (N_JOINTS, 3, 3))
    status: Array("uint8", (N_JOINTS,))


class LimbSolution(Message):
    """The joints of one limb after IK gap filling (``skeleton/limb/<limb>``), laid out as in SkeletonFrame.
    Version 1 carried quaternions (``orientations``); the codec still reads it."""

    SCHEMA: ClassVar[str] = "mocap.LimbSolution"
    VERSION: ClassVar[int] = 2
    limb: str
    joints: list[str]
    positions: Array("float32", (None, 3))
    rotations: Array("float32", (None, 3, 3))
    status: Array("uint8", (None,))
    solver: str = ""
    iterations: int = 0
    residual_m: float = 0.0
    solve_time_us: float = 0.0

    @model_validator(mode="after")
    def _check_lengths(self):
        n = len(self.joints)
        if not (self.positions.shape[0] == self.rotations.shape[0] == self.status.shape[0] == n):
            raise ValueError(f"{n} joints but arrays {self.positions.shape}, {self.rotations.shape}, "
                             f"{self.status.shape}")
        return self


class RigPose(Message):
    """A pose of the target rig (``rig/pose``), in the rig's own frame (Unity: left-handed, Y up):
    the root position, and per rig bone its local rotation and local position (offset from its parent
    this frame), both relative to the rig's T-pose rest. ``held`` marks bones whose joint was held."""

    SCHEMA: ClassVar[str] = "mocap.RigPose"
    rig: str
    bones: list[str]
    root_position: Array("float32", (3,))
    rotations: Array("float32", (None, 4))
    positions: Array("float32", (None, 3))
    held: Array("uint8", (None,))

    @model_validator(mode="after")
    def _check_lengths(self):
        n = len(self.bones)
        if not (self.rotations.shape[0] == self.positions.shape[0] == self.held.shape[0] == n):
            raise ValueError(f"{n} bones but rotations {self.rotations.shape}, positions {self.positions.shape} "
                             f"and held {self.held.shape}")
        return self


class Latency(BaseModel):
    p50_ms: float = 0.0
    p95_ms: float = 0.0
    p99_ms: float = 0.0
    max_ms: float = 0.0
    samples: int = 0


class Cpu(BaseModel):
    """A process's CPU time so far (s): all of it, and (with MOCAP_CPU_SPLIT=1 in the node's environment) the part
    spent in the node's handlers and, within them, in publishing (encoding and sending). The rest is the runtime's
    own loop: receiving, decoding, statistics."""
    process_s: float = 0.0
    handlers_s: float = 0.0
    publishing_s: float = 0.0


class Heartbeat(Message):
    """Published by every node at 1 Hz on ``diagnostics``."""

    SCHEMA: ClassVar[str] = "mocap.Heartbeat"
    node: str
    kind: str
    pid: int
    state: Literal["starting", "waiting", "running", "finished", "stopping", "error"]
    uptime_s: float
    rates_hz: dict[str, float] = {}      # per topic, received and published
    received: dict[str, int] = {}
    published: dict[str, int] = {}
    drops: dict[str, int] = {}           # per received topic: sequence gaps
    lost_frames: dict[str, int] = {}     # per received topic: frames lost while a publisher restarted
    errors: dict[str, int] = {}          # per reason
    latency: Latency = Latency()         # entry_time -> receive, over the last second
    last_error: str = ""
    cpu: Cpu = Cpu()


ALL_MESSAGES: tuple[type[Message], ...] = (MarkerSet, MarkerFrame, SkeletonFrame, LimbSolution, RigPose, Heartbeat)
BY_SCHEMA: dict[str, type[Message]] = {m.SCHEMA: m for m in ALL_MESSAGES}

"""Replays a C3D, TRC or MAT recording onto ``markers/raw`` at the recording's rate (or ``rate_hz``).

The frames' headers carry the recording's up axis where the file says it (a bag; a synthetic take), or
``up_axis`` where it says it wrongly or not at all; otherwise the first node with a profile stamps the
profile's."""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator

from messages import FLAG_MEASURED, FLAG_MISSING, MarkerFrame, MarkerSet, Message
from mocap_core.up_axis import recording_up_axis
from mocap_core.world import normalize_up
from nodes.actor_split import ActorSplit, actor_topics
from nodes.bags import read_take
from nodes.lockstep import Lockstep
from nodes.runtime import Node

SET_PERIOD_S = 1.0
REPO = Path(__file__).resolve().parents[1]


def resolve_path(path: str) -> str:
    """Relative paths are tried from the working directory, then from the repository root."""
    if path.startswith("synthetic:") or Path(path.split(".mat:")[0]).exists() or Path(path).is_absolute():
        return path
    return str(REPO / path)  # re-send the marker set so late subscribers and tools learn the labels


class Params(BaseModel):
    model_config = ConfigDict(extra="forbid")
    path: str = Field(description="recording: .c3d, .trc, .mat (file.mat:take picks a take)")
    rate_hz: float = Field(0.0, ge=0, description="replay rate; 0 = the recording's own rate")
    loop: bool = False
    start_s: float = Field(0.0, ge=0, description="start this many seconds into the take")
    max_frames: int = Field(0, ge=0, description="stop after this many frames; 0 = the whole take")
    lockstep_topic: str | None = Field(None, description="for tests: send the next frame only once this topic "
                                       "has carried the last one (e.g. skeleton/solved)")
    lockstep_timeout_s: float = Field(2.0, gt=0)
    up_axis: str | None = Field(None, description="the recording's up axis (+z, -y, ...), over what the file "
                                "says; unset: the file's, else the profile's")
    actors: list[str] = Field(default_factory=list, description="split the stream by the subject in front of "
                              "each label (actor1:LASI) onto mocap/<actor>/markers/raw; the launch file's actors: "
                              "sets it")

    @field_validator("up_axis")
    @classmethod
    def _up(cls, v):
        return None if v is None else normalize_up(v)


class FileSource(Node):
    kind = "file_source"
    Params = Params
    publishes = {"markers/raw": MarkerFrame, "markers/set": MarkerSet}
    is_source = True

    @classmethod
    def outputs(cls, params):
        return {**cls.publishes, **actor_topics(params.actors)}

    @classmethod
    def inputs(cls, params):
        return {params.lockstep_topic: Message} if params.lockstep_topic else {}

    def on_message(self, topic, msg) -> None:
        self.lockstep.heard(msg.header.frame)

    def setup(self) -> None:
        p = self.params
        self.rec = read_take(resolve_path(p.path))
        self.rate = p.rate_hz or self.rec.rate_hz
        self.first = min(int(p.start_s * self.rec.rate_hz), self.rec.n_frames - 1)
        self.index = self.first
        self.sent = 0
        self.next_set = 0.0
        self.up_axis = p.up_axis or recording_up_axis(self.rec, self.log) or ""
        self.lockstep = Lockstep(self.ctx, p.lockstep_topic, p.lockstep_timeout_s)
        self.split = ActorSplit(self.ctx, p.actors, self.log)
        self.log.info("replaying %s: %d markers, %d frames at %.0f Hz", self.rec.source, len(self.rec.labels),
                      self.rec.n_frames, self.rate)

    def tick(self) -> float | None:
        p, rec = self.params, self.rec
        if self.lockstep.blocked():
            return 0.0002
        if self.index >= rec.n_frames:
            if not p.loop:
                return None
            self.index = self.first
        if p.max_frames and self.sent >= p.max_frames:
            return None
        now = time.monotonic()
        if now >= self.next_set:
            self.split.publish("markers/set", MarkerSet(header=self._header(0, 0.0), labels=rec.labels,
                                                        rate_hz=self.rate, source=rec.source))
            self.next_set = now + SET_PERIOD_S
        pos = rec.positions[self.index]
        flags = np.where(np.isnan(pos).any(axis=1), FLAG_MISSING, FLAG_MEASURED).astype(np.uint8)
        frame = rec.first_frame + self.index
        self.split.publish("markers/raw", MarkerFrame(
            header=self._header(frame, self.index / rec.rate_hz),
            labels=rec.labels, positions=pos, flags=flags))
        self.index += 1
        self.sent += 1
        if p.lockstep_topic:
            self.lockstep.sent(frame)
            return 0.0
        return 1.0 / self.rate

    def _header(self, frame: int, t: float):
        return MarkerFrame.make_header(frame, t, time.time_ns(), self.up_axis)

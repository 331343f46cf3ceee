"""Replays a bag onto its topics: timed (keeping the recorded spacing, scaled by ``rate``) or in
lockstep (the next frame goes out only when the graph has produced the last one on
``lockstep_topic``), for deterministic tests. Payloads go out byte for byte unless ``restamp``
gives them a fresh graph-entry time (so latency figures mean something on a replay).
"""
from __future__ import annotations

import time

import numpy as np

from pydantic import BaseModel, ConfigDict, Field

from messages import Message, decode
from nodes.bags import bag_info, read_bag
from nodes.lockstep import Lockstep
from nodes.runtime import Node, percentiles


class Params(BaseModel):
    model_config = ConfigDict(extra="forbid")
    path: str
    rate: float = Field(1.0, gt=0, description="playback speed factor")
    loop: bool = False
    topics: list[str] | None = Field(None, description="topics to play (default: every topic in the bag)")
    start_offset_s: float = Field(0.0, ge=0)
    lockstep_topic: str | None = Field(None, description="wait for this topic's frame before the next one")
    lockstep_after: str = Field("markers/raw", description="the played topic that carries frames")
    lockstep_timeout_s: float = Field(2.0, gt=0)
    restamp: bool = False
    spin_ms: float = Field(1.0, ge=0, description="busy-wait this long before each timed message: sleeping "
                           "alone wakes up to 2 ms late at p99 on a loaded machine (0 = sleep only, no spinning)")


class BagPlayer(Node):
    kind = "bag_player"
    Params = Params
    is_source = True

    @classmethod
    def outputs(cls, params):
        topics = params.topics or list(bag_info(params.path)["topics"])
        return {t: Message for t in topics}

    @classmethod
    def inputs(cls, params):
        return {params.lockstep_topic: Message} if params.lockstep_topic else {}

    def setup(self) -> None:
        p = self.params
        self.messages = list(read_bag(p.path, p.topics))
        if not self.messages:
            raise ValueError(f"{p.path}: no messages to play")
        t_first = self.messages[0].log_time_ns
        self.messages = [m for m in self.messages if m.log_time_ns - t_first >= p.start_offset_s * 1e9]
        self.i = 0
        self.t0_bag = self.messages[0].log_time_ns
        self.t0 = None
        self.spin_s = p.spin_ms / 1000
        self.lockstep = Lockstep(self.ctx, p.lockstep_topic, p.lockstep_timeout_s)
        self.late_s: list[float] = []  # timed replay: how late each message left (reported at the end)
        self.log.info("playing %d messages from %s", len(self.messages), p.path)

    def on_message(self, topic, msg) -> None:
        self.lockstep.heard(msg.header.frame)

    def tick(self) -> float | None:
        p = self.params
        now = time.monotonic()
        if self.lockstep.blocked():
            return 0.0002
        if self.i >= len(self.messages):
            if not p.loop:
                return None
            self.i, self.t0 = 0, None
        if self.t0 is None:
            self.t0 = now
        m = self.messages[self.i]
        if not p.lockstep_topic:
            due = self.t0 + (m.log_time_ns - self.t0_bag) / 1e9 / p.rate
            if due - now > max(self.spin_s, 0.0002):
                return due - now - self.spin_s
            while time.monotonic() < due:  # the last stretch: a spin is on time, a sleep often is not
                pass
            self.late_s.append(time.monotonic() - due)
        self._send(m)
        self.i += 1
        if p.lockstep_topic and m.topic == p.lockstep_after:
            self.lockstep.sent(decode(m.data, m.topic).header.frame)
            return 0.0002
        if self.i < len(self.messages) and not p.lockstep_topic:
            nxt = self.t0 + (self.messages[self.i].log_time_ns - self.t0_bag) / 1e9 / p.rate
            return max(0.0, nxt - time.monotonic() - self.spin_s)
        return 0.0

    def _send(self, m) -> None:
        if self.params.restamp:
            msg = decode(m.data, m.topic)
            msg.header.entry_time_ns = 0
            self.ctx.publish(m.topic, msg)  # fresh sequence number and entry time
        else:
            self.ctx.send_raw(self.ctx.wire_topic(m.topic), m.data)

    def teardown(self) -> None:
        if self.late_s:
            p50, p99, top = percentiles(np.array(self.late_s) * 1000, (50, 99, 100))
            self.log.info("timed replay of %d messages: sent late by p50 %.3f ms, p99 %.3f ms, max %.3f ms",
                          len(self.late_s), p50, p99, top)

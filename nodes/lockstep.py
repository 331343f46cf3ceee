"""Lockstep for sources in tests: send the next frame only after the graph has put out the last one."""
from __future__ import annotations

import time


class Lockstep:
    def __init__(self, ctx, topic: str | None, timeout_s: float):
        self.ctx, self.topic, self.timeout_s = ctx, topic, timeout_s
        self.waiting_for: int | None = None
        self.since = 0.0

    def sent(self, frame: int) -> None:
        if self.topic:
            self.waiting_for, self.since = frame, time.monotonic()

    def heard(self, frame: int) -> None:
        if self.waiting_for is not None and frame >= self.waiting_for:
            self.waiting_for = None

    def blocked(self) -> bool:
        """Still waiting? After the timeout the frame is counted as lost and the source goes on."""
        if self.waiting_for is None:
            return False
        if time.monotonic() - self.since < self.timeout_s:
            return True
        self.ctx.count_error("lockstep_timeout", f"no {self.topic} for frame {self.waiting_for}; going on")
        self.waiting_for = None
        return False

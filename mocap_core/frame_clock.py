"""The interval between frames, from the frames' own capture times, for stages that count durations in frames."""
from __future__ import annotations

import math


def next_frame_s(frame_s: float, last_time_s: float, time_s: float) -> float:
    """The time since the last frame; a missing, repeated or backward stamp (a looping file, a restarted QTM) or
    one over a second keeps the last good interval ``frame_s``."""
    step = time_s - last_time_s
    return step if 0 < step <= 1.0 else frame_s


class FrameClock:
    def __init__(self, frame_s: float):
        self.frame_s, self.last_time_s = frame_s, math.nan  # frame_s: until the times say (or none are given)

    def advance(self, time_s: float) -> None:
        self.frame_s, self.last_time_s = next_frame_s(self.frame_s, self.last_time_s, time_s), time_s

    def frames(self, seconds: float) -> int:
        """``seconds`` as a whole number of frames at the take's rate (at least one)."""
        return max(1, round(seconds / self.frame_s))

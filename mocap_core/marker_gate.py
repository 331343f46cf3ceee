"""Markers that no body could have put there: dropped for the frame, counted, and never learned from.

A marker further from the origin than ``max_distance_m``, or one that moved faster than ``max_speed_m_s`` since it
was last accepted, is taken as missing in that frame (a glitch of the cameras, a corrupt packet). The fastest
marker in the shared recordings moves at 17 m/s (a strike), so the default of 50 m/s keeps every real
motion. A marker whose new track goes on consistently is accepted again on the next frame: it is checked against
where it was last rejected too, so a wrong first position (a glitch in the first frame) is left after one frame.
Every stage that learns from the markers sits behind this gate (the hip stage, the fit), so one glitched frame
cannot corrupt what they learn for the rest of the session.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class MarkerGate:
    max_speed_m_s: float = 50.0
    max_distance_m: float = 1000.0
    last: np.ndarray | None = None          # (M, 3) where each marker was last accepted
    last_t: np.ndarray | None = None        # (M,) and when
    rejected: np.ndarray | None = None      # (M, 3) where it was last rejected
    rejected_t: np.ndarray | None = None
    dropped: int = field(default=0)         # markers dropped so far

    def filter(self, markers: np.ndarray, time_s: float) -> tuple[np.ndarray, np.ndarray]:
        """One frame's markers (M, 3) -> (a copy with the impossible ones NaN, the mask of those)."""
        x = np.array(markers, np.float64)
        m = len(x)
        if self.last is None or len(self.last) != m:
            self.last, self.last_t = np.full((m, 3), np.nan), np.full(m, np.nan)
            self.rejected, self.rejected_t = np.full((m, 3), np.nan), np.full(m, np.nan)
        seen = np.isfinite(x).all(axis=1)
        with np.errstate(invalid="ignore", over="ignore"):
            bad = seen & ~(np.abs(x) <= self.max_distance_m).all(axis=1)
            fast = seen & ~bad & ~self._reachable(x, self.last, self.last_t, time_s, True)
            fast &= ~self._reachable(x, self.rejected, self.rejected_t, time_s, False)  # not a track going on
        drop = bad | fast
        self.rejected[fast], self.rejected_t[fast] = x[fast], time_s
        keep = seen & ~drop
        self.last[keep], self.last_t[keep] = x[keep], time_s
        x[drop] = np.nan
        self.dropped += int(drop.sum())
        return x, drop

    def filter_take(self, markers: np.ndarray, frame_s: float, start: int = 0) -> np.ndarray:
        """Frames ``start``.. of a take (F, M, 3), ``frame_s`` apart -> a copy with the impossible markers NaN."""
        out = np.empty(markers.shape, np.float64)
        for f in range(len(markers)):
            out[f] = self.filter(markers[f], (start + f) * frame_s)[0]
        return out

    def _reachable(self, x, before, before_t, time_s, unknown: bool) -> np.ndarray:
        """Markers within max speed of where they were at ``before_t``; ``unknown`` for those with no such place."""
        dt = time_s - before_t
        step = np.linalg.norm(x - before, axis=1)
        ok = step <= self.max_speed_m_s * np.where(dt > 0, dt, np.inf)
        return np.where(np.isfinite(before_t), ok, unknown)

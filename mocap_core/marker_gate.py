"""Markers that no body could have put there: dropped for the frame, counted, and never learned from.

A marker further from the origin than ``max_distance_m``, or one that moved faster than ``max_speed_m_s`` since it
was last accepted, is taken as missing in that frame (a glitch of the cameras, a corrupt packet). The fastest
marker in the shared recordings moves at 17 m/s (a strike), so the default of 50 m/s keeps every real
motion. A frame stamped at or before the last (a duplicated or replayed time) counts as one frame interval later.
A marker with no place accepted yet (the first frame, its first appearance) is accepted within ``max_body_m`` of
the frame's median marker (a body with its arms stretched overhead spans little over 2 m). A marker whose new
track goes on consistently is accepted again on the next frame: it is checked against where it was last rejected
too, so a prop away from the body, or a marker that really moved, is kept from its second frame.
Every stage that learns from the markers sits behind this gate (the hip stage, the fit), so one glitched frame
cannot corrupt what they learn for the rest of the session.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from mocap_core.world import MAX_COORDINATE_M


@dataclass
class MarkerGate:
    max_speed_m_s: float = 50.0
    max_distance_m: float = MAX_COORDINATE_M
    max_body_m: float = 3.0
    last: np.ndarray | None = None          # (M, 3) where each marker was last accepted
    last_t: np.ndarray | None = None        # (M,) and when
    rejected: np.ndarray | None = None      # (M, 3) where it was last rejected
    rejected_t: np.ndarray | None = None
    last_time_s: float = np.nan             # the last frame's time
    frame_s: float = 0.01                   # the last interval between frames (until two frames say)
    dropped: int = field(default=0)         # markers dropped so far

    def filter(self, markers: np.ndarray, time_s: float) -> tuple[np.ndarray, np.ndarray]:
        """One frame's markers (M, 3) -> (a copy with the impossible ones NaN, the mask of those)."""
        x = np.array(markers, np.float64)
        m = len(x)
        if self.last is None or len(self.last) != m:
            self.last, self.last_t = np.full((m, 3), np.nan), np.full(m, np.nan)
            self.rejected, self.rejected_t = np.full((m, 3), np.nan), np.full(m, np.nan)
        seen = np.isfinite(x).all(axis=1)
        if math.isfinite(self.last_time_s):
            if time_s > self.last_time_s:
                self.frame_s = min(time_s - self.last_time_s, 1.0)
            else:  # (no time, or at or before the last frame's: one interval on)
                time_s = self.last_time_s + self.frame_s
        elif not math.isfinite(time_s):
            time_s = 0.0
        self.last_time_s = time_s
        with np.errstate(invalid="ignore", over="ignore"):
            bad = seen & ~(np.abs(x) <= self.max_distance_m).all(axis=1)
            near = seen & ~bad
            if (near & ~np.isfinite(self.last_t)).any() and near.sum() >= 3:  # (only a new marker needs the body)
                near &= _norm(x - np.median(x[near], axis=0)) <= self.max_body_m
            fast = seen & ~bad & ~self._reachable(x, self.last, self.last_t, time_s, near)
            if fast.any():  # (most frames have none: the check against the rejected places is for them)
                fast &= ~self._reachable(x, self.rejected, self.rejected_t, time_s, False)  # not a track going on
                self.rejected[fast], self.rejected_t[fast] = x[fast], time_s
        drop = bad | fast
        keep = seen & ~drop
        self.last[keep], self.last_t[keep] = x[keep], time_s
        if drop.any():
            x[drop] = np.nan
            self.dropped += int(drop.sum())
        return x, drop

    def filter_take(self, markers: np.ndarray, frame_s: float, start: int = 0) -> np.ndarray:
        """Frames ``start``.. of a take (F, M, 3), ``frame_s`` apart -> a copy with the impossible markers NaN."""
        out = np.empty(markers.shape, np.float64)
        for f in range(len(markers)):
            out[f] = self.filter(markers[f], (start + f) * frame_s)[0]
        return out

    def _reachable(self, x, before, before_t, time_s, unknown) -> np.ndarray:
        """Markers within max speed of where they were at ``before_t``; ``unknown`` (bool, or per marker) for those
        with no such place."""
        ok = _norm(x - before) <= self.max_speed_m_s * (time_s - before_t)
        return np.where(np.isfinite(before_t), ok, unknown)


def _norm(v: np.ndarray) -> np.ndarray:
    """Each row's length, as np.linalg.norm(v, axis=1) computes it, without its checks (a few us a call)."""
    return np.sqrt((v * v).sum(axis=1))

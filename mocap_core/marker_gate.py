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
from numba import njit

from mocap_core.ik.kernels import vdist
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
        x = np.array(markers, np.float64, order="C")  # (the kernel is compiled for C order only)
        m = len(x)
        if self.last is None or len(self.last) != m:
            self.last, self.last_t = np.full((m, 3), np.nan), np.full(m, np.nan)
            self.rejected, self.rejected_t = np.full((m, 3), np.nan), np.full(m, np.nan)
        if math.isfinite(self.last_time_s):
            if time_s > self.last_time_s:
                self.frame_s = min(time_s - self.last_time_s, 1.0)
            else:  # (no time, or at or before the last frame's: one interval on)
                time_s = self.last_time_s + self.frame_s
        elif not math.isfinite(time_s):
            time_s = 0.0
        self.last_time_s = time_s
        drop = np.zeros(m, np.bool_)
        self.dropped += _screen(x, (self.last, self.last_t, self.rejected, self.rejected_t), float(time_s),
                                (float(self.max_speed_m_s), float(self.max_distance_m), float(self.max_body_m)), drop)
        return x, drop

    def filter_take(self, markers: np.ndarray, frame_s: float, start: int = 0) -> np.ndarray:
        """Frames ``start``.. of a take (F, M, 3), ``frame_s`` apart -> a copy with the impossible markers NaN."""
        out = np.empty(markers.shape, np.float64)
        for f in range(len(markers)):
            out[f] = self.filter(markers[f], (start + f) * frame_s)[0]
        return out


@njit(cache=True)
def _screen(x, state, time_s, limits, drop):
    """One frame's markers ``x`` (M, 3) in place: the impossible ones NaN and marked in ``drop``; ``state``: the gate's
    (last, last_t, rejected, rejected_t), updated; ``limits``: (max speed, max distance, max body). Returns how many
    it dropped."""
    last, last_t, rejected, rejected_t = state
    max_speed, max_distance, max_body = limits
    m = x.shape[0]
    seen, near = np.zeros(m, np.bool_), np.zeros(m, np.bool_)
    bad = np.zeros(m, np.bool_)
    n_near, new = 0, False
    for i in range(m):
        seen[i] = np.isfinite(x[i, 0]) and np.isfinite(x[i, 1]) and np.isfinite(x[i, 2])
        bad[i] = seen[i] and not (abs(x[i, 0]) <= max_distance and abs(x[i, 1]) <= max_distance
                                  and abs(x[i, 2]) <= max_distance)
        near[i] = seen[i] and not bad[i]
        if near[i]:
            n_near += 1
            new = new or not np.isfinite(last_t[i])
    if new and n_near >= 3:  # (only a new marker needs the body: within max_body of the markers' median)
        column = np.empty(n_near)
        middle = np.empty(3)
        for c in range(3):
            k = 0
            for i in range(m):
                if near[i]:
                    column[k] = x[i, c]
                    k += 1
            middle[c] = np.median(column)
        for i in range(m):
            if near[i]:
                near[i] = vdist(x[i], middle) <= max_body
    dropped = 0
    for i in range(m):
        if not seen[i]:
            continue
        # too fast from where it was last accepted, and not a new track going on from where it was last rejected
        fast = (not bad[i] and not _reachable(x[i], last[i], last_t[i], time_s, max_speed, near[i])
                and not _reachable(x[i], rejected[i], rejected_t[i], time_s, max_speed, False))
        if fast:
            rejected[i] = x[i]
            rejected_t[i] = time_s
        if bad[i] or fast:
            drop[i] = True
            x[i] = np.nan
            dropped += 1
        else:
            last[i] = x[i]
            last_t[i] = time_s
    return dropped


@njit(cache=True, inline="always")
def _reachable(x, before, before_t, time_s, max_speed, unknown):
    """Whether a marker is within ``max_speed`` of where it was at ``before_t``; ``unknown`` where it was nowhere."""
    if not np.isfinite(before_t):
        return unknown
    return vdist(x, before) <= max_speed * (time_s - before_t)

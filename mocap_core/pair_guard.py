"""Beyond the thesis: a bony pair whose spacing jumps is dropped until it is back (the hip stage, first of the
landmark fills).

The styloids sit on the ends of the radius and the ulna, which the distal radio-ulnar joint holds together, and
the malleoli on the tibia and the fibula (segment_rebuild.BONY_PAIRS): their spacing hardly changes. When it jumps,
the cameras have put a marker wrong (a ghost, a swap, a reflection), and which one cannot be told from the two. So
both are marked lost from where the spacing is off the one learned by more than PAIR_OFF of it until it is back
within PAIR_BACK_M and held there (not swung through), and the gap fills take over. A marker that slid slowly is
followed (SPACING_RATE a frame); one stuck back elsewhere is taken at its new spacing once the pair holds it for
PAIR_STEADY_S. A glitch is not held: one swings through far larger and smaller spacings within a fraction of a
second.

Fast moves change the spacing too, and there the markers are still the better guess than any fill: so only a
change by PAIR_OFF (40 %) of the spacing drops the pair, which strikes and swings do not reach and glitches do.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from mocap_core.blend import DEFAULT_FRAME_S
from mocap_core.fill_units import LandmarkFill, switch
from mocap_core.ik.kernels import vnorm
from mocap_core.profiles import LANDMARK_INDEX
from mocap_core.segment_rebuild import BONY_PAIRS

PAIR_OFF = 0.4         # dropped when the spacing is off the learned one by this part of it
PAIR_BACK_M = 0.005    # taken back within this of the learned spacing,
PAIR_STEADY_S = 0.2    # or at a new one held within PAIR_BACK_M for this long (a marker stuck back elsewhere)
SPACING_RATE = 1 / 100  # how fast the learned spacing follows the frames kept (as segment_rebuild.DISTANCE_RATE)
PAIRS = tuple((f"{side}_{a}", f"{side}_{b}") for side in "LR" for a, b in BONY_PAIRS.values())
PAIR_GUARD_HELP = ("beyond the thesis: a bony pair (styloids, malleoli) whose spacing is off the one learned by "
                   f"more than {PAIR_OFF * 100:.0f} percent has a marker put wrong by the cameras; both are dropped "
                   "(marked lost, for the gap fills) until it is back")


class PairGuard(LandmarkFill):
    """Drops the bony pairs whose spacing is off, frame by frame, for the fills after it. Keep one per actor: it
    learns the spacings."""
    Settings = switch("pair_guard", PAIR_GUARD_HELP)

    def __init__(self):
        self.pairs = np.array([[LANDMARK_INDEX[a], LANDMARK_INDEX[b]] for a, b in PAIRS])
        self.spacing = np.full(len(PAIRS), np.nan)  # learned (NaN: not yet seen together)
        self.dropped = np.zeros(len(PAIRS), np.bool_)
        self.held = np.full(len(PAIRS), np.nan)     # while dropped: the spacing the pair holds to, since
        self.held_s = np.zeros(len(PAIRS))          # this long
        self.began = np.zeros(len(PAIRS), np.bool_)  # which the last frame began to drop
        self.last_time = np.nan
        self._state = (self.spacing, self.dropped, self.held, self.held_s, self.began)  # (what the kernel keeps)

    def fill(self, landmarks, tracking=None, time_s=np.nan, markers=None, filled=None) -> np.ndarray:
        """One frame (LandmarkFill.fill), in place: the dropped pairs set to NaN; it puts nothing (an empty mask).
        A dropped pair not both seen is taken back: the one seen cannot be told wrong."""
        dt = time_s - self.last_time if np.isfinite(time_s - self.last_time) else DEFAULT_FRAME_S
        self.last_time = time_s
        dropped = np.zeros(len(landmarks), np.bool_)
        guard_frame(landmarks, self.pairs, self._state, dt, dropped)
        return np.zeros(len(landmarks), np.bool_)

    def said(self) -> list[tuple[str, str]]:
        """What the last frame began to drop."""
        return [("pair_dropped", f"{PAIRS[p][0]} and {PAIRS[p][1]} {self.held[p] * 1000:.0f} mm apart where they "
                 f"were {self.spacing[p] * 1000:.0f}: both dropped until their spacing is back")
                for p in np.flatnonzero(self.began)]


@njit(cache=True)
def guard_frame(lm, pairs, state, dt, mask):
    """One frame of landmarks, in place; ``state``: PairGuard's arrays, in place too (a plain tuple: numba reads it
    from Python in a fraction of a microsecond, a NamedTuple in about one)."""
    spacing, dropped, held, held_s, began = state
    for p in range(len(pairs)):
        a, b = pairs[p, 0], pairs[p, 1]
        now = vnorm(lm[a] - lm[b])  # NaN: one lost
        seen = not np.isnan(now)
        if seen and np.isnan(spacing[p]):
            spacing[p] = now
        off = abs(now - spacing[p])
        if abs(now - held[p]) > PAIR_BACK_M:
            held[p], held_s[p] = now, 0.0
        else:  # (held within PAIR_BACK_M since held_s)
            held_s[p] += dt
        moved = held_s[p] == 0.0
        began[p] = False
        if dropped[p]:
            if seen and held_s[p] >= PAIR_STEADY_S:  # stuck back elsewhere: learned anew
                spacing[p], dropped[p] = now, False
            elif not seen or (off <= PAIR_BACK_M and not moved):  # (a swing through it is not back)
                dropped[p] = False
        elif seen and off > PAIR_OFF * spacing[p]:
            dropped[p] = began[p] = True
            held[p], held_s[p] = now, 0.0
        if dropped[p]:
            mask[a] = mask[b] = True
            lm[a] = lm[b] = np.nan
        elif seen:
            spacing[p] += SPACING_RATE * (now - spacing[p])

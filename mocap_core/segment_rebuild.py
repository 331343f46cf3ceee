"""Rebuilding lost limb landmarks from the markers of their segment that are still seen.

Beyond the thesis (issue 9's "use what is still visible: a joint's remaining markers"; the thesis's
2018 code had a first version of it, SegmentTracking, facts section 8). The markers of one bone
move as one rigid body, so a lost landmark is put where the best rigid motion (Kabsch) of its
segment's seen markers, from the last frame they were seen with it, carries it:

- forearm: the humeral epicondyles sit on the elbow's flexion axis, which the ulna turns about, so
  they keep their place among the forearm's markers (olecranon, both styloids; the styloids are
  partners only);
- foot: the malleoli sit on the ankle's hinge, so they keep their place among heel and toe.

A landmark is rebuilt only from at least ``MIN_PARTNERS`` markers of its segment seen both now and
in its reference frame: two leave the rotation about their line free (the forearm's swivel, which
the IK stage's swivel option handles). Segments tried and left out, because they made the fills
worse on the recordings: the shank (epicondyles, tibia, malleoli: a lost ankle came out 45 mm off
where the foot's carry gives 4 mm) and the hand with the forearm (a wrist flexes).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from mocap_core.ik.kernels import mv, rigid_fit_first
from mocap_core.profiles import LANDMARK_INDEX

MIN_PARTNERS = 3
REBUILD_HELP = ("beyond the thesis: a lost elbow, olecranon, ankle, heel or toe marker rebuilt from the rigid "
                "motion of at least 3 markers of its forearm or foot still seen")
# Rigid bodies of landmarks: (rebuilt when lost, partners only). The styloids only help: rebuilt
# from the elbow's markers, a lost wrist came out 27 mm off on the sprint where the IK stage's
# swivel gives 13 mm (the radius turns about the ulna).
SEGMENTS = (
    (("HLE", "HME", "UOA"), ("RSP", "USP")),   # forearm: the elbow's axis, the olecranon, the styloids
    (("FAL", "TAM", "FCC", "FM2"), ()),        # foot: the ankle's axis (malleoli), heel and toe
)
WIDTH = max(len(a) + len(b) for a, b in SEGMENTS)
# (segments x WIDTH) landmark indices, the rebuilt ones first, -1 padding; both sides
SEGMENT_INDEX = np.array([[LANDMARK_INDEX[f"{side}_{name}"] for name in a + b] + [-1] * (WIDTH - len(a) - len(b))
                          for side in ("L", "R") for a, b in SEGMENTS], dtype=np.int64)
REBUILT_COUNT = np.array([len(a) for side in ("L", "R") for a, _ in SEGMENTS], dtype=np.int64)


class SegmentRebuilder:
    """Fills lost limb landmarks frame by frame. Keep one per actor: it owns the reference frames."""

    def __init__(self):
        # per segment and member: where the segment's markers were the last time that member was
        # seen with at least MIN_PARTNERS of the others (NaN rows: not seen then)
        self.reference = np.full((len(SEGMENT_INDEX), WIDTH, WIDTH, 3), np.nan)

    def fill(self, landmarks: np.ndarray) -> np.ndarray:
        """One frame of landmarks (n_landmarks, 3) float64, NaN = lost: fill what can be rebuilt, in
        place; returns the mask of rebuilt landmarks."""
        rebuilt = np.zeros(len(landmarks), np.bool_)
        rebuild_frame(landmarks, SEGMENT_INDEX, REBUILT_COUNT, self.reference, rebuilt)
        return rebuilt

    def fill_landmarks(self, landmarks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Landmark frames (F, n_landmarks, 3) -> filled copy and the (F, n_landmarks) rebuilt mask."""
        out = np.array(landmarks, dtype=np.float64, copy=True)
        mask = np.zeros(out.shape[:2], bool)
        for f in range(out.shape[0]):
            mask[f] = self.fill(out[f])
        return out, mask


@njit(cache=True)
def _seen(p):
    return np.isfinite(p[0]) and np.isfinite(p[1]) and np.isfinite(p[2])


@njit(cache=True)
def rebuild_frame(lm, segments, rebuilt_count, reference, rebuilt):
    seen = np.zeros(segments.shape[1], np.bool_)
    before, after = np.empty((segments.shape[1], 3)), np.empty((segments.shape[1], 3))
    for s in range(segments.shape[0]):
        seg = segments[s]
        width, count = 0, 0
        for k in range(seg.shape[0]):
            if seg[k] < 0:
                break
            width += 1
            seen[k] = _seen(lm[seg[k]])
            if seen[k]:
                count += 1
        if count > MIN_PARTNERS:  # each seen member's reference: the segment as it is now
            for k in range(width):
                if seen[k]:
                    for m in range(width):
                        if seen[m]:
                            reference[s, k, m] = lm[seg[m]]
                        else:
                            reference[s, k, m] = np.nan
        if count == width or count < MIN_PARTNERS:
            continue
        for k in range(rebuilt_count[s]):
            if seen[k] or rebuilt[seg[k]] or not _seen(reference[s, k, k]):
                continue
            n = 0
            for m in range(width):
                if seen[m] and _seen(reference[s, k, m]):
                    before[n], after[n] = reference[s, k, m], lm[seg[m]]
                    n += 1
            if n < MIN_PARTNERS:
                continue
            rot, t = rigid_fit_first(before, after, n)
            lm[seg[k]] = mv(rot, reference[s, k, k]) + t
            rebuilt[seg[k]] = True

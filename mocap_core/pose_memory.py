"""Lost knee and ankle landmarks from the poses the take has already shown (beyond the thesis).

The segment rebuild (mocap_core.segment_rebuild) needs three markers left on the bone. A sparse
marker set has none: the 28-marker dance set puts one marker on the knee, one on the ankle and two
on the toes, so with knee and ankle lost only the pelvis and the toe remain, and two degrees of
freedom (the knee's bend direction, the ankle's angle) are not observed at all. What is left is
what the actor has done before: while a leg is seen whole, its knee and ankle landmarks are
remembered in the pelvis's frame, together with where the toe was. Once they are lost (and the toe
and the pelvis are seen), they are put where the remembered poses whose toe was nearest had them
(inverse-distance weighted mean), smoothed over frames, starting from the last pose seen so that
nothing jumps when the markers go. The knee is remembered where it was in the pelvis's frame (the
thigh keeps it near the hip), the ankle as its offset from the toe (the foot keeps it near the
toe): on dance1 the other way round puts the knee 54 mm off instead of 37 and the ankle 66 instead
of 57.

Issue 9's "bone lengths learned online from located frames", taken one step further: the whole
leg's shape, learned from the same take. It never uses frames it has not seen (a live graph
learns from the frames before a gap) and never learns from landmarks that were themselves filled.
"""
from __future__ import annotations

from typing import Iterable

import numpy as np
from numba import njit

from mocap_core.ik.kernels import mtv, mv
from mocap_core.profiles import LANDMARK_INDEX

POSE_MEMORY_HELP = ("beyond the thesis: lost knee and ankle landmarks put where the take's earlier poses with the "
                    "toe nearest where it is now had them (for marker sets with nothing else left on shank and foot)")
KEY = "FM2"                             # the toe: every profile has it
PELVIS_TARGETS = ("FLE", "FME", "TTC")  # the knee's landmarks, remembered in the pelvis's frame
TOE_TARGETS = ("FAL", "TAM")            # the ankle's, remembered as offsets from the toe
# With the heel seen, the foot is tracked and the IK stage's segment carry does better (Qualisys walk,
# knee+ankle hidden from 0.5 s: 33 / 11 mm, where the memory of 0.5 s gives 53 / 46): legs whose heel
# is seen are left to it.
HEEL = "FCC"
NEIGHBOURS = 20     # remembered poses averaged (dance1: 10 gives the same error, 20 half the jitter)
CAPACITY = 4000     # poses kept per leg (the oldest make room)
MIN_MOVE_M = 0.005  # a pose is remembered when its toe has moved this far from the last one kept
SMOOTHING = 0.5     # per frame: how far the estimate moves towards the remembered poses' mean
SACR, L_IAS, R_IAS = LANDMARK_INDEX["SACR"], LANDMARK_INDEX["L_IAS"], LANDMARK_INDEX["R_IAS"]


class PoseMemory:
    """Fills lost knee and ankle landmarks frame by frame. Keep one per actor: it owns the poses.
    ``present``: the landmark names the profile has (LandmarkMap.present())."""

    def __init__(self, present: Iterable[str]):
        present = set(present)
        width = len(PELVIS_TARGETS + TOE_TARGETS)
        legs, from_toe = [], []
        for side in ("L", "R"):
            targets = [t for t in PELVIS_TARGETS + TOE_TARGETS if f"{side}_{t}" in present]
            if f"{side}_{KEY}" in present and targets:
                row = [LANDMARK_INDEX[f"{side}_{KEY}"], LANDMARK_INDEX[f"{side}_{HEEL}"], len(targets)]
                legs.append(row + [LANDMARK_INDEX[f"{side}_{t}"] for t in targets] + [-1] * (width - len(targets)))
                from_toe.append([t in TOE_TARGETS for t in targets] + [False] * (width - len(targets)))
        n = len(legs)
        # per leg: toe, heel, number of targets, the targets (-1 padding); whether each is kept from the toe
        self.legs = np.array(legs, np.int64).reshape(n, 3 + width)
        self.from_toe = np.array(from_toe, np.bool_).reshape(n, width)
        self.toes = np.full((n, CAPACITY, 3), np.inf)       # remembered toe positions (pelvis frame)
        self.offsets = np.zeros((n, CAPACITY, width, 3))   # and the targets' offsets then
        self.state = np.zeros((n, 2), np.int64)            # poses kept, where the next one goes
        self.last_kept = np.full((n, 3), np.inf)           # the toe of the last pose kept
        self.last_seen = np.full((n, width, 3), np.nan)    # the offsets of the last frame seen whole
        self.estimate = np.full((n, width, 3), np.nan)     # the smoothed offsets during a gap (NaN: none)
        self._nothing_filled: np.ndarray | None = None

    def fill(self, landmarks: np.ndarray, filled: np.ndarray | None = None) -> np.ndarray:
        """One frame of landmarks (n_landmarks, 3) float64, NaN = lost; ``filled``: the landmarks an
        earlier stage estimated this frame (never learned from). Fills in place; returns the mask it filled."""
        if filled is None:
            if self._nothing_filled is None or len(self._nothing_filled) != len(landmarks):
                self._nothing_filled = np.zeros(len(landmarks), np.bool_)
            filled = self._nothing_filled
        out = np.zeros(len(landmarks), np.bool_)
        if len(self.legs):
            fill_frame(landmarks, filled, self.legs, self.from_toe, self.toes, self.offsets, self.state,
                       self.last_kept, self.last_seen, self.estimate, out)
        return out

    def fill_landmarks(self, landmarks: np.ndarray, filled: np.ndarray | None = None
                       ) -> tuple[np.ndarray, np.ndarray]:
        """Landmark frames (F, n_landmarks, 3) -> filled copy and the (F, n_landmarks) mask filled here."""
        out = np.array(landmarks, dtype=np.float64, copy=True)
        mask = np.zeros(out.shape[:2], bool)
        for f in range(out.shape[0]):
            mask[f] = self.fill(out[f], None if filled is None else filled[f])
        return out, mask


@njit(cache=True)
def _seen(p):
    return np.isfinite(p[0]) and np.isfinite(p[1]) and np.isfinite(p[2])


@njit(cache=True)
def pelvis_frame(lm, origin, rot):
    """The pelvis's origin (between the ASIS) and axes (columns: x to the left ASIS, z up from the
    sacrum's side), written into ``origin`` and ``rot``; False when a pelvis landmark is lost."""
    left, right, sacrum = lm[L_IAS], lm[R_IAS], lm[SACR]
    if not (_seen(left) and _seen(right) and _seen(sacrum)):
        return False
    origin[:] = (left + right) / 2
    x = left - right
    z = np.cross(x, origin - sacrum)
    nx, nz = np.sqrt((x ** 2).sum()), np.sqrt((z ** 2).sum())
    if nx < 1e-6 or nz < 1e-9:
        return False
    x, z = x / nx, z / nz
    rot[:, 0], rot[:, 1], rot[:, 2] = x, np.cross(z, x), z
    return True


@njit(cache=True)
def fill_frame(lm, filled, legs, from_toe, toes, offsets, state, last_kept, last_seen, estimate, out):
    origin, rot = np.empty(3), np.empty((3, 3))
    if not pelvis_frame(lm, origin, rot):
        return
    best_d, best_i = np.empty(NEIGHBOURS), np.empty(NEIGHBOURS, np.int64)
    for g in range(legs.shape[0]):
        key, heel, nt = legs[g, 0], legs[g, 1], legs[g, 2]
        toe = lm[key].copy()
        if not _seen(toe):
            estimate[g, 0, 0] = np.nan
            continue
        local_toe = mtv(rot, toe - origin)
        lost, measured = False, not filled[key]
        for t in range(nt):
            lost = lost or not _seen(lm[legs[g, 3 + t]])
            measured = measured and not filled[legs[g, 3 + t]]
        if not lost or _seen(lm[heel]):  # seen whole, or the foot is tracked (segment carry)
            estimate[g, 0, 0] = np.nan
            if not lost and measured:
                for t in range(nt):
                    anchor = toe if from_toe[g, t] else origin
                    last_seen[g, t] = mtv(rot, lm[legs[g, 3 + t]] - anchor)
                if np.sqrt(((local_toe - last_kept[g]) ** 2).sum()) >= MIN_MOVE_M:
                    i = state[g, 1]
                    toes[g, i] = local_toe
                    offsets[g, i, :nt] = last_seen[g, :nt]
                    last_kept[g] = local_toe
                    state[g, 1], state[g, 0] = (i + 1) % CAPACITY, min(state[g, 0] + 1, CAPACITY)
            continue
        if state[g, 0] < NEIGHBOURS:
            continue
        best_d[:] = np.inf  # the NEIGHBOURS nearest remembered toes, by insertion
        for i in range(state[g, 0]):  # (written out: no temporary arrays in the loop)
            dx, dy, dz = toes[g, i, 0] - local_toe[0], toes[g, i, 1] - local_toe[1], toes[g, i, 2] - local_toe[2]
            d = np.sqrt(dx * dx + dy * dy + dz * dz)
            if d < best_d[NEIGHBOURS - 1]:
                j = NEIGHBOURS - 1
                while j > 0 and best_d[j - 1] > d:
                    best_d[j], best_i[j] = best_d[j - 1], best_i[j - 1]
                    j -= 1
                best_d[j], best_i[j] = d, i
        mean, total = np.zeros((nt, 3)), 0.0
        for n in range(NEIGHBOURS):
            w = 1.0 / (best_d[n] + 1e-3)
            mean += w * offsets[g, best_i[n], :nt]
            total += w
        mean /= total
        if np.isnan(estimate[g, 0, 0]):  # the gap begins: from the last pose seen, so nothing jumps
            if np.isnan(last_seen[g, 0, 0]):
                estimate[g, :nt] = mean
            else:
                estimate[g, :nt] = last_seen[g, :nt]
        estimate[g, :nt] += SMOOTHING * (mean - estimate[g, :nt])
        for t in range(nt):
            k = legs[g, 3 + t]
            if not _seen(lm[k]):
                anchor = toe if from_toe[g, t] else origin
                lm[k] = anchor + mv(rot, estimate[g, t])
                out[k] = True

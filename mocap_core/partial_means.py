"""Landmarks that are the mean of several markers, with some of them lost (beyond the thesis).

A profile may name a landmark the mean of markers (``L_SAE: mean(LFSH, LBSH)``, the acromion between the
front and back shoulder markers). One of them lost made the whole landmark lost, and what stands in for it
moved the body's frames: on the Vicon take LBSH flickers (50 frames in 17 runs), the chest then fell back to
other markers and turned up to 50 degrees in a frame, its sternum-clavicle point moved 40 mm, and the left
shoulder, estimated out of its neighbours' reach, turned 130-175 degrees. Here a lost member keeps its offset
from its landmark's members still seen, as it was in the last frame in which the landmark was whole, turned as
the markers nearest it have turned since (use what is still visible; the last turn is kept while fewer than
three of them are seen). Anchored to the landmark's own markers, a rotation that is a little off moves it
little; the rigid motion of the nearest markers alone, centre included, moved a kicking toe 200 mm in a frame
when one of them came back.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from mocap_core.ik.kernels import mv, nearness_weight, rigid_fit_weighted
from mocap_core.profiles import LandmarkMap

# The markers nearest a lost member (in its landmark's last whole frame) whose rotation turns its offset. On the
# Vicon take, the back shoulder, head, pelvis, toe and hand markers hidden for 12 frames (from every 5th frame):
# the landmark 7.8 / 3.6 / 5.7 / 2.7 / 2.1 mm off on average (max 55 / 39 / 99 / 17 / 21) with 4, where the
# offset without a turn gave 14.5 / 5.5 / 16.2 / 5.7 / 6.2 (max 89 / 92 / 128 / 41 / 33) and the nearest
# markers' rigid motion alone 10.1 / 3.9 / 6.3 / 2.6 / 3.2 (max 109 / 38 / 136 / 21 / 83). Hidden for 43 frames
# (the longest real loss): 19.9 / 10.0 / 14.9 / 4.8 / 3.6 against 36.4 / 14.0 / 46.1 / 12.3 / 11.9 without a turn.
# 5 of them, or only those within 0.2-0.3 m: worse on the toe (max 41-72 mm).
# Each weighs by its nearness to the lost member: measured as above again,
# 7.7 / 3.8 / 6.0 / 2.7 / 1.9 mm (max 53 / 39 / 87 / 13 / 12) -> 7.6 / 3.4 / 5.4 / 2.3 / 1.7 (max 53 / 36 / 100 /
# 12 / 10); for 43 frames 20.5 / 10.7 / 12.5 / 5.1 / 3.2 -> 20.0 / 9.8 / 11.0 / 4.6 / 2.9.
NEIGHBOURS = 4


class PartialMeans:
    """Fills, frame by frame, the landmarks still lost that are the mean of several markers of which some are
    seen. It runs after the other landmark fills (the hips', then last in LandmarkFills), and fills only what
    they could not: the segment rebuild's rigid foot puts a kicking toe better than its one metatarsal marker
    left. Keep one per actor and marker set: it keeps, per such landmark, the last frame in which all its markers
    were seen."""

    def __init__(self, landmark_map: LandmarkMap):
        self.map = landmark_map
        self.count = landmark_map.count.astype(np.int64)
        self.means = np.flatnonzero(landmark_map.count > 1)
        self.last_whole = np.full((len(self.means), landmark_map.n_labels, 3), np.nan)
        self.turns = np.tile(np.eye(3), (len(self.means), 1, 1))  # and how its nearest markers turned since

    def fill(self, markers: np.ndarray, landmarks: np.ndarray) -> np.ndarray:
        """One frame: ``markers`` (n_labels, 3) as received, ``landmarks`` (n_landmarks, 3) from the map and the
        fills before, its lost ones filled in place; returns the mask of the landmarks filled."""
        filled = np.zeros(len(landmarks), bool)
        if len(self.means):
            _fill_means(np.asarray(markers, np.float64), landmarks, self.map.idx, self.count, self.means,
                        self.last_whole, self.turns, filled)
        return filled

    def fill_landmarks(self, markers: np.ndarray, landmarks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Frames (F, n_labels, 3) and their landmarks (F, n_landmarks, 3) -> the filled copy and its mask."""
        out = landmarks.copy()
        filled = np.zeros(out.shape[:2], bool)
        for f in range(len(out)):
            filled[f] = self.fill(markers[f], out[f])
        return out, filled


@njit(cache=True)
def _seen(p):
    return np.isfinite(p[0]) and np.isfinite(p[1]) and np.isfinite(p[2])


@njit(cache=True)
def _turn(markers, ref, lost, turn):
    """The rotation of the NEIGHBOURS markers nearest ``lost`` in ``ref`` (seen there and now) since ``ref``, kept
    in ``turn``; with fewer than three of them seen, the last one (``turn`` as it was)."""
    n = markers.shape[0]
    dist = np.full(n, np.inf)
    for i in range(n):
        if i != lost and _seen(ref[i]) and _seen(markers[i]):
            d = ref[i] - ref[lost]
            dist[i] = d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
    order = np.argsort(dist)
    k = 0
    while k < NEIGHBOURS and k < n and np.isfinite(dist[order[k]]):
        k += 1
    if k >= 3:
        before, after, weights = np.empty((k, 3)), np.empty((k, 3)), np.empty(k)
        for i in range(k):
            before[i], after[i] = ref[order[i]], markers[order[i]]
            weights[i] = nearness_weight(np.sqrt(dist[order[i]]))
        turn[:] = rigid_fit_weighted(before, after, weights, k)[0]


@njit(cache=True)
def _fill_means(markers, landmarks, idx, count, means, last_whole, turns, filled):
    for r in range(means.shape[0]):
        li = means[r]
        members, c, ref = idx[li], count[li], last_whole[r]
        seen = 0
        anchor, anchor_ref = np.zeros(3), np.zeros(3)
        for i in range(c):
            if _seen(markers[members[i]]):
                anchor += markers[members[i]]
                anchor_ref += ref[members[i]]
                seen += 1
        if seen == c:
            last_whole[r] = markers
            turns[r] = np.eye(3)
            continue
        if seen == 0 or not _seen(ref[members[0]]) or _seen(landmarks[li]):  # (filled by the fills before)
            continue
        anchor, anchor_ref = anchor / seen, anchor_ref / seen
        total = np.zeros(3)
        for i in range(c):
            p = markers[members[i]]
            if not _seen(p):
                _turn(markers, ref, members[i], turns[r])
                p = anchor + mv(turns[r], ref[members[i]] - anchor_ref)
            total += p
        landmarks[li] = total / c
        filled[li] = True

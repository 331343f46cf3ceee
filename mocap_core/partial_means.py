"""Landmarks that are the mean of several markers, with some of them lost (beyond the thesis).

A profile may name a landmark the mean of markers (``L_SAE: mean(LFSH, LBSH)``, the acromion between the
front and back shoulder markers). One of them lost made the whole landmark lost, and what stands in for it
moved the body's frames (a flickering back-shoulder marker turned the chest tens of degrees in a frame). Here a lost member keeps its offset
from its landmark's members still seen, as it was in the last frame in which the landmark was whole, turned as
the markers nearest it have turned since (use what is still visible; the last turn is kept while fewer than
three of them are seen). Anchored to the landmark's own markers, a rotation that is a little off moves it
little; the rigid motion of the nearest markers alone, centre included, jumps when one of them comes back.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from mocap_core.fill_units import LandmarkFill, MarkerSet
from mocap_core.ik.kernels import mv, nearness_weight, rigid_fit_weighted
from mocap_core.profiles import LandmarkMap
from mocap_core.segment_rebuild import SegmentRebuilder

# The markers nearest a lost member (in its landmark's last whole frame) whose rotation turns its offset, each
# weighed by its nearness to the member. A turn from fewer is noise; from more, or from farther ones, it follows
# the body less closely (a toe's member moved with the leg rather than the foot).
NEIGHBOURS = 4


class PartialMeans(LandmarkFill):
    """Fills, frame by frame, the landmarks still lost that are the mean of several markers of which some are
    seen. It runs after the other landmark fills (the hips', then last in LandmarkFills), and fills only what
    they could not: the segment rebuild's rigid foot puts a kicking toe better than its one metatarsal marker
    left. Keep one per actor and marker set: it keeps, per such landmark, the last frame in which all its markers
    were seen. On with the segment rebuild."""
    Settings = SegmentRebuilder.Settings

    @classmethod
    def for_marker_set(cls, markers: MarkerSet) -> "PartialMeans | None":
        return None if markers.means is None else cls(markers.means)

    def __init__(self, landmark_map: LandmarkMap):
        self.map = landmark_map
        self.count = landmark_map.count.astype(np.int64)
        self.means = np.flatnonzero(landmark_map.count > 1)
        self.last_whole = np.full((len(self.means), landmark_map.n_labels, 3), np.nan)
        self.turns = np.tile(np.eye(3), (len(self.means), 1, 1))  # and how its nearest markers turned since

    def fill(self, landmarks, tracking=None, time_s=np.nan, markers=None, filled=None) -> np.ndarray:
        """One frame (LandmarkFill.fill): ``landmarks`` from the map and the fills before, its lost ones filled in
        place from ``markers`` (n_labels, 3) as received (None: nothing is)."""
        put = np.zeros(len(landmarks), bool)
        if len(self.means) and markers is not None:
            _fill_means(np.asarray(markers, np.float64), landmarks, self.map.idx, self.count, self.means,
                        self.last_whole, self.turns, put)
        return put


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

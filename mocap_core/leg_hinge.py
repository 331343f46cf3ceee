"""Lost knee and ankle landmarks from the hip and one marker on the shank (beyond the thesis, part of
the rebuild).

The segment rebuild (mocap_core.segment_rebuild) carries a lost knee with its shank, but it needs two
markers on the shank: a tracking marker on its shaft and the ankle at its end, which the foot's markers
put. In a high kick a studio loses the foot's markers as well, and the knee and ankle were then held, a metre
off by the kick's end.

One marker on the shank is still enough for the whole leg but one angle. The leg is two rigid bodies:
the thigh turns about the hip joint centre and carries the knee's epicondyles, and the shank turns about
the axis between them and carries the malleoli and the marker. Their shape is taken from the last frame
the knee's epicondyles and the marker were all seen (bone lengths are constant). The marker's
distance from the hip then fixes the knee's bend, and its direction all of the thigh's turn but the
turn about the hip-marker line. That one is carried in the pelvis frame (the "swivel angle carried
in its parent's frame"): the thigh turns with the pelvis, then as little as puts the marker where it is,
then about the hip-marker line as keeps the knee's axis nearest its direction in the pelvis frame. (A
leg that only bends, hip and knee, is then followed exactly, but near a straight knee: there the marker's
distance from the hip hardly changes with the bend, which is then ambiguous.) The ankle is on the shank
too: with the marker lost and the ankle seen (or rebuilt from the foot), it takes the marker's place.

The rebuild runs first: where it has its partners it does better (the malleoli from the foot's markers,
the knee from the ankle and the shank marker). The tibial tuberosity is left to it.

Where the rebuild had only those two (the shank marker and the ankle), the shank's roll about their line is
kept from its reference frame, and the knee's epicondyles, 20 cm off that line, swing with any error in it.
The thigh then settles it (``settle_roll``): the epicondyles are turned about that line to the roll that keeps
them at their learned distances from the hip joint centre (the femur is rigid: over a take they hold within a
centimetre or so, Harrington's centre included).
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
from numba import njit

from mocap_core.fill_units import LandmarkFill, MarkerSet
from mocap_core.frame_clock import FrameClock
from mocap_core.ik.kernels import (axis_angle, best_roll, follow, mm, mv, rigid_fit_first, rotation_between,
                                   vfinite, vnorm)
from mocap_core.localization import hip_centres
from mocap_core.profiles import LANDMARK_INDEX
from mocap_core.segment_rebuild import SegmentRebuilder

# The points of one leg's model, in this order: the hip centre, the knee's epicondyles (the bend's axis),
# the malleoli, and the shank marker.
HIP, FLE, FME, FAL, TAM, MARKER = range(6)
KNEE_ANKLE = ("FLE", "FME", "FAL", "TAM")
MAX_BEND_STEP = np.radians(30.0)  # the knee's bend searched this far either side of the last frame's
SEARCH_STEP = np.radians(1.0)     # first in these steps, then in tenths of them about the best
BEND_PRICE_M = 0.001              # per radian away from the last bend: settles near-ties between two bends
# A shank marker lost goes on at its last step for this long, and the leg with it (the "velocity over short
# gaps"); after that the ankle, where it is seen or rebuilt, takes its place, and else the leg is left to the IK
# stage. Held still instead, a kicking leg falls far behind; carried on for long, it overshoots.
COURSE_S = 0.05
# The knee's roll about the shank marker-ankle line is searched this far either side of the rebuild's, in
# ROLL_STEP steps, then in tenths and hundredths of them (0.05 deg: 0.05 mm at the epicondyles). ROLL_PRICE
# (square metres per square radian) holds it near the rebuild's where the distances hardly fix it: their own
# noise is a centimetre or so, and unpriced the roll follows it.
MAX_ROLL = np.radians(60.0)
ROLL_STEP = np.radians(5.0)
ROLL_PRICE = 0.001
DISTANCE_RATE = 1 / 100  # how fast the learned hip-epicondyle distances follow the frames that measure them


class LegHinge(LandmarkFill):
    """Fills lost knee and ankle landmarks frame by frame, with the segment rebuild. Keep one per actor: it owns
    each leg's shape. ``tracking_of``: the segment of each tracking marker passed to :meth:`fill`
    (LandmarkMap.tracking_of)."""
    Settings = SegmentRebuilder.Settings

    @classmethod
    def for_marker_set(cls, markers: MarkerSet) -> "LegHinge | None":
        hinge = cls(markers.tracking_of)
        return hinge if hinge.active else None

    def __init__(self, tracking_of: Sequence[str] = (), roll_price: float = ROLL_PRICE):
        self.n_tracking = len(tracking_of)
        self.roll_price = roll_price
        # per leg: all its shank's tracking markers (-1 padding): the rebuild's partners with the malleoli
        shanks = [[j for j, seg in enumerate(tracking_of) if seg == f"{side}_shank"] for side in ("L", "R")]
        width = max(1, *map(len, shanks))
        self.shank_markers = np.array([m + [-1] * (width - len(m)) for m in shanks], np.int64)
        # per leg: its knee and ankle landmarks, and its shank's first tracking marker (-1: none)
        self.legs = np.array([[LANDMARK_INDEX[f"{side}_{name}"] for name in KNEE_ANKLE] + [first]
                              for side, first in zip(("L", "R"), self.shank_markers[:, 0])], np.int64)
        self.hip_distance = np.full((2, 2), np.nan)    # the epicondyles' learned distances from the hip centre
        self.shape = np.full((2, 6, 3), np.nan)        # the model's points in the frame its shape was taken
        self.turn = np.zeros((2, 3, 3))                # the thigh's turn since then, in the pelvis frame
        self.bend = np.zeros(2)                        # and the knee's bend since then (radians)
        self.course = np.full((2, 2, 3), np.nan)       # the shank marker's last position and step
        self.lost_frames = np.zeros(2, np.int64)       # and for how many frames it has been lost
        self.clock = FrameClock(1 / 120)               # (the frames' interval, from their times)
        self.active = bool((self.legs[:, -1] >= 0).any())  # False: no shank marker, nothing to fill from
        # (as the kernel takes them)
        self._layout = (self.legs, self.shank_markers)
        self._state = (self.shape, self.turn, self.bend, self.course, self.lost_frames, self.hip_distance)

    def fill(self, landmarks, tracking=None, time_s=np.nan, markers=None, filled=None) -> np.ndarray:
        """One frame (LandmarkFill.fill), in place. ``filled``: what the segment rebuild put this frame (their roll
        is settled); ``time_s``: the course's length is in seconds."""
        out = np.zeros(len(landmarks), np.bool_)
        if tracking is None or not self.active:
            return out
        if len(tracking) != self.n_tracking:  # (as the segment rebuild: a caller's mistake, not bad input)
            raise ValueError(f"expected {self.n_tracking} tracking markers, got {len(tracking)}")
        rebuilt = np.zeros(len(landmarks), np.bool_) if filled is None else filled
        tracking = np.asarray(tracking, np.float64)
        self.clock.advance(float(time_s))
        fill_frame(landmarks, tracking, rebuilt, self._layout, self._state, self.clock.frames(COURSE_S),
                   self.roll_price, out)
        return out


@njit(cache=True)
def settle_roll(lm, tracking, rebuilt, layout, hip_distance, price, hips):
    """Learn the epicondyles' distances from the hip centre where they are seen; where the rebuild put them
    from the shank marker and the ankle alone, turn them about that line to keep those distances. ``layout``:
    LegHinge's (legs, shank_markers); ``hips``: this frame's (left, right) hip centres."""
    legs, shank_markers = layout
    left_hip, right_hip = hips
    points, hip_only = np.empty((2, 3)), np.empty((1, 3))
    for leg in range(2):
        hip = left_hip if leg == 0 else right_hip
        fle, fme, fal, tam, marker = legs[leg]
        if marker < 0 or not vfinite(hip):
            continue
        if vfinite(lm[fle]) and vfinite(lm[fme]) and not (rebuilt[fle] or rebuilt[fme]):
            for i, k in enumerate((fle, fme)):
                hip_distance[leg, i] = follow(hip_distance[leg, i], vnorm(lm[k] - hip), DISTANCE_RATE)
            continue
        if not (rebuilt[fle] and rebuilt[fme]) or np.isnan(hip_distance[leg, 0]) or not vfinite(tracking[marker]):
            continue
        partners = int(vfinite(lm[fal])) + int(vfinite(lm[tam]))
        for j in shank_markers[leg]:
            if j >= 0 and vfinite(tracking[j]):
                partners += 1
        if partners != 2 or not vfinite(lm[fal]):  # (three or more fix the roll themselves)
            continue
        pivot = tracking[marker]
        line = lm[fal] - pivot
        if vnorm(line) < 1e-6:
            continue
        line /= vnorm(line)
        for e, k in enumerate((fle, fme)):
            points[e] = lm[k]
        hip_only[0] = hip
        turn = axis_angle(line, best_roll(pivot, line, points, hip_only, hip_distance[leg].reshape(2, 1), price,
                                          MAX_ROLL, ROLL_STEP))
        for k in (fle, fme):
            lm[k] = pivot + mv(turn, lm[k] - pivot)


@njit(cache=True)
def fill_frame(lm, tracking, rebuilt, layout, state, course_frames, roll_price, out):
    """One frame, in place (LegHinge.fill); ``layout`` and ``state``: LegHinge's arrays, as plain tuples."""
    legs = layout[0]
    shape, turn, bend, course, lost_frames, hip_distance = state
    pelvis, left_hip, right_hip = hip_centres(lm)
    settle_roll(lm, tracking, rebuilt, layout, hip_distance, roll_price, (left_hip, right_hip))
    now = np.empty((6, 3))
    for leg in range(2):
        if legs[leg, 4] < 0:
            continue
        seen = follow_marker(tracking[legs[leg, 4]], course[leg], lost_frames[leg:leg + 1])
        if not (vfinite(left_hip) and vfinite(right_hip)):
            continue
        now[HIP] = left_hip if leg == 0 else right_hip
        for i in range(4):
            now[FLE + i] = lm[legs[leg, i]]
        now[MARKER] = course[leg, 0]
        point = MARKER
        if not (seen or lost_frames[leg] <= course_frames):
            if not (vfinite(now[FAL]) and vfinite(shape[leg, FAL])):
                continue
            point = FAL
        knee_seen = vfinite(now[FLE]) and vfinite(now[FME])
        if seen and knee_seen:
            take_shape(now, shape[leg], turn[leg], pelvis)
            bend[leg] = 0.0
        elif not knee_seen and vfinite(shape[leg, HIP]):
            bend[leg] = put_leg(now, shape[leg], turn[leg], bend[leg], pelvis, point)
            for i in range(4):
                if not vfinite(lm[legs[leg, i]]) and vfinite(now[FLE + i]):
                    lm[legs[leg, i]] = now[FLE + i]
                    out[legs[leg, i]] = True


@njit(cache=True)
def follow_marker(marker, course, lost_frames):
    """The marker's course (its last position and step): True when it is seen; lost, it goes on at its
    last step (``course[0]``, while ``lost_frames`` counts up; NaN when it never was seen)."""
    if vfinite(marker):
        if lost_frames[0] == 0 and vfinite(course[0]):
            course[1] = marker - course[0]
        else:
            course[1] = 0.0
        course[0] = marker
        lost_frames[0] = 0
        return True
    lost_frames[0] += 1
    course[0] += course[1]
    return False


@njit(cache=True)
def take_shape(now, shape, turn, pelvis):
    """The leg seen (or rebuilt): its shape from this frame. A lost malleolus keeps its place on the shank
    (the rigid motion of epicondyles and marker since the last shape)."""
    if vfinite(shape[HIP]) and not (vfinite(now[FAL]) and vfinite(now[TAM])):
        before, after = np.empty((3, 3)), np.empty((3, 3))
        for r, m in enumerate((FLE, FME, MARKER)):
            before[r], after[r] = shape[m], now[m]
        rot, t = rigid_fit_first(before, after, before.shape[0])  # (a literal 3 would compile the fit again)
        for k in range(FAL, TAM + 1):
            if not vfinite(now[k]) and vfinite(shape[k]):
                now[k] = mv(rot, shape[k]) + t
    shape[:] = now
    turn[:] = pelvis.T  # (the thigh's turn in the pelvis frame: none in the world since this frame)


@njit(cache=True)
def put_leg(now, shape, turn, bend, pelvis, point):
    """The lost points of ``now`` put by the hip and a point on the shank (``point``: the marker, or the
    ankle while the marker is lost); returns the knee's bend."""
    axis = shape[FME] - shape[FLE]
    if vnorm(axis) < 1e-6:
        return bend
    axis /= vnorm(axis)
    # the bend that puts the point as far from the hip as it is (Rodrigues on the point's offset)
    v = shape[point] - shape[FLE]
    across, along = np.cross(axis, v), (axis @ v) * axis
    to_hip = shape[FLE] - shape[HIP]
    target = vnorm(now[point] - now[HIP])
    best, best_cost = bend, np.inf
    for step, half_width in ((SEARCH_STEP, MAX_BEND_STEP), (SEARCH_STEP / 10, SEARCH_STEP)):
        centre = best
        n = int(half_width / step)
        for i in range(-n, n + 1):
            phi = centre + i * step
            c, s = np.cos(phi), np.sin(phi)
            cost = abs(vnorm(to_hip + c * v + s * across + (1 - c) * along) - target) + BEND_PRICE_M * abs(phi - bend)
            if cost < best_cost:
                best, best_cost = phi, cost
    bent = axis_angle(axis, best)
    # the thigh turned with the pelvis, then as little as puts the marker in its direction from the hip,
    # then about the hip-marker line as keeps the knee's axis nearest its direction in the pelvis frame
    world = mm(pelvis, turn)
    was = mv(world, axis)
    line = now[point] - now[HIP]
    world = mm(rotation_between(mv(world, to_hip + mv(bent, v)), line), world)
    world = mm(_about_line(line, mv(world, axis), was), world)
    turn[:] = mm(pelvis.T.copy(), world)
    for k in range(FLE, TAM + 1):
        if vfinite(now[k]) or not vfinite(shape[k]):
            continue
        p = shape[k] - shape[HIP] if k < FAL else to_hip + mv(bent, shape[k] - shape[FLE])
        now[k] = now[HIP] + mv(world, p)
    return best


@njit(cache=True)
def _about_line(line, direction, target):
    """The turn about ``line`` that brings ``direction`` nearest ``target``."""
    u = line / vnorm(line)
    a, b = direction - (direction @ u) * u, target - (target @ u) * u
    if vnorm(a) < 1e-9 or vnorm(b) < 1e-9:
        return np.eye(3)
    return axis_angle(u, np.arctan2(u @ np.cross(a, b), a @ b))

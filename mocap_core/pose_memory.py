"""Lost knee and ankle landmarks from the poses the take has already shown (beyond the thesis).

The segment rebuild (mocap_core.segment_rebuild) needs three markers left on the bone. A sparse
marker set has none: the 28-marker dance set puts one marker on the knee, one on the ankle and two
on the toes, so with knee and ankle lost only the pelvis and the toe remain, and two degrees of
freedom (the knee's bend direction, the ankle's angle) are not observed at all. What is left is
what the actor has done before: while a leg is seen whole, its knee and ankle landmarks are
remembered in the pelvis's frame (tracked, so that its skin markers' shake stays out: track_pelvis),
together with where the toe was. Once they are lost (and the toe and the pelvis are seen), they are
put where the remembered poses whose toe was nearest had them (inverse-distance weighted, fitted),
smoothed over frames, starting from the last pose seen so that nothing jumps when the markers go.
The ankle goes as far from the toe as it was in those poses (the foot keeps it near the toe); the
knee goes where they had it in the pelvis's frame (the thigh keeps it near the hip), moved by 30 % of
how far the toe is from theirs (TOE_SHARE).

Where the profile names the foot's two toe markers one by one (its ``tracking`` markers of the foot:
the dance set's big-toe and little-toe markers, whose mean is the toe), the line between them tells
how the foot is turned, which the toe's place alone does not: the ankle's offset from the toe in each
remembered pose is turned as its foot's line is turned now (foot_line). Unless the two markers have
come apart from their learned spacing: then a marker is wrong, and the offsets are taken as they were.

Where the frames' times are known, the poses are also looked for by where the toe is going: a walking
toe passes each place twice a step, in the swing and in the stance, with the knee bent differently
(VELOCITY_S). The poses found are fitted, not averaged: the targets'
offsets as a linear function of the poses' toes, read off at the toe now (LOCAL_FIT_RIDGE).

A recalled ankle is held within the leg's reach: no farther from the hip joint centre than either leg's
ankle has been seen (a leg stretched with the foot pointed, where its poses had it flat, would otherwise
recall an ankle beyond the leg's reach).

Each leg also keeps the other leg's poses, mirrored across the body, and falls back on them for a
place of its own toe that none of its own comes within FALLBACK_M of (a dancer often does with one
leg what the other did before); the velocity's search then looks there too. Always pooled, they made
walks worse (the two legs' markers sit differently), so they are only a fallback.

The bone lengths learned online from located frames, taken one step further: the whole
leg's shape, learned from the same take. It never uses frames it has not seen (a live graph
learns from the frames before a gap) and never learns from landmarks that were themselves filled.
"""
from __future__ import annotations

from typing import Iterable, Sequence

import numpy as np
from numba import njit

from mocap_core.fill_units import LandmarkFill, MarkerSet, switch
from mocap_core.frame_clock import FrameClock
from mocap_core.ik.kernels import follow, mm, mtv, mv, rotation_between, rotation_vector, turned_by, vfinite, vnorm
from mocap_core.localization import hip_centres
from mocap_core.profiles import LANDMARK_INDEX, LANDMARKS
from mocap_core.remembered_poses import CAPACITY, keep, local_fit, nearest  # poses a leg; a pose per 5 mm of its key

POSE_MEMORY_HELP = ("beyond the thesis: lost knee and ankle landmarks put where the take's earlier poses with the "
                    "toe nearest where it is now had them (also by where the toe is going: the frames' "
                    "times give its velocity), the ankle held within the leg's reach, for marker sets with nothing "
                    "else left on shank and foot")
KEY = "FM2"                             # the toe: every profile has it
# The knee's and the ankle's landmarks, and how much of the toe's offset from the remembered poses'
# toes each takes along (0: where the poses had it in the pelvis's frame; 1: as far from the toe as
# it was there). The thigh keeps the knee near the hip, the foot the ankle near the toe.
TOE_SHARE = {"FLE": 0.3, "FME": 0.3, "TTC": 0.3, "FAL": 1.0, "TAM": 1.0}
# With the heel seen, the foot is tracked and the IK stage's segment carry does better than a memory of
# a few poses: legs whose heel is seen are left to it.
HEEL = "FCC"
# Remembered poses fitted. Over every shared take together (hidden elbows, knees and ankles, the worst case), 10
# gives a slightly lower mean error than 20 and 40 a higher one, but with 10 a recalled knee jumps where its markers
# come back (tests/core/test_blend.py); VELOCITY_S was chosen over every take with it.
NEIGHBOURS = 20
# How each setting below was chosen, with every value tried, is in docs/gap_filling.md ("The pose memory").
# No own pose had the toe this near: the other leg's, mirrored, if one did. Decided by the toe's place alone;
# the velocity's search then looks in the same memory (its own, larger distances fell back far too often).
FALLBACK_M = 0.1
# Per frame, how far the estimate moves towards the recalled answer, whose poses change as the toe moves: a
# smaller share lags behind a walking knee, a larger one lets the recall's jumps through at a marker's return.
SMOOTHING = 0.5
# The pelvis frame comes from three skin markers, whose shake turns it by a degree or two a frame (a degree is
# about 8 mm at the knee) and whose slips move its origin. An alpha-beta tracker of its axes and origin
# (Benedict-Bordner: the turn's and the step's gain is PELVIS_GAIN^2 / (2 - PELVIS_GAIN)) follows a steady
# motion without lag and takes only PELVIS_GAIN of a one-frame slip.
PELVIS_GAIN = 0.6
PELVIS_TURN_GAIN = PELVIS_GAIN ** 2 / (2.0 - PELVIS_GAIN)
PELVIS_RESET_RAD = 0.35  # 20 deg away from where the tracker expected it
# The foot's line (its two toe markers, the profile's tracking markers of the foot: foot_line) turns the
# ankle's offset from the toe: a remembered pose's foot may have pointed elsewhere with its toe in the same
# place (the ankle better on all eight dance-set legs; turning the knee's offset too made the knees worse).
FOOT_WIDTH_TOLERANCE = 0.2  # the toe markers' spacing off its learned value by more than this share: not used
FOOT_WIDTH_RATE = 1 / 100   # how fast the learned spacing follows the frames where the leg is seen whole
# ... and used only once the spacing has held this long (toe markers that come apart can be right again for a few
# frames; turning the ankle with them then makes it jump at a return)
FOOT_SOUND_S = 1 / 3
# A walking toe passes each place twice a step, forward in the swing and back (in the pelvis's frame) in the
# stance, with the knee bent differently each time. A second search finds the poses by the toe's place and
# VELOCITY_S times its velocity (where it will be VELOCITY_S from now), and each target is the two searches'
# answers weighted by how closely each one's poses agree (inverse variance): where the velocity tells nothing
# (a dancer standing on one foot) its poses spread and the place's answer stays.
VELOCITY_S = 0.4
# The poses found are fitted, not averaged (remembered_poses.local_fit): each target's offset as a linear
# function of where the pose's toe was, read off where the toe is now. At the edge of what the memory has seen
# the poses lie to one side and their mean is off by however the knee follows the toe there. The slope is
# pulled towards none (the weighted mean) by this ridge against the toes' weighted spread (m^2), so poses whose
# toes lie within a few cm of each other keep their mean.
LOCAL_FIT_RIDGE = 0.005
# A leg reaches no farther than it has been seen to: a recalled ankle beyond the farthest either leg's ankle has
# been from its hip joint centre goes, on its sphere about the toe, to that distance (the pose memory's poses
# may have had the foot flat where it is now pointed, the toe as far as the leg goes).
# ... learned so that one wrong frame cannot undo it: the reach grows by at most this a frame (a marker
# swapped for one frame 1 m off would otherwise leave the ankle free for the rest of the take).
REACH_GROWTH_M = 0.005
MAX_STEP_S = 0.1  # frames further apart than this give no velocity (the last one is kept)
SACR, L_IAS, R_IAS = LANDMARK_INDEX["SACR"], LANDMARK_INDEX["L_IAS"], LANDMARK_INDEX["R_IAS"]
L_TOE = LANDMARK_INDEX[f"L_{KEY}"]
FLIP = np.array([-1.0, 1.0, 1.0])  # mirrored across the body (the pelvis frame's x)
FLIP_KEY = np.array([-1.0, 1.0, 1.0, -1.0, 1.0, 1.0])  # a pose key: the toe and its velocity


class PoseMemory(LandmarkFill):
    """Fills lost knee and ankle landmarks frame by frame. Keep one per actor: it owns the poses.
    ``present``: the landmark names the profile has (LandmarkMap.present())."""
    Settings = switch("pose_memory", POSE_MEMORY_HELP)

    @classmethod
    def for_marker_set(cls, markers: MarkerSet) -> "PoseMemory":
        return cls(markers.present, markers.tracking_of)

    def __init__(self, present: Iterable[str], tracking_of: Sequence[str] = ()):
        present = set(present)
        width = len(TOE_SHARE)
        legs, share, kinds = [], [], []
        for side in ("L", "R"):
            targets = [t for t in TOE_SHARE if f"{side}_{t}" in present]
            if f"{side}_{KEY}" in present and targets:
                row = [LANDMARK_INDEX[f"{side}_{KEY}"], LANDMARK_INDEX[f"{side}_{HEEL}"], len(targets)]
                legs.append(row + [LANDMARK_INDEX[f"{side}_{t}"] for t in targets] + [-1] * (width - len(targets)))
                share.append([TOE_SHARE[t] for t in targets] + [0.0] * (width - len(targets)))
                kinds.append(targets)
        n = len(legs)
        # per leg, its foot's first two tracking markers (the toe's line; -1: none)
        self.n_tracking = len(tracking_of)
        self.foot = np.full((n, 2), -1, np.int64)
        for g in range(n):
            side = LANDMARKS[legs[g][0]][0]  # (the toe's landmark: "L_FM2")
            on_foot = [j for j, seg in enumerate(tracking_of) if seg == f"{side}_foot"]
            if len(on_foot) >= 2:
                self.foot[g] = on_foot[:2]
        # per leg: toe, heel, number of targets, the targets (-1 padding); each target's toe share
        self.legs = np.array(legs, np.int64).reshape(n, 3 + width)
        self.toe_share = np.array(share, np.float64).reshape(n, width)
        # the other leg, when it has the same landmarks: each side learns the other's poses too, mirrored
        same = n == 2 and kinds[0] == kinds[1]
        self.mirror = np.array([1, 0] if same else [-1] * n, np.int64)
        # per leg, its own poses [0] and the other leg's, mirrored [1]:
        self.keys = np.full((n, 2, CAPACITY, 6), np.inf)      # the toes (pelvis frame), VELOCITY_S x their velocity
        # and the targets then, and last the foot's line (unit; zero: not known), in the pelvis frame
        self.offsets = np.zeros((n, 2, CAPACITY, width + 1, 3))
        self.state = np.zeros((n, 2, 2), np.int64)           # poses kept, where the next one goes
        self.last_kept = np.full((n, 2, 6), np.inf)          # the key of the last pose kept
        self.last_seen = np.full((n, width, 3), np.nan)      # the targets of the last frame seen whole
        self.estimate = np.full((n, width, 3), np.nan)       # the smoothed targets during a gap (NaN: none)
        self.foot_width = np.full(n, np.nan)                 # the learned spacing of the foot's toe markers
        self.foot_sound = np.zeros(n, np.int64)              # and for how many frames it has held
        self.clock = FrameClock(1 / 60)                      # (the frames' interval, from their times)
        self.reach = np.zeros(n)                             # the farthest its ankle has been from its hip
        self.toe_motion = np.full((n, 3, 3), np.nan)         # per leg: the last toe (pelvis frame), its velocity,
        self.toe_motion[:, 1] = 0.0                          # and [2, 0] its time (no velocity yet: zero)
        self._nothing_filled: np.ndarray | None = None
        self._no_tracking, self._no_foot = np.zeros((0, 3)), np.full_like(self.foot, -1)
        self.pelvis_axes = np.zeros((3, 3))                  # the tracked pelvis frame (track_pelvis): its axes,
        self.pelvis_motion = np.zeros((4, 3))                # origin, step, turn per frame, and tracking or not
        # (as the kernel takes them)
        self._memory = (self.keys, self.offsets, self.state, self.last_kept)
        self._state = (self.last_seen, self.estimate, self.pelvis_axes, self.pelvis_motion, self.foot_width,
                       self.foot_sound, self.reach, self.toe_motion)

    def fill(self, landmarks, tracking=None, time_s=np.nan, markers=None, filled=None) -> np.ndarray:
        """One frame (LandmarkFill.fill), in place. ``time_s`` NaN: the poses are found by the toe's place
        alone."""
        if filled is None:
            if self._nothing_filled is None or len(self._nothing_filled) != len(landmarks):
                self._nothing_filled = np.zeros(len(landmarks), np.bool_)
            filled = self._nothing_filled
        out = np.zeros(len(landmarks), np.bool_)
        if tracking is None:
            tracking, foot = self._no_tracking, self._no_foot
        elif len(tracking) != self.n_tracking:  # (as the segment rebuild: a caller's mistake, not bad input)
            raise ValueError(f"expected {self.n_tracking} tracking markers, got {len(tracking)}")
        else:
            tracking, foot = np.asarray(tracking, np.float64), self.foot
        if len(self.legs):
            self.clock.advance(float(time_s))
            fill_frame((landmarks, filled, tracking, float(time_s)), (self.legs, self.mirror, self.toe_share, foot),
                       self._memory, self._state, self.clock.frames(FOOT_SOUND_S), out)
        return out


@njit(cache=True)
def pelvis_frame(lm, origin, rot):
    """The pelvis's origin (between the ASIS) and axes (columns: x to the left ASIS, z up from the
    sacrum's side), written into ``origin`` and ``rot``; False when a pelvis landmark is lost."""
    left, right, sacrum = lm[L_IAS], lm[R_IAS], lm[SACR]
    if not (vfinite(left) and vfinite(right) and vfinite(sacrum)):
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


ORIGIN, STEP, TURN, TRACKING = range(4)  # the rows of PoseMemory.pelvis_motion


@njit(cache=True)
def track_pelvis(origin, rot, axes, motion):
    """The pelvis frame (``origin``, axes ``rot``), replaced by an alpha-beta tracker's (``axes``, and
    ``motion``'s rows ORIGIN ... TRACKING: the origin, its step, the axes' turn per frame in their own
    axes, and 1 once tracking). A steady motion is followed without lag; a hip marker's one-frame slip
    moves the frame by PELVIS_GAIN of it."""
    if motion[TRACKING, 0] != 0.0:
        predicted = turned_by(axes, motion[TURN])
        miss = rotation_vector(mm(predicted.T.copy(), rot))
        if vnorm(miss) <= PELVIS_RESET_RAD:  # (past it, a real jolt or a relabelled marker: start again)
            axes[:] = turned_by(predicted, PELVIS_GAIN * miss)
            motion[TURN] += PELVIS_TURN_GAIN * miss
            rot[:] = axes
            shift = origin - (motion[ORIGIN] + motion[STEP])
            motion[ORIGIN] += motion[STEP] + PELVIS_GAIN * shift
            motion[STEP] += PELVIS_TURN_GAIN * shift
            origin[:] = motion[ORIGIN]
            return
    axes[:] = rot
    motion[:] = 0.0
    motion[ORIGIN] = origin
    motion[TRACKING, 0] = 1.0


@njit(cache=True)
def foot_line(tracking, pair, rot, learned):
    """The foot's line (unit, in the pelvis frame ``rot``) from its two toe markers ``pair`` of
    ``tracking``, and their spacing; zero and NaN when one is lost or the spacing is off the ``learned``
    one by more than FOOT_WIDTH_TOLERANCE (a marker is then wrong)."""
    line = np.zeros(3)
    if pair[0] < 0 or not (vfinite(tracking[pair[0]]) and vfinite(tracking[pair[1]])):
        return line, np.nan
    d = tracking[pair[1]] - tracking[pair[0]]
    width = vnorm(d)
    if width < 1e-6 or (learned == learned and abs(width - learned) > FOOT_WIDTH_TOLERANCE * learned):
        return line, np.nan
    return mtv(rot, d / width), width


@njit(cache=True)
def toe_velocity(motion, toe, time_s):
    """``motion``: the leg's last toe, its velocity and [2, 0] the last time; updated with this frame's toe
    (pelvis frame). The velocity stays as it was when the frames' times do not give one."""
    step = time_s - motion[2, 0]
    if vfinite(motion[0]) and 0.0 < step <= MAX_STEP_S:  # (NaN times fail both)
        motion[1] = (toe - motion[0]) / step
    motion[0], motion[2, 0] = toe, time_s


@njit(cache=True)
def recall(memory, point, source, line, share, nt, width):
    """The targets' offsets (nt, 3) where the NEIGHBOURS poses of one leg's ``memory`` ((keys, offsets,
    state): its own [0] and the other leg's [1]) whose key is nearest ``point`` had them, less each
    target's ``share`` of its toe; a target kept as far from the toe as it was (share 1) turned as the foot's
    ``line`` has turned since, when both are known. ``point``: the toe (3: the keys' first three numbers are
    compared), or the toe and its velocity (6). ``source``: the memory searched, the leg's own (0) or the
    other leg's (1), or -1: the leg's own, unless none of its poses comes within FALLBACK_M of ``point`` and
    one of the other leg's is nearer.
    Each offset is the local fit's (remembered_poses.local_fit) at the toe's place. Also returns how far the
    poses' offsets spread about their weighted mean (nt: the weighted variance, m^2), and the memory searched."""
    keys, offsets, state = memory
    best_d, best_i = np.full(NEIGHBOURS, np.inf), np.empty(NEIGHBOURS, np.int64)
    nearest(keys[max(source, 0)], state[max(source, 0), 0], point, best_d, best_i)
    if source < 0:
        source = 0
        if best_d[0] > FALLBACK_M and state[1, 0] >= NEIGHBOURS:
            other_d, other_i = np.full(NEIGHBOURS, np.inf), np.empty(NEIGHBOURS, np.int64)
            nearest(keys[1], state[1, 0], point, other_d, other_i)
            if other_d[0] < best_d[0]:  # the other leg has been nearer this pose: its poses, mirrored
                best_d, best_i, source = other_d, other_i, 1
    weights, toe_offsets = np.empty(NEIGHBOURS), np.empty((NEIGHBOURS, 3))
    found = np.empty((NEIGHBOURS, nt, 3))
    turning = vnorm(line) > 0.0  # (no line now: nothing to turn)
    turn = np.eye(3)
    for n in range(NEIGHBOURS):
        weights[n] = 1.0 / (best_d[n] + 1e-3)
        pose, pose_toe = offsets[source, best_i[n]], keys[source, best_i[n], :3]
        toe_offsets[n] = pose_toe - point[:3]
        if turning:  # (the identity when the pose had no line)
            turn = rotation_between(pose[width], line)
        for t in range(nt):
            offset = pose[t] - share[t] * pose_toe
            found[n, t] = mv(turn, offset) if turning and share[t] == 1.0 else offset
    weights /= weights.sum()
    every = found.reshape(NEIGHBOURS, nt * 3)  # (one fit for all the targets: the poses' toes are the same)
    average = (weights @ every).reshape(nt, 3)
    spread = np.empty(nt)
    for t in range(nt):
        spread[t] = max(weights @ ((found[:, t] - average[t]) ** 2).sum(axis=1), 1e-8)
    mean = np.ascontiguousarray(local_fit(weights, toe_offsets, every, LOCAL_FIT_RIDGE)).reshape(nt, 3)
    return mean, spread, source


@njit(cache=True)
def grown_reach(reach, far):
    """The reach learned so far, after a frame that had the ankle ``far`` from the hip (the first sets it)."""
    return far if reach == 0.0 else max(reach, min(far, reach + REACH_GROWTH_M))


@njit(cache=True)
def within_reach(point, toe, hip, reach):
    """``point`` if it is within ``reach`` of ``hip``; else the nearest point to it as far from ``toe`` as it is
    and ``reach`` from ``hip`` (on the line from the toe towards the hip when none is)."""
    if not (vnorm(point - hip) > reach and vfinite(hip)):
        return point
    radius, apart = vnorm(point - toe), vnorm(hip - toe)
    axis = (hip - toe) / max(apart, 1e-9)
    along = (radius * radius - reach * reach + apart * apart) / (2.0 * max(apart, 1e-9))
    across = (point - toe) - ((point - toe) * axis).sum() * axis
    ring = radius * radius - along * along
    if ring <= 0.0 or vnorm(across) < 1e-9:
        return toe + radius * axis
    return toe + along * axis + np.sqrt(ring) * across / vnorm(across)


@njit(cache=True)
def fill_frame(frame, layout, memory, state, sound_frames, out):
    """One frame, in place (PoseMemory.fill), as plain tuples: ``frame`` (lm, filled, tracking, time_s); ``layout``
    (legs, mirror, toe_share, foot); ``memory`` (keys, offsets, state, last_kept); ``state`` (last_seen, estimate,
    pelvis_axes, pelvis_motion, foot_width, foot_sound, reach, toe_motion). ``out``: the landmarks put."""
    lm, legs, pelvis_axes, pelvis_motion = frame[0], layout[0], state[2], state[3]
    origin, rot = np.empty(3), np.empty((3, 3))
    if not pelvis_frame(lm, origin, rot):
        pelvis_motion[TRACKING, 0] = 0.0
        return
    track_pelvis(origin, rot, pelvis_axes, pelvis_motion)
    _, left_hip, right_hip = hip_centres(lm)
    seen = np.zeros((legs.shape[1] - 2, 3))  # the targets, then the foot's line (one buffer for both legs)
    for g in range(legs.shape[0]):
        hip = left_hip if legs[g, 0] == L_TOE else right_hip
        _fill_leg(g, frame, layout, memory, state, (origin, rot, hip, seen), sound_frames, out)


@njit(cache=True, inline="always")
def _fill_leg(g, frame, layout, memory, state, pelvis, sound_frames, out):
    """Leg ``g``: learn its pose where it is seen whole; else put its lost targets where the poses learned had
    them. ``pelvis``: (origin, axes, this leg's hip centre, a buffer for the pose)."""
    lm, filled, tracking, time_s = frame
    legs, mirror, toe_share, foot = layout
    keys, offsets, kept, _ = memory
    last_seen, estimate, _, _, foot_width, foot_sound, reach, toe_motion = state
    origin, rot, hip, _ = pelvis
    key, heel, nt = legs[g, 0], legs[g, 1], legs[g, 2]
    width = legs.shape[1] - 3
    toe = lm[key].copy()
    if not vfinite(toe):
        estimate[g, 0, 0] = np.nan
        toe_motion[g, 0, 0] = np.nan
        return
    local_toe = mtv(rot, toe - origin)
    toe_velocity(toe_motion[g], local_toe, time_s)
    pose_key = np.empty(6)
    pose_key[:3], pose_key[3:] = local_toe, VELOCITY_S * toe_motion[g, 1]
    line, spacing = foot_line(tracking, foot[g], rot, foot_width[g])
    foot_sound[g] = foot_sound[g] + 1 if spacing == spacing else 0
    line = line if foot_sound[g] >= sound_frames else np.zeros(3)
    lost, measured = False, not filled[key]
    for t in range(nt):
        lost = lost or not vfinite(lm[legs[g, 3 + t]])
        measured = measured and not filled[legs[g, 3 + t]]
    if not lost or vfinite(lm[heel]):  # seen whole, or the foot is tracked (segment carry)
        estimate[g, 0, 0] = np.nan
        if not lost and measured:
            _keep_pose(g, lm, layout, memory, state, pelvis, (local_toe, pose_key, line))
            if spacing == spacing:
                foot_width[g] = follow(foot_width[g], spacing, FOOT_WIDTH_RATE)
        return
    if kept[g, 0, 0] < NEIGHBOURS:
        return
    # the poses found by the toe's place, and by its place and velocity (VELOCITY_S), in the same memory: each
    # target from both, weighted by how closely each search's poses agree
    leg_memory = (keys[g], offsets[g], kept[g])
    mean, place_spread, source = recall(leg_memory, local_toe, -1 if mirror[g] >= 0 else 0, line, toe_share[g], nt,
                                        width)
    by_motion, motion_spread, _ = recall(leg_memory, pose_key, source, line, toe_share[g], nt, width)
    for t in range(nt):
        w = place_spread[t] / (place_spread[t] + motion_spread[t])
        mean[t] = w * by_motion[t] + (1.0 - w) * mean[t]
    if np.isnan(estimate[g, 0, 0]):  # the gap begins: from the last pose seen, so nothing jumps
        if np.isnan(last_seen[g, 0, 0]):
            estimate[g, :nt] = mean
        else:
            estimate[g, :nt] = last_seen[g, :nt]
    estimate[g, :nt] += SMOOTHING * (mean - estimate[g, :nt])
    for t in range(nt):
        k = legs[g, 3 + t]
        if not vfinite(lm[k]):
            lm[k] = origin + mv(rot, estimate[g, t] + toe_share[g, t] * local_toe)
            if toe_share[g, t] == 1.0 and reach[g] > 0.0:
                lm[k] = within_reach(lm[k], toe, hip, reach[g])
            out[k] = True


@njit(cache=True, inline="always")
def _keep_pose(g, lm, layout, memory, state, pelvis, pose):
    """Leg ``g`` seen whole: keep its pose (and, mirrored, as one the other leg may fall back on) and how far it
    reaches. ``pose``: (the toe in the pelvis frame, the pose's key, the foot's line)."""
    legs, mirror, toe_share, _ = layout
    keys, offsets, kept, last_kept = memory
    last_seen, reach = state[0], state[6]
    origin, rot, hip, seen = pelvis
    local_toe, pose_key, line = pose
    nt, width = legs[g, 2], legs.shape[1] - 3
    for t in range(nt):
        seen[t] = mtv(rot, lm[legs[g, 3 + t]] - origin)
        last_seen[g, t] = seen[t] - toe_share[g, t] * local_toe
    seen[width] = line
    keep(keys[g, 0], offsets[g, 0], kept[g, 0], last_kept[g, 0], pose_key, seen)
    for t in range(nt):
        if toe_share[g, t] == 1.0:  # (an ankle: how far the leg reaches, for either leg)
            far = vnorm(lm[legs[g, 3 + t]] - hip)
            reach[g] = grown_reach(reach[g], far)
            if mirror[g] >= 0:
                reach[mirror[g]] = grown_reach(reach[mirror[g]], far)
    other = mirror[g]
    if other >= 0:  # and, mirrored, as a pose the other leg may fall back on
        keep(keys[other, 1], offsets[other, 1], kept[other, 1], last_kept[other, 1], pose_key * FLIP_KEY,
             seen * FLIP)

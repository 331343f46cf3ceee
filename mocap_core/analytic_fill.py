"""Gap filling beyond the thesis, without iterating (numba kernels; gapfill.LimbFiller calls them).

- swivel_fill: a run of missing joints between two located ones. Its first joint lies on the circle
  of its bone and of its distance to the located joint after the run (which the run's last shape
  keeps); where on the circle is the last well-defined bend direction, carried in the frame of the
  located joint after the run, else of the limb's parent, and turned to where the bone's direction
  in that joint's frame is nearest its usual one, each of its three components weighted by how
  steady it has been (the forearm in the wrist's frame). The rest of the run keeps its last shape.
  A lone joint's two bones are the last whole frame's, or (learn_lengths) their mean over the
  frames that located them.
- segment_carry: a lost ankle moves with its still-tracked foot (ankle, foot and toe are one body).
- carry_lost_end: a lost end of the limb moves with the last tracked bone before it.
- blend_transitions: a joint that changes source (markers lost or back) goes on where it was heading,
  and the offset to the new source dies out (inertialization); after a loss it leaves its markers'
  course for the fill only as the course grows less trustworthy than that fill has been.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from mocap_core.ik.kernels import (angle_about, axis_angle, mm, mtv, mv, rotation_between, rotation_vector, vcross,
                                   vdot, vnorm)

MISSING, LOCATED, ESTIMATED, HELD = 0, 1, 2, 3   # mocap_core.skeleton.Status
MIN_SAMPLES = 30    # located frames before a bone's direction in the next joint's frame is trusted
# Where on the swivel circle: the bone's direction in the next joint's frame nearest its usual one,
# every component weighted by 1 / (its variance + SD_FLOOR^2), plus TURN_WEIGHT per squared radian
# of turn from the carried bend direction (which only settles near-ties). Leaning on the steadiest
# component alone (the forearm along the hand, SD 0.005) failed whenever the wrist flexed: the
# dance set's elbows, hidden from 1 s, were 18-76 mm off on average, 66-228 mm at worst; with all
# three weighted, 10-54 / 33-264 mm (dance1 left 16 / 55, right 41 -> 10 mean).
SD_FLOOR = 0.02
TURN_WEIGHT = 1.0
FIT_STEPS = 360     # a coarse pass over the whole circle (1 degree), then a fine one around the best
# With the limb memory (mocap_core.limb_memory) on, the joint is also pulled towards where the earlier
# poses had it, as if that point were this far off (SD, metres). Dance set, elbows hidden from 1 s
# (prototype): 0.017 m left dance2 and walk2 at 19-34 mm mean, 0.0095 at 14-36, 0.0055 at 12-39.
MEMORY_SD = 0.01
# A critically damped spring from rest, offset o0, is o0 (1 + w t) e^(-w t): it is halved at t = BLEND_X / w.
BLEND_X = 1.6783469900166612
# Faster than this, an estimate has jumped to another source (no joint moves so fast: the karate kata's strikes
# take the wrist to 4-7 m/s); the Vicon take's held left wrist jumped 147 and 286 mm in a frame (18-34 m/s).
SOURCE_JUMP_M_S = 10.0
# A source seen again within this many frames (a flickering marker) gets its step from its last sighting.
FLICKER_FRAMES = 5
# Seconds between frames when the caller gives no capture times (the blend's spring needs them).
DEFAULT_FRAME_S = 0.01
# After a loss, the output leaves the markers' course for the fill only as fast as the course can be trusted
# less than the fill (the dead blending of game engines, weighted): by w = c^2 / (c^2 + s^2), where
# c = COURSE_K * |a| t^2 / 2 is how far the course may have strayed t seconds on (|a| the joint's mean
# acceleration while located, at least ACCEL_FLOOR) and s the fill's RMS miss where the markers came back
# (FILL_SD_PRIOR counting as one such), the spring's offset included. Both are learned per joint: on
# dance2's short gaps the pose memory's knee misses by 42 mm RMS and stays on its course longer, the
# elbows by 21-24 mm, the sprint's rebuilt elbow by 10 mm (its arm accelerating at 13 m/s^2).
# The spring's offset alone gave the course up at once, at the fill's own velocity: on dance2's knee and
# ankle (0.1 s hidden in every 0.5 s) a fill that moved 30 mm a frame where the markers moved 5.
# Short gaps, the studio options (prototype): knee+ankle on dance2 left 17.9 / 17.8 mm mean -> 11.1 /
# 10.4, right 15.6 / 15.7 -> 10.0 / 10.7, dance1 left 13.5 / 13.5 -> 11.3 / 8.6; dance2's elbows 9.1 /
# 10.4 -> 9.5 / 9.6; the sprint's elbow 4.0 -> 5.6 (its arms swing hardest; the spring's offset alone
# keeps a rebuild's steady bias better). COURSE_K 1: dance2's elbows 13 mm, the sprint 12; 10: the knees
# 13-15 mm. Without the weight (a fixed ease over 0.2 s) the sprint was 31 mm; the miss of the raw fill
# instead of the output's, the sprint 6.2; the course's own misses at returns learned too, 8.3.
COURSE_K = 3.0
ACCEL_FLOOR = 1.0       # m/s^2
FILL_SD_PRIOR = 0.01    # metres
# reacquire_step_m caps how far the blend moves the output off its source in a frame; a source moving over
# four times that may be left or met at a quarter of its own step. A kicking foot lost at 10 mm a frame, its
# fill running on at 60, fell 0.75 m behind at the 10 mm cap, and then took 0.65 s to meet its markers (stop
# 29: the Vicon take's right foot at frame 534). A half: the Vicon take's moves of filled joints over 1.5x
# their normal went 24 -> 101 and dance1's ankle came back at 1.56x its normal step on short gaps; a
# quarter: 68, and 1.47x as before.
PACE_SHARE = 0.25
EASED = 0.999           # the weight at which the fill is taken whole
# While a fill stands in for the markers, the output stays within this of it. The markers' course runs on
# straight at their last step, and the step cap lets the output leave it at 10 mm a frame: a hand lost in a
# strike at 65 mm a frame (karate, a whole arm hidden 1 s in every 2 s) flew 1.2 m off its held fill in 0.2 s,
# and the offsets that came back with it, closed at the same cap, piled up gap after gap (2.0 m off on average,
# 7.1 m at worst; dance2's hand 1.8 / 4.6 m). At 0.5 m: 0.23 / 0.84 m and 0.43 / 1.06 m, and not one figure of
# the short-gap, long-gap or real-gap tables moved (it never binds there); at 0.3 m the Vicon take's kicking
# ankle, whose held fill is the one that is wrong, went 117 -> 214 mm at worst.
MAX_APART_M = 0.5
# BlendState.trust's columns: |acceleration| summed while located and how many; the output's squared misses
# where the markers came back and how many; frames located in a row.
ACC_SUM, ACC_N, MISS_SQ, MISS_N, LOCATED_RUN = range(5)
# How far a lost joint's frame turns with the plane of its two bones (shape_turn): not at all below a bend of
# STRAIGHT_SIN (about 3 degrees), wholly from STRAIGHT_SIN + PLANE_RANGE (17 degrees). Nearly straight, the plane is
# noise: a lost joint out of its neighbours' reach (put on their line) turned its frame about an arbitrary axis
# (the Vicon take's left shoulder, its acromion lost, turned 130-175 degrees a frame, and the held wrist and hand
# it carries moved 83 mm a frame), and a lone wrist bent 4-6 degrees turned 45 degrees a frame (135 degrees in 4
# frames where its markers, seen on either side, turned 15).
STRAIGHT_SIN = 0.05
PLANE_RANGE = 0.25
BEND_MIN = 0.1      # a bend direction is trusted when the middle joint is off the line by 10 % of its bone


@njit(cache=True)
def all_finite(a):
    for v in a.ravel():
        if not np.isfinite(v):
            return False
    return True


@njit(cache=True)
def learn_directions(positions, frames, status, idx, dir_sum, dir_sq, dir_n):
    """Accumulate each bone's direction in the frame of the joint it ends at, while both are located."""
    for k in range(1, idx.shape[0] - 1):
        if status[idx[k]] != LOCATED or status[idx[k + 1]] != LOCATED:
            continue
        bone = positions[idx[k + 1]] - positions[idx[k]]
        size = vnorm(bone)
        frame = frames[idx[k + 1]].copy()
        if size > 1e-6 and all_finite(frame):
            local = mtv(frame, bone / size)
            for c in range(3):
                dir_sum[k, c] += local[c]
                dir_sq[k, c] += local[c] * local[c]
            dir_n[k] += 1


@njit(cache=True)
def learn_lengths(positions, status, idx, lengths):
    """Accumulate each bone's length (sum, count) while both its joints are located: bones are rigid,
    and one frame's length (the last one seen before a gap) carries that frame's marker noise."""
    for k in range(idx.shape[0] - 1):
        if status[idx[k]] == LOCATED and status[idx[k + 1]] == LOCATED:
            size = vnorm(positions[idx[k + 1]] - positions[idx[k]])
            if np.isfinite(size):
                lengths[k, 0] += size
                lengths[k, 1] += 1


@njit(cache=True)
def _length(lengths, k, last):
    """Bone k's learned length once MIN_SAMPLES frames showed it, else its length in the last frame."""
    return lengths[k, 0] / lengths[k, 1] if lengths[k, 1] >= MIN_SAMPLES else last


@njit(cache=True)
def swivel_circle(root, target, upper, lower):
    """The circle of the points ``upper`` from ``root`` and ``lower`` from ``target`` (apart): its centre, axis
    (from root to target) and radius (0 out of reach: the point of the line nearest both)."""
    dist = vnorm(target - root)
    axis = (target - root) / dist
    along = min(upper, max(-upper, (upper * upper - lower * lower + dist * dist) / (2 * dist)))
    return root + along * axis, axis, math.sqrt(max(upper * upper - along * along, 0.0))


@njit(cache=True)
def nearest_on_circle(point, root, target, upper, lower):
    """The point of swivel_circle(root, target, upper, lower) nearest ``point`` (``point`` itself where that is
    not defined: ends together, or the point on the axis)."""
    if not vnorm(target - root) > 1e-9:
        return point
    centre, axis, radius = swivel_circle(root, target, upper, lower)
    v = point - centre
    v = v - vdot(v, axis) * axis
    size = vnorm(v)
    if not size > 1e-9:
        return point
    return centre + v * (radius / size)


@njit(cache=True)
def _frame_along(y, like):
    """A bone frame whose y runs along ``y``, turned from ``like`` by the shortest arc."""
    return mm(rotation_between(like[:, 1].copy(), y), like)


@njit(cache=True)
def _plane_frame(first, second):
    """Orthonormal frame (columns) with x along ``second`` and y in the plane of the two bones (not straight)."""
    x = second / vnorm(second)
    y = first - vdot(first, x) * x
    y = y / vnorm(y)
    out = np.empty((3, 3))
    out[:, 0], out[:, 1], out[:, 2] = x, y, vcross(x, y)
    return out


@njit(cache=True)
def _bend_sin(first, second):
    """The sine of the angle between two bones (0: a straight limb, or a bone of no length)."""
    size = vnorm(first) * vnorm(second)
    return vnorm(vcross(first, second)) / size if size > 1e-12 else 0.0


@njit(cache=True)
def shape_turn(first_before, second_before, first, second):
    """The rotation that carries two bones' last shape onto their new one: the least rotation of the second
    bone, then the least roll about it that turns their plane with them, taken whole once both shapes bend by
    STRAIGHT_SIN + PLANE_RANGE and not at all below STRAIGHT_SIN (a nearly straight shape's plane is noise)."""
    least = rotation_between(second_before, second)
    bend = min(_bend_sin(first_before, second_before), _bend_sin(first, second))
    share = min(1.0, max(0.0, (bend - STRAIGHT_SIN) / PLANE_RANGE))
    if share == 0.0:
        return least
    axis = second / vnorm(second)
    rolled = mv(least, _plane_frame(first_before, second_before)[:, 1].copy())
    plane_y = _plane_frame(first, second)[:, 1].copy()
    roll = angle_about(axis, rolled, plane_y)
    # a plane, not a side of it: a lone joint that crosses its neighbours' line between two frames (a wrist bent
    # 6 degrees with a 47 mm hand, 5 mm aside) flips its bend's side, not its bone by a half turn (the Vicon
    # take's right wrist turned 180 degrees in a frame at frame 945 so); no bone rolls 90 degrees in a frame
    if roll > 0.5 * math.pi:
        roll -= math.pi
    elif roll < -0.5 * math.pi:
        roll += math.pi
    return mm(axis_angle(axis, share * roll), least)


@njit(cache=True)
def _fit_cost(psi, u, e2, radius, to_target, ref, mean, weight, to_recalled, pull):
    arm = radius * (math.cos(psi) * u + math.sin(psi) * e2)
    d = to_target - arm
    local = mtv(ref, d / vnorm(d))
    cost = TURN_WEIGHT * psi * psi
    for c in range(3):
        cost += weight[c] * (local[c] - mean[c]) ** 2
    gap = arm - to_recalled
    return cost + pull * vdot(gap, gap)


@njit(cache=True)
def on_circle_fitting(u, axis, radius, to_target, ref, mean, weight, to_recalled, pull):
    """The direction on the swivel circle (from its centre; ``u`` is the prior, on the circle) at which
    the bone to the target, in the target joint's frame ``ref``, is nearest its usual direction
    ``mean``, component by component with ``weight`` (see SD_FLOOR), and the joint nearest the point
    the limb memory recalled (``to_recalled`` from the centre), with ``pull`` per square metre."""
    if not radius > 1e-6:
        return u
    e2 = vcross(axis, u)
    best, best_cost = 0.0, _fit_cost(0.0, u, e2, radius, to_target, ref, mean, weight, to_recalled, pull)
    step = 2 * math.pi / FIT_STEPS
    for i in range(FIT_STEPS):
        psi = -math.pi + i * step
        cost = _fit_cost(psi, u, e2, radius, to_target, ref, mean, weight, to_recalled, pull)
        if cost < best_cost:
            best, best_cost = psi, cost
    centre = best
    for i in range(-20, 21):  # then to a twentieth of a degree
        psi = centre + i * step / 20
        cost = _fit_cost(psi, u, e2, radius, to_target, ref, mean, weight, to_recalled, pull)
        if cost < best_cost:
            best, best_cost = psi, cost
    return math.cos(best) * u + math.sin(best) * e2


@njit(cache=True)
def usual_direction(k, dir_sum, dir_sq, dir_n):
    """(mean, weight) of each component of bone k's direction in the next joint's frame."""
    mean, weight = np.zeros(3), np.zeros(3)
    for c in range(3):
        m = dir_sum[k, c] / dir_n[k]
        mean[c] = m
        weight[c] = 1.0 / (max(dir_sq[k, c] / dir_n[k] - m * m, 0.0) + SD_FLOOR * SD_FLOOR)
    return mean, weight


@njit(cache=True)
def _fill_run(positions, frames, status, idx, a, k, b, parent_now, prev_parent, prev_pos, prev_frames,
              bend, bend_ok, dir_sum, dir_sq, dir_n, recalled, lengths, modelled, model_weight):
    pa, pk, pb = prev_pos[a], prev_pos[k], prev_pos[b]
    upper, lower = vnorm(pk - pa), vnorm(pb - pk)
    if b == k + 1:  # a lone joint: both its bones as learned
        upper, lower = _length(lengths, a, upper), _length(lengths, k, lower)
    # (a longer run keeps its last shape, from the hip to the toe, say, with the knee, ankle and foot
    # lost: its bones stay as they were, so the toe stays in reach. A learned thigh with the shape's
    # last knee-toe distance left it out of reach on dance1, the plane of hip, knee and toe undefined,
    # and the ankle 240 mm off where the last frame's lengths give 77.)
    root, target = positions[idx[a]].copy(), positions[idx[b]].copy()
    if not (vnorm(target - root) > 1e-9 and upper > 0 and lower > 0):
        return 0
    centre, axis, radius = swivel_circle(root, target, upper, lower)
    d_prev = pb - pa
    u_prev = (pk - pa) - (vdot(pk - pa, d_prev) / vdot(d_prev, d_prev)) * d_prev
    ref_now, ref_prev, kind = frames[idx[b]].copy(), prev_frames[b].copy(), 0
    if not (all_finite(ref_now) and all_finite(ref_prev)):
        ref_now, ref_prev, kind = parent_now, prev_parent.copy(), 1
    # A nearly straight limb (a knee at mid-stance) has no bend direction worth the name: its sign
    # is noise. Keep the last well-defined one, in the reference frame.
    size = vnorm(u_prev)
    if size > BEND_MIN * upper:
        bend[k, b, kind] = mtv(ref_prev, u_prev / size)
        bend_ok[k, b, kind] = True
    if bend_ok[k, b, kind]:
        local = bend[k, b, kind].copy()
    elif size > 1e-9:
        local = mtv(ref_prev, u_prev / size)
    else:
        return 0
    u = mv(ref_now, local)
    u = u - vdot(u, axis) * axis
    nu = vnorm(u)
    if not nu > 1e-9:
        return 0
    u = u / nu
    mean, weight = np.zeros(3), np.zeros(3)
    fit = False
    if b == k + 1 and kind == 0 and status[idx[b]] == LOCATED and dir_n[k] >= MIN_SAMPLES:
        mean, weight = usual_direction(k, dir_sum, dir_sq, dir_n)  # a measured frame, not a carried one
        fit = True
    pull, to_recalled = 0.0, np.zeros(3)
    if b == k + 1 and all_finite(recalled[k]):
        pull, to_recalled = 1.0 / (MEMORY_SD * MEMORY_SD), recalled[k] - centre
        fit = True
    if fit:
        u = on_circle_fitting(u, axis, radius, target - centre, ref_now, mean, weight, to_recalled, pull)
    if b == k + 1 and model_weight[k] > 0 and all_finite(modelled[k]):
        u = _turn_towards(u, axis, modelled[k] - centre, model_weight[k])
    joint = centre + radius * u
    positions[idx[k]] = joint
    # the rest of the run: its last shape, turned with the plane of (a, k, b)
    turn = shape_turn(pk - pa, pb - pk, joint - root, target - joint)
    for j in range(k + 1, b):
        positions[idx[j]] = joint + mv(turn, prev_pos[j] - pk)
    for j in range(k, b):
        frames[idx[j]] = mm(turn, prev_frames[j])
        status[idx[j]] = ESTIMATED
    if not all_finite(frames[idx[b]]):
        frames[idx[b]] = mm(turn, prev_frames[b])
    like = frames[idx[a]].copy()
    if not all_finite(like):
        like = mm(mm(parent_now, prev_parent.T.copy()), prev_frames[a])
    frames[idx[a]] = _frame_along(joint - root, like)
    return b - k


@njit(cache=True)
def _turn_towards(u, axis, to_point, weight):
    """The direction ``weight`` of the way from ``u`` to ``to_point``'s, both on the circle about ``axis``
    (the mean of the two points on the circle, put back on it; u where they are opposite)."""
    v = to_point - vdot(to_point, axis) * axis
    size = vnorm(v)
    if not size > 1e-9:
        return u
    w = (1.0 - weight) * u + weight * v / size
    size = vnorm(w)
    return w / size if size > 1e-9 else u


@njit(cache=True)
def swivel_fill(positions, frames, status, idx, parent, prev_pos, prev_frames, prev_parent, bend, bend_ok,
                dir_sum, dir_sq, dir_n, recalled, lengths, modelled, model_weight):
    """Fill every run of missing joints that has a located joint on both sides; returns how many.
    ``recalled``: per chain joint, where the limb memory puts it (NaN: no memory); ``lengths``: the
    learned bone lengths (learn_lengths); ``modelled``, ``model_weight``: per chain joint, where the body
    model puts it and how far a lone joint turns towards it on its circle (0: no model)."""
    parent_now = frames[parent].copy()
    if not (all_finite(parent_now) and all_finite(prev_parent)):
        return 0
    n, filled, k = idx.shape[0], 0, 1
    while k < n - 1:
        if not (status[idx[k]] == MISSING and status[idx[k - 1]] != MISSING):
            k += 1
            continue
        b = k
        while b < n and status[idx[b]] == MISSING:
            b += 1
        if b == n:  # no located joint after the run: Algorithm 1's carry handles it
            break
        filled += _fill_run(positions, frames, status, idx, k - 1, k, b, parent_now, prev_parent, prev_pos,
                            prev_frames, bend, bend_ok, dir_sum, dir_sq, dir_n, recalled, lengths, modelled,
                            model_weight)
        k = b + 1
    return filled


@njit(cache=True)
def segment_carry(positions, frames, status, idx, carried, prev_pos, prev_frames):
    """carried: rows (j, c, g) of one rigid body; a lost j keeps its last offset from c, turned by the
    least rotation that carries the last c->g axis onto the current one."""
    filled = 0
    for t in range(carried.shape[0]):
        j, c, g = carried[t, 0], carried[t, 1], carried[t, 2]
        if status[idx[j]] != MISSING or status[idx[c]] == MISSING or status[idx[g]] == MISSING:
            continue
        axis_now = positions[idx[g]] - positions[idx[c]]
        if not (all_finite(axis_now) and vnorm(axis_now) > 1e-6):
            continue
        turn = rotation_between(prev_pos[g] - prev_pos[c], axis_now)
        positions[idx[j]] = positions[idx[c]] + mv(turn, prev_pos[j] - prev_pos[c])
        frames[idx[j]] = mm(turn, prev_frames[j])
        status[idx[j]] = ESTIMATED
        filled += 1
    return filled


@njit(cache=True)
def carry_lost_end(positions, frames, status, idx, prev_pos, prev_frames):
    """The missing tail of the limb keeps its last pose relative to the last tracked bone before it."""
    n = idx.shape[0]
    j = n
    while j > 0 and status[idx[j - 1]] == MISSING:
        j -= 1
    root = j - 1
    if j == n or root < 1 or status[idx[root]] == MISSING or status[idx[root - 1]] == MISSING:
        return 0
    bone_now, bone_prev = frames[idx[root - 1]].copy(), prev_frames[root - 1]
    if not (all_finite(bone_now) and all_finite(bone_prev)):
        return 0
    turn = mm(bone_now, bone_prev.T.copy())
    for m in range(root, n):
        if m > root:
            positions[idx[m]] = positions[idx[root]] + mv(turn, prev_pos[m] - prev_pos[root])
            status[idx[m]] = HELD
        if not all_finite(frames[idx[m]]):
            frames[idx[m]] = mm(turn, prev_frames[m])
    return n - j


@dataclass
class BlendState:
    """The blend of a limb: its settings (``step``: reacquire_step_m; ``omega``: the spring's, from
    blend_half_life_s), what blend_transitions keeps per joint between frames, and the frame clock."""
    last_out: np.ndarray      # (n, 3) the last output
    out_step: np.ndarray      # (n, 3) and its last step
    last_raw: np.ndarray      # (n, 3) the source's last position, before the offset
    raw_vel: np.ndarray       # (n, 3) and its last step
    seen_raw: np.ndarray      # (n, 2, 3) where each kind of source (0 markers, 1 a fill) was last seen
    seen_age: np.ndarray      # (n, 2) and how many frames ago
    last_status: np.ndarray   # (n,)
    has_last: np.ndarray      # (1,) bool
    offset: np.ndarray        # (n, 3) the spring's offset
    offset_vel: np.ndarray    # (n, 3) and its velocity
    course: np.ndarray        # (n, 3) where the markers' course leads, since they were lost
    course_step: np.ndarray   # (n, 3) and its step
    since_loss: np.ndarray    # (n,) seconds since the markers were lost (inf: no loss being eased)
    eased: np.ndarray         # (n,) and how far it has gone from that course towards the fill (0-1)
    trust: np.ndarray         # (n, 5) what course_weight learns from (columns ACC_SUM ... LOCATED_RUN)
    prev_raw: np.ndarray      # (n, 3) the source's position a frame before last_raw
    prev_vel: np.ndarray      # (n, 3) and its step then
    course_len: np.ndarray    # (n, 2) a lone joint's distances to its two neighbours where its course began
    last_frame: np.ndarray    # (n, 3, 3) the last output bone frame (NaN: none)
    turn_axis: np.ndarray     # (n, 3) the frame's offset where its source changed: a turn about this axis
    turn: np.ndarray          # (n, 3) by this angle (radians, column 0) times the spring's share (1), and its
    #                           velocity (2)
    step: float = 0.0
    omega: float = 0.0
    course_on: bool = True    # blend_course: after a loss, leave the markers' course as course_weight says
    frame_s: float = DEFAULT_FRAME_S
    last_time_s: float = float("nan")

    @classmethod
    def empty(cls, n: int, step: float = 0.0, half_life_s: float = 0.0, course: bool = True) -> "BlendState":
        return cls(np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 2, 3)),
                   np.full((n, 2), 1 << 30, np.int64), np.zeros(n, np.int64), np.zeros(1, bool), np.zeros((n, 3)),
                   np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3)), np.full(n, np.inf), np.zeros(n),
                   np.zeros((n, 5)), np.zeros((n, 3)), np.zeros((n, 3)), np.full((n, 2), np.nan),
                   np.full((n, 3, 3), np.nan), np.zeros((n, 3)), np.zeros((n, 3)), step,
                   BLEND_X / half_life_s if half_life_s > 0 else 0.0, course)

    @property
    def on(self) -> bool:
        return self.step > 0 or self.omega > 0

    def advance_clock(self, time_s: float) -> None:
        """The time since the last frame; a missing, repeated or backward stamp (a looping file, a
        restarted QTM) or one over a second keeps the last good interval."""
        step = time_s - self.last_time_s
        if 0 < step <= 1.0:
            self.frame_s = step
        self.last_time_s = time_s

    def blend(self, positions, status, idx, frames=None) -> None:
        """One frame of the limb's joints ``idx`` (arrays of the whole skeleton), in place; ``frames``, the bone
        frames, are blended too where given (blend_frames, with the spring's half-life)."""
        if frames is not None and self.omega > 0:  # (before blend_transitions, which moves last_status on)
            blend_frames(frames, status, idx, self.last_status, self.has_last, self.last_frame, self.turn_axis,
                         self.turn, self.omega, self.frame_s)
        blend_transitions(positions, status, idx, self.last_out, self.out_step, self.last_raw, self.raw_vel,
                          self.seen_raw, self.seen_age, self.last_status, self.has_last, self.offset, self.offset_vel,
                          self.course, self.course_step, self.since_loss, self.eased, self.trust, self.step, self.omega,
                          self.frame_s, self.course_on, self.prev_raw, self.prev_vel, self.course_len)


@njit(cache=True)
def spring_step(x, v, omega, dt, decay):
    """One step of a critically damped spring towards 0 from ``x`` at velocity ``v`` (Holden's exact form for any
    ``dt``; ``decay`` = exp(-omega dt)): the new (x, v). For a number or a vector."""
    spring = v + omega * x
    return decay * (x + spring * dt), decay * (v - spring * omega * dt)


@njit(cache=True)
def blend_frames(frames, status, idx, last_status, has_last, last_frame, turn_axis, turn, omega, dt):
    """A joint's bone frame that changes source (its or a neighbour's markers lost or back, a fill handed to
    another) goes on from the frame it had, and the turn between the two dies out as a critically damped spring
    (the positions' blend, for the bone frames a rig streams), in place. The Vicon take's left wrist, handed
    between its sliding markers and the swivel's fill, turned up to 174 degrees in a frame there."""
    decay = math.exp(-omega * dt)
    n = idx.shape[0]
    for k in range(n):
        j = idx[k]
        frame = frames[j].copy()
        s, was = status[j], last_status[k]
        if not all_finite(frame):
            last_frame[k] = np.nan
            turn[k, 1] = 0.0
            continue
        # a frame is built from its joint and the joints either side (a bone's frame runs to the next joint, the
        # hand's is the wrist's): a change of source of any of them is one of the frame's
        changed = s != was and s != MISSING and was != MISSING
        for m in (k - 1, k + 1):
            if 0 <= m < n and status[idx[m]] != last_status[m]:
                changed = True
        if has_last[0] and changed and all_finite(last_frame[k]):
            offset = rotation_vector(mm(last_frame[k], frame.T.copy()))  # the old frame, less the new one
            angle = vnorm(offset)
            if angle > 1e-12:
                turn_axis[k] = offset / angle
                turn[k, 0], turn[k, 1], turn[k, 2] = angle, 1.0, 0.0
            else:
                turn[k, 1] = 0.0
        elif turn[k, 1] != 0.0:
            turn[k, 1], turn[k, 2] = spring_step(turn[k, 1], turn[k, 2], omega, dt, decay)
            if abs(turn[k, 1]) < 1e-4:
                turn[k, 1] = 0.0
        if turn[k, 1] != 0.0:
            frame = mm(axis_angle(turn_axis[k], turn[k, 0] * turn[k, 1]), frame)
            frames[j] = frame
        last_frame[k] = frame


@njit(cache=True)
def _take_step(velocity, step, last_step, limit):
    """A source's step becomes its velocity unless it is faster than any joint moves and as far off its own last
    step (a jump, or two fills of one kind that are not one source), in place. (Faster alone is not enough: a
    kicking toe filled at 105 mm a frame, 12.6 m/s, kept a velocity of 83 mm a frame from before; its curving
    course then left that by over the jump's threshold, every next frame was met as a jump, and the output stood
    still for 4 frames, 400 mm behind: the Vicon take's right toe at frame 490.)"""
    if vnorm(step) <= limit or vnorm(step - last_step) <= limit:
        velocity[:] = step


@njit(cache=True)
def _spring_blend(p, s, was, k, last_out, out_step, last_raw, raw_vel, seen_raw, seen_age, offset, offset_vel,
                  course, course_step, since_loss, eased, trust, step, omega, dt, decay, course_on, prev_raw, prev_vel,
                  course_len, neighbours):
    """One joint's position ``p`` (status ``s``, ``was`` the frame before) plus its offset, in place; after
    a loss, eased from the markers' course into that (see blend_transitions). ``neighbours``: the joints
    before and after it in the chain, where both are located (else NaN)."""
    kind = 0 if s == LOCATED else 1
    raw = p.copy()
    heading = last_raw[k] + raw_vel[k]  # where the source was heading
    before_raw = last_raw[k].copy()  # (the next frame's prev_raw / prev_vel, for its spike test)
    before_step = raw_vel[k].copy()  # (also the markers' last step, at a loss; the estimate's, given up)
    lost = s != LOCATED and was == LOCATED
    # an estimate given up for a hold, which knows nothing of where the joint went, is met like a loss: the
    # output goes on along the estimate's course (stop 29: the Vicon take's kicking right knee, its shank's wand
    # lost too, was 215 mm off after four held frames, then eased back from 260 mm); a course running goes on
    gave_up = s == HELD and was == ESTIMATED and since_loss[k] == math.inf
    found_or_lost = (s == LOCATED) != (was == LOCATED)
    jumped = s != LOCATED and was != LOCATED and vnorm(raw - heading) > SOURCE_JUMP_M_S * dt
    # a fill that stepped out for one frame, under the jump's threshold, and is back where it was heading
    # before that: not a jump, and the output goes on at the step it had before the spike (stop 29: the Vicon
    # take's left elbow stepped 82 mm out at frame 172 and back; met as a jump, the output went on at the
    # spike's step, 150 mm off for 25 frames)
    spike = jumped and s == was and vnorm(raw - (prev_raw[k] + 2.0 * prev_vel[k])) <= SOURCE_JUMP_M_S * dt
    jumped = jumped and not spike
    # handed from one fill to another (estimated, held) without such a jump: the new fill's jump is taken into
    # the offset too (the Vicon take's right wrist, handed from held to estimated at frame 979, moved 73 mm in
    # that frame, 2.11x its normal step; 0.31x with it). A course goes on through a hold; an estimate back
    # from one ends it, and the output goes on from itself at its own step into the estimate, as into
    # returning markers (the Vicon take's left elbow stayed on a stale course for 0.3 s: 107 -> 106 mm)
    handed = s != LOCATED and was != LOCATED and was != MISSING and s != was and not jumped
    spring_moved = 0.0
    limit = step  # how far the blend may move the output off its source this frame
    trust[k, LOCATED_RUN] = trust[k, LOCATED_RUN] + 1 if s == LOCATED else 0
    if trust[k, LOCATED_RUN] >= 3 and vnorm(raw - last_raw[k]) <= SOURCE_JUMP_M_S * dt:  # two markers' steps
        trust[k, ACC_SUM] += vnorm(raw - heading) / (dt * dt)  # |acceleration|
        trust[k, ACC_N] += 1
    if s == LOCATED and was != LOCATED and was != MISSING:  # how far the output's course missed the markers
        miss = vnorm(raw - (heading + offset[k]))
        trust[k, MISS_SQ] += miss * miss
        trust[k, MISS_N] += 1
    back = handed and was == HELD and since_loss[k] < math.inf  # an estimate back from a hold, on a course
    if spike:  # (ending a course, as a jump does)
        offset[k] = last_out[k] + prev_vel[k] - raw
        offset_vel[k] = 0.0
        since_loss[k] = math.inf
        raw_vel[k] = (raw - prev_raw[k]) * 0.5
    if handed and not back:
        offset[k] -= raw - heading
        offset_vel[k] = 0.0
    if was != MISSING and (found_or_lost or jumped or back):
        if since_loss[k] < math.inf:
            # the output left the spring's course for the markers': go on from it, at its own last step (the
            # fill's can be a recall's jitter: on dance1's knee 31 mm a frame where the leg moved 10)
            offset[k] = last_out[k] + out_step[k] - heading
            since_loss[k] = math.inf
        offset[k] -= raw - heading
        offset_vel[k] = 0.0  # a new offset, eased from rest
        since = seen_age[k, kind]  # frames since this kind of source was last seen
        if found_or_lost and since <= FLICKER_FRAMES:
            _take_step(raw_vel[k], (raw - seen_raw[k, kind]) / since, raw_vel[k].copy(), SOURCE_JUMP_M_S * dt)
        elif jumped:  # the new source's step is unknown: the old one kept made every next frame a jump too,
            raw_vel[k] = 0.0  # each taken into the offset (stop 28: the Vicon take's kicking knee, 0.46 m in 5 frames)
    else:
        if was != MISSING and not handed and not spike:  # (a hand-over's jump is not the source's step)
            _take_step(raw_vel[k], raw - last_raw[k], last_raw[k] - prev_raw[k], SOURCE_JUMP_M_S * dt)
        limit = max(step, PACE_SHARE * vnorm(raw_vel[k]))
        before = offset[k].copy()
        offset[k], offset_vel[k] = spring_step(before, offset_vel[k], omega, dt, decay)
        moved = vnorm(offset[k] - before)
        if step > 0 and moved > limit:
            offset[k] = before + (offset[k] - before) * (limit / moved)
        spring_moved = min(moved, limit)
    last_raw[k] = raw
    prev_raw[k] = before_raw
    prev_vel[k] = before_step
    seen_raw[k, kind] = raw
    seen_age[k, kind] = 0
    p += offset[k]
    if (lost or gave_up) and course_on and trust[k, ACC_N] > 0:
        course[k], course_step[k], since_loss[k], eased[k] = p, before_step, 0.0, 0.0
        course_len[k, 0] = vnorm(p - neighbours[0])  # (NaN unless both are located)
        course_len[k, 1] = vnorm(neighbours[1] - p)
    elif since_loss[k] < math.inf:
        since_loss[k] += dt
        course[k] += course_step[k]
        # a lone joint's course keeps its distances to its located neighbours, turning with them (an elbow swings
        # about the shoulder; its markers' straight course flies off the arm). Once one is lost it goes on
        # straight from where it is. Stop 30, short gaps: dance2's elbows 9.5 / 9.6 -> 7.3 / 7.1 mm. Neighbours out
        # of reach of those distances (skin that slid) leave a circle shrunk to a point on their line, which is not
        # where the joint went: the course is pulled towards it by at most the step cap a frame (stop 35: the Vicon
        # take's right upper arm stretched 233 -> 280 mm in 8 frames; lost for two, its shoulder's course jumped
        # 36 mm onto that line, and its markers came back at 1.75x its own pace; 1.1x now)
        if all_finite(course_len[k]) and all_finite(neighbours):
            on = nearest_on_circle(course[k], neighbours[0], neighbours[1], course_len[k, 0], course_len[k, 1])
            pull = vnorm(on - course[k])
            if vnorm(neighbours[1] - neighbours[0]) > course_len[k, 0] + course_len[k, 1] and pull > limit:
                on = course[k] + (on - course[k]) * (limit / pull)
            course[k] = on
        else:
            course_len[k] = np.nan
        w = course_weight(since_loss[k], trust[k])
        w = 1.0 if w >= EASED else w
        apart = vnorm(p - course[k])
        if step > 0 and (w - eased[k]) * apart > limit - spring_moved:  # one cap on the two together
            w = eased[k] + max(limit - spring_moved, 0.0) / apart
        eased[k] = min(w, 1.0)
        p[:] = course[k] + eased[k] * (p - course[k])
        if eased[k] == 1.0:
            since_loss[k] = math.inf
    # a fill further off than that where it takes over is met as ever; from there on the output only may not
    # drift further from it (clamping the frame it took over moved a karate ankle 84 mm, 2.5x its normal step)
    if s != LOCATED and was != LOCATED and was != MISSING and not (gave_up or jumped or handed or spike):
        apart = vnorm(p - raw)
        reach = max(MAX_APART_M, vnorm(last_out[k] - before_raw))
        if apart > reach:  # (the course and the offset go on from there)
            p[:] = raw + (p - raw) * (reach / apart)
            offset[k] = p - raw
            offset_vel[k] = 0.0
            if since_loss[k] < math.inf:
                course[k] = p


@njit(cache=True)
def course_weight(t, trust):
    """How far the output has gone from the markers' course towards the fill, ``t`` seconds after a loss
    (``trust``: a joint's row of BlendState.trust)."""
    stray = COURSE_K * 0.5 * max(trust[ACC_SUM] / trust[ACC_N], ACCEL_FLOOR) * t * t
    fill_var = (FILL_SD_PRIOR * FILL_SD_PRIOR + trust[MISS_SQ]) / (1.0 + trust[MISS_N])
    return stray * stray / (stray * stray + fill_var)


@njit(cache=True)
def _linear_return(p, s, was, last, offset, step):
    """reacquire_step_m alone: returning markers are met from where the estimate ``last`` was, the gap
    closed by at most ``step`` a frame; a joint that is not located has no offset."""
    if s == LOCATED and (was == ESTIMATED or was == HELD) and all_finite(last):
        offset[:] = last - p
    if s != LOCATED:
        offset[:] = 0.0
    size = vnorm(offset)
    if size > 0:
        offset *= min(1.0, max(0.0, (size - step) / size))
        p += offset


@njit(cache=True)
def blend_transitions(positions, status, idx, last_out, out_step, last_raw, raw_vel, seen_raw, seen_age, last_status,
                      has_last, offset, offset_vel, course, course_step, since_loss, eased, trust, step, omega, dt,
                      course_on, prev_raw, prev_vel, course_len):
    """Meet a joint's change of source without a twitch (inertialization, as game engines do), in place.

    With ``omega`` 0 (reacquire_step_m alone): when a joint's markers come back, start where the estimate
    had it and close the gap by at most ``step`` metres a frame (a rate-limited decaying offset).
    With ``omega`` > 0 (blend_half_life_s): the output is the source (markers, or a fill's estimate) plus an
    offset. Where the markers are lost or come back, the offset takes in the jump: the new source less where the
    old one was heading (its last position plus its own last step), so the output goes on as it went. The offset
    then dies out as a critically damped spring (Holden's, exact for any ``dt``), by at most ``step`` a frame
    when that is set (or PACE_SHARE of the source's own step, if more). At loss the offset is the truth the
    estimate has not got: over a short gap it keeps the joint near its markers' last course. After a loss the
    output also stays on that course (the markers' last step, on and on), leaving it for the fill as
    course_weight says, which learns from the joint how fast its markers turn and how far its fill missed them
    where they came back (``trust``); ``step`` caps that too (``course_on`` False: the spring alone, as until
    stop 23). Markers that come back while the output is still leaving that course are met from the output as it
    went (its own last step), not as the fill went. An estimate that leaves its course faster than
    SOURCE_JUMP_M_S has changed source (a held hand carried by another bone) and is met the same way; one handed
    between fills (estimated, held) without such a jump has its jump taken into the offset (since stop 25; until
    then it was not met). An estimate given up for a hold starts a course as a loss does, and one back from a
    hold ends a course as returning markers do (stop 29). The course of a lone joint between two located ones
    keeps its distances to them, on their circle (stop 30); out of their reach, it is pulled towards their line
    by no more than the step cap a frame (stop 35). While a fill stands in, the output stays within MAX_APART_M
    of it (stop 31). A flickering marker swings the offset back and forth by the two sources' difference:
    nothing builds up.
    State per joint: ``last_out`` and ``out_step``, the output's last position and step; ``last_raw`` and
    ``raw_vel``, the source's; ``seen_raw`` and ``seen_age``, the last position of each kind of source
    (0 markers, 1 a fill) and frames since; ``course``, ``course_step``, ``since_loss`` and ``eased``, the
    markers' course after a loss and how far the output has left it; ``course_len``, a lone joint's distances to
    its neighbours where the course began."""
    n = idx.shape[0]
    decay = math.exp(-omega * dt)
    neighbours = np.empty((2, 3))
    for k in range(n):
        j = idx[k]
        s = status[j]
        seen_age[k, 0] += 1
        seen_age[k, 1] += 1
        if s == MISSING or not all_finite(positions[j]) or (omega == 0 and not has_last[0]):
            offset[k] = 0.0
            offset_vel[k] = 0.0
            raw_vel[k] = 0.0
            since_loss[k] = math.inf
            # nothing to measure the next steps from (the source's acceleration, the spike test): the position
            # from before this frame, kept, made the next two frames' samples a two-frame and a one-frame step
            last_raw[k] = np.nan
            trust[k, LOCATED_RUN] = 0
        elif omega > 0:
            was = last_status[k] if has_last[0] else MISSING  # the first frame comes from nothing
            neighbours[:] = np.nan
            if 0 < k < n - 1 and status[idx[k - 1]] == LOCATED and status[idx[k + 1]] == LOCATED:
                neighbours[0] = positions[idx[k - 1]]
                neighbours[1] = positions[idx[k + 1]]
            _spring_blend(positions[j], s, was, k, last_out, out_step, last_raw, raw_vel, seen_raw, seen_age, offset,
                          offset_vel, course, course_step, since_loss, eased, trust, step, omega, dt, decay, course_on,
                          prev_raw, prev_vel, course_len, neighbours)
        else:
            _linear_return(positions[j], s, last_status[k], last_out[k], offset[k], step)
    for k in range(n):
        out_step[k] = positions[idx[k]] - last_out[k]
        last_out[k] = positions[idx[k]]
        last_status[k] = status[idx[k]]
    has_last[0] = True

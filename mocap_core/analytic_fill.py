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

What these fills hand over is blended into the output by mocap_core.blend.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from mocap_core.skeleton import ESTIMATED, HELD, LOCATED, MISSING
from mocap_core.ik.kernels import angle_about, axis_angle, mm, mtv, mv, rotation_between, vcross, vdist, vdot, vnorm

MIN_SAMPLES = 30    # located frames before a bone's direction in the next joint's frame is trusted
# Where on the swivel circle: the bone's direction in the next joint's frame nearest its usual one,
# every component weighted by 1 / (its variance + SD_FLOOR^2), plus TURN_WEIGHT per squared radian
# of turn from the carried bend direction (which only settles near-ties). Leaning on the steadiest
# component alone (the forearm along the hand) fails whenever the wrist flexes; all three weighted hold.
SD_FLOOR = 0.02
TURN_WEIGHT = 1.0
FIT_STEPS = 360     # a coarse pass over the whole circle (1 degree), then a fine one around the best
# With the limb memory (mocap_core.limb_memory) on, the joint is also pulled towards where the earlier
# poses had it, as if that point were this far off (SD, metres): about a joint centre's own uncertainty.
MEMORY_SD = 0.01
# How far a lost joint's frame turns with the plane of its two bones (shape_turn): not at all below a bend of
# STRAIGHT_SIN (about 3 degrees), wholly from STRAIGHT_SIN + PLANE_RANGE (17 degrees). Nearly straight, the plane is
# noise: a lost joint out of its neighbours' reach (put on their line) would turn its frame about an arbitrary
# axis, and the joints it carries with it, by up to half a turn a frame.
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
    unit = np.empty(3)
    for k in range(1, idx.shape[0] - 1):
        if status[idx[k]] != LOCATED or status[idx[k + 1]] != LOCATED:
            continue
        a, b = positions[idx[k]], positions[idx[k + 1]]
        size = vdist(b, a)
        frame = frames[idx[k + 1]]
        if size > 1e-6 and all_finite(frame):
            for c in range(3):
                unit[c] = (b[c] - a[c]) / size
            local = mtv(frame, unit)
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
            size = vdist(positions[idx[k + 1]], positions[idx[k]])
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
def nearest_on_sphere(point, centre, radius):
    """The point at ``radius`` from ``centre`` nearest ``point`` (``point`` itself where it is the centre): the
    sphere's twin of nearest_on_circle, for a joint with one neighbour."""
    off = point - centre
    size = vnorm(off)
    return centre + off * (radius / size) if size > 1e-9 else point.copy()


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
    # a plane, not a side of it: a lone joint that crosses its neighbours' line between two frames (a nearly
    # straight wrist) flips its bend's side, not its bone by a half turn; no bone rolls 90 degrees in a frame
    if roll > 0.5 * math.pi:
        roll -= math.pi
    elif roll < -0.5 * math.pi:
        roll += math.pi
    return mm(axis_angle(axis, share * roll), least)


@njit(cache=True)
def _fit_cost(psi, u, e2, radius, to_target, usual, recall):
    ref, mean, weight = usual
    to_recalled, pull = recall
    arm = radius * (math.cos(psi) * u + math.sin(psi) * e2)
    d = to_target - arm
    local = mtv(ref, d / vnorm(d))
    cost = TURN_WEIGHT * psi * psi
    for c in range(3):
        cost += weight[c] * (local[c] - mean[c]) ** 2
    gap = arm - to_recalled
    return cost + pull * vdot(gap, gap)


@njit(cache=True)
def on_circle_fitting(u, axis, radius, to_target, usual, recall):
    """The direction on the swivel circle (from its centre; ``u`` is the prior, on the circle) at which
    the bone to the target, in the target joint's frame (``usual``: ref, mean, weight), is nearest its usual
    direction ``mean``, component by component with ``weight`` (see SD_FLOOR), and the joint nearest the point
    the limb memory recalled (``recall``: to_recalled, from the centre, and pull, per square metre)."""
    if not radius > 1e-6:
        return u
    e2 = vcross(axis, u)
    best, best_cost = 0.0, _fit_cost(0.0, u, e2, radius, to_target, usual, recall)
    step = 2 * math.pi / FIT_STEPS
    for i in range(FIT_STEPS):
        psi = -math.pi + i * step
        cost = _fit_cost(psi, u, e2, radius, to_target, usual, recall)
        if cost < best_cost:
            best, best_cost = psi, cost
    centre = best
    for i in range(-20, 21):  # then to a twentieth of a degree
        psi = centre + i * step / 20
        cost = _fit_cost(psi, u, e2, radius, to_target, usual, recall)
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
def _fill_run(skeleton, idx, run, parent_now, last, state, steer):
    """The run (a, k, b): joints k..b-1 lost between the located a and b (swivel_fill says the rest)."""
    positions, frames, status = skeleton
    a, k, b = run
    prev_pos, prev_frames, prev_parent, _, lengths = last
    bend, bend_ok, dir_sum, dir_sq, dir_n = state
    recalled, modelled, model_weight = steer
    pa, pk, pb = prev_pos[a], prev_pos[k], prev_pos[b]
    upper, lower = vnorm(pk - pa), vnorm(pb - pk)
    if b == k + 1:  # a lone joint: both its bones as learned
        upper, lower = _length(lengths, a, upper), _length(lengths, k, lower)
    # (a longer run keeps its last shape, from the hip to the toe, say, with the knee, ankle and foot
    # lost: its bones stay as they were, so the toe stays in reach. A learned thigh mixed with the shape's
    # last knee-toe distance can leave the toe out of reach, and the plane of hip, knee and toe undefined.)
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
        u = on_circle_fitting(u, axis, radius, target - centre, (ref_now, mean, weight), (to_recalled, pull))
    if b == k + 1 and model_weight[k] > 0 and all_finite(modelled[k]):
        u = _turn_towards(u, axis, modelled[k] - centre, model_weight[k])
    _place_run(skeleton, idx, run, parent_now, last, centre + radius * u)
    return b - k


@njit(cache=True)
def _place_run(skeleton, idx, run, parent_now, last, joint):
    """The run's first joint at ``joint``; the rest of the run in its last shape, turned with the plane of
    (a, k, b); their frames turned alike, and a's along its bone to the joint."""
    positions, frames, status = skeleton
    a, k, b = run
    prev_pos, prev_frames, prev_parent = last[0], last[1], last[2]
    pa, pk, pb = prev_pos[a], prev_pos[k], prev_pos[b]
    root, target = positions[idx[a]].copy(), positions[idx[b]].copy()
    positions[idx[k]] = joint
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
def swivel_fill(skeleton, chain, last, state, steer):
    """Fill every run of missing joints that has a located joint on both sides; returns how many.
    ``skeleton``: (positions, frames, status) of the whole skeleton; ``chain``: the limb's (joints, parent);
    ``last``: its last whole output and learned bone lengths (prev_pos, prev_frames, prev_parent, has_prev,
    lengths: learn_lengths); ``state``: the swivel's (bend, bend_ok, dir_sum, dir_sq, dir_n); ``steer``:
    (recalled, modelled, model_weight), per chain joint where the limb memory puts it (NaN: no memory), where
    the body model puts it and how far a lone joint turns towards it on its circle (0: no model)."""
    frames, status = skeleton[1], skeleton[2]
    idx, parent = chain
    prev_parent = last[2]
    parent_now = frames[parent].copy()
    if not (all_finite(parent_now) and all_finite(prev_parent)):
        return 0
    # (k an int64 from the start: a literal would compile each kernel it reaches twice)
    n, filled, k = idx.shape[0], 0, np.int64(1)
    while k < n - 1:
        if not (status[idx[k]] == MISSING and status[idx[k - 1]] != MISSING):
            k += 1
            continue
        b = k
        while b < n and status[idx[b]] == MISSING:
            b += 1
        if b == n:  # no located joint after the run: Algorithm 1's carry handles it
            break
        filled += _fill_run(skeleton, idx, (k - 1, k, b), parent_now, last, state, steer)
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

"""The per-frame fit's numba kernel: damped Gauss-Newton over the whole skeleton's pose.

The pose is the root's position and every bone's frame (world rotation; an end site carries its
parent's). Joint positions follow by forward kinematics from the subject's fixed offsets, so every
bone keeps its length by construction: ``P[j] = P[parent] + R[parent] @ offset[j]``. A marker on
bone ``b`` sits at ``P[b] + R[b] @ c``.

Each step linearises the markers in small world-frame turns ``d_k`` of each bone's local rotation
(a turn of bone k swings everything it carries about ``P[k]``), so a marker's Jacobian block for an
ancestor k is ``-[m - P[k]]x`` and for the root's position the identity. Tasks, as weighted least
squares (one system per step, 3 + 3 x bones unknowns):
- markers: every seen marker on its bone, weight 1 / sigma_m^2 times a Cauchy weight on its
  residual (iteratively re-weighted), so one swapped or ghost marker is outvoted, not followed;
- motion: every bone's local rotation near its prediction, the root near its prediction, which
  settles what no marker sees (a bone with nothing seen keeps its pose relative to its parent);
- posture: every bone's local rotation, weakly, near the subject's typical one, which keeps what the
  markers leave free (a twist, one of two bones in a row with one marker) from drifting.
Limits: the thesis's cone and twist limits (thesis 3.3, mocap_core.ik.kernels) bound the motion task's
prediction, so they hold what no marker sees inside a human range but never pull a bone off the markers
that place it (located bone frames fall outside the thesis's limits in many frames, the ankles in most).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from mocap_core.ik.kernels import (axis_angle, clamp_twist, cone_project, mm, mtv, mv, rotation_between,
                                   rotation_vector, twist_angle, vnorm)


@njit(cache=True)
def forward(root, R, parent, offsets, P):
    """Joint positions P (J, 3) from the root's position and the bone frames (model order: parents first)."""
    for j in range(P.shape[0]):
        p = parent[j]
        if p < 0:
            P[j] = root
        else:
            P[j] = P[p] + mv(R[p], offsets[j])


@njit(cache=True)
def logm(R):
    """The rotation vector of R (the inverse of expm), without temporaries; near a half turn through the
    quaternion (mocap_core.ik.kernels.rotation_vector), where the antisymmetric part fades."""
    c = 0.5 * (R[0, 0] + R[1, 1] + R[2, 2] - 1.0)
    w0, w1, w2 = R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]
    if c > 1.0 - 1e-12:
        return np.array([0.5 * w0, 0.5 * w1, 0.5 * w2])
    if c < -0.99:
        return rotation_vector(R)
    angle = math.acos(c)
    k = angle / (2.0 * math.sin(angle))
    return np.array([k * w0, k * w1, k * w2])


@njit(cache=True)
def expm(v):
    angle = vnorm(v)
    if angle < 1e-15:
        return np.eye(3)
    return axis_angle(v / angle, angle)


@njit(cache=True)
def _limit(R, p, pp, cone, has_cone, twist, has_twist):
    """Bone frame R brought inside its cone and twist limits about the reference frame R[parent] @ pp."""
    ref = mm(p, pp)
    if has_cone:
        y = R[:, 1].copy()
        inside, legal = cone_project(mtv(ref, y), cone)
        if not inside:
            R = mm(rotation_between(y, mv(ref, legal)), R)
    if has_twist:
        alpha = twist_angle(R, ref)
        target = clamp_twist(alpha, twist[0], twist[1])
        if target != alpha:
            y = R[:, 1].copy()
            R = mm(axis_angle(y / vnorm(y), target - alpha), R)
    return R


@njit(cache=True)
def limit_locals(L, pp, cones, has_cone, twists, has_twist):
    """Each bone's rotation in its parent's frame (J, 3, 3) brought inside its limits, in place."""
    eye = np.eye(3)
    for k in range(1, L.shape[0]):
        if has_cone[k] or has_twist[k]:
            L[k] = _limit(L[k].copy(), eye, pp[k], cones[k], has_cone[k], twists[k], has_twist[k])


@njit(cache=True)
def _orthonormal(R):
    """The nearest rotation's cheap stand-in: y kept, z made perpendicular, x = y cross z."""
    y = R[:, 1] / vnorm(R[:, 1])
    z = R[:, 2] - (R[0, 2] * y[0] + R[1, 2] * y[1] + R[2, 2] * y[2]) * y
    z = z / vnorm(z)
    out = np.empty((3, 3))
    out[:, 0] = np.array([y[1] * z[2] - y[2] * z[1], y[2] * z[0] - y[0] * z[2], y[0] * z[1] - y[1] * z[0]])
    out[:, 1], out[:, 2] = y, z
    return out


@njit(cache=True)
def _accumulate(H, g, slot, chain, a, r, w):
    """Add one marker's residual r (weight w, position a[i] from each ancestor's joint) to the normal equations:
    the lower triangle only (row: the deeper unknown), which is all the tree solve reads."""
    for i in range(3):
        H[i, i] += w
        g[i] += w * r[i]
    for ia in range(chain.shape[0]):
        ka = chain[ia]
        if ka < 0:
            break
        sa = slot[ka]
        va = a[ia]
        # against the root's position: w * J_a^T with J_a = -[va]x, so J_a^T = [va]x
        H[sa + 0, 1] -= w * va[2]
        H[sa + 0, 2] += w * va[1]
        H[sa + 1, 0] += w * va[2]
        H[sa + 1, 2] -= w * va[0]
        H[sa + 2, 0] -= w * va[1]
        H[sa + 2, 1] += w * va[0]
        # g_a += w * va x r
        g[sa + 0] += w * (va[1] * r[2] - va[2] * r[1])
        g[sa + 1] += w * (va[2] * r[0] - va[0] * r[2])
        g[sa + 2] += w * (va[0] * r[1] - va[1] * r[0])
        for ib in range(ia, chain.shape[0]):  # itself and its ancestors
            kb = chain[ib]
            if kb < 0:
                break
            sb = slot[kb]
            vb = a[ib]
            d = va[0] * vb[0] + va[1] * vb[1] + va[2] * vb[2]
            for i in range(3):  # J_a^T J_b = (va . vb) I - vb va^T
                for j in range(3):
                    H[sa + i, sb + j] += w * ((d if i == j else 0.0) - vb[i] * va[j])


@njit(cache=True)
def tree_solve(H, g, up):
    """Solve H x = g where H is nonzero only between an unknown and those above it in a tree (``up``: each
    unknown's parent, -1 at the top; parents first), from H's lower triangle, in place of g: Featherstone's
    LTDL factorisation, which exploits that sparsity (no fill-in; Rigid Body Dynamics Algorithms, 6.5)."""
    n = g.shape[0]
    for k in range(n - 1, -1, -1):
        i = up[k]
        while i >= 0:
            a = H[k, i] / H[k, k]
            j = i
            while j >= 0:
                H[i, j] -= a * H[k, j]
                j = up[j]
            H[k, i] = a
            i = up[i]
    for i in range(n - 1, -1, -1):
        j = up[i]
        while j >= 0:
            g[j] -= H[i, j] * g[i]
            j = up[j]
    for i in range(n):
        g[i] /= H[i, i]
    for i in range(n):
        j = up[i]
        while j >= 0:
            g[i] -= H[i, j] * g[j]
            j = up[j]
    return g


@njit(cache=True)
def fit_pose(pose, markers, tree, up, motion, robust_m, stop, out):
    """One frame's fit, in place on ``pose`` = (root (3,), R (J, 3, 3)); ``out`` = (P, weights): P gets the joints,
    weights (M,) each marker's final robust weight (0 for an unseen or unassigned marker). ``markers``: (x, bone,
    c, w_marker); ``tree``: (parent, offsets, slot, chains, rotating); ``motion``: (root_pred, L_pred, w_rot,
    w_root, L_rest, w_rest); ``stop``: (max_iterations, tolerance). Plain tuples: numba reads them from Python
    faster than NamedTuples. Returns (iterations, residual RMS of the seen markers in metres)."""
    root, R = pose
    parent, offsets, slot = tree[0], tree[1], tree[2]
    max_iterations, tolerance = stop
    P, weights = out
    n = slot.max() + 3
    it = 0
    for it in range(1, max_iterations + 1):
        forward(root, R, parent, offsets, P)
        H = np.zeros((n, n))
        g = np.zeros(n)
        _marker_task(H, g, P, R, markers, tree, robust_m, weights)
        _motion_task(H, g, root, R, motion, tree)
        if _step(root, R, tree_solve(H, g, up), tree) < tolerance:
            break
    forward(root, R, parent, offsets, P)
    return it, _residual_rms(P, R, markers)


@njit(cache=True, inline="always")
def _marker_task(H, g, P, R, markers, tree, robust_m, weights):
    """Add every seen marker's residual from its calibrated place to the normal equations (H, g), Cauchy-weighted
    by ``robust_m``; ``weights`` gets each marker's robust weight (0: unseen or on no bone)."""
    x, bone, c, w_marker = markers
    _, _, slot, chains, _ = tree
    a = np.empty((chains.shape[1], 3))
    for m in range(x.shape[0]):
        b = bone[m]
        weights[m] = 0.0
        if b < 0 or not (np.isfinite(x[m, 0]) and np.isfinite(x[m, 1]) and np.isfinite(x[m, 2])):
            continue
        pos = P[b] + mv(R[b], c[m])
        r = x[m] - pos
        e = vnorm(r) / robust_m
        w = w_marker[m] / (1.0 + e * e)
        weights[m] = 1.0 / (1.0 + e * e)
        for i in range(chains.shape[1]):
            k = chains[b, i]
            if k < 0:
                break
            a[i] = pos - P[k]
        _accumulate(H, g, slot, chains[b], a, r, w)


@njit(cache=True, inline="always")
def _motion_task(H, g, root, R, motion, tree):
    """The motion and posture tasks: each bone's local rotation (the root's world one) near its prediction and
    near the subject's usual one, the root near its predicted position."""
    root_pred, L_pred, w_rot, w_root, L_rest, w_rest = motion
    parent, _, slot, _, rotating = tree
    for i in range(3):
        H[i, i] += w_root
        g[i] += w_root * (root_pred[i] - root[i])
    for k in range(R.shape[0]):
        if not rotating[k]:
            continue
        s = slot[k]
        p = parent[k]
        for target, w in ((L_pred[k], w_rot[k]), (L_rest[k], w_rest[k])):
            if p < 0:
                t = logm(mm(target, R[k].T))
            else:
                t = mv(R[p], logm(mm(target, mm(R[p].T, R[k]).T)))
            for i in range(3):
                H[s + i, s + i] += w
                g[s + i] += w * t[i]


@njit(cache=True, inline="always")
def _step(root, R, d, tree):
    """Apply the step ``d`` (the root's move, then each rotating bone's world-frame turn); returns its largest
    component."""
    parent, _, slot, _, rotating = tree
    root += d[:3]
    old = R.copy()
    for k in range(R.shape[0]):
        p = parent[k]
        if not rotating[k]:
            R[k] = R[p]
            continue
        turn = expm(d[slot[k]:slot[k] + 3])
        if p < 0:
            R[k] = _orthonormal(mm(turn, old[k]))
        else:
            R[k] = _orthonormal(mm(R[p], mm(old[p].T, mm(turn, old[k]))))
    step = 0.0
    for i in range(d.shape[0]):
        step = max(step, abs(d[i]))
    return step


@njit(cache=True, inline="always")
def _residual_rms(P, R, markers):
    """RMS (m) of the seen markers off their calibrated places; NaN when none is seen."""
    x, bone, c, _ = markers
    total, count = 0.0, 0
    for m in range(x.shape[0]):
        b = bone[m]
        if b < 0 or not np.isfinite(x[m, 0]):
            continue
        r = x[m] - (P[b] + mv(R[b], c[m]))
        total += r[0] * r[0] + r[1] * r[1] + r[2] * r[2]
        count += 1
    return math.sqrt(total / count) if count else math.nan

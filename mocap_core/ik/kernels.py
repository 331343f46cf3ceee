"""Numba kernels of the IK hot loops: rotations, cone and twist limits, sub-chain moves.

A chain is plain arrays: joint positions ``P`` (n+1, 3) with P[0] the fixed root, bone frames
``R`` (n, 3, 3) whose columns are the bone's x, y, z axes (y from P[i] to P[i+1]), and per bone a
parent pointer ``pp`` (3, 3), cone angles (4,) and twist limits (2,). The reference frame of bone
i is ``R[i-1] @ pp[i]`` (``ref0 @ pp[0]`` for the first bone), as in the thesis's code (facts 9.5).

Cone limits (thesis 3.3.2): four angles from the reference y axis towards reference +x, +z, -x
and -z. The thesis intersects the cone with the plane at its height and finds the nearest point
on the quarter ellipse there (Eberly); at 90 degrees and beyond that plane is gone, hence its
special cases. We pose the same 2-D problem in the azimuthal-equidistant plane around the cone
axis (the point's distance from the centre is its angle from the axis), where a quarter ellipse
of semi-axes equal to the angles is well defined up to 180 degrees: hinge joints, reversed cones
and targets "behind the parent" need no special cases, and the nearest point is still Eberly's.

Twist limits (thesis 3.3.1): the reference z carried onto the bone by the shortest swing, and
the signed angle from it to the bone's z about the bone's y (right-hand rule), clamped into
[min, max] by rotating the bone (and everything after it) about its own axis.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

EPS = 1e-12


@njit(cache=True)
def vnorm(v):
    return math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])


@njit(cache=True)
def vdist(a, b):
    """vnorm(a - b), without making a - b (a kernel that runs every frame makes no array it need not)."""
    d0, d1, d2 = a[0] - b[0], a[1] - b[1], a[2] - b[2]
    return math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)


@njit(cache=True)
def follow(learned, sample, rate):
    """A learned value (a distance between two points on one bone) moved by ``rate`` towards a new
    ``sample``; the sample itself while nothing is learned (NaN)."""
    return sample if math.isnan(learned) else learned + rate * (sample - learned)


@njit(cache=True)
def vcross(a, b):
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


@njit(cache=True)
def vdot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True)
def vfinite(v):
    """All three coordinates finite (a point that is seen)."""
    return np.isfinite(v[0]) and np.isfinite(v[1]) and np.isfinite(v[2])


@njit(cache=True)
def mv(M, v):
    """3x3 matrix times vector, written out (small fixed sizes beat BLAS calls)."""
    return np.array([M[0, 0] * v[0] + M[0, 1] * v[1] + M[0, 2] * v[2],
                     M[1, 0] * v[0] + M[1, 1] * v[1] + M[1, 2] * v[2],
                     M[2, 0] * v[0] + M[2, 1] * v[1] + M[2, 2] * v[2]])


@njit(cache=True)
def mtv(M, v):
    """Transposed 3x3 matrix times vector."""
    return np.array([M[0, 0] * v[0] + M[1, 0] * v[1] + M[2, 0] * v[2],
                     M[0, 1] * v[0] + M[1, 1] * v[1] + M[2, 1] * v[2],
                     M[0, 2] * v[0] + M[1, 2] * v[1] + M[2, 2] * v[2]])


@njit(cache=True)
def mm(A, B):
    """3x3 matrix product, written out (numba sends @ on 2-D arrays to BLAS, slow at this size)."""
    C = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            C[i, j] = A[i, 0] * B[0, j] + A[i, 1] * B[1, j] + A[i, 2] * B[2, j]
    return C


@njit(cache=True)
def wrap(a):
    """Angle into [-pi, pi)."""
    return (a + math.pi) % (2 * math.pi) - math.pi


@njit(cache=True)
def axis_angle(axis, angle):
    """Rotation matrix about a unit axis (Rodrigues)."""
    x, y, z = axis[0], axis[1], axis[2]
    c, s = math.cos(angle), math.sin(angle)
    t = 1.0 - c
    return np.array([[t * x * x + c, t * x * y - s * z, t * x * z + s * y],
                     [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
                     [t * x * z - s * y, t * y * z + s * x, t * z * z + c]])


@njit(cache=True)
def rotation_vector(R):
    """The rotation vector (unit axis times angle, 0 to 180 degrees) of a rotation matrix, the inverse of
    axis_angle. Through its quaternion, so a turn near a half one keeps its axis (the matrix's antisymmetric part,
    2 sin(angle) axis, fades there)."""
    q = frames_to_quats(np.ascontiguousarray(R).reshape(1, 3, 3))[0]
    s = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2])  # sin(angle / 2)
    if s < 1e-15:
        return np.zeros(3)
    return q[:3] * (2.0 * math.atan2(s, q[3]) / s)


@njit(cache=True)
def angle_about(axis, a, b):
    """The signed angle (radians) that turns ``a`` to ``b`` about the unit ``axis``, both seen across it."""
    a = a - vdot(a, axis) * axis
    b = b - vdot(b, axis) * axis
    return math.atan2(vdot(axis, vcross(a, b)), vdot(a, b))


@njit(cache=True)
def turned_by(R, v):
    """``R`` followed by the turn of rotation vector ``v`` in R's own axes."""
    angle = vnorm(v)
    if angle < 1e-15:
        return R.copy()
    return mm(R, axis_angle(v / angle, angle))


@njit(cache=True)
def rotation_between(a, b):
    """Shortest-arc rotation carrying direction a onto direction b (scalar code: no temporaries)."""
    na = math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
    nb = math.sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2])
    if na < EPS or nb < EPS:
        return np.eye(3)
    ax, ay, az = a[0] / na, a[1] / na, a[2] / na
    bx, by, bz = b[0] / nb, b[1] / nb, b[2] / nb
    c = ax * bx + ay * by + az * bz
    cx, cy, cz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
    s = math.sqrt(cx * cx + cy * cy + cz * cz)
    if s < 1e-12:
        if c > 0:
            return np.eye(3)
        # opposite: half turn about any axis perpendicular to a
        helper = np.array([1.0, 0.0, 0.0]) if abs(ax) < 0.9 else np.array([0.0, 1.0, 0.0])
        axis = vcross(np.array([ax, ay, az]), helper)
        return axis_angle(axis / vnorm(axis), math.pi)
    return axis_angle(np.array([cx / s, cy / s, cz / s]), math.atan2(s, c))


@njit(cache=True)
def line_carry(before0, before1, after0, after1):
    """(R, t): the least rotation that turns the line between two points, and the shift that then puts their
    midpoint (what two points tell of a rigid motion; the roll about their line is left as it was)."""
    rot = rotation_between(before1 - before0, after1 - after0)
    return rot, 0.5 * (after0 + after1) - mv(rot, 0.5 * (before0 + before1))


@njit(cache=True)
def best_roll(pivot, line, points, targets, distances, price, max_roll, step):
    """The turn about the line through ``pivot`` along the unit ``line`` that keeps ``points`` (n, 3) nearest
    their ``distances`` (n, m; NaN: unknown) from ``targets`` (m, 3; NaN: not seen), plus ``price`` per squared
    radian: searched within ``max_roll`` either side of none, in ``step``s, then in tenths and hundredths of
    them about the best. Returns the angle (Rodrigues: each point's offset from the pivot, split once)."""
    n = points.shape[0]
    v, across, along = np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3))
    for e in range(n):
        v[e] = points[e] - pivot
        along[e] = (line @ v[e]) * line
        across[e] = np.cross(line, v[e])
    best, best_cost = 0.0, np.inf
    for fine, half_width in ((step, max_roll), (step / 10, step), (step / 100, step / 10)):
        centre = best
        k = int(round(half_width / fine))
        for i in range(-k, k + 1):
            a = centre + i * fine
            c, s = math.cos(a), math.sin(a)
            cost = price * a * a
            for e in range(n):
                turned = pivot + c * v[e] + s * across[e] + (1 - c) * along[e]
                for m in range(targets.shape[0]):
                    if not np.isnan(distances[e, m]) and vfinite(targets[m]):
                        cost += (vnorm(turned - targets[m]) - distances[e, m]) ** 2
            if cost < best_cost:
                best, best_cost = a, cost
    return best


# Skin deforms a body's markers more the farther apart they are (a forearm twists along its length), so a rigid
# fit made to carry one point weighs each partner by the inverse square of its distance from that point, no
# nearer than NEAR_FLOOR_M: the rotation's error then has a shorter lever (segment_rebuild and partial_means give
# what it changed).
NEAR_FLOOR_M = 0.02


@njit(cache=True)
def nearness_weight(distance):
    """A partner's weight in a rigid fit that carries a point ``distance`` metres from it."""
    return 1.0 / max(distance, NEAR_FLOOR_M) ** 2


@njit(cache=True)
def rigid_fit_first(before, after, n):
    """(R, t) with R before[i] + t ~ after[i] for the first n rows, least squares (Kabsch, unweighted)."""
    return rigid_fit_weighted(before, after, np.ones(n), n)


@njit(cache=True)
def rigid_fit_weighted(before, after, weights, n):
    """(R, t) minimising sum w[i] |R before[i] + t - after[i]|^2 over the first n rows (weighted Kabsch; the
    kernel twin of geometry.rigid_fit)."""
    w = weights[:n] / weights[:n].sum()
    cb, ca = np.zeros(3), np.zeros(3)
    for i in range(n):
        cb += w[i] * before[i]
        ca += w[i] * after[i]
    h = np.zeros((3, 3))
    for i in range(n):
        h += w[i] * np.outer(before[i] - cb, after[i] - ca)
    u, _, vt = np.linalg.svd(h)
    rot = vt.T @ u.T
    if np.linalg.det(rot) < 0:  # a reflection: flip the weakest axis
        vt[2] *= -1.0
        rot = vt.T @ u.T
    return rot, ca - mv(rot, cb)


@njit(cache=True)
def rotate_subchain(P, R, i, rot):
    """Rotate joints i+1.. about P[i], and bone frames i.. (the sub-chain that bone i carries)."""
    n = R.shape[0]
    ox, oy, oz = P[i, 0], P[i, 1], P[i, 2]
    for k in range(i + 1, n + 1):
        x, y, z = P[k, 0] - ox, P[k, 1] - oy, P[k, 2] - oz
        P[k, 0] = ox + rot[0, 0] * x + rot[0, 1] * y + rot[0, 2] * z
        P[k, 1] = oy + rot[1, 0] * x + rot[1, 1] * y + rot[1, 2] * z
        P[k, 2] = oz + rot[2, 0] * x + rot[2, 1] * y + rot[2, 2] * z
    for k in range(i, n):
        for col in range(3):
            x, y, z = R[k, 0, col], R[k, 1, col], R[k, 2, col]
            R[k, 0, col] = rot[0, 0] * x + rot[0, 1] * y + rot[0, 2] * z
            R[k, 1, col] = rot[1, 0] * x + rot[1, 1] * y + rot[1, 2] * z
            R[k, 2, col] = rot[2, 0] * x + rot[2, 1] * y + rot[2, 2] * z


@njit(cache=True)
def ref_frame(R, ref0, pp, i):
    if i == 0:
        return mm(ref0, pp[0])
    return mm(R[i - 1], pp[i])


# -- cone limits -------------------------------------------------------------------------------------
@njit(cache=True)
def _ellipse_root(r0, z0, z1, g):
    """Eberly's bisection for the nearest point on an ellipse (robust form, at most 149 steps)."""
    n0 = r0 * z0
    s0 = z1 - 1.0
    s1 = 0.0 if g < 0 else math.sqrt(n0 * n0 + z1 * z1) - 1.0
    s = 0.0
    for _ in range(149):
        s = 0.5 * (s0 + s1)
        if s == s0 or s == s1:
            break
        ratio0 = n0 / (s + r0)
        ratio1 = z1 / (s + 1.0)
        g = ratio0 * ratio0 + ratio1 * ratio1 - 1.0
        if g > 0:
            s0 = s
        elif g < 0:
            s1 = s
        else:
            break
    return s


@njit(cache=True)
def nearest_on_ellipse(e0, e1, y0, y1):
    """Nearest point to (y0, y1) >= 0 on the ellipse (x0/e0)^2 + (x1/e1)^2 = 1 (Eberly 2011)."""
    swap = e1 > e0
    if swap:
        e0, e1, y0, y1 = e1, e0, y1, y0
    if y1 > 0:
        if y0 > 0:
            z0, z1 = y0 / e0, y1 / e1
            g = z0 * z0 + z1 * z1 - 1.0
            if g != 0:
                r0 = (e0 / e1) ** 2
                sbar = _ellipse_root(r0, z0, z1, g)
                x0, x1 = r0 * y0 / (sbar + r0), y1 / (sbar + 1.0)
            else:
                x0, x1 = y0, y1
        else:
            x0, x1 = 0.0, e1
    else:
        numer0, denom0 = e0 * y0, e0 * e0 - e1 * e1
        if numer0 < denom0:
            xde0 = numer0 / denom0
            x0, x1 = e0 * xde0, e1 * math.sqrt(max(0.0, 1.0 - xde0 * xde0))
        else:
            x0, x1 = e0, 0.0
    if swap:
        return x1, x0
    return x0, x1


@njit(cache=True)
def cone_project(local, cone):
    """Direction (reference coordinates) -> (inside, nearest legal direction)."""
    x, y, z = local[0], local[1], local[2]
    theta = math.acos(max(-1.0, min(1.0, y)))
    h = math.sqrt(x * x + z * z)
    if h < 1e-12:
        if theta < 1e-9:
            return True, local
        x, z, h = 0.0, -1.0, 1.0  # straight behind: leave through the -z side (thesis: "behind the parent")
    u, v = theta * x / h, theta * z / h
    a = cone[0] if u >= 0 else cone[2]
    b = cone[1] if v >= 0 else cone[3]
    a, b = max(a, 1e-3), max(b, 1e-3)
    if (u / a) ** 2 + (v / b) ** 2 <= 1.0 + 1e-9:
        return True, local
    pu, pv = nearest_on_ellipse(a, b, abs(u), abs(v))
    pu = pu if u >= 0 else -pu
    pv = pv if v >= 0 else -pv
    t = math.sqrt(pu * pu + pv * pv)
    if t < 1e-12:
        return False, np.array([0.0, 1.0, 0.0])
    st = math.sin(t)
    return False, np.array([st * pu / t, math.cos(t), st * pv / t])


@njit(cache=True)
def twist_angle(Rb, ref):
    """Signed twist (radians) of bone frame Rb about its y relative to the reference frame."""
    swing = rotation_between(ref[:, 1], Rb[:, 1])
    carried = mv(swing, ref[:, 2].copy())
    bz, by = Rb[:, 2], Rb[:, 1]
    return math.atan2(vdot(vcross(carried, bz), by), vdot(carried, bz))


@njit(cache=True)
def clamp_twist(alpha, lo, hi):
    """Nearest angle in [lo, hi] on the circle (returns alpha itself when inside)."""
    if lo <= alpha <= hi:
        return alpha
    d_lo = abs(wrap(alpha - lo))
    d_hi = abs(wrap(alpha - hi))
    return lo if d_lo < d_hi else hi


@njit(cache=True)
def constrain_bone(P, R, i, limits):
    """Bring bone i inside its cone and twist limits (ChainLimits), moving everything it carries. True if moved."""
    pp, cones, has_cone, twists, has_twist = limits.pp, limits.cones, limits.has_cone, limits.twists, limits.has_twist
    ref = ref_frame(R, limits.ref0, pp, i)
    moved = False
    if has_cone[i]:
        d = P[i + 1] - P[i]
        nd = vnorm(d)
        if nd > EPS:
            local = mtv(ref, d / nd)
            inside, legal = cone_project(local, cones[i])
            if not inside:
                rotate_subchain(P, R, i, rotation_between(d, mv(ref, legal)))
                moved = True
    if has_twist[i]:
        alpha = twist_angle(R[i], ref)
        target = clamp_twist(alpha, twists[i, 0], twists[i, 1])
        if target != alpha:
            y = R[i][:, 1].copy()
            rot = axis_angle(y / vnorm(y), target - alpha)
            rotate_subchain(P, R, i, rot)
            moved = True
    return moved


@njit(cache=True)
def constrain_chain(P, R, limits):
    for i in range(R.shape[0]):
        constrain_bone(P, R, i, limits)


@njit(cache=True)
def escape_rotation(P, R, ref0, attempt, step_deg, max_deg):
    """Deadlock escape (facts 9.2): rotate the whole chain about its root by +-10, +-20 ... degrees,
    first about the reference y axis, then about its x axis. False when every angle was tried."""
    per_axis = 2 * int(max_deg // step_deg)
    if attempt >= 2 * per_axis:
        return False
    axis = ref0[:, 1].copy() if attempt < per_axis else ref0[:, 0].copy()
    k = attempt % per_axis
    angle = math.radians(step_deg * (k // 2 + 1) * (1 if k % 2 == 0 else -1))
    rotate_subchain(P, R, 0, axis_angle(axis / vnorm(axis), angle))
    return True


@njit(cache=True)
def jacobian(P, n):
    """Positional Jacobian of the end effector for rotations about world x, y, z at every joint."""
    J = np.zeros((3, 3 * n))
    end = P[n]
    for i in range(n):
        r = end - P[i]
        for a in range(3):
            axis = np.zeros(3)
            axis[a] = 1.0
            J[:, 3 * i + a] = vcross(axis, r)
    return J


@njit(cache=True)
def apply_angles(P, R, dtheta):
    n = R.shape[0]
    for i in range(n):
        w = dtheta[3 * i: 3 * i + 3]
        angle = vnorm(w)
        if angle > 1e-12:
            rotate_subchain(P, R, i, axis_angle(w / angle, angle))


# -- quaternion conversions (x, y, z, w), per joint -----------------------------------------------------------
@njit(cache=True)
def frames_to_quats(frames):
    """(J, 3, 3) rotation matrices -> (J, 4) unit quaternions (x, y, z, w), w >= 0; NaN stays NaN."""
    out = np.empty((frames.shape[0], 4))
    for j in range(frames.shape[0]):
        m = frames[j]
        t = m[0, 0] + m[1, 1] + m[2, 2]
        if not np.isfinite(t):
            out[j] = np.nan
            continue
        if t > 0:  # Shepperd's method: divide by the largest of the four candidates
            s = 2.0 * math.sqrt(1.0 + t)
            q = (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s
        elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
            s = 2.0 * math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
            q = 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s
        elif m[1, 1] > m[2, 2]:
            s = 2.0 * math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
            q = (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s
        else:
            s = 2.0 * math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
            q = (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s, (m[1, 0] - m[0, 1]) / s
        n = math.sqrt(q[0] ** 2 + q[1] ** 2 + q[2] ** 2 + q[3] ** 2)
        sign = -1.0 if q[3] < 0 else 1.0
        for k in range(4):
            out[j, k] = sign * q[k] / n
    return out


@njit(cache=True)
def quats_to_frames(quats):
    """(J, 4) quaternions (x, y, z, w) -> (J, 3, 3) rotation matrices; NaN stays NaN."""
    out = np.empty((quats.shape[0], 3, 3))
    for j in range(quats.shape[0]):
        x, y, z, w = quats[j, 0], quats[j, 1], quats[j, 2], quats[j, 3]
        out[j, 0, 0], out[j, 0, 1], out[j, 0, 2] = 1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)
        out[j, 1, 0], out[j, 1, 1], out[j, 1, 2] = 2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)
        out[j, 2, 0], out[j, 2, 1], out[j, 2, 2] = 2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)
    return out

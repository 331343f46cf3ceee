"""Gap filling with IK, one limb at a time (thesis 3.6, Algorithm 1; facts 9.1).

A limb is a chain of joints from a root that is always known once its parent stage ran (the torso
from spine0, the arms from the clavicle at the sternum, the legs from the hip centres). In each
frame, for every run of missing joints in the limb:

- the IK chain runs from the closest located parent to the next located joint (the target);
- it starts from the previous frame's solved chain, moved so its root sits on the current root;
- the chosen solver moves it onto the target; the joints in between are *estimated*, the target
  keeps its measured position;
- with no located joint after the run (a missing end effector), the previous chain is carried
  rigidly by the change of the root's parent frame since the last frame: it keeps its last
  rotation relative to its parent. Those joints are *held*.

Before the limb has been seen whole once there is no previous chain to start from, so its missing
joints stay missing (the original code started from a default H-Anim pose in Unity's frame, which
means nothing in a studio's coordinates).
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from numba import njit

from mocap_core.geometry import rotation_between
from mocap_core.ik.constraints import Constraints, load_constraints
from mocap_core.ik.kernels import mm, mv
from mocap_core.ik.solvers import KernelSolver, SolverParams, get_solver
from mocap_core.ik.solvers_kernels import solve
from mocap_core.skeleton import INDEX, LIMBS, PARENT, Status

MISSING, ESTIMATED, HELD = int(Status.MISSING), int(Status.ESTIMATED), int(Status.HELD)

# The first joint of each limb chain; its position comes from the stage before.
LIMB_CHAINS: dict[str, tuple[str, ...]] = {
    "torso": ("spine0", "spine1", "spine3", "neck", "head", "head_top"),
    "left_arm": LIMBS["left_arm"],
    "right_arm": LIMBS["right_arm"],
    "left_leg": LIMBS["left_leg"],
    "right_leg": LIMBS["right_leg"],
}
LIMB_ORDER = ("torso", "left_arm", "right_arm", "left_leg", "right_leg")
MIN_SAMPLES = 30    # located frames before a bone's direction in the next joint's frame is trusted
STABLE_STD = 0.08   # ... and the spread of its steadiest component that still counts as steady
BEND_MIN = 0.1  # a bend direction is trusted when the middle joint is off the line by 10 % of its bone
# Joints that begin a rigid segment of two more joints (ankle, foot, toe: the foot's bones).
CARRIED_BY_SEGMENT = frozenset({"ankle_l", "ankle_r"})


@dataclass
class FillStats:
    estimated: int = 0
    held: int = 0
    iterations: int = 0
    residual_m: float = 0.0
    solve_time_us: float = 0.0


class LimbFiller:
    """Fills the gaps of one limb frame after frame. Owns the limb's previous solved chain."""

    def __init__(self, limb: str, solver: KernelSolver | str = "ccd", params: SolverParams | None = None,
                 constraints: Constraints | None = None, reacquire_step_m: float = 0.0, swivel: bool = False,
                 segment_carry: bool = False):
        if limb not in LIMB_CHAINS:
            raise ValueError(f"unknown limb {limb!r} (limbs: {', '.join(LIMB_CHAINS)})")
        self.limb = limb
        self.solver = get_solver(solver) if isinstance(solver, str) else solver
        self.params = params or SolverParams()
        self.constraints = constraints or load_constraints()
        self.joints = np.array([INDEX[j] for j in LIMB_CHAINS[limb]], dtype=np.int64)
        self.parent_of_root = INDEX[PARENT[LIMB_CHAINS[limb][0]]]
        n = len(self.joints)
        self.prev_pos = np.full((n, 3), np.nan)        # the limb's last whole output
        self.prev_frames = np.full((n, 3, 3), np.nan)
        self.prev_parent_frame = np.full((3, 3), np.nan)
        self.has_prev = np.zeros(1, bool)
        # Re-acquisition without a twitch (beyond the thesis): when a joint's markers come back, the
        # gap between where IK had it and where the markers are is closed by at most this much per
        # frame (a rate-limited decaying offset, like game engines' inertialization); 0 = off.
        self.reacquire_step_m = reacquire_step_m
        # Beyond the thesis: a single missing joint between two located ones (an elbow between
        # shoulder and wrist, a knee between hip and ankle) lies on a circle fixed by its two bone
        # lengths; where on it (the swivel angle) is carried over from the last frame in the frame of
        # the limb's parent (chest or pelvis), not in world space. No iteration, no drift.
        self.swivel = swivel
        self.bend: dict[tuple, np.ndarray] = {}  # last well-defined bend direction per run, in its frame
        # each bone's direction in the frame of the joint it ends at, learned while both are located
        self.dir_sum, self.dir_sq, self.dir_n = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros(n)
        # Beyond the thesis: a lost ankle moves with its foot while the foot is still tracked (heel
        # and toe markers): ankle, foot and toe are one rigid body, so the ankle keeps its last
        # offset from the foot, turned by the least rotation that carries the foot's last heel-to-toe
        # axis onto the current one. The knee is then a lone missing joint (swivel or IK).
        # And a lost end of the limb (a hand, the head's top) moves with the last tracked bone before
        # it (the forearm, the neck), where Algorithm 1 would carry it with the limb's parent (chest).
        self.carried = [(k, k + 1, k + 2) for k, name in enumerate(LIMB_CHAINS[limb]) if name in CARRIED_BY_SEGMENT] \
            if segment_carry else None
        self.blend_offset = np.zeros((n, 3))
        self.last_out: np.ndarray | None = None
        self.last_status: np.ndarray | None = None
        c = self.constraints  # this limb's limits, gathered once; a chain takes a slice of them
        self._limits_of = (c.pp[self.joints], c.cones[self.joints], c.has_cone[self.joints],
                           c.twists[self.joints], c.has_twist[self.joints])

    def fill(self, positions: np.ndarray, frames: np.ndarray, status: np.ndarray) -> FillStats:
        """Fill this limb's joints of one skeleton frame in place (arrays of the whole skeleton)."""
        t0 = time.perf_counter()
        out = np.zeros(4)
        if self.carried is not None and self.has_prev[0]:
            out[0] += self._segment_carry(positions, frames, status)
            out[1] += self._carry_lost_end(positions, frames, status)
        if self.swivel:
            self._learn_directions(positions, frames, status)
            if self.has_prev[0]:
                out[0] += self._swivel_fill(positions, frames, status)
        p = self.params
        _fill_limb(positions, frames, status, self.joints, self.parent_of_root, self.limb.endswith("arm"),
                   self.prev_pos, self.prev_frames, self.prev_parent_frame, self.has_prev, *self._limits_of,
                   self.solver.kernel_id, p.constraints, p.max_iterations, p.stop_distance_m, p.escape_step_deg,
                   p.escape_max_deg, out)
        if self.reacquire_step_m > 0:
            self._blend_reacquired(positions, status)
        took_us = (time.perf_counter() - t0) * 1e6
        return FillStats(int(out[0]), int(out[1]), int(out[2]), float(out[3]), took_us if out[0] else 0.0)

    def _learn_directions(self, positions, frames, status) -> None:
        idx = self.joints
        for k in range(1, len(idx) - 1):
            if status[idx[k]] != Status.LOCATED or status[idx[k + 1]] != Status.LOCATED:
                continue
            bone, frame = positions[idx[k + 1]] - positions[idx[k]], frames[idx[k + 1]]
            size = np.linalg.norm(bone)
            if size > 1e-6 and np.isfinite(frame).all():
                local = frame.T @ (bone / size)
                self.dir_sum[k] += local
                self.dir_sq[k] += local * local
                self.dir_n[k] += 1

    def _stable_axis(self, k: int) -> tuple[int, float] | None:
        """The axis of joint k+1's frame along which bone k's direction hardly varies (the forearm
        against the radio-ulnar line of the wrist), and its mean component; None if there is none."""
        if self.dir_n[k] < MIN_SAMPLES:
            return None
        mean = self.dir_sum[k] / self.dir_n[k]
        std = np.sqrt(np.maximum(self.dir_sq[k] / self.dir_n[k] - mean * mean, 0.0))
        axis = int(np.argmin(std))
        return (axis, float(mean[axis])) if std[axis] < STABLE_STD else None

    def _segment_carry(self, positions: np.ndarray, frames: np.ndarray, status: np.ndarray) -> int:
        idx, prev, filled = self.joints, self.prev_pos, 0
        for j, c, g in self.carried:
            if status[idx[j]] != Status.MISSING or Status.MISSING in (status[idx[c]], status[idx[g]]):
                continue
            axis_prev, axis_now = prev[g] - prev[c], positions[idx[g]] - positions[idx[c]]
            if not (np.isfinite(axis_now).all() and np.linalg.norm(axis_now) > 1e-6):
                continue
            turn = rotation_between(axis_prev, axis_now)
            positions[idx[j]] = positions[idx[c]] + turn @ (prev[j] - prev[c])
            frames[idx[j]] = turn @ self.prev_frames[j]
            status[idx[j]] = Status.ESTIMATED
            filled += 1
        return filled

    def _carry_lost_end(self, positions: np.ndarray, frames: np.ndarray, status: np.ndarray) -> int:
        idx, prev, n = self.joints, self.prev_pos, len(self.joints)
        j = n
        while j > 0 and status[idx[j - 1]] == Status.MISSING:
            j -= 1
        root = j - 1  # the last located joint; the bone before it gives the turn
        if j == n or root < 1 or status[idx[root]] == Status.MISSING or status[idx[root - 1]] == Status.MISSING:
            return 0
        bone_now, bone_prev = frames[idx[root - 1]], self.prev_frames[root - 1]
        if not (np.isfinite(bone_now).all() and np.isfinite(bone_prev).all()):
            return 0
        turn = bone_now @ bone_prev.T
        for m in range(root, n):
            if m > root:
                positions[idx[m]] = positions[idx[root]] + turn @ (prev[m] - prev[root])
                status[idx[m]] = Status.HELD
            if not np.isfinite(frames[idx[m]]).all():
                frames[idx[m]] = turn @ self.prev_frames[m]
        return n - j

    def _swivel_fill(self, positions: np.ndarray, frames: np.ndarray, status: np.ndarray) -> int:
        """Fill each run of missing joints between two located ones without iterating.

        The first missing joint (an elbow, a knee) lies on a circle fixed by two lengths: its bone
        from the located joint before the run, and the distance from it to the located joint after
        the run, which the run's last shape keeps (for a lone joint that is simply its second bone;
        for a knee and an ankle lost together it is knee to toe with the ankle angle held). Where on
        the circle (the swivel angle) is carried over from the last frame in the frame of the located
        joint after the run, else of the limb's parent (pelvis or chest): never in world space. The
        rest of the run keeps its last shape in the plane of the two "bones"."""
        idx, n = self.joints, len(self.joints)
        parent_now, parent_prev = frames[self.parent_of_root], self.prev_parent_frame
        if not (np.isfinite(parent_now).all() and np.isfinite(parent_prev).all()):
            return 0
        filled = 0
        k = 1
        while k < n - 1:
            if not (status[idx[k]] == Status.MISSING and status[idx[k - 1]] != Status.MISSING):
                k += 1
                continue
            b = k
            while b < n and status[idx[b]] == Status.MISSING:
                b += 1
            if b == n:  # no located joint after the run: Algorithm 1's carry handles it
                break
            filled += self._fill_run(positions, frames, status, k - 1, k, b, parent_now, parent_prev)
            k = b + 1
        return filled

    def _fill_run(self, positions, frames, status, a: int, k: int, b: int, parent_now, parent_prev) -> int:
        """Joints k..b-1 missing, a and b located (limb-chain indices)."""
        idx, prev = self.joints, self.prev_pos
        pa, pk, pb = prev[a], prev[k], prev[b]
        upper, lower = np.linalg.norm(pk - pa), np.linalg.norm(pb - pk)
        root, target = positions[idx[a]], positions[idx[b]]
        d = target - root
        dist = np.linalg.norm(d)
        if not (dist > 1e-9 and upper > 0 and lower > 0):
            return 0
        axis = d / dist
        along = np.clip((upper * upper - lower * lower + dist * dist) / (2 * dist), -upper, upper)
        radius = np.sqrt(max(upper * upper - along * along, 0.0))
        # the previous bend direction, carried to now in the frame of the located joint after the run
        # (the wrist for an elbow: it turns with the forearm), else in the limb parent's frame
        d_prev = pb - pa
        u_prev = (pk - pa) - ((pk - pa) @ d_prev) / (d_prev @ d_prev) * d_prev
        ref_now, ref_prev = frames[idx[b]], self.prev_frames[b]
        key = (a, k, b, True)
        if not (np.isfinite(ref_now).all() and np.isfinite(ref_prev).all()):
            ref_now, ref_prev, key = parent_now, parent_prev, (a, k, b, False)
        # A nearly straight limb (a knee at mid-stance) has no bend direction worth the name: its sign
        # is noise. Keep the last well-defined one (bent over BEND_MIN of the bone) in the frame.
        size = np.linalg.norm(u_prev)
        if size > BEND_MIN * upper:
            self.bend[key] = ref_prev.T @ (u_prev / size)
        local = self.bend.get(key)
        if local is None:
            if not size > 1e-9:
                return 0
            local = ref_prev.T @ (u_prev / size)
        u = ref_now @ local
        u = u - (u @ axis) * axis
        nu = np.linalg.norm(u)
        if not nu > 1e-9:
            return 0
        u = u / nu
        # only a measured frame, not one carried over by segment_carry
        stable = self._stable_axis(k) if b == k + 1 and key[3] and status[idx[b]] == Status.LOCATED else None
        if stable is not None:  # the next joint's frame tells where on the circle: turn u there
            u = _on_circle_towards(u, axis, radius, target - (root + along * axis), lower,
                                   ref_now[:, stable[0]], stable[1])
        knee = root + along * axis + radius * u
        positions[idx[k]] = knee
        # the rest of the run: its last shape, turned with the plane of (a, k, b)
        turn = _plane_frame(knee - root, target - knee) @ _plane_frame(pk - pa, pb - pk).T
        for j in range(k + 1, b):
            positions[idx[j]] = knee + turn @ (prev[j] - pk)
        for j in range(k, b):
            frames[idx[j]] = turn @ self.prev_frames[j]
        if not np.isfinite(frames[idx[b]]).all():
            frames[idx[b]] = turn @ self.prev_frames[b]
        like = frames[idx[a]] if np.isfinite(frames[idx[a]]).all() else parent_now @ parent_prev.T @ self.prev_frames[a]
        frames[idx[a]] = _frame_along(knee - root, like)
        status[idx[k:b]] = Status.ESTIMATED
        return b - k

    def _blend_reacquired(self, positions: np.ndarray, status: np.ndarray) -> None:
        idx = self.joints
        now = status[idx]
        if self.last_out is not None:
            back = (now == Status.LOCATED) & np.isin(self.last_status, (Status.ESTIMATED, Status.HELD))
            back &= np.isfinite(self.last_out).all(axis=1)
            self.blend_offset[back] = self.last_out[back] - positions[idx[back]]
            self.blend_offset[now != Status.LOCATED] = 0.0
            size = np.linalg.norm(self.blend_offset, axis=1)
            active = size > 0
            if active.any():
                shrink = np.clip((size - self.reacquire_step_m) / np.where(active, size, 1.0), 0.0, 1.0)
                self.blend_offset *= shrink[:, None]
                positions[idx] += self.blend_offset
        self.last_out = positions[idx].copy()
        self.last_status = now.copy()


def _on_circle_towards(u, axis, radius, to_target, lower, n, c):
    """The direction on the swivel circle (from its centre) nearest to ``u`` at which the bone from
    the circle to the target has the component ``c`` along ``n``, or ``u`` when none is near."""
    e2 = np.cross(axis, u)
    a, b = radius * (n @ u), radius * (n @ e2)
    r = np.hypot(a, b)
    if not (radius > 1e-6 and r > 0.2 * radius):  # straight, or n along the axis: nothing to pick
        return u
    phi = np.arctan2(b, a)
    spread = np.arccos(np.clip((n @ to_target - c * lower) / r, -1.0, 1.0))
    psi = min((phi + spread, phi - spread), key=lambda x: abs(np.arctan2(np.sin(x), np.cos(x))))
    return np.cos(psi) * u + np.sin(psi) * e2


def _plane_frame(first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """Orthonormal frame (columns) with x along ``second`` and y in the plane of the two bones."""
    x = second / np.linalg.norm(second)
    y = first - (first @ x) * x
    ny = np.linalg.norm(y)
    if not ny > 1e-9:  # a straight limb: any perpendicular will do
        y = np.cross(x, [0.0, 0.0, 1.0] if abs(x[2]) < 0.9 else [1.0, 0.0, 0.0])
        ny = np.linalg.norm(y)
    y = y / ny
    return np.column_stack([x, y, np.cross(x, y)])


def _frame_along(y: np.ndarray, like: np.ndarray) -> np.ndarray:
    """A bone frame whose y runs along ``y``, turned from ``like`` by the shortest arc."""
    return rotation_between(like[:, 1], y) @ like


@njit(cache=True)
def _all_finite(a):
    for v in a.ravel():
        if not np.isfinite(v):
            return False
    return True


@njit(cache=True)
def _fill_limb(positions, frames, status, idx, parent, is_arm, prev_pos, prev_frames, prev_parent, has_prev,
               pp, cones, has_cone, twists, has_twist, solver, constrained, max_iter, stop_m, esc_step, esc_max,
               out):
    """Algorithm 1 for one limb, in place. out = [estimated, held, iterations, max residual m]."""
    n = idx.shape[0]
    parent_frame = frames[parent].copy()
    if status[idx[0]] == MISSING and is_arm and status[parent] != MISSING:
        # the clavicle joint sits on the sternum-clavicle point, its parent's position (facts 9.1)
        positions[idx[0]] = positions[parent]
        status[idx[0]] = ESTIMATED
    parent_ok = _all_finite(parent_frame)
    if has_prev[0] and parent_ok and status[idx[0]] != MISSING:
        i = 1
        while i < n:
            if status[idx[i]] != MISSING:
                i += 1
                continue
            root, t = i - 1, i
            while t < n and status[idx[t]] == MISSING:
                t += 1
            last = t if t < n else n - 1
            m = last - root  # bones in the chain
            # the previous chain from root to target (or to the limb's end), moved onto the current root
            P = np.empty((m + 1, 3))
            for k in range(m + 1):
                P[k] = prev_pos[root + k] - prev_pos[root] + positions[idx[root]]
            R = prev_frames[root:last].copy()
            ref0 = parent_frame if root == 0 else frames[idx[root - 1]].copy()
            if not _all_finite(ref0):
                ref0 = parent_frame
            if t < n:
                target = positions[idx[t]].astype(np.float64)
                it, res = solve(solver, P, R, target, ref0, pp[root:last], cones[root:last], has_cone[root:last],
                                twists[root:last], has_twist[root:last], constrained, max_iter, stop_m, esc_step,
                                esc_max)
                out[2] += it
                out[3] = max(out[3], res)
                first, stop, code = 1, m, ESTIMATED     # the target keeps its measured position
            else:
                # no target: keep the last rotation relative to the parent (a rigid carry)
                turn = mm(parent_frame, prev_parent.T.copy())
                for k in range(m + 1):
                    P[k] = positions[idx[root]] + mv(turn, prev_pos[root + k] - prev_pos[root])
                for k in range(m):
                    R[k] = mm(turn, prev_frames[root + k])
                frames[idx[last]] = mm(turn, prev_frames[last])
                first, stop, code = 1, m + 1, HELD
            for k in range(first, stop):
                positions[idx[root + k]] = P[k]
                status[idx[root + k]] = code
                out[0 if code == ESTIMATED else 1] += 1
            for k in range(m):
                frames[idx[root + k]] = R[k]
            i = t + 1
    # remember this frame's limb as the next frame's starting chain, if it is whole
    whole = parent_ok
    for k in range(n):
        whole = whole and _all_finite(positions[idx[k]])
    if whole:
        for k in range(n):
            prev_pos[k] = positions[idx[k]]
            if _all_finite(frames[idx[k]]) or not has_prev[0]:
                prev_frames[k] = frames[idx[k]]  # an end joint without a frame keeps its previous one
        prev_parent[:] = parent_frame
        has_prev[0] = True


class GapFiller:
    """All five limbs in graph order (torso first), for offline use; the nodes use LimbFiller."""

    def __init__(self, solver: str = "ccd", params: SolverParams | None = None,
                 constraints: Constraints | None = None, reacquire_step_m: float = 0.0, swivel: bool = False,
                 segment_carry: bool = False):
        constraints = constraints if constraints is not None else load_constraints()
        self.limbs = {limb: LimbFiller(limb, solver, params, constraints, reacquire_step_m, swivel, segment_carry)
                      for limb in LIMB_ORDER}

    def fill(self, positions, frames, status) -> dict[str, FillStats]:
        return {limb: f.fill(positions, frames, status) for limb, f in self.limbs.items()}

"""Gap filling with IK, one limb at a time (thesis 3.6, Algorithm 1; facts 9.1).

A limb is a chain of joints from a root that is always known once its parent stage ran (the torso
from spine0, the arms from the clavicle at the sternum, the legs from the hip centres). In each
frame, for every run of missing joints in the limb:

- the IK chain runs from the closest located parent to the next located joint (the target);
- it starts from the previous frame's solved chain, moved so its root sits on the current root, each
  bone at its length learned while both its joints were located (the thesis's C# code keeps every
  bone's length too; taking the last output's lengths, the chain's last bone took up each frame's
  residual and stretched frame after frame);
- the chosen solver moves it onto the target; the joints in between are *estimated*, the target
  keeps its measured position if the chain reaches it; out of reach, the target and the joints
  after it hang at the chain's end, as they are, and the target is *estimated* too;
- with no located joint after the run (a missing end effector), the previous chain is carried
  rigidly by the change of the root's parent frame since the last frame: it keeps its last
  rotation relative to its parent. Those joints are *held*.

A limb ends at its last joint ever located: a marker set without hand markers has arms that end at the
wrist. Before the limb has been seen whole once there is no previous chain to start from, so its missing
joints stay missing (the original code started from a default H-Anim pose in Unity's frame, which
means nothing in a studio's coordinates).
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from numba import njit

from mocap_core import analytic_fill as af
from mocap_core.analytic_fill import all_finite
from mocap_core.blend import DEFAULT_FRAME_S
from mocap_core.fill_options import FillOptions
from mocap_core.fill_units import LimbFill, LimbFrame
from mocap_core.frame_clock import FrameClock
from mocap_core.ik.constraints import Constraints, load_constraints
from mocap_core.ik.kernels import mm, mv
from mocap_core.ik.solvers import ChainLimits, Solver, SolverParams, get_solver
from mocap_core.ik.solvers_kernels import solve
from mocap_core.rigid_chain import RigidChain
from mocap_core.skeleton import ESTIMATED, HELD, INDEX, LIMBS, LOCATED, MISSING, PARENT

# The limb whose poses, mirrored, a limb's fills also learn from.
MIRRORED = {"left_arm": "right_arm", "right_arm": "left_arm", "left_leg": "right_leg", "right_leg": "left_leg"}


@dataclass
class FillStats:
    estimated: int = 0
    held: int = 0
    iterations: int = 0
    residual_m: float = 0.0
    solve_time_us: float = 0.0


class LimbFiller:
    """Fills the gaps of one limb frame after frame: the fills ``options`` turn on (mocap_core.fills.LIMB_FILLS,
    in their order; none: the thesis's method), then Algorithm 1. Owns the limb's previous solved chain and the
    bone lengths learned, which the fills read too."""

    def __init__(self, limb: str, solver: Solver | str = "ccd", params: SolverParams | None = None,
                 constraints: Constraints | None = None, options: FillOptions = FillOptions()):
        if limb not in LIMBS:
            raise ValueError(f"unknown limb {limb!r} (limbs: {', '.join(LIMBS)})")
        options.refuse_idle(limb)
        self.limb = limb
        self.solver = get_solver(solver) if isinstance(solver, str) else solver
        self.params = (params or SolverParams()).typed()
        self._params = tuple(self.params)  # (as the kernel takes it)
        self.constraints = constraints or load_constraints()
        self.joints = np.array([INDEX[j] for j in LIMBS[limb]], dtype=np.int64)
        self.parent_of_root = INDEX[PARENT[LIMBS[limb][0]]]
        other = MIRRORED.get(limb)
        self.other = None if other is None else np.array([INDEX[j] for j in LIMBS[other]], dtype=np.int64)
        n = len(self.joints)
        self.prev_pos = np.full((n, 3), np.nan)        # the limb's last whole output
        self.prev_frames = np.full((n, 3, 3), np.nan)
        self.prev_parent_frame = np.full((3, 3), np.nan)
        self.has_prev = np.zeros(1, bool)
        # Bone lengths learned online: each bone's mean length over the frames that located both its joints
        # (sum, count). The IK chains and the swivel keep them (the thesis's rigid bones): the last whole frame's
        # would keep its marker noise, and the stretch of a limb that straightened past its reach, the whole gap.
        self.lengths = np.zeros((n, 2))
        # (the chain and that state as the fills' kernels take them)
        self.chain = (self.joints, self.parent_of_root)
        self.last = (self.prev_pos, self.prev_frames, self.prev_parent_frame, self.has_prev, self.lengths)
        self.seen = np.zeros(n, bool)    # joints located at least once
        self.all_seen = False
        self.chain_end = n               # the limb's joints up to its last one ever located
        self._chain = None               # and what the kernel takes of them (_chain_up_to)
        self.clock = FrameClock(DEFAULT_FRAME_S)  # the frames' interval, from their times
        made = (fill.for_limb(self, options) for fill in options.fills if fill.wanted(options))
        self.fills: list[LimbFill] = [fill for fill in made if fill is not None]
        # (the steps each fill takes: a frame calls no method that does nothing)
        self._before = [fill.before for fill in self.fills if type(fill).before is not LimbFill.before]
        self._after = [fill.after for fill in self.fills if type(fill).after is not LimbFill.after]
        # what the swivel reads where no fill steers it
        self.no_recall, self.no_model, self.no_weight = np.full((n, 3), np.nan), np.full((n, 3), np.nan), np.zeros(n)
        c = self.constraints  # this limb's limits, gathered once; a chain takes a slice of them
        self.limits = ChainLimits(np.eye(3), c.pp[self.joints], c.cones[self.joints], c.has_cone[self.joints],
                                  c.twists[self.joints], c.has_twist[self.joints])  # (each run's ref0 its own)

    def use(self, subject, labels: list[str] | None = None) -> None:
        """The limb's rigid chain (if on) with the bones of a calibrated subject (mocap_core.fit.subject); with the
        stream's marker ``labels``, fitted to the markers the subject places on the limb (``fill``'s ``markers``)."""
        if self.rigid is not None:
            self.rigid.use(subject, labels)

    @property
    def rigid(self) -> RigidChain | None:
        return self.get(RigidChain)

    def get(self, kind: type) -> LimbFill | None:
        """This limb's fill of that class, if on."""
        return next((fill for fill in self.fills if isinstance(fill, kind)), None)

    def fill(self, positions: np.ndarray, frames: np.ndarray, status: np.ndarray,
             time_s: float = float("nan"), markers: np.ndarray | None = None) -> FillStats:
        """Fill this limb's joints of one skeleton frame in place (arrays of the whole skeleton).
        ``time_s``: the frame's capture time, which paces the fills (else blend.DEFAULT_FRAME_S a frame);
        ``markers``: the frame's markers (M, 3), labelled as ``use`` was told."""
        t0 = time.perf_counter()
        self.clock.advance(time_s)
        idx = self.joints
        frame = LimbFrame(positions, frames, status, np.zeros(4), self.no_recall, self.no_model, self.no_weight,
                          markers)
        af.learn_lengths(positions, status, idx, self.lengths)
        for before in self._before:
            before(frame)
        # a limb ends at its last joint ever located: a marker set without hand markers has arms that end at the
        # wrist (the hand, never seen, would keep the limb from ever being whole, and so from ever being filled)
        if not self.all_seen:  # (once every joint has been, the limb ends at its last for good)
            self.seen |= status[idx] == LOCATED
            self.all_seen = bool(self.seen.all())
            n = int(np.flatnonzero(self.seen)[-1]) + 1 if self.seen.any() else len(idx)
            if n != self.chain_end or self._chain is None:  # a joint seen for the first time: the limb is whole
                self.chain_end, self.has_prev[0] = n, False        # again only once it is seen
                self._chain = self._chain_up_to(n)
        out = frame.out
        _fill_limb(frame.skeleton, *self._chain, self.solver.kernel_id, self._params, out)
        if self.chain_end < len(idx):
            never = idx[self.chain_end:]  # joints never located (the carries would hold them from nothing)
            positions[never], frames[never], status[never] = np.nan, np.nan, MISSING
        for after in self._after:
            after(frame)
        took_us = (time.perf_counter() - t0) * 1e6
        return FillStats(int(out[0]), int(out[1]), int(out[2]), float(out[3]), took_us if out[0] else 0.0)

    def _chain_up_to(self, n: int) -> tuple:
        """What Algorithm 1 takes of the limb's first n joints: the chain, views of its last output and learned
        lengths (which the kernel updates) and its limits, as plain tuples (numba reads a NamedTuple from Python
        about a microsecond slower a call, and this runs for every limb of every frame)."""
        lim = self.limits
        return ((self.joints[:n], self.parent_of_root, self.limb.endswith("arm")),
                (self.prev_pos[:n], self.prev_frames[:n], self.prev_parent_frame, self.has_prev, self.lengths),
                (lim.pp[:n], lim.cones[:n], lim.has_cone[:n], lim.twists[:n], lim.has_twist[:n]))


@njit(cache=True)
def _rigid_chain(prev_pos, lengths, root, m):
    """The previous chain's joints root..root+m with each bone turned as it was and as long as learned."""
    P = np.empty((m + 1, 3))
    P[0] = prev_pos[root]
    for k in range(1, m + 1):
        bone = prev_pos[root + k] - prev_pos[root + k - 1]
        size = np.sqrt(np.sum(bone * bone))
        length = af._length(lengths, root + k - 1, size)
        P[k] = P[k - 1] + (bone * (length / size) if size > 0 else bone)
    return P


@njit(cache=True)
def _fill_limb(skeleton, chain, last, limits, solver, params, out):
    """Algorithm 1 for one limb, in place: every run of missing joints after a located one. ``skeleton``:
    (positions, frames, status) of the whole skeleton; ``chain``: the limb's (joints, parent, is_arm); ``last``:
    its last whole output (prev_pos, prev_frames, prev_parent, has_prev) and learned bone lengths; ``limits``:
    its bones' (pp, cones, has_cone, twists, has_twist); ``solver``: its place in SOLVERS; ``params``:
    SolverParams as a plain tuple. out = [estimated, held, iterations, max residual m]."""
    positions, frames, status = skeleton
    idx, parent, is_arm = chain
    has_prev = last[3]
    n = idx.shape[0]
    parent_frame = frames[parent].copy()
    if status[idx[0]] == MISSING and is_arm and status[parent] != MISSING:
        # the clavicle joint sits on the sternum-clavicle point, its parent's position (facts 9.1)
        positions[idx[0]] = positions[parent]
        status[idx[0]] = ESTIMATED
    parent_ok = all_finite(parent_frame)
    if has_prev[0] and parent_ok and status[idx[0]] != MISSING:
        how = (solver, SolverParams(*params))
        i = 1
        while i < n:
            if status[idx[i]] != MISSING:
                i += 1
                continue
            t = i
            while t < n and status[idx[t]] == MISSING:
                t += 1
            _fill_gap(skeleton, idx, last, limits, parent_frame, (i - 1, t), how, out)
            i = t + 1
    if parent_ok:
        _remember(skeleton, idx, last, parent_frame)


@njit(cache=True)
def _fill_gap(skeleton, idx, last, limits, parent_frame, run, how, out):
    """One run of missing joints: from ``run`` = (root, t), root located and t the next located joint (the
    limb's length: none). ``how``: (solver, SolverParams)."""
    positions, frames, status = skeleton
    prev_pos, prev_frames, prev_parent, _, lengths = last
    pp, cones, has_cone, twists, has_twist = limits
    root, t = run
    solver, params = how
    n = idx.shape[0]
    last_k = t if t < n else n - 1
    m = last_k - root  # bones in the chain
    # the previous chain from root to target (or to the limb's end), moved onto the current root, each
    # bone at its learned length: the chain's last bone would otherwise carry each frame's residual
    # into the next frame's start, and stretch frame after frame
    prev = _rigid_chain(prev_pos, lengths, root, m)
    P = np.empty((m + 1, 3))
    for k in range(m + 1):
        P[k] = prev[k] - prev[0] + positions[idx[root]]
    R = prev_frames[root:last_k].copy()
    ref0 = parent_frame if root == 0 else frames[idx[root - 1]].copy()
    if not all_finite(ref0):
        ref0 = parent_frame
    if t < n:
        target = positions[idx[t]].astype(np.float64)
        chain_limits = ChainLimits(ref0, pp[root:last_k], cones[root:last_k], has_cone[root:last_k],
                                   twists[root:last_k], has_twist[root:last_k])
        it, res = solve(solver, P, R, target, chain_limits, params)
        out[2] += it
        out[3] = max(out[3], res)
        first, stop, code = 1, m, ESTIMATED     # the target keeps its measured position, if reached
        if res > params.stop_distance_m:
            # out of the rigid chain's reach: the target and the joints after it hang at the chain's end,
            # as they are, so no bone stretches (the thesis's C# code keeps every bone's length too)
            shift = P[m] - target
            for k in range(t, n):
                positions[idx[k]] = positions[idx[k]] + shift
            status[idx[t]] = ESTIMATED
    else:
        # no target: keep the last rotation relative to the parent (a rigid carry)
        turn = mm(parent_frame, prev_parent.T.copy())
        for k in range(m + 1):
            P[k] = positions[idx[root]] + mv(turn, prev[k] - prev[0])
        for k in range(m):
            R[k] = mm(turn, prev_frames[root + k])
        frames[idx[last_k]] = mm(turn, prev_frames[last_k])
        first, stop, code = 1, m + 1, HELD
    for k in range(first, stop):
        positions[idx[root + k]] = P[k]
        status[idx[root + k]] = code
        out[0 if code == ESTIMATED else 1] += 1
    for k in range(m):
        frames[idx[root + k]] = R[k]


@njit(cache=True)
def _remember(skeleton, idx, last, parent_frame):
    """This frame's limb as the next frame's starting chain, if it is whole."""
    positions, frames = skeleton[0], skeleton[1]
    prev_pos, prev_frames, prev_parent, has_prev = last[0], last[1], last[2], last[3]
    n = idx.shape[0]
    for k in range(n):
        if not all_finite(positions[idx[k]]):
            return
    for k in range(n):
        prev_pos[k] = positions[idx[k]]
        if all_finite(frames[idx[k]]) or not has_prev[0]:
            prev_frames[k] = frames[idx[k]]  # an end joint without a frame keeps its previous one
    prev_parent[:] = parent_frame
    has_prev[0] = True


class GapFiller:
    """All five limbs in graph order (torso first), for offline use; the nodes use LimbFiller."""

    def __init__(self, solver: str = "ccd", params: SolverParams | None = None,
                 constraints: Constraints | None = None, options: FillOptions = FillOptions()):
        constraints = constraints if constraints is not None else load_constraints()
        self.limbs = {limb: LimbFiller(limb, solver, params, constraints, options.for_limb(limb))
                      for limb in LIMBS}  # the torso first

    def use(self, subject, labels: list[str] | None = None) -> None:
        """Every limb's rigid chain (where on) with a calibrated subject's bones (and markers: LimbFiller.use)."""
        for f in self.limbs.values():
            f.use(subject, labels)

    @property
    def rigid(self) -> bool:
        return any(f.rigid is not None for f in self.limbs.values())

    def fill(self, positions, frames, status, time_s: float = float("nan"),
             markers: np.ndarray | None = None) -> dict[str, FillStats]:
        """One frame in place, as the graph fills it: the torso first, then each limb from the torso's output
        (the limb nodes run side by side: none sees another's filled joints)."""
        torso, *limbs = self.limbs.values()
        stats = {"torso": torso.fill(positions, frames, status, time_s, markers)}
        filled = []
        for f in limbs:
            p, r, s = positions.copy(), frames.copy(), status.copy()
            stats[f.limb] = f.fill(p, r, s, time_s, markers)
            filled.append((f.joints, p, r, s))
        for idx, p, r, s in filled:
            positions[idx], frames[idx], status[idx] = p[idx], r[idx], s[idx]
        return stats

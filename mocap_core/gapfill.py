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

from mocap_core.ik.constraints import Constraints, load_constraints
from mocap_core.ik.solvers import ChainLimits, Solver, SolverParams, get_solver
from mocap_core.skeleton import INDEX, LIMBS, PARENT, Status

# The first joint of each limb chain; its position comes from the stage before.
LIMB_CHAINS: dict[str, tuple[str, ...]] = {
    "torso": ("spine0", "spine1", "spine3", "neck", "head", "head_top"),
    "left_arm": LIMBS["left_arm"],
    "right_arm": LIMBS["right_arm"],
    "left_leg": LIMBS["left_leg"],
    "right_leg": LIMBS["right_leg"],
}
LIMB_ORDER = ("torso", "left_arm", "right_arm", "left_leg", "right_leg")


@dataclass
class FillStats:
    estimated: int = 0
    held: int = 0
    iterations: int = 0
    residual_m: float = 0.0
    solve_time_us: float = 0.0


class LimbFiller:
    """Fills the gaps of one limb frame after frame. Owns the limb's previous solved chain."""

    def __init__(self, limb: str, solver: Solver | str = "ccd", params: SolverParams | None = None,
                 constraints: Constraints | None = None):
        if limb not in LIMB_CHAINS:
            raise ValueError(f"unknown limb {limb!r} (limbs: {', '.join(LIMB_CHAINS)})")
        self.limb = limb
        self.solver = get_solver(solver) if isinstance(solver, str) else solver
        self.params = params or SolverParams()
        self.constraints = constraints or load_constraints()
        self.joints = np.array([INDEX[j] for j in LIMB_CHAINS[limb]])
        self.parent_of_root = INDEX[PARENT[LIMB_CHAINS[limb][0]]]
        self.prev_pos: np.ndarray | None = None     # (n, 3) last output of the limb's joints
        self.prev_frames: np.ndarray | None = None  # (n, 3, 3)
        self.prev_parent_frame: np.ndarray | None = None
        c = self.constraints  # this limb's limits, gathered once; a chain takes a slice of them
        self._limits_of = (c.pp[self.joints], c.cones[self.joints], c.has_cone[self.joints],
                           c.twists[self.joints], c.has_twist[self.joints])

    def _limits(self, root: int, last: int, ref0: np.ndarray) -> ChainLimits:
        pp, cones, has_cone, twists, has_twist = (a[root:last] for a in self._limits_of)
        return ChainLimits(np.ascontiguousarray(ref0), pp, cones, has_cone, twists, has_twist)

    def fill(self, positions: np.ndarray, frames: np.ndarray, status: np.ndarray) -> FillStats:
        """Fill this limb's joints of one skeleton frame in place (arrays of the whole skeleton)."""
        stats = FillStats()
        idx = self.joints
        parent_frame = frames[self.parent_of_root]
        missing = status[idx] == Status.MISSING
        have_history = self.prev_pos is not None and np.isfinite(parent_frame).all()
        if missing.any() and have_history and status[idx[0]] != Status.MISSING:
            t0 = time.perf_counter()
            self._fill_runs(positions, frames, status, missing, parent_frame, stats)
            stats.solve_time_us = (time.perf_counter() - t0) * 1e6
        pos = positions[idx]
        if np.isfinite(pos).all() and np.isfinite(parent_frame).all():
            self.prev_pos = pos.astype(np.float64).copy()
            fr = frames[idx].astype(np.float64).copy()
            # a located end joint may lack a frame (no child seen): keep the previous one
            if self.prev_frames is not None:
                bad = ~np.isfinite(fr).all(axis=(1, 2))
                fr[bad] = self.prev_frames[bad]
            self.prev_frames = fr
            self.prev_parent_frame = np.array(parent_frame, dtype=np.float64)
        return stats

    def _fill_runs(self, positions, frames, status, missing, parent_frame, stats: FillStats) -> None:
        idx, n = self.joints, len(self.joints)
        i = 1
        while i < n:
            if not missing[i]:
                i += 1
                continue
            root = i - 1
            t = i
            while t < n and missing[t]:
                t += 1
            # previous chain from root to the target (or to the limb's end), moved onto the current root
            last = t if t < n else n - 1
            chain = np.arange(root, last + 1)
            P = self.prev_pos[chain] - self.prev_pos[root] + positions[idx[root]]
            R = self.prev_frames[chain[:-1]].copy()
            ref0 = parent_frame if root == 0 else frames[idx[root - 1]]
            if not np.isfinite(ref0).all():
                ref0 = parent_frame
            if t < n:
                result = self.solver.solve(P, R, positions[idx[t]].astype(np.float64),
                                           self._limits(root, last, ref0), self.params)
                stats.iterations += result.iterations
                stats.residual_m = max(stats.residual_m, result.residual_m)
                filled = chain[1:-1]
                code = Status.ESTIMATED
            else:
                # no target: keep the last rotation relative to the parent (rigid carry)
                turn = parent_frame @ self.prev_parent_frame.T
                P = positions[idx[root]] + (self.prev_pos[chain] - self.prev_pos[root]) @ turn.T
                R = turn @ self.prev_frames[chain[:-1]]
                frames[idx[last]] = turn @ self.prev_frames[last]
                filled = chain[1:]
                code = Status.HELD
            positions[idx[filled]] = P[filled - root]
            frames[idx[chain[:-1]]] = R
            status[idx[filled]] = code
            if code == Status.ESTIMATED:
                stats.estimated += len(filled)
            else:
                stats.held += len(filled)
            i = t + 1


class GapFiller:
    """All five limbs in graph order (torso first), for offline use; the nodes use LimbFiller."""

    def __init__(self, solver: str = "ccd", params: SolverParams | None = None,
                 constraints: Constraints | None = None):
        constraints = constraints or load_constraints()
        self.limbs = {limb: LimbFiller(limb, solver, params, constraints) for limb in LIMB_ORDER}

    def fill(self, positions, frames, status) -> dict[str, FillStats]:
        return {limb: f.fill(positions, frames, status) for limb, f in self.limbs.items()}

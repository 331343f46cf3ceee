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
from mocap_core.blend import BlendState
from mocap_core.body_model import END_WAIT_S, MODELLED, MODELLED_ENDS, BodyModel
from mocap_core.fill_options import FillOptions
from mocap_core.ik.constraints import Constraints, load_constraints
from mocap_core.ik.kernels import mm, mv
from mocap_core.ik.solvers import ChainLimits, Solver, SolverParams, get_solver
from mocap_core.ik.solvers_kernels import solve
from mocap_core.limb_memory import LimbMemory
from mocap_core.skeleton import ESTIMATED, HELD, INDEX, LIMBS, LOCATED, MISSING, PARENT

# The limb whose poses, mirrored, each limb also remembers (limb memory).
MIRRORED = {"left_arm": "right_arm", "right_arm": "left_arm", "left_leg": "right_leg", "right_leg": "left_leg"}
# A predicted end is put at most this share of the limb's reach from its root: the joints between stay bent.
REACH_SHARE = 0.99
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

    def __init__(self, limb: str, solver: Solver | str = "ccd", params: SolverParams | None = None,
                 constraints: Constraints | None = None, options: FillOptions = FillOptions()):
        """``options``: the fills beyond the thesis (none: the thesis's method)."""
        if limb not in LIMBS:
            raise ValueError(f"unknown limb {limb!r} (limbs: {', '.join(LIMBS)})")
        options.refuse_idle(limb)
        self.limb = limb
        self.solver = get_solver(solver) if isinstance(solver, str) else solver
        self.params = (params or SolverParams()).typed()
        self.constraints = constraints or load_constraints()
        self.joints = np.array([INDEX[j] for j in LIMBS[limb]], dtype=np.int64)
        self.parent_of_root = INDEX[PARENT[LIMBS[limb][0]]]
        n = len(self.joints)
        self.prev_pos = np.full((n, 3), np.nan)        # the limb's last whole output
        self.prev_frames = np.full((n, 3, 3), np.nan)
        self.prev_parent_frame = np.full((3, 3), np.nan)
        self.has_prev = np.zeros(1, bool)
        # Re-acquisition without a twitch (beyond the thesis): when a joint's markers come back, the
        # gap between where IK had it and where the markers are is closed by at most reacquire_step_m per
        # frame (a rate-limited decaying offset, like game engines' inertialization); 0 = off.
        # Inertialization at both ends of a gap (blend_half_life_s): a joint whose markers are lost
        # goes on where it was heading, then eases into the estimate; one whose markers come back eases into
        # them. The offset dies out as a critically damped spring (mocap_core/blend.py).
        o = options
        self.blend = BlendState.empty(n, o.reacquire_step_m, o.blend_half_life_s, o.blend_course)
        # Beyond the thesis (mocap_core/analytic_fill.py): runs of missing joints between located
        # ones on their swivel circle; a lost ankle carried by its foot and a lost end by the bone
        # before it. State: the last well-defined bend direction per run (joint, end, frame kind),
        # and each bone's direction statistics in the frame of the joint it ends at.
        self.swivel = o.swivel
        self.bend, self.bend_ok = np.zeros((n, n + 1, 2, 3)), np.zeros((n, n + 1, 2), bool)
        self.dir_sum, self.dir_sq, self.dir_n = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros(n)
        # Bone lengths learned online: each bone's mean length over the frames that located both its joints
        # (sum, count). The IK chains and the swivel keep them (the thesis's rigid bones): the last whole frame's
        # would keep its marker noise, and the stretch of a limb that straightened past its reach, the whole gap.
        self.lengths = np.zeros((n, 2))
        self.seen = np.zeros(n, bool)    # joints located at least once
        self.chain_end = n               # the limb's joints up to its last one ever located
        self._chain = None               # and what the kernel takes of them (_chain_up_to)
        other = MIRRORED.get(limb)  # the other limb's chain, whose poses both memories learn too, mirrored
        other_idx = None if other is None else np.array([INDEX[j] for j in LIMBS[other]], dtype=np.int64)
        self.memory = LimbMemory(n, other_idx) if o.limb_memory else None
        self.no_recall = np.full((n, 3), np.nan)
        self.body_model, self.end_model = self._models(o, other_idx)
        self.modelled, self.model_weight = np.full((n, 3), np.nan), np.zeros(n)
        self.end_local = np.full(3, np.nan)  # the lost end's offset from the root where the gap began
        self.end_seen = False                 # and whether its markers were the end's last source
        self.end_since = 0.0                  # and how long the limb has been lost
        self.carried = np.array([(k, k + 1, k + 2) for k, name in enumerate(LIMBS[limb])
                                 if name in CARRIED_BY_SEGMENT], dtype=np.int64).reshape(-1, 3) \
            if o.segment_carry else None
        c = self.constraints  # this limb's limits, gathered once; a chain takes a slice of them
        self.limits = ChainLimits(np.eye(3), c.pp[self.joints], c.cones[self.joints], c.has_cone[self.joints],
                                  c.twists[self.joints], c.has_twist[self.joints])  # (each run's ref0 its own)

    def _models(self, o: FillOptions, other_idx) -> tuple[BodyModel | None, BodyModel | None]:
        """The body model: a lone lost elbow or knee turned on its circle towards where a regression from the rest
        of the located body puts it (mocap_core.body_model). The end model: a limb lost from its first joint down
        (elbow, wrist and hand; knee, ankle and foot) has its end put where the same kind of regression puts it,
        learned from the wrist's (ankle's) place from the shoulder (hip); the joints between then aim at it
        (Algorithm 1 held the limb as it was relative to its parent). Both learn from the other limb too, so
        the torso has neither."""
        names = LIMBS[self.limb]
        middle = [k for k, name in enumerate(names) if name in MODELLED]
        ends = [k for k, name in enumerate(names) if name in MODELLED_ENDS]
        if other_idx is None or not middle:
            return None, None
        body = BodyModel(self.joints, other_idx, middle[0], self.parent_of_root) if o.body_model else None
        end = BodyModel(self.joints, other_idx, ends[0], self.parent_of_root, root=middle[0] - 1) \
            if o.end_model and ends else None
        return body, end

    def fill(self, positions: np.ndarray, frames: np.ndarray, status: np.ndarray,
             time_s: float = float("nan")) -> FillStats:
        """Fill this limb's joints of one skeleton frame in place (arrays of the whole skeleton).
        ``time_s``: the frame's capture time, which paces the blend (else blend.DEFAULT_FRAME_S a frame)."""
        t0 = time.perf_counter()
        self.blend.advance_clock(time_s)
        out = np.zeros(4)
        idx, prev_pos, prev_frames = self.joints, self.prev_pos, self.prev_frames
        if self.end_model is not None:  # (before the carry, which would hold the whole lost limb with the clavicle)
            out[0] += self._predict_end(positions, frames, status)
        if self.carried is not None and self.has_prev[0]:
            out[0] += af.segment_carry(positions, frames, status, idx, self.carried, prev_pos, prev_frames)
            out[1] += af.carry_lost_end(positions, frames, status, idx, prev_pos, prev_frames)
        af.learn_lengths(positions, status, idx, self.lengths)
        if self.swivel:
            af.learn_directions(positions, frames, status, idx, self.dir_sum, self.dir_sq, self.dir_n)
            recalled = self.no_recall
            if self.memory is not None:
                self.memory.learn(positions, frames, status, idx, self.parent_of_root)
                recalled = self.memory.recall(positions, frames, status, idx, self.parent_of_root)
            if self.body_model is not None:
                self._model(positions, frames, status)
            if self.has_prev[0]:
                out[0] += af.swivel_fill(positions, frames, status, idx, self.parent_of_root, prev_pos, prev_frames,
                                         self.prev_parent_frame, self.bend, self.bend_ok, self.dir_sum,
                                         self.dir_sq, self.dir_n, recalled,
                                         self.lengths, self.modelled,
                                         self.model_weight)
        # a limb ends at its last joint ever located: a marker set without hand markers has arms that end at the
        # wrist (the hand, never seen, would keep the limb from ever being whole, and so from ever being filled)
        self.seen |= status[idx] == LOCATED
        n = int(np.flatnonzero(self.seen)[-1]) + 1 if self.seen.any() else len(idx)
        if n != self.chain_end or self._chain is None:  # a joint seen for the first time: the limb is whole again
            self.chain_end, self.has_prev[0] = n, False        # only once it is seen
            self._chain = self._chain_up_to(n)
        _fill_limb(positions, frames, status, *self._chain, self.solver.kernel_id, *self.params, out)
        never = idx[n:]  # joints never located (the carries would hold them from nothing)
        positions[never], frames[never], status[never] = np.nan, np.nan, MISSING
        if self.blend.on:
            self.blend.blend(positions, status, idx, frames)
        took_us = (time.perf_counter() - t0) * 1e6
        return FillStats(int(out[0]), int(out[1]), int(out[2]), float(out[3]), took_us if out[0] else 0.0)

    def _chain_up_to(self, n: int) -> tuple:
        """What Algorithm 1 takes of the limb's first n joints: the chain, views of its state (which the kernel
        updates) and its limits. One by one, not as tuples: numba reads a tuple of arrays microseconds slower
        a call, and this runs for every limb of every frame."""
        lim = self.limits
        return (self.joints[:n], self.parent_of_root, self.limb.endswith("arm"), self.prev_pos[:n],
                self.prev_frames[:n], self.prev_parent_frame, self.has_prev, self.lengths, lim.pp[:n], lim.cones[:n],
                lim.has_cone[:n], lim.twists[:n], lim.has_twist[:n])

    def _predict_end(self, positions, frames, status) -> int:
        """The end model's point for a limb lost from its first joint down, within the limb's reach; 1 if put."""
        model = self.end_model
        model.learn(positions, frames, status)
        idx, root, k = self.joints, model.root, model.k
        if status[idx[k]] != MISSING:  # seen, or put by the hip stage's fills (the leg hinge, say)
            self.end_seen = status[idx[k]] == LOCATED
        # a limb whose better fill drops out for a few frames is held as that fill left it, not handed to the
        # model and back (each hand-over is a jump of its own)
        if not self.has_prev[0] or not (self.end_seen or all_finite(self.end_local)):
            return 0
        point, weight = model.predict(positions, frames, status, self.blend.frame_s)
        if not all_finite(point):
            self.end_local[:] = np.nan
            return 0
        parent = frames[self.parent_of_root]
        if not all_finite(self.end_local):  # the gap begins: the end as it was, in the limb parent's frame
            self.end_local[:] = self.prev_parent_frame.T @ (self.prev_pos[k] - self.prev_pos[root])
            self.end_since = 0.0
        self.end_since += self.blend.frame_s  # (seconds into the gap)
        if self.end_since < END_WAIT_S - self.blend.frame_s / 2:  # to the nearest frame: stamps are rounded (QTM's
            return 0                                               # to the microsecond), sums of 1/rate inexact
        held = positions[idx[root]] + parent @ self.end_local
        if all_finite(held):  # a pose unlike those learned moves the end less far from where it was held
            point = held + weight * (point - held)
        bones = [af._length(self.lengths, j, float(np.linalg.norm(self.prev_pos[j + 1] - self.prev_pos[j])))
                 for j in range(root, k)]  # as the swivel takes them
        reach = REACH_SHARE * sum(bones)
        out = point - positions[idx[root]]
        size = float(np.linalg.norm(out))
        if size > reach:  # a bent limb's joints cannot be placed between root and an end out of reach
            point = positions[idx[root]] + out * (reach / size)
        positions[idx[k]] = point
        status[idx[k]] = ESTIMATED
        return 1

    def _model(self, positions, frames, status) -> None:
        model = self.body_model
        model.learn(positions, frames, status)
        self.modelled[model.k], self.model_weight[model.k] = model.predict(positions, frames, status,
                                                                             self.blend.frame_s)


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
def _fill_limb(positions, frames, status, idx, parent, is_arm, prev_pos, prev_frames, prev_parent, has_prev,
               lengths, pp, cones, has_cone, twists, has_twist, solver, max_iterations, stop_distance_m, constraints,
               escape_step_deg, escape_max_deg, out):
    """Algorithm 1 for one limb, in place. out = [estimated, held, iterations, max residual m]."""
    params = SolverParams(max_iterations, stop_distance_m, constraints, escape_step_deg, escape_max_deg)
    n = idx.shape[0]
    parent_frame = frames[parent].copy()
    if status[idx[0]] == MISSING and is_arm and status[parent] != MISSING:
        # the clavicle joint sits on the sternum-clavicle point, its parent's position (facts 9.1)
        positions[idx[0]] = positions[parent]
        status[idx[0]] = ESTIMATED
    parent_ok = all_finite(parent_frame)
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
            # the previous chain from root to target (or to the limb's end), moved onto the current root, each
            # bone at its learned length: the chain's last bone would otherwise carry each frame's residual
            # into the next frame's start, and stretch frame after frame
            prev = _rigid_chain(prev_pos, lengths, root, m)
            P = np.empty((m + 1, 3))
            for k in range(m + 1):
                P[k] = prev[k] - prev[0] + positions[idx[root]]
            R = prev_frames[root:last].copy()
            ref0 = parent_frame if root == 0 else frames[idx[root - 1]].copy()
            if not all_finite(ref0):
                ref0 = parent_frame
            if t < n:
                target = positions[idx[t]].astype(np.float64)
                run = ChainLimits(ref0, pp[root:last], cones[root:last], has_cone[root:last], twists[root:last],
                                  has_twist[root:last])
                it, res = solve(solver, P, R, target, run, params)
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
        whole = whole and all_finite(positions[idx[k]])
    if whole:
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

    def fill(self, positions, frames, status, time_s: float = float("nan")) -> dict[str, FillStats]:
        return {limb: f.fill(positions, frames, status, time_s) for limb, f in self.limbs.items()}

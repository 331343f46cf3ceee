"""Where a lone lost joint was in the limb's earlier poses, its own and the other limb's (beyond the thesis).

The swivel (mocap_core.analytic_fill) puts a lone missing joint on the circle that its two bones
allow, and turns it to where the bone after it keeps its usual direction in the next joint's frame.
On a dancer that direction moves with the wrist. What the actor did before says more: while a limb is seen
whole, each of its middle joints is remembered relative to the joint before it, in the limb
parent's frame (the chest for the arms, the pelvis for the legs), together with where the joint
after it was. Once the middle joint is lost, the poses whose next joint was nearest where it is now
(inverse-distance weighted mean of NEIGHBOURS) say where it should be, and the swivel's search is
pulled towards that point (analytic_fill.MEMORY_SD); the joint stays on its circle, so the bone
lengths stay exact.

Each limb also remembers the other limb's poses, mirrored across the body (the parent frame's x
runs to the subject's left, so a mirror negates it), and keeps learning them while its own joint is
lost: a dancer does with one arm what the other did.

Like the pose memory of the hip stage, it learns only from located joints, never from filled ones.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from mocap_core.analytic_fill import all_finite
from mocap_core.fill_units import LimbFill, LimbFrame, switch
from mocap_core.ik.kernels import mtv, mv
from mocap_core.skeleton import LOCATED, MISSING
from mocap_core.remembered_poses import CAPACITY, keep, nearest  # per joint and source; a pose per 5 mm

LIMB_MEMORY_HELP = ("beyond the thesis: the swivel of a lone missing joint pulled towards where the limb's earlier "
                    "poses, and the other limb's mirrored, had it with the next joint where it is now")
NEIGHBOURS = 20     # remembered poses averaged
MIN_POSES = 30      # poses before the memory is trusted
MIRROR = np.array([-1.0, 1.0, 1.0])
SAME = np.ones(3)


class LimbMemory(LimbFill):
    """State of one limb's memory: per middle joint k of the chain (k-1, k, k+1), a ring of the limb's
    own poses [0] and one of the other limb's, mirrored [1] (where the limb has another)."""
    Settings = switch("limb_memory", LIMB_MEMORY_HELP + " (with swivel)")
    needs = "swivel"

    def __init__(self, limb, options):
        super().__init__(limb, options)
        n, other = len(limb.joints), limb.other
        self.other = np.asarray(other if other is not None else np.full(n, -1), np.int64)
        self.keys = np.full((n, 2, CAPACITY, 3), np.inf)   # the next joint from the one before (parent frame)
        self.vals = np.zeros((n, 2, CAPACITY, 1, 3))       # the middle joint from the one before
        self.state = np.zeros((n, 2, 2), np.int64)         # poses kept, where the next one goes
        self.last = np.full((n, 2, 3), np.inf)             # the last key kept
        self.pred = np.full((n, 3), np.nan)                # this frame's recalled positions (world)
        self._rings = (self.keys, self.vals, self.state, self.last)  # (as the kernels take them)

    def before(self, frame: LimbFrame) -> None:
        """Learn this frame's pose, and hand the swivel where the poses learned put the lost joints."""
        idx, parent = self.limb.joints, self.limb.parent_of_root
        _learn(frame.skeleton, idx, self.other, parent, self._rings)
        _recall(frame.skeleton, idx, parent, self._rings, self.pred)
        frame.recalled = self.pred


@njit(cache=True)
def _learn(skeleton, idx, other, parent, rings):
    """Keep this frame's pose of the chain ``idx`` (and of ``other``, mirrored) in ``rings`` (keys, vals, state,
    last). ``skeleton``: (positions, frames, status) of the whole skeleton."""
    positions, frames, status = skeleton
    keys, vals, state, last = rings
    ref = frames[parent].copy()
    if not all_finite(ref):
        return
    n = idx.shape[0]
    step, key, val = np.empty(3), np.empty(3), np.empty((1, 3))  # (room for every pose of the frame)
    for src in range(2):
        if src == 1 and other[0] < 0:
            break
        chain = idx if src == 0 else other
        sign = SAME if src == 0 else MIRROR
        for k in range(1, n - 1):
            a, m, b = chain[k - 1], chain[k], chain[k + 1]
            if status[a] != LOCATED or status[m] != LOCATED or status[b] != LOCATED:
                continue
            for e in range(3):
                step[e] = positions[b, e] - positions[a, e]
            turned = mtv(ref, step)
            for e in range(3):
                key[e] = turned[e] * sign[e]
                step[e] = positions[m, e] - positions[a, e]
            turned = mtv(ref, step)
            for e in range(3):
                val[0, e] = turned[e] * sign[e]
            if all_finite(key) and all_finite(val):
                keep(keys[k, src], vals[k, src], state[k, src], last[k, src], key, val)


@njit(cache=True)
def _recall(skeleton, idx, parent, rings, pred):
    """Where the poses kept put each lone missing joint, into ``pred`` (NaN: no say)."""
    positions, frames, status = skeleton
    keys, vals, state, _ = rings
    pred[:] = np.nan
    ref = frames[parent].copy()
    if not all_finite(ref):
        return
    n = idx.shape[0]
    best_d = np.empty(NEIGHBOURS)
    best_i = np.empty(NEIGHBOURS, np.int64)
    for k in range(1, n - 1):
        a, m, b = idx[k - 1], idx[k], idx[k + 1]
        if status[m] != MISSING or status[a] == MISSING or status[b] == MISSING:
            continue
        if state[k, 0, 0] + state[k, 1, 0] < MIN_POSES:
            continue
        key = mtv(ref, positions[b] - positions[a])
        if not all_finite(key):
            continue
        best_d[:] = np.inf  # both rings, own and mirrored, into one list
        nearest(keys[k, 0], state[k, 0, 0], key, best_d, best_i, 0)
        nearest(keys[k, 1], state[k, 1, 0], key, best_d, best_i, CAPACITY)
        total, mean = 0.0, np.zeros(3)
        for j in range(NEIGHBOURS):
            if best_d[j] < np.inf:
                w = 1.0 / (best_d[j] + 1e-3)
                total += w
                mean += w * vals[k, best_i[j] // CAPACITY, best_i[j] % CAPACITY, 0]
        pred[k] = positions[a] + mv(ref, mean / total)

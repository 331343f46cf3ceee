"""The limb as the subject's rigid chain: the IK stage's last step, so what a limb outputs keeps its bones' lengths.

Whatever placed the limb's joints this frame (the localization, Algorithm 1, the fills), the output is the chain of
the subject's bones fitted to them: the limb's first joint where the subject has it in its parent's bone frame
(its parent was placed by the stage before), then each bone at its length, turned to bring the joints after it
as close as can be to where they were placed, a located joint counting more than an estimated one. Each bone's
frame is turned by the least rotation that points it along its new direction, so its twist is kept.

The subject is the calibrated one (``mocap calibrate``, or ``mocap solve``'s calibration of the whole take) or,
until one is given, what the limb learned so far: each bone's mean length while both its joints were located
(LimbFiller.lengths), and the first joint's mean place in its parent's frame.

The fit is block coordinate descent: one bone's best direction, the others held, is the weighted mean of where the
joints after it want it (exact for that bone); a few sweeps down the chain settle a limb of four or five bones.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from mocap_core import analytic_fill as af
from mocap_core.analytic_fill import all_finite
from mocap_core.fill_units import LimbFill, LimbFrame, switch
from mocap_core.ik.kernels import mm, mtv, mv, rotation_between
from mocap_core.skeleton import END_SITES, LIMBS, LOCATED, MISSING

RIGID_HELP = ("beyond the thesis: each limb output as the subject's rigid chain, its bones at their calibrated (or, "
              "until calibrated, learned) lengths, fitted to the joints placed this frame")
# How much an estimated or held joint counts against a located one where the chain cannot meet both.
ESTIMATED_WEIGHT = 0.3
SWEEPS = 4


class RigidChain(LimbFill):
    Settings = switch("rigid", RIGID_HELP)

    def __init__(self, limb, options):
        super().__init__(limb, options)
        n = len(limb.joints)
        self.fixed = np.full(n, np.nan)        # each bone's length (k to k + 1) from a subject; NaN: learned
        self.root_fixed = np.full(3, np.nan)   # the first joint in its parent's frame from a subject
        self.root_sum = np.zeros(4)            # its running sum (x, y, z, count) while both are located
        self.end_site = np.array([name in END_SITES for name in LIMBS[limb.limb]])
        self._bones = (limb.lengths, self.fixed, self.root_sum, self.root_fixed)  # (as the kernel takes them)

    def use(self, subject) -> None:
        """Take the bones from a calibrated subject (mocap_core.fit.subject.Subject): they stay as it has them."""
        idx = self.limb.joints
        if subject.known[idx[0]]:
            self.root_fixed[:] = subject.offsets[idx[0]]
        lengths = subject.lengths()
        for k in range(len(idx) - 1):
            self.fixed[k] = lengths[idx[k + 1]] if subject.known[idx[k + 1]] else np.nan

    def after(self, frame: LimbFrame) -> None:
        rigid_fit(frame.skeleton, self.limb.joints, self.limb.parent_of_root, self.end_site, self._bones)


@njit(cache=True)
def rigid_fit(skeleton, idx, parent, end_site, bones):
    """The limb's joints ``idx`` of ``skeleton`` (positions, frames, status) replaced, in place, by the rigid chain
    fitted to them, up to its first missing joint. ``bones``: (learned (n, 2) length sums and counts, fixed (n,)
    lengths or NaN, the first joint's learned offset (sum xyz, count), its fixed offset or NaN)."""
    positions, frames, status = skeleton
    learned, fixed, root_sum, root_fixed = bones
    n = idx.shape[0]
    m = 0
    while m < n and status[idx[m]] != MISSING and all_finite(positions[idx[m]]):
        m += 1
    if m == 0:
        return
    P = np.empty((m, 3))
    for k in range(m):
        P[k] = positions[idx[k]]
    R_parent = frames[parent].copy()
    if all_finite(R_parent) and all_finite(positions[parent]):
        root = _root_offset(positions, status, idx[0], parent, R_parent, root_sum, root_fixed)
        if all_finite(root):
            P[0] = positions[parent] + mv(R_parent, root)
    T = np.empty((m, 3))   # where the joints were placed: the targets
    w = np.empty(m)
    for k in range(m):
        T[k] = positions[idx[k]]
        w[k] = 1.0 if status[idx[k]] == LOCATED else ESTIMATED_WEIGHT
    L = np.empty(max(m - 1, 0))
    U = np.empty((max(m - 1, 0), 3))
    for k in range(m - 1):
        bone = T[k + 1] - T[k]
        size = math.sqrt(bone[0] * bone[0] + bone[1] * bone[1] + bone[2] * bone[2])
        L[k] = fixed[k] if np.isfinite(fixed[k]) else af._length(learned, k, size)
        U[k] = bone / size if size > 1e-9 else np.array([0.0, 1.0, 0.0])
    _place(P, L, U)
    for _ in range(SWEEPS):
        for i in range(m - 1):
            # the joints after bone i, bone i taken out, want it pointing along the weighted mean of these
            want = np.zeros(3)
            for k in range(i + 1, m):
                want += w[k] * (T[k] - P[k] + L[i] * U[i])
            size = math.sqrt(want[0] * want[0] + want[1] * want[1] + want[2] * want[2])
            if size < 1e-12:
                continue
            move = L[i] * (want / size - U[i])
            U[i] = want / size
            for k in range(i + 1, m):
                P[k] += move
    for k in range(m):
        positions[idx[k]] = P[k]
    for k in range(m - 1):
        R = frames[idx[k]].copy()
        if all_finite(R):
            frames[idx[k]] = mm(rotation_between(R[:, 1].copy(), U[k]), R)
    for k in range(1, m):
        if end_site[k]:
            frames[idx[k]] = frames[idx[k - 1]]


@njit(cache=True)
def _place(P, L, U):
    """The chain's joints from its first, each bone at its length along its direction."""
    for k in range(1, P.shape[0]):
        P[k] = P[k - 1] + L[k - 1] * U[k - 1]


@njit(cache=True)
def _root_offset(positions, status, root, parent, R_parent, root_sum, root_fixed):
    """The limb's first joint in its parent's bone frame: the subject's, else the mean of where it was while both
    were located (learning this frame's), else this frame's."""
    here = mtv(R_parent, positions[root] - positions[parent])
    if np.isfinite(root_fixed[0]):
        return root_fixed.copy()
    if status[root] == LOCATED and status[parent] == LOCATED and all_finite(here):
        for c in range(3):
            root_sum[c] += here[c]
        root_sum[3] += 1
    if root_sum[3] >= af.MIN_SAMPLES:
        return root_sum[:3] / root_sum[3]
    return here

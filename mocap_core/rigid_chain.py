"""The limb as the subject's rigid chain: the IK stage's last step, so what a limb outputs keeps its bones' lengths.

Whatever placed the limb's joints this frame (the localization, Algorithm 1, the fills), the output is the chain of
the subject's bones fitted to them: the limb's first joint where the subject has it in its parent's bone frame
(its parent was placed by the stage before), then each bone at its length, turned to bring the joints after it
as close as can be to where they were placed, a located joint counting more than an estimated one. Each bone's
frame is turned by the least rotation that points it along its new direction, so its twist is kept.

The subject is the calibrated one (``mocap calibrate``, or ``mocap solve``'s calibration of the whole take) or,
until one is given, the one calibrated from the stream so far as a take's is calibrated (fit.calibration.LiveBones:
the joints' median places in their parents' bone frames, left and right bones of one length), its medians
re-taken one joint at a time (a joint a frame in the first second) so that every bone is new each second. Until a
bone is calibrated it keeps this frame's length.

The fit is block coordinate descent: one bone's best direction, the others held, is the weighted mean of where the
joints after it want it (exact for that bone); a few sweeps down the chain settle a limb of four or five bones.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from mocap_core.analytic_fill import all_finite
from mocap_core.fill_units import LimbFill, LimbFrame, switch
from mocap_core.fit.calibration import LiveBones
from mocap_core.ik.kernels import mm, mv, rotation_between
from mocap_core.skeleton import END_SITES, ESTIMATED, LIMBS, LOCATED, MISSING

RIGID_HELP = ("beyond the thesis: each limb output as the subject's rigid chain, its bones at their calibrated (or, "
              "until one is given, calibrated from the stream) lengths, fitted to the joints placed this frame")
# How much an estimated or held joint counts against a located one where the chain cannot meet both.
ESTIMATED_WEIGHT = 0.3
SWEEPS = 4
RETAKE_S = 1.0  # every bone calibrated from the stream is re-taken this often


class RigidChain(LimbFill):
    Settings = switch("rigid", RIGID_HELP)

    def __init__(self, limb, options):
        super().__init__(limb, options)
        n = len(limb.joints)
        self.offsets = np.full((n, 3), np.nan)       # each joint in its parent's bone frame; NaN: not calibrated
        self.rest = np.tile(np.eye(3), (n, 1, 1))    # and its bone frame's typical turn from its parent's
        self.end_site = np.array([name in END_SITES for name in LIMBS[limb.limb]])
        mirrored = () if limb.other is None else limb.other
        self.live: LiveBones | None = LiveBones(np.concatenate([limb.joints, mirrored]))
        self.wait = 0                                 # frames until the next joint's re-take

    def use(self, subject) -> None:
        """Take the bones from a calibrated subject (mocap_core.fit.subject.Subject): they stay as it has them."""
        self.live = None
        self._take(subject.offsets, subject.known)
        self.rest[:] = subject.rest[self.limb.joints]

    def _take(self, offsets: np.ndarray, known: np.ndarray) -> None:
        idx = self.limb.joints
        self.offsets[:] = np.where(known[idx, None], offsets[idx], np.nan)

    def before(self, frame: LimbFrame) -> None:
        live = self.live  # (learns from the joints as located, before any fill moves them)
        if live is not None:
            live.add(frame.skeleton)
            self.wait -= 1
            if self.wait <= 0:  # (the first second, a joint a frame: a bone first seen need not wait its turn)
                clock = self.limb.clock
                self.wait = 1 if live.seen < clock.frames(RETAKE_S) else clock.frames(RETAKE_S / len(live.joints))
                if live.retake():
                    self._take(live.offsets, live.known)

    def after(self, frame: LimbFrame) -> None:
        rigid_fit(frame.skeleton, self.limb.joints, self.limb.parent_of_root, self.end_site, self.offsets,
                  self.rest)


@njit(cache=True)
def rigid_fit(skeleton, idx, parent, end_site, offsets, rest):
    """The limb's joints ``idx`` of ``skeleton`` (positions, frames, status) replaced, in place, by the rigid chain
    fitted to them. ``offsets``: (n, 3) each joint in its parent's bone frame (NaN: not calibrated; the bone keeps
    this frame's length); ``rest``: (n, 3, 3) its bone frame's typical turn from its parent's. A calibrated joint
    that nothing placed this frame is put where the subject has it (estimated); the chain ends at the first joint
    neither placed nor calibrated."""
    positions, frames, status = skeleton
    n = idx.shape[0]
    m = 0
    while m < n:
        j = idx[m]
        if status[j] == MISSING or not all_finite(positions[j]):
            up = parent if m == 0 else idx[m - 1]
            if m > 0 and not all_finite(frames[up]):  # (a bone frame its lost end left unknown: its typical turn)
                frames[up] = mm(frames[parent if m == 1 else idx[m - 2]], rest[m - 1])
            if not (all_finite(offsets[m]) and all_finite(frames[up]) and all_finite(positions[up])):
                break
            positions[j] = positions[up] + mv(frames[up], offsets[m])
            frames[j] = mm(frames[up], rest[m])
            status[j] = ESTIMATED
        m += 1
    if m == 0:
        return
    P = np.empty((m, 3))
    for k in range(m):
        P[k] = positions[idx[k]]
    R_parent = frames[parent].copy()
    if all_finite(R_parent) and all_finite(positions[parent]) and all_finite(offsets[0]):
        P[0] = positions[parent] + mv(R_parent, offsets[0])
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
        known = offsets[k + 1]
        L[k] = math.sqrt(known[0] * known[0] + known[1] * known[1] + known[2] * known[2]) if all_finite(known) \
            else size
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
    for k in range(m):  # a bone frame its lost end left unknown: its parent's, turned as the subject holds it
        if not all_finite(frames[idx[k]]):
            up = frames[parent] if k == 0 else frames[idx[k - 1]]
            if all_finite(up):
                frames[idx[k]] = mm(up, rest[k])


@njit(cache=True)
def _place(P, L, U):
    """The chain's joints from its first, each bone at its length along its direction."""
    for k in range(1, P.shape[0]):
        P[k] = P[k - 1] + L[k - 1] * U[k - 1]

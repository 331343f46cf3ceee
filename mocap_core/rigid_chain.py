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

With a subject that places markers on its bones (``mocap calibrate``) and the frame's markers, the chain is fitted
to the markers riding the limb too: the whole-body fit's solve (mocap_core.fit.kernel.fit_pose) over the limb
alone, its first joint's parent pinned where the stage before placed it, each joint placed this frame a marker on
its parent bone (an estimated one counting ``ESTIMATED_WEIGHT``), the bones turning from their last frame's pose as
the fit's motion and posture tasks let them. A seen hand or toe marker then turns the hand or foot, and the joints
above it follow, where the fills had only the joints to go by.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from mocap_core.analytic_fill import all_finite
from mocap_core.fill_units import LimbFill, LimbFrame, switch
from mocap_core.fit.calibration import ROTATING, LiveBones
from mocap_core.fit.fitter import FitSettings, tree_of_unknowns
from mocap_core.fit.kernel import fit_pose
from mocap_core.ik.kernels import mm, mv, rotation_between, vdist, vnorm
from mocap_core.skeleton import END_SITES, ESTIMATED, LIMBS, LOCATED, MISSING

RIGID_HELP = ("beyond the thesis: each limb output as the subject's rigid chain, its bones at their calibrated (or, "
              "until one is given, calibrated from the stream) lengths, fitted to the joints placed this frame "
              "(and to the markers a subject file places on the limb)")
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
        self.markers: MarkerFit | None = None

    def use(self, subject, labels: list[str] | None = None) -> None:
        """Take the bones from a calibrated subject (mocap_core.fit.subject.Subject): they stay as it has them. With
        the stream's marker ``labels`` (the subject's names), the chain is fitted to the markers riding it too."""
        self.live = None
        self._take(subject.offsets, subject.known)
        self.rest[:] = subject.rest[self.limb.joints]
        self.markers = MarkerFit(self.limb, subject, labels) if labels else None
        if self.markers is not None and not self.markers.cols.size:  # no marker rides the limb: its joints only
            self.markers = None

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
        if self.markers is not None and frame.markers is not None and self.markers.fit(frame):
            return
        rigid_fit(frame.skeleton, self.limb.joints, self.limb.parent_of_root, self.end_site, self.offsets,
                  self.rest)


class MarkerFit:
    """The limb's chain fitted to the markers that the subject places on its bones and to its joints placed this
    frame. The fit's model of the limb: node 0 the limb's parent joint (pinned), then the limb's joints up to the
    first the subject does not know."""
    PIN = 1e12  # the weight that holds the parent joint where the stage before placed it

    def __init__(self, limb, subject, labels: list[str], settings: FitSettings | None = None):
        s = settings or FitSettings()
        self.limb, self.s = limb, s
        idx = limb.joints
        known = subject.known[idx]
        n = int(np.argmin(known)) if not known.all() else len(idx)
        self.n = n
        nodes = np.concatenate([[limb.parent_of_root], idx[:n]]).astype(np.int64)
        self.nodes = nodes
        self.parent = np.arange(-1, n, dtype=np.int64)
        self.offsets = np.zeros((n + 1, 3))
        self.offsets[1:] = subject.offsets[idx[:n]]
        self.rotating = ROTATING[nodes].copy()
        self.rotating[0] = True
        self.slot, self.chains, self.up = tree_of_unknowns(self.parent, self.rotating)
        self.rest = np.tile(np.eye(3), (n + 1, 1, 1))
        self.rest[1:] = subject.rest[idx[:n]]
        # the stream's markers on these bones (their columns), then one place for each joint placed this frame
        rows = subject.marker_index(labels)
        bone = np.where(rows >= 0, subject.marker_bone[np.maximum(rows, 0)], -1)
        local = {int(j): k + 1 for k, j in enumerate(idx[:n]) if self.rotating[k + 1]}
        self.cols = np.array([m for m in range(len(labels)) if int(bone[m]) in local], np.int64)
        m = len(self.cols)
        self.x = np.full((m + n, 3), np.nan)
        self.bone = np.empty(m + n, np.int64)
        self.c = np.zeros((m + n, 3))
        self.bone[:m] = [local[int(bone[k])] for k in self.cols]
        self.c[:m] = subject.marker_offsets[rows[self.cols]]
        self.bone[m:] = np.arange(n)          # joint k+1 rides bone k at its offset
        self.c[m:] = self.offsets[1:]
        self.w_marker = 1 / s.marker_sigma_m ** 2
        self.w = np.full(m + n, self.w_marker)
        self.w_rest = np.full(n + 1, 1 / s.posture_rad ** 2)
        self.w_rest[0] = 0.0
        self.root, self.root_pred = np.zeros(3), np.zeros(3)
        self.R = np.tile(np.eye(3), (n + 1, 1, 1))
        self.L_last = None                     # the bones' last local rotations (their rotations in their parents')
        self.L_pred, self.w_rot = np.empty((n + 1, 3, 3)), np.empty(n + 1)  # the motion task, set each frame
        self._P = np.zeros((n + 1, 3))
        self._weights = np.zeros(m + n)

    def fit(self, frame: LimbFrame) -> bool:
        """Fit this frame's limb in place; False where there is nothing to fit from (the parent joint unplaced)."""
        positions, frames, status = frame.skeleton
        base = self.nodes[0]
        if self.n == 0 or not (all_finite(positions[base]) and all_finite(frames[base])):
            return False
        m, L_pred = len(self.cols), self.L_pred
        self.x[:m] = frame.markers[self.cols]
        idx = self.nodes[1:]
        self.x[m:] = positions[idx]
        placed = status[idx] != MISSING
        self.x[m:][~placed] = np.nan
        located = status[idx] == LOCATED
        # a fill's joint between located ones counts as in the chain without markers; one beyond them (a lost end,
        # which the fills extrapolate) is left to the markers
        between = (np.cumsum(located) > 0) & (np.cumsum(located[::-1])[::-1] > 0)
        self.w[m:] = np.where(located, 1.0, np.where(between, ESTIMATED_WEIGHT, 0.0)) * self.w_marker
        if not np.isfinite(self.x).all(axis=1).any():
            return False
        self.root[:] = self.root_pred[:] = positions[base]
        self.R[0] = L_pred[0] = frames[base]
        if self.L_last is None:  # the first frame: from the fills' bone frames where they placed them
            for k in range(1, self.n + 1):
                f = frames[self.nodes[k]]
                self.R[k] = f if all_finite(f) else self.R[k - 1] @ self.rest[k]
            L_pred[1:] = np.einsum("kba,kbc->kac", self.R[:-1], self.R[1:])
            iterations, motion = self.s.start_iterations, 1e-4  # (a start: the motion task almost off)
        else:
            L_pred[1:] = self.L_last
            for k in range(1, self.n + 1):
                self.R[k] = self.R[k - 1] @ self.L_last[k - 1]
            iterations, motion = self.s.max_iterations, 1.0
        w_rot = self.w_rot
        w_rot[1:], w_rot[0] = motion / (self.s.turn_rad_s * self.limb.clock.frame_s) ** 2, self.PIN
        fit_pose((self.root, self.R), (self.x, self.bone, self.c, self.w),
                 (self.parent, self.offsets, self.slot, self.chains, self.rotating), self.up,
                 (self.root_pred, L_pred, w_rot, self.PIN, self.rest, self.w_rest),
                 self.s.robust_m, (iterations, self.s.tolerance), (self._P, self._weights))
        self.L_last = np.einsum("kba,kbc->kac", self.R[:-1], self.R[1:])
        positions[idx] = self._P[1:]
        frames[idx] = self.R[1:]
        status[idx[~placed]] = ESTIMATED
        return True


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
        size = vdist(T[k + 1], T[k])
        known = offsets[k + 1]
        L[k] = vnorm(known) if all_finite(known) else size
        for e in range(3):
            U[k, e] = (T[k + 1, e] - T[k, e]) / size if size > 1e-9 else (1.0 if e == 1 else 0.0)
    _place(P, L, U)
    want, move = np.empty(3), np.empty(3)  # (one pair for every sweep: this loop runs thousands of times a second)
    for _ in range(SWEEPS):
        for i in range(m - 1):
            # the joints after bone i, bone i taken out, want it pointing along the weighted mean of these
            want[:] = 0.0
            for k in range(i + 1, m):
                for e in range(3):
                    want[e] += w[k] * (T[k, e] - P[k, e] + L[i] * U[i, e])
            size = vnorm(want)
            if size < 1e-12:
                continue
            for e in range(3):
                move[e] = L[i] * (want[e] / size - U[i, e])
                U[i, e] = want[e] / size
            for k in range(i + 1, m):
                for e in range(3):
                    P[k, e] += move[e]
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

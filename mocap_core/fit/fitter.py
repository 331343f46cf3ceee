"""The rigid-skeleton fit, frame by frame: a calibrated subject brought onto the markers seen (docs/design.md).

In the style of mink's typed IK core: the configuration is the pose (root position, bone frames), the
tasks are the markers and the motion prior, the limits are the thesis's cone and twist limits, and
one solve (``mocap_core.fit.kernel.fit_pose``) runs damped Gauss-Newton warm-started from the last
frame. Closest of the thesis's four solvers to damped least squares (its DLS), but over the whole
body at once and on markers rather than on joint targets.

Status of the joints: ``located`` where a seen marker rides the bone that carries the joint or the bone
that starts there; ``estimated`` where the pose of nearby bones and the motion prior place it;
``missing`` for a joint the calibration never located (a set with no hand marker has no hand).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mocap_core.fit.calibration import ROTATING
from mocap_core.fit.kernel import fit_pose, forward, limit_locals
from mocap_core.fit.subject import Subject
from mocap_core.geometry import rigid_fit
from mocap_core.ik.constraints import Constraints, load_constraints
from mocap_core.skeleton import N_JOINTS, PARENT_INDEX, Status


@dataclass
class FitSettings:
    """Noise scales of the tasks (their weights are 1 / scale^2) and the solve's bounds."""
    marker_sigma_m: float = 0.01      # how far a seen marker may sit off its calibrated place (skin, noise)
    robust_m: float = 0.03            # Cauchy scale: a marker this far off counts half, 10x as far 1 %
    turn_rad_s: float = 24.0          # how fast a bone may turn against its parent, unseen (the motion task)
    root_sigma_m: float = 0.05        # how far the root may move from its predicted place in a frame
    posture_rad: float = 1.0          # how far a bone may turn from its typical rotation in its parent's frame
    max_iterations: int = 6
    start_iterations: int = 60        # the first frame (and a re-start) begins from the rest pose
    tolerance: float = 1e-3           # a step below this (rad; m) ends the solve: 0.3 mm at 30 cm, under the noise
    limits: bool = True               # the thesis's cone and twist limits on what the motion task predicts
    located_weight: float = 0.5       # a marker counts as seen (for the status) above this robust weight


@dataclass
class FitFrame:
    positions: np.ndarray   # (J, 3)
    frames: np.ndarray      # (J, 3, 3)
    status: np.ndarray      # (J,) uint8
    residual_m: float       # RMS distance of the seen markers from their calibrated places
    iterations: int


def tree_of_unknowns(parent: np.ndarray, rotating: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A model's unknowns for the fit's solve (parents first; the first node rotating): each node's ``slot`` (its
    turn's first unknown, after the root's position; -1 for a node that turns with its parent), its ``chains``
    (its rotating ancestors, itself first, padded with -1) and each unknown's parent unknown (``up``, -1 at the top:
    a bone's first below its nearest rotating ancestor's last)."""
    n = len(parent)
    slot = np.where(rotating, 3 + 3 * (np.cumsum(rotating) - 1), -1).astype(np.int64)
    rows = []
    for j in range(n):
        chain, k = [], j
        while k >= 0:
            if rotating[k]:
                chain.append(k)
            k = parent[k]
        rows.append(chain)
    chains = np.full((n, max(map(len, rows))), -1, np.int64)
    for j, chain in enumerate(rows):
        chains[j, :len(chain)] = chain
    up = np.arange(-1, int(slot.max()) + 2, dtype=np.int64)  # each below the one before ...
    for j in range(1, n):
        if rotating[j]:
            k = parent[j]
            while not rotating[k]:
                k = parent[k]
            up[slot[j]] = slot[k] + 2  # ... but a bone's first below its parent bone's last
    return slot, chains, up


SLOT, CHAINS, UP = tree_of_unknowns(PARENT_INDEX, ROTATING)


class SkeletonFitter:
    """Owns one actor's pose from frame to frame. ``labels``: the stream's marker labels (the subject's names,
    prefixes stripped as the profile says)."""

    def __init__(self, subject: Subject, labels: list[str], settings: FitSettings | None = None,
                 constraints: Constraints | None = None, rate_hz: float = 120.0):
        self.subject = subject
        self.settings = s = settings or FitSettings()
        rows = subject.marker_index(labels)
        self.bone = np.where(rows >= 0, subject.marker_bone[np.maximum(rows, 0)], -1).astype(np.int64)
        self.bone[~subject.known[np.maximum(self.bone, 0)]] = -1
        self.offsets_m = np.where(rows[:, None] >= 0, subject.marker_offsets[np.maximum(rows, 0)], 0.0)
        self.limits = constraints or load_constraints()
        self.w_marker = np.full(len(labels), 1 / s.marker_sigma_m ** 2)
        self.w_root = 1 / s.root_sigma_m ** 2
        self.w_rot = np.full(N_JOINTS, 1 / (s.turn_rad_s / rate_hz) ** 2)
        self.w_rest = np.where(np.arange(N_JOINTS) > 0, 1 / s.posture_rad ** 2, 0.0)
        self.root = np.zeros(3)
        self.velocity = np.zeros(3)  # the root's last step: the motion task predicts it goes on
        self.R = np.tile(np.eye(3), (N_JOINTS, 1, 1))
        self.started = False
        self._P = np.zeros((N_JOINTS, 3))
        self._w = np.zeros(len(labels))
        self._on_parent = np.zeros((N_JOINTS, len(labels)), bool)  # joint j is located by markers on these bones
        for j in range(N_JOINTS):
            carriers = {j, PARENT_INDEX[j]} if ROTATING[j] else {PARENT_INDEX[j]}
            self._on_parent[j] = np.isin(self.bone, list(carriers))

    def reset(self) -> None:
        self.started = False

    def take_pose_from(self, other: "SkeletonFitter") -> None:
        """Go on from another fitter's pose (a subject re-calibrated mid-stream)."""
        self.root, self.R, self.velocity = other.root.copy(), other.R.copy(), other.velocity.copy()
        self.started = other.started

    def fit(self, x: np.ndarray) -> FitFrame:
        """One frame's markers (M, 3) metres, NaN where not seen -> the pose."""
        x = np.ascontiguousarray(x, np.float64)
        if not self.started and not self._start(x):
            return self._missing()
        s = self.settings
        L_pred = self._locals()  # each bone held as it was against its parent
        if s.limits:
            c = self.limits
            limit_locals(L_pred, c.pp, c.cones, c.has_cone, c.twists, c.has_twist)
        root_pred = self.root + self.velocity
        before = self.root.copy()
        iterations, residual = self._solve(x, root_pred, L_pred, s.max_iterations)
        self.velocity = self.root - before
        return self._frame(residual, iterations)

    def fit_all(self, markers: np.ndarray, progress=None):
        """Every frame of a take (F, M, 3) in order -> positions (F, J, 3), frames (F, J, 3, 3), status (F, J) and each
        frame's residual (F,); ``progress(1)`` after each frame, if given."""
        n = len(markers)
        pos, frames = np.empty((n, N_JOINTS, 3)), np.empty((n, N_JOINTS, 3, 3))
        status, residual = np.empty((n, N_JOINTS), np.uint8), np.empty(n)
        for f in range(n):
            out = self.fit(markers[f])
            pos[f], frames[f], status[f], residual[f] = out.positions, out.frames, out.status, out.residual_m
            if progress is not None:
                progress(1)
        return pos, frames, status, residual

    def _start(self, x: np.ndarray) -> bool:
        """The first pose: the subject at rest (every bone at its typical rotation in its parent's frame) placed by
        a rigid fit of the seen markers on the pelvis and the bones it carries (three at least), then a long
        solve with a weak motion prior."""
        for j in range(1, N_JOINTS):
            self.R[j] = self.subject.rest[j] if ROTATING[j] else np.eye(3)
            self.R[j] = self.R[PARENT_INDEX[j]] @ self.R[j]
        self.root = np.zeros(3)
        P = self.pose_positions()
        near = np.isin(self.bone, [0] + [j for j in range(1, N_JOINTS) if PARENT_INDEX[j] == 0])
        use = near & np.isfinite(x).all(axis=1)
        if use.sum() < 3:
            return False
        rest = P[self.bone[use]] + np.einsum("mab,mb->ma", self.R[self.bone[use]], self.offsets_m[use])
        turn, self.root = rigid_fit(rest, x[use], np.ones(int(use.sum())))
        self.R = np.einsum("ab,jbc->jac", turn, self.R)
        # least squares first (a far start would have the robust loss ignore whole limbs), then robust
        self._solve(x, self.root.copy(), self._locals(), self.settings.start_iterations, weak=True, robust_m=1.0)
        self._solve(x, self.root.copy(), self._locals(), self.settings.start_iterations, weak=True)
        self.velocity = np.zeros(3)
        self.started = True
        return True

    def _locals(self) -> np.ndarray:
        """Each bone's rotation in its parent's frame (the root's in the world): the motion task's prediction."""
        L = np.empty_like(self.R)
        L[0] = self.R[0]
        L[1:] = np.einsum("jba,jbc->jac", self.R[PARENT_INDEX[1:]], self.R[1:])
        return L

    def _solve(self, x, root_pred, L_pred, iterations, weak=False, robust_m=None):
        """``weak``: the motion task almost off (a start has no last frame); ``robust_m``: another Cauchy scale."""
        s = self.settings
        motion = 1e-4 if weak else 1.0
        return fit_pose((self.root, self.R), (x, self.bone, self.offsets_m, self.w_marker),
                        (PARENT_INDEX, self.subject.offsets, SLOT, CHAINS, ROTATING), UP,
                        (root_pred, L_pred, self.w_rot * motion, self.w_root * motion, self.subject.rest, self.w_rest),
                        robust_m or s.robust_m, (iterations, s.tolerance), (self._P, self._w))

    def _frame(self, residual: float, iterations: int) -> FitFrame:
        seen = self._w > self.settings.located_weight
        status = np.where((self._on_parent & seen).any(axis=1), Status.LOCATED, Status.ESTIMATED).astype(np.uint8)
        P, R = self._P.copy(), self.R.copy()
        unknown = ~self.subject.known
        status[unknown], P[unknown], R[unknown] = Status.MISSING, np.nan, np.nan
        return FitFrame(P, R, status, residual, iterations)

    def _missing(self) -> FitFrame:
        return FitFrame(np.full((N_JOINTS, 3), np.nan), np.full((N_JOINTS, 3, 3), np.nan),
                        np.full(N_JOINTS, Status.MISSING, np.uint8), float("nan"), 0)

    def pose_positions(self) -> np.ndarray:
        P = np.zeros((N_JOINTS, 3))
        forward(self.root, self.R, PARENT_INDEX, self.subject.offsets, P)
        return P

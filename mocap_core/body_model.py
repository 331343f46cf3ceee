"""Where a lone lost elbow or knee is, from the rest of the located body (beyond the thesis).

The swivel (mocap_core.analytic_fill) puts a lone missing joint on the circle its two bones allow;
the limb memory (mocap_core.limb_memory) pulls it towards where earlier poses with the next joint in
the same place had it. Neither looks past the limb. A dancer's elbow goes with the rest of her: the
other arm, the head, the trunk's lean, the hand's turn. This model is a ridge regression, learned
online, from the whole located skeleton (every joint but the two elbows, or the two knees, and those
that repeat their neighbours, from the limb's first joint in the limb parent's frame, and the next
joint's frame) to the joint. It learns
from the limb's own located poses and from the other limb's, mirrored across the body, as the limb
memory does, and never from filled joints.

Its point turns the swivel's estimate along the circle, by at most half the angle between them and
less the further this frame's body lies from those it learned from (its leverage, z^T (Z^T Z + lam I)^-1 z):
a linear model is trusted where it interpolates, and poses unlike any learned are left to the swivel.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from mocap_core.analytic_fill import all_finite
from mocap_core.fill_units import LimbFill, LimbFrame, switch
from mocap_core.ik.kernels import mtv
from mocap_core.skeleton import END_SITES, INDEX, JOINTS, LIMBS, LOCATED, MISSING

BODY_MODEL_HELP = ("beyond the thesis: a lone lost elbow or knee turned on its swivel circle towards where a "
                   "regression from the rest of the located body, learned online from this limb and the other "
                   "(mirrored), puts it (with swivel)")
MODELLED = frozenset({"elbow_l", "elbow_r", "knee_l", "knee_r"})
MODELLED_ENDS = frozenset({"wrist_l", "wrist_r", "ankle_l", "ankle_r"})  # the end model's
RIDGE = 10.0          # on standardized features: the fit is flat over an order of magnitude either side
MIN_SAMPLES = 60      # poses before the model is trusted (one second at 60 Hz)
REFIT_SAMPLES = 60    # new poses before the model is refitted, when it is needed
MAX_WEIGHT = 0.5      # of the turn towards the model's point, at zero leverage
LEVERAGE_SCALE = 2.0  # the weight is MAX_WEIGHT / (1 + leverage / LEVERAGE_SCALE)
# The end model's point is taken the same way, from where the end was held, with 1 in place of MAX_WEIGHT: taken
# whole at once, its returns jump more.
END_MAX_WEIGHT = 1.0
# The model's point moves at most this fast in the limb parent's frame: on a fast move its leverage rises and
# the linear model swings for a frame or two; a joint itself moves slower than this.
MAX_SPEED_M_S = 3.0
SD_FLOOR = 1e-3        # of a feature (metres, or a unit vector's component): constant ones stay harmless
# Joints left out of the features: they repeat their neighbours (an end site is its parent's frame, the
# clavicle joint the sternum point). Without them 60 features, not 81: the same answers, and a refit costs 0.4x.
REPEATED = frozenset(INDEX[j] for j in END_SITES | {"clavicle_l", "clavicle_r"})
SWAPPED = np.array([INDEX[j[:-1] + {"l": "r", "r": "l"}[j[-1]]] if j[-2:] in ("_l", "_r") else INDEX[j]
                    for j in JOINTS], np.int64)


class BodyModel:
    """One limb's model of its joint ``k`` (chain index), from the limb's joint ``root`` (default k - 1):
    ``idx`` the limb's chain, ``other`` the other limb's (the same length), ``parent`` the limb parent's joint
    index. With the default root, ``k`` is the middle joint (the elbow, the knee), lost alone between two
    located ones, and the features include the next joint's frame. With a root further up, ``k`` is the
    limb's end (the wrist, the ankle), lost with every joint between the two (end_model): none of them, on
    either limb, is a feature."""

    def __init__(self, idx: np.ndarray, other: np.ndarray, k: int, parent: int, root: int | None = None):
        root = k - 1 if root is None else root
        self.idx, self.other, self.k, self.parent, self.root = idx, other, k, parent, root
        self.with_next = root == k - 1
        self.max_weight = MAX_WEIGHT if self.with_next else END_MAX_WEIGHT
        excluded = {int(c[j]) for c in (idx, other) for j in range(root + 1, k + 1)} | REPEATED
        self.features = np.array([j for j in range(len(JOINTS)) if j not in excluded], np.int64)
        d = 3 * len(self.features) + (6 if self.with_next else 0)
        self.n = np.zeros(1)
        self.sx, self.sy = np.zeros(d), np.zeros(3)
        self.sxx, self.sxy = np.zeros((d, d)), np.zeros((d, 3))
        self.x, self.local = np.zeros(d), np.zeros(3)
        self.fitted_at = -1.0
        self.last_local = np.full(3, np.nan)  # the point of the frame before, while the joint is lost
        self.mu = self.sd = self.coef = self.chol = self.y_mean = None
        # (as the kernels take them)
        self._layout = (self.k, self.root, self.with_next, self.parent, self.features)
        self._sums = (self.n, self.sx, self.sy, self.sxx, self.sxy)

    def learn(self, positions, frames, status) -> None:
        _learn((positions, frames, status), self.idx, self.other, self._layout, self.x, self._sums)

    def lost(self, status) -> bool:
        """Whether this frame asks the model: its joint missing; as the middle joint, both neighbours not;
        as the end, every joint from the root's next on missing and the root not (no joint below to aim at)."""
        idx, k = self.idx, self.k
        if status[idx[self.root]] == MISSING:
            return False
        if self.with_next:
            return status[idx[k]] == MISSING and status[idx[k + 1]] != MISSING
        for j in range(self.root + 1, len(idx)):
            if status[idx[j]] != MISSING:
                return False
        return True

    def predict(self, positions, frames, status, frame_s: float) -> tuple[np.ndarray, float]:
        """(where the model puts the joint, world; the weight of its turn), or (NaNs, 0) without a model.
        ``frame_s``: seconds since the frame before (the point's speed is capped)."""
        k, idx = self.k, self.idx
        none = np.full(3, np.nan), 0.0
        if status[idx[k]] != MISSING:  # (so not lost: the frame does not ask the model)
            self.last_local[:] = np.nan
            return none
        if not self.lost(status) or self.n[0] < MIN_SAMPLES:
            return none
        if self.n[0] - self.fitted_at >= REFIT_SAMPLES or self.fitted_at < 0:
            self._fit()
        if not _features((positions, frames, status), idx, self._layout, False, self.mu, self.x):
            return none
        leverage = _predict(self.x, self.mu, self.sd, self.chol, self.coef, self.y_mean, self.local)
        _cap_step(self.local, self.last_local, MAX_SPEED_M_S * frame_s)
        self.last_local[:] = self.local
        point = positions[idx[self.root]] + frames[self.parent] @ self.local
        return point, self.max_weight / (1.0 + leverage / LEVERAGE_SCALE)

    def _fit(self) -> None:
        self.mu, self.sd, self.y_mean, self.chol, self.coef = _fit(self.n[0], self.sx, self.sy, self.sxx, self.sxy)
        self.fitted_at = self.n[0]


def chain_place(limb: str, names: frozenset[str]) -> int | None:
    """Where the first of ``names`` sits in ``limb``'s chain (None: not in it)."""
    return next((k for k, name in enumerate(LIMBS[limb]) if name in names), None)


class BodyModelSteer(LimbFill):
    """The body model as the IK stage's fill: it hands the swivel where the model puts the limb's lone lost
    middle joint (the elbow, the knee), and how much to turn towards it."""
    Settings = switch("body_model", BODY_MODEL_HELP)
    needs = "swivel"
    mirrored = True

    @classmethod
    def for_limb(cls, limb, options) -> "BodyModelSteer | None":
        middle = chain_place(limb.limb, MODELLED)
        return None if limb.other is None or middle is None else cls(limb, options, middle)

    def __init__(self, limb, options, middle: int):
        super().__init__(limb, options)
        self.model = BodyModel(limb.joints, limb.other, middle, limb.parent_of_root)
        n = len(limb.joints)
        self.modelled, self.weight = np.full((n, 3), np.nan), np.zeros(n)

    def before(self, frame: LimbFrame) -> None:
        model = self.model
        model.learn(frame.positions, frame.frames, frame.status)
        self.modelled[model.k], self.weight[model.k] = model.predict(frame.positions, frame.frames, frame.status,
                                                                     self.limb.clock.frame_s)
        frame.modelled, frame.model_weight = self.modelled, self.weight


@njit(cache=True)
def _fit(n, sx, sy, sxx_upper, sxy):
    """The ridge fit on the standardized features from the running sums: (means, SDs, the joint's mean,
    the Cholesky factor L of Z^T Z + RIDGE I, the coefficients). Written out in numba: with numpy and
    LAPACK calls a refit took 400 us in a frame on a slow VM (an 81 x 81 inverse 350 us alone)."""
    d = sx.shape[0]
    mu, y_mean = sx / n, sy / n
    sd = np.empty(d)
    for a in range(d):
        sd[a] = max(math.sqrt(max(sxx_upper[a, a] / n - mu[a] * mu[a], 0.0)), SD_FLOOR)
    chol = np.zeros((d, d))  # first Z^T Z + RIDGE I (lower triangle), then its factor in place
    for a in range(d):
        for b in range(a + 1):
            chol[a, b] = (sxx_upper[b, a] - n * mu[a] * mu[b]) / (sd[a] * sd[b])
        chol[a, a] += RIDGE
    for j in range(d):
        s = chol[j, j]
        for k in range(j):
            s -= chol[j, k] * chol[j, k]
        chol[j, j] = math.sqrt(s)
        for i in range(j + 1, d):
            s = chol[i, j]
            for k in range(j):
                s -= chol[i, k] * chol[j, k]
            chol[i, j] = s / chol[j, j]
    coef = np.empty((d, 3))
    for c in range(3):
        rhs = np.empty(d)  # Z^T (y - mean), column c
        for a in range(d):
            rhs[a] = (sxy[a, c] - n * mu[a] * y_mean[c]) / sd[a]
        coef[:, c] = _back(chol, _forward(chol, rhs))
    return mu, sd, y_mean, chol, coef


@njit(cache=True)
def _cap_step(point, last, limit):
    """Move ``point`` back towards ``last`` so it is at most ``limit`` from it (no ``last``: as it is)."""
    step = point - last
    size = math.sqrt((step * step).sum())
    if size > limit and np.isfinite(size):
        point[:] = last + step * (limit / size)


@njit(cache=True)
def _forward(chol, b):
    """L^-1 b."""
    out = np.empty(b.shape[0])
    for i in range(b.shape[0]):
        s = b[i]
        for k in range(i):
            s -= chol[i, k] * out[k]
        out[i] = s / chol[i, i]
    return out


@njit(cache=True)
def _back(chol, b):
    """L^-T b."""
    d = b.shape[0]
    out = np.empty(d)
    for i in range(d - 1, -1, -1):
        s = b[i]
        for k in range(i + 1, d):
            s -= chol[k, i] * out[k]
        out[i] = s / chol[i, i]
    return out


@njit(cache=True)
def _predict(x, mu, sd, chol, coef, y_mean, local):
    """The joint from the limb's first joint (parent frame) into ``local``; returns the pose's leverage,
    z^T (Z^T Z + RIDGE I)^-1 z = |L^-1 z|^2."""
    z = (x - mu) / sd
    local[:] = y_mean
    for c in range(3):
        for a in range(z.shape[0]):
            local[c] += z[a] * coef[a, c]
    half = _forward(chol, z)
    return (half * half).sum()


@njit(cache=True)
def _features(skeleton, chain, layout, mirrored, fallback, x):
    """This frame's feature vector into x, from ``chain``'s view (mirrored: the other limb's, as if it
    were this one): the feature joints from the chain's ``root_k`` joint, and with ``with_next`` the y and z
    axes of the joint after ``k``. Joints that are not located take ``fallback`` (the model's means), or,
    without one, make the frame unusable. False when the frame has no usable reference. (Written out
    without temporaries: it runs twice a frame per limb.) ``skeleton``: (positions, frames, status);
    ``layout``: BodyModel's (k, root_k, with_next, parent, features)."""
    positions, frames, status = skeleton
    k, root_k, with_next, parent, features = layout
    ref = frames[parent]
    root = positions[chain[root_k]]
    if not (all_finite(ref) and all_finite(root)):
        return False
    sx = -1.0 if mirrored else 1.0  # a mirror negates the parent frame's x (the subject's left)
    nxt = frames[chain[k + 1]] if with_next else ref
    m = features.shape[0]
    for i in range(m + 2 if with_next else m):
        if i < m:  # a joint, from the limb's first joint
            j = SWAPPED[features[i]] if mirrored else features[i]
            usable = status[j] == LOCATED
            d0, d1, d2 = positions[j, 0] - root[0], positions[j, 1] - root[1], positions[j, 2] - root[2]
        else:      # the next joint's y and z axes (x = y cross z flips with a mirror)
            usable = True
            d0, d1, d2 = nxt[0, i - m + 1], nxt[1, i - m + 1], nxt[2, i - m + 1]
        for c in range(3):
            v = ref[0, c] * d0 + ref[1, c] * d1 + ref[2, c] * d2
            x[3 * i + c] = v * sx if c == 0 else v
            usable = usable and np.isfinite(v)
        if not usable:
            if fallback is None:
                return False
            x[3 * i:3 * i + 3] = fallback[3 * i:3 * i + 3]
    return True


@njit(cache=True)
def _learn(skeleton, idx, other, layout, x, sums):
    """Add this frame's poses of the limb and of the other, mirrored, to ``sums`` (n, sx, sy, sxx, sxy)."""
    positions, frames, status = skeleton
    k, root_k, with_next, parent, _ = layout
    n, sx, sy, sxx, sxy = sums
    for src in range(2):
        chain = idx if src == 0 else other
        if status[chain[root_k]] != LOCATED or status[chain[k]] != LOCATED or \
                (with_next and status[chain[k + 1]] != LOCATED):
            continue
        if not _features(skeleton, chain, layout, src == 1, None, x):
            continue
        y = mtv(frames[parent].copy(), positions[chain[k]] - positions[chain[root_k]])
        if not all_finite(y):  # a "located" joint without a position: one NaN would spoil the sums for good
            continue
        if src == 1:
            y[0] = -y[0]
        n[0] += 1
        for a in range(x.shape[0]):
            sx[a] += x[a]
            for b in range(a, x.shape[0]):  # the upper triangle (all _fit reads)
                sxx[a, b] += x[a] * x[b]
            for b in range(3):
                sxy[a, b] += x[a] * y[b]
        sy += y

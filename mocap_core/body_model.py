"""Where a lone lost elbow or knee is, from the rest of the located body (beyond the thesis).

The swivel (mocap_core.analytic_fill) puts a lone missing joint on the circle its two bones allow;
the limb memory (mocap_core.limb_memory) pulls it towards where earlier poses with the next joint in
the same place had it. Neither looks past the limb. A dancer's elbow goes with the rest of her: the
other arm, the head, the trunk's lean, the hand's turn. This model is a ridge regression, learned
online, from the whole located skeleton (every joint but the two elbows, or the two knees, from the
limb's first joint in the limb parent's frame, and the next joint's frame) to the joint. It learns
from the limb's own located poses and from the other limb's, mirrored across the body, as the limb
memory does, and never from filled joints.

Its point turns the swivel's estimate along the circle, by at most half the angle between them and
less the further this frame's body lies from those it learned from (its leverage, z^T (Z^T Z + lam I)^-1 z):
a linear model is trusted where it interpolates. On the dance set's eight arms, elbow hidden from
1 s to the end (prototype, joint level), the swivel and limb memory were 164.9 mm summed over the
eight means; with this point at half weight 150.6, but walk1's right arm went 16.6 -> 21.3 mm, max
50 -> 101, on poses unlike any learned; weighted by leverage, 150.5 and walk1 right 17.4 / 50. The
model alone was 156; a nearest-neighbour search on the same features 191.
"""
from __future__ import annotations

import numpy as np
from numba import njit
from scipy.linalg import cho_solve, solve_triangular

from mocap_core.analytic_fill import LOCATED, MISSING, all_finite
from mocap_core.ik.kernels import mtv
from mocap_core.skeleton import INDEX, JOINTS

BODY_MODEL_HELP = ("beyond the thesis: a lone lost elbow or knee turned on its swivel circle towards where a "
                   "regression from the rest of the located body, learned online from this limb and the other "
                   "(mirrored), puts it (with swivel)")
MODELLED = frozenset({"elbow_l", "elbow_r", "knee_l", "knee_r"})
RIDGE = 10.0          # on standardized features (prototype: 1, 10 and 30 within 1.5 mm on dance2, 300 worse)
MIN_SAMPLES = 60      # poses before the model is trusted (one second at 60 Hz)
REFIT_SAMPLES = 60    # new poses before the model is refitted, when it is needed (prototype: every 30 frames)
MAX_WEIGHT = 0.5      # of the turn towards the model's point, at zero leverage
LEVERAGE_SCALE = 2.0  # the weight is MAX_WEIGHT / (1 + leverage / LEVERAGE_SCALE) (prototype: 0.5-4 within 2 mm)
SD_FLOOR = 1e-3        # of a feature (metres, or a unit vector's component): constant ones stay harmless
SWAPPED = np.array([INDEX[j[:-1] + {"l": "r", "r": "l"}[j[-1]]] if j[-2:] in ("_l", "_r") else INDEX[j]
                    for j in JOINTS], np.int64)


class BodyModel:
    """One limb's model of its middle joint ``k`` (the elbow or the knee): ``idx`` the limb's chain,
    ``other`` the other limb's (the same length), ``parent`` the limb parent's joint index."""

    def __init__(self, idx: np.ndarray, other: np.ndarray, k: int, parent: int):
        self.idx, self.other, self.k, self.parent = idx, other, k, parent
        excluded = {int(idx[k]), int(other[k])}
        self.features = np.array([j for j in range(len(JOINTS)) if j not in excluded], np.int64)
        d = 3 * len(self.features) + 6
        self.n = np.zeros(1)
        self.sx, self.sy = np.zeros(d), np.zeros(3)
        self.sxx, self.sxy = np.zeros((d, d)), np.zeros((d, 3))
        self.x = np.zeros(d)
        self.fitted_at = -1.0
        self.mu = self.sd = self.coef = self.chol = self.y_mean = None

    def learn(self, positions, frames, status) -> None:
        _learn(positions, frames, status, self.idx, self.other, self.k, self.parent, self.features, self.x,
               self.n, self.sx, self.sy, self.sxx, self.sxy)

    def predict(self, positions, frames, status) -> tuple[np.ndarray, float]:
        """(where the model puts the joint, world; the weight of its turn), or (NaNs, 0) without a model."""
        none = np.full(3, np.nan), 0.0
        k, idx = self.k, self.idx
        if status[idx[k]] != MISSING or status[idx[k - 1]] == MISSING or status[idx[k + 1]] == MISSING:
            return none
        if self.n[0] < MIN_SAMPLES:
            return none
        if self.n[0] - self.fitted_at >= REFIT_SAMPLES or self.fitted_at < 0:
            self._fit()
        if not _features(positions, frames, status, idx, k, self.parent, self.features, False, self.mu, self.x):
            return none
        z = (self.x - self.mu) / self.sd
        half = solve_triangular(self.chol, z, lower=True, check_finite=False)
        leverage = float(half @ half)  # z^T (Z^T Z + RIDGE I)^-1 z
        local = z @ self.coef + self.y_mean
        ref = frames[self.parent]
        point = positions[idx[k - 1]] + ref @ local
        return point, MAX_WEIGHT / (1.0 + leverage / LEVERAGE_SCALE)

    def _fit(self) -> None:
        n = self.n[0]
        mu, y_mean = self.sx / n, self.sy / n
        sxx = _symmetric(self.sxx)
        var = np.maximum(np.diag(sxx) / n - mu * mu, 0.0)
        sd = np.maximum(np.sqrt(var), SD_FLOOR)
        zz = (sxx - n * np.outer(mu, mu)) / np.outer(sd, sd)      # Z^T Z of the standardized features
        zy = (self.sxy - n * np.outer(mu, y_mean)) / sd[:, None]        # Z^T (y - mean)
        # Cholesky, not an inverse: a third of the work (an 81 x 81 inverse took 350 us on this VM)
        self.chol = np.linalg.cholesky(zz + RIDGE * np.eye(len(mu)))
        self.coef, self.mu, self.sd, self.y_mean = cho_solve((self.chol, True), zy, check_finite=False), mu, sd, y_mean
        self.fitted_at = n


@njit(cache=True)
def _features(positions, frames, status, chain, k, parent, features, mirrored, fallback, x):
    """This frame's feature vector into x, from ``chain``'s view (mirrored: the other limb's, as if it
    were this one). Joints that are not located take ``fallback`` (the model's means), or, without
    one, make the frame unusable. False when the frame has no usable reference. (Written out without
    temporaries: it runs twice a frame per limb.)"""
    ref = frames[parent]
    root = positions[chain[k - 1]]
    if not (all_finite(ref) and all_finite(root)):
        return False
    sx = -1.0 if mirrored else 1.0  # a mirror negates the parent frame's x (the subject's left)
    nxt = frames[chain[k + 1]]
    m = features.shape[0]
    for i in range(m + 2):
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
def _symmetric(upper):
    out = upper.copy()
    for a in range(upper.shape[0]):
        for b in range(a):
            out[a, b] = upper[b, a]
    return out


@njit(cache=True)
def _learn(positions, frames, status, idx, other, k, parent, features, x, n, sx, sy, sxx, sxy):
    for src in range(2):
        chain = idx if src == 0 else other
        if status[chain[k - 1]] != LOCATED or status[chain[k]] != LOCATED or status[chain[k + 1]] != LOCATED:
            continue
        if not _features(positions, frames, status, chain, k, parent, features, src == 1, None, x):
            continue
        y = mtv(frames[parent].copy(), positions[chain[k]] - positions[chain[k - 1]])
        if src == 1:
            y[0] = -y[0]
        n[0] += 1
        for a in range(x.shape[0]):
            sx[a] += x[a]
            for b in range(a, x.shape[0]):  # the upper triangle (BodyModel._fit mirrors it)
                sxx[a, b] += x[a] * x[b]
            for b in range(3):
                sxy[a, b] += x[a] * y[b]
        sy += y

"""Small vectorised geometry for the parts that run outside the numba kernels (hip interpolation,
the swivel option, tests). Arrays may have any leading dimensions (..., 3). Frames are rotation
matrices whose columns are the local x, y, z axes in world coordinates. The per-frame hot paths
(localization, IK, quaternion conversion) live in mocap_core/ik/kernels.py and localization.py.
"""
from __future__ import annotations

import numpy as np

EPS = 1e-9


def norm(v: np.ndarray) -> np.ndarray:
    return np.sqrt(np.einsum("...i,...i->...", v, v))


def normalize(v: np.ndarray) -> np.ndarray:
    n = norm(v)[..., None]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > EPS, v / n, np.nan)


def frame_yx(y: np.ndarray, x_hint: np.ndarray) -> np.ndarray:
    """y exactly along ``y``, x as close to ``x_hint`` as possible, z = x cross y (LookAtRight)."""
    yy = normalize(y)
    xx = normalize(x_hint - np.einsum("...i,...i->...", x_hint, yy)[..., None] * yy)
    return np.stack([xx, yy, np.cross(xx, yy)], axis=-1)


def rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Shortest-arc rotation matrices carrying direction a onto direction b (Rodrigues)."""
    a, b = normalize(a), normalize(b)
    v = np.cross(a, b)
    c = np.einsum("...i,...i->...", a, b)
    s2 = np.einsum("...i,...i->...", v, v)
    k = np.zeros(v.shape[:-1] + (3, 3))
    k[..., 0, 1], k[..., 0, 2], k[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    k[..., 1, 0], k[..., 2, 0], k[..., 2, 1] = v[..., 2], -v[..., 1], v[..., 0]
    with np.errstate(invalid="ignore", divide="ignore"):
        f = np.where(s2 > 1e-18, (1 - c) / np.where(s2 > 1e-18, s2, 1), 0.5)
    r = np.eye(3) + k + (k @ k) * f[..., None, None]
    # opposite directions: rotate 180 degrees about any axis perpendicular to a
    opposite = (c < -1 + 1e-12)
    if np.any(opposite):
        perp = normalize(np.cross(a, np.where(np.abs(a[..., :1]) < 0.9, [1.0, 0, 0], [0, 1.0, 0])))
        flip = 2 * perp[..., :, None] * perp[..., None, :] - np.eye(3)
        r = np.where(opposite[..., None, None], flip, r)
    return r


def rigid_fit(before: np.ndarray, after: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation and translation (R, t) minimising sum w |R before + t - after|^2 (weighted Kabsch)."""
    w = weights / weights.sum()
    cb, ca = w @ before, w @ after
    h = ((before - cb) * w[:, None]).T @ (after - ca)
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(vt.T @ u.T))
    rot = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return rot, ca - rot @ cb

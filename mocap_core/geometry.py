"""Small vectorised geometry: every function takes arrays with any leading dimensions (..., 3).

Frames are rotation matrices whose columns are the local x, y, z axes in world coordinates.
Quaternions are scalar-last (x, y, z, w), as in every message.
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


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("...i,...i->...", a, b)


def mid(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return 0.5 * (a + b)


def reject(v: np.ndarray, axis_unit: np.ndarray) -> np.ndarray:
    """The part of v perpendicular to a unit axis."""
    return v - dot(v, axis_unit)[..., None] * axis_unit


def frame_yz(y: np.ndarray, z_hint: np.ndarray) -> np.ndarray:
    """y exactly along ``y``, z as close to ``z_hint`` as possible, x = y cross z (LookAtUp)."""
    yy = normalize(y)
    zz = normalize(reject(z_hint, yy))
    return np.stack([cross(yy, zz), yy, zz], axis=-1)


def frame_yx(y: np.ndarray, x_hint: np.ndarray) -> np.ndarray:
    """y exactly along ``y``, x as close to ``x_hint`` as possible, z = x cross y (LookAtRight)."""
    yy = normalize(y)
    xx = normalize(reject(x_hint, yy))
    return np.stack([xx, yy, cross(xx, yy)], axis=-1)


def frame_zx(z: np.ndarray, x_hint: np.ndarray) -> np.ndarray:
    """z exactly along ``z``, x as close to ``x_hint`` as possible, y = z cross x."""
    zz = normalize(z)
    xx = normalize(reject(x_hint, zz))
    return np.stack([xx, cross(zz, xx), zz], axis=-1)


def matrix_to_quat(m: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) -> unit quaternions (..., 4) as (x, y, z, w); NaN stays NaN."""
    m = np.asarray(m, dtype=np.float64)
    t = m[..., 0, 0] + m[..., 1, 1] + m[..., 2, 2]
    cands = np.stack([
        np.stack([m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1], 1 + t], -1),
        np.stack([1 + m[..., 0, 0] - m[..., 1, 1] - m[..., 2, 2], m[..., 0, 1] + m[..., 1, 0],
                  m[..., 0, 2] + m[..., 2, 0], m[..., 2, 1] - m[..., 1, 2]], -1),
        np.stack([m[..., 0, 1] + m[..., 1, 0], 1 + m[..., 1, 1] - m[..., 0, 0] - m[..., 2, 2],
                  m[..., 1, 2] + m[..., 2, 1], m[..., 0, 2] - m[..., 2, 0]], -1),
        np.stack([m[..., 0, 2] + m[..., 2, 0], m[..., 1, 2] + m[..., 2, 1],
                  1 + m[..., 2, 2] - m[..., 0, 0] - m[..., 1, 1], m[..., 1, 0] - m[..., 0, 1]], -1),
    ], axis=-2)  # (..., 4 candidates, 4); pick the numerically largest (Shepperd's method)
    diag = np.stack([t, m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]], -1)
    best = np.nanargmax(np.where(np.isnan(diag), -np.inf, diag), axis=-1)
    q = np.take_along_axis(cands, best[..., None, None], axis=-2)[..., 0, :]
    q = q / norm(q)[..., None]
    return np.where(q[..., 3:4] < 0, -q, q)


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    x, y, z, w = np.moveaxis(np.asarray(q, dtype=np.float64), -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Shortest-arc rotation matrices carrying direction a onto direction b (Rodrigues)."""
    a, b = normalize(a), normalize(b)
    v = np.cross(a, b)
    c = dot(a, b)
    s2 = dot(v, v)
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


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis (written out: np.cross is slow on small arrays)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)

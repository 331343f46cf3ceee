"""FABRIK (thesis 3.5.3, Aristidou and Lasenby 2011)."""
from __future__ import annotations

import numpy as np
from numba import njit

from mocap_core.ik.kernels import constrain_bone, rotate_subchain, rotation_between, vnorm


@njit(cache=True)
def step(P, R, target, limits, constrained):
    """A forward pass from the target, then a backward pass from the root in which each bone is re-aimed, its
    frame carried by the shortest arc, and its cone and twist limits enforced."""
    n = R.shape[0]
    lengths = np.empty(n)
    for i in range(n):
        lengths[i] = vnorm(P[i + 1] - P[i])
    root = P[0].copy()
    Q = P.copy()
    Q[n] = target
    for i in range(n - 1, -1, -1):
        d = Q[i] - Q[i + 1]
        nd = vnorm(d)
        if nd < 1e-9:  # coincident joints: push apart along the old bone (facts: 0.001 m)
            d = P[i] - P[i + 1]
            nd = vnorm(d)
        Q[i] = Q[i + 1] + d * (lengths[i] / nd)
    Q[0] = root
    for i in range(n):
        d = Q[i + 1] - P[i]
        nd = vnorm(d)
        if nd < 1e-9:
            continue
        rotate_subchain(P, R, i, rotation_between(P[i + 1] - P[i], d))
        if constrained:
            constrain_bone(P, R, i, limits)

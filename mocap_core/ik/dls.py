"""Damped least squares (thesis 3.5.1)."""
from __future__ import annotations

import numpy as np
from numba import njit

from mocap_core.ik.kernels import apply_angles, constrain_chain, jacobian

DLS_LAMBDA = 1.1  # thesis 3.5.1


@njit(cache=True)
def step(P, R, target, limits, constrained):
    """dtheta = J^T (J J^T + lambda^2 I)^-1 e, lambda = 1.1."""
    n = R.shape[0]
    J = jacobian(P, n)
    e = target - P[n]
    A = J @ J.T + (DLS_LAMBDA * DLS_LAMBDA) * np.eye(3)
    apply_angles(P, R, J.T @ np.linalg.solve(A, e))
    if constrained:
        constrain_chain(P, R, limits)

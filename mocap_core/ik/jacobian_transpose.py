"""Jacobian transpose (thesis 3.5.1) with the step that minimises the new error (Buss 2004)."""
from __future__ import annotations

from numba import njit

from mocap_core.ik.kernels import EPS, apply_angles, constrain_chain, jacobian


@njit(cache=True)
def step(P, R, target, limits, constrained):
    """dtheta = alpha J^T e, alpha = <e, J J^T e> / <J J^T e, J J^T e>."""
    n = R.shape[0]
    J = jacobian(P, n)
    e = target - P[n]
    g = J.T @ e
    jje = J @ g
    denom = jje @ jje
    if denom < EPS:
        return
    apply_angles(P, R, g * ((e @ jje) / denom))
    if constrained:
        constrain_chain(P, R, limits)

"""Cyclic coordinate descent (thesis 3.5.2)."""
from __future__ import annotations

from numba import njit

from mocap_core.ik.kernels import constrain_bone, rotate_subchain, rotation_between


@njit(cache=True)
def step(P, R, target, limits, constrained):
    """From the last bone to the first, turn each bone so the end effector points at the target, then enforce
    that bone's limits."""
    n = R.shape[0]
    for i in range(n - 1, -1, -1):
        rotate_subchain(P, R, i, rotation_between(P[n] - P[i], target - P[i]))
        if constrained:
            constrain_bone(P, R, i, limits)

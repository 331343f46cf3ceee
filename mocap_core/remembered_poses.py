"""The store both pose memories keep (mocap_core.pose_memory in the hip stage, mocap_core.limb_memory in
the IK stage): a ring of remembered poses, each a key point and what went with it, and a search for
the poses whose key is nearest a point (a key: a point in 3-D, or longer: the pose memory adds the toe's
velocity), and a local fit of what the poses found had with them."""
from __future__ import annotations

import numpy as np
from numba import njit

CAPACITY = 4000     # poses kept per ring (the oldest make room)
MIN_MOVE_M = 0.005  # a pose is kept when its key has moved this far from the last one kept


@njit(cache=True)
def keep(keys, values, state, last_key, key, value):
    """Remember one pose (its key point and its values) if the key has moved since the last one kept.
    One ring: keys (CAPACITY, k), values (CAPACITY, m, 3), state [poses kept, where the next goes]."""
    moved = 0.0
    for c in range(key.shape[0]):
        moved += (key[c] - last_key[c]) ** 2
    if np.sqrt(moved) < MIN_MOVE_M:
        return
    i = state[1]
    keys[i] = key
    values[i, :len(value)] = value
    last_key[:] = key
    state[1], state[0] = (i + 1) % CAPACITY, min(state[0] + 1, CAPACITY)


@njit(cache=True, inline="always")  # called with constants: inlined, not compiled once per constant
def nearest(keys, count, point, best_d, best_i, offset=0):
    """Merge the first ``count`` keys of one ring into the nearest found so far (``best_d``, ``best_i``,
    nearest first, len = how many are wanted; start them at inf), by insertion. A key's index is
    ``offset`` + its slot, so several rings can be searched into one list. A point shorter than the keys is
    compared with their first numbers (the pose memory finds poses by the toe's place alone that way)."""
    wanted = best_d.shape[0]
    width = point.shape[0]
    for i in range(count):  # (written out: no temporary arrays in the loop)
        d = 0.0
        for c in range(width):
            d += (keys[i, c] - point[c]) ** 2
        d = np.sqrt(d)
        if d < best_d[wanted - 1]:
            j = wanted - 1
            while j > 0 and best_d[j - 1] > d:
                best_d[j], best_i[j] = best_d[j - 1], best_i[j - 1]
                j -= 1
            best_d[j], best_i[j] = d, offset + i


@njit(cache=True)
def local_fit(weights, key_offsets, found, ridge):
    """Where a linear fit of the remembered poses' values ``found`` (n, k: each column fitted alike) over their
    keys' offsets from the key now (``key_offsets``, n x 3), weighted by ``weights`` (summing to 1), puts the
    key now (k): the intercept of a weighted least-squares fit whose slope is pulled towards none by ``ridge``
    (m^2, against the keys' weighted spread). Poses found all to one side of the key (at the edge of what was
    seen) have a mean off by however the value follows the key there; the fit reads it off where the key is.
    With no slope, or all keys in one place, it is the weighted mean."""
    design = np.ones((len(weights), 4))
    design[:, 1:] = key_offsets
    weighted = design.T * weights
    normal = weighted @ design
    for i in range(1, 4):
        normal[i, i] += ridge
    return np.linalg.solve(normal, weighted @ found)[0]

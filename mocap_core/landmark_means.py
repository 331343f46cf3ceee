"""The landmark map's kernel (mocap_core.profiles.LandmarkMap.apply): a module of its own, so that what reads
profiles without mapping frames (the outputs, the viewer, ingest) does not load numba."""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def means(markers, idx, count, out):
    """Each frame's landmarks (F, n_landmarks, 3) into ``out``: the mean of the markers ``idx`` names (a row padded
    with the index past the last marker, which reads as 0), summed in the row's order; NaN where ``count`` is 0."""
    n = markers.shape[1]
    for f in range(markers.shape[0]):
        for i in range(idx.shape[0]):
            for c in range(3):
                total = markers[f, idx[i, 0], c] if idx[i, 0] < n else 0.0
                for k in range(1, idx.shape[1]):
                    total += markers[f, idx[i, k], c] if idx[i, k] < n else 0.0
                out[f, i, c] = total / count[i] if count[i] != 0 else np.nan

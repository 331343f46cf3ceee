"""Load (or compile) the numba kernels before the first real frame, so frame one is not late.

Nodes call this in setup(), before they report ready; offline commands call it once up front.
Loading from the on-disk cache takes well under a second; the very first compile on a machine
takes about a minute.
"""
from __future__ import annotations

import numpy as np


def warm_up() -> None:
    from mocap_core.gapfill import BEYOND_THESIS, LimbFiller
    from mocap_core.ik.kernels import frames_to_quats, quats_to_frames
    from mocap_core.ik.solvers import SOLVERS
    from mocap_core.localization import Localizer
    from mocap_core.profiles import LANDMARKS
    from mocap_core.skeleton import N_JOINTS, Status

    loc = Localizer().localize(np.full((1, len(LANDMARKS), 3), np.nan))
    quats_to_frames(frames_to_quats(np.tile(np.eye(3), (N_JOINTS, 1, 1))))
    # one solve per solver, on a chain with a missing middle joint
    for solver, options in [(s, {}) for s in SOLVERS] + [("ccd", BEYOND_THESIS)]:  # the analytic kernels too
        filler = LimbFiller("left_leg", solver, **options)
        pos = np.zeros((N_JOINTS, 3))
        frames = np.tile(np.eye(3), (N_JOINTS, 1, 1))
        status = np.full(N_JOINTS, Status.LOCATED, np.uint8)
        for k, j in enumerate(filler.joints):
            pos[j] = [0.0, 0.1, 1.0 - 0.2 * k]
        filler.fill(pos, frames, status)
        status[filler.joints[1]] = Status.MISSING
        pos[filler.joints[1]] = np.nan
        filler.fill(pos, frames, status)
        status[filler.joints[1:]] = Status.LOCATED
        filler.fill(pos, frames, status)
    del loc

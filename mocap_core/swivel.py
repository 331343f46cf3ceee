"""Beyond the thesis: a run of lost joints between two located ones put on their swivel circle (the IK stage's fill;
its kernels, and what they do, are mocap_core.analytic_fill's)."""
from __future__ import annotations

import numpy as np

from mocap_core import analytic_fill as af
from mocap_core.fill_units import LimbFill, LimbFrame, switch

SWIVEL_HELP = ("beyond the thesis: missing joints between two located ones from bone lengths (each bone as long as on "
               "average while located) and the swivel angle carried in the next joint's or the limb parent's frame")


class Swivel(LimbFill):
    """Keeps, per run of lost joints (joint, end, frame kind), the last well-defined bend direction, and each bone's
    direction statistics in the frame of the joint it ends at. The limb memory and the body model steer it
    (frame.recalled, frame.modelled)."""
    Settings = switch("swivel", SWIVEL_HELP)

    def __init__(self, limb, options):
        super().__init__(limb, options)
        n = len(limb.joints)
        self.bend, self.bend_ok = np.zeros((n, n + 1, 2, 3)), np.zeros((n, n + 1, 2), bool)
        self.dir_sum, self.dir_sq, self.dir_n = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros(n)
        self._state = (self.bend, self.bend_ok, self.dir_sum, self.dir_sq, self.dir_n)  # (as the kernel takes it)

    def before(self, frame: LimbFrame) -> None:
        limb = self.limb
        af.learn_directions(frame.positions, frame.frames, frame.status, limb.joints, self.dir_sum, self.dir_sq,
                            self.dir_n)
        if limb.has_prev[0]:
            frame.out[0] += af.swivel_fill(frame.skeleton, limb.chain, limb.last,
                                           self._state, (frame.recalled, frame.modelled, frame.model_weight))

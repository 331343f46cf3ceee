"""Beyond the thesis: a lost ankle moves with its still-tracked foot, a lost hand or toe with the last tracked bone
before it (the IK stage's fill; its kernels are mocap_core.analytic_fill's)."""
from __future__ import annotations

import numpy as np

from mocap_core import analytic_fill as af
from mocap_core.fill_units import LimbFill, LimbFrame, switch
from mocap_core.skeleton import LIMBS

SEGMENT_CARRY_HELP = ("beyond the thesis: a lost ankle moves with its still-tracked foot (heel and toe markers), a "
                      "lost hand or toe with the last tracked bone before it")
# Joints that begin a rigid segment of two more joints (ankle, foot, toe: the foot's bones).
CARRIED_BY_SEGMENT = frozenset({"ankle_l", "ankle_r"})


class SegmentCarry(LimbFill):
    Settings = switch("segment_carry", SEGMENT_CARRY_HELP)

    def __init__(self, limb, options):
        super().__init__(limb, options)
        self.carried = np.array([(k, k + 1, k + 2) for k, name in enumerate(LIMBS[limb.limb])
                                 if name in CARRIED_BY_SEGMENT], dtype=np.int64).reshape(-1, 3)

    def before(self, frame: LimbFrame) -> None:
        limb = self.limb
        if limb.has_prev[0]:
            p, f, s = frame.positions, frame.frames, frame.status
            frame.out[0] += af.segment_carry(p, f, s, limb.joints, self.carried, limb.prev_pos, limb.prev_frames)
            frame.out[1] += af.carry_lost_end(p, f, s, limb.joints, limb.prev_pos, limb.prev_frames)

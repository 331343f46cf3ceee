"""Beyond the thesis: a limb lost from its first joint down (elbow, wrist and hand; knee, ankle and foot) has its end
put where a regression from the rest of the located body puts it (mocap_core.body_model's, with the limb's first
joint as its root), once the gap has lasted END_WAIT_S; the joints between then aim at it, where Algorithm 1 held
the whole limb as it was relative to its parent."""
from __future__ import annotations

import numpy as np

from mocap_core import analytic_fill as af
from mocap_core.analytic_fill import all_finite
from mocap_core.body_model import MODELLED, MODELLED_ENDS, BodyModel, chain_place
from mocap_core.fill_units import LimbFill, LimbFrame, switch
from mocap_core.skeleton import ESTIMATED, LOCATED, MISSING

# The end model takes a lost limb over only once the gap has lasted this long: before, the limb held as it was,
# with the blend's course on the markers' last motion, does better (most real gaps last a tenth of a second or
# less), and a model taken at once makes more of the returns jump.
END_WAIT_S = 0.2
END_MODEL_HELP = ("beyond the thesis: a limb lost from its first joint down (elbow, wrist and hand; knee, ankle and "
                  f"foot) has its end put, once the gap has lasted {END_WAIT_S:g} s, where a regression from the rest "
                  "of the located body, learned online from this limb and the other (mirrored), puts it, and the "
                  "joints between aim at it; the thesis held the lost limb as it was relative to its parent")
# A predicted end is put at most this share of the limb's reach from its root: the joints between stay bent.
REACH_SHARE = 0.99


class EndModel(LimbFill):
    """Runs first of the limb's fills: the segment carry would hold the whole lost limb with the clavicle."""
    Settings = switch("end_model", END_MODEL_HELP)
    mirrored = True

    @classmethod
    def for_limb(cls, limb, options) -> "EndModel | None":
        middle, end = chain_place(limb.limb, MODELLED), chain_place(limb.limb, MODELLED_ENDS)
        if limb.other is None or middle is None or end is None:
            return None
        return cls(limb, options, BodyModel(limb.joints, limb.other, end, limb.parent_of_root, root=middle - 1))

    def __init__(self, limb, options, model: BodyModel):
        super().__init__(limb, options)
        self.model = model
        self.end_local = np.full(3, np.nan)  # the lost end's offset from the root where the gap began
        self.end_seen = False                 # and whether its markers were the end's last source
        self.end_since = 0.0                  # and how long the limb has been lost

    def before(self, frame: LimbFrame) -> None:
        frame.out[0] += self._put_end(frame.positions, frame.frames, frame.status)

    def _put_end(self, positions, frames, status) -> int:
        """The model's point for a limb lost from its first joint down, within the limb's reach; 1 if put."""
        limb, model = self.limb, self.model
        model.learn(positions, frames, status)
        idx, root, k, frame_s = limb.joints, model.root, model.k, limb.clock.frame_s
        seen = status[idx[k]] != MISSING  # seen, or put by the hip stage's fills (the leg hinge, say)
        if seen:
            self.end_seen = status[idx[k]] == LOCATED
        # a limb whose better fill drops out for a few frames is held as that fill left it, not handed to the
        # model and back (each hand-over is a jump of its own)
        if not limb.has_prev[0] or not (self.end_seen or all_finite(self.end_local)):
            return 0
        if seen:  # nothing to put, and the gap, if one was going on, is over
            model.last_local[:] = np.nan
            self.end_local[:] = np.nan
            return 0
        point, weight = model.predict(positions, frames, status, frame_s)
        if not all_finite(point):
            self.end_local[:] = np.nan
            return 0
        parent = frames[limb.parent_of_root]
        if not all_finite(self.end_local):  # the gap begins: the end as it was, in the limb parent's frame
            self.end_local[:] = limb.prev_parent_frame.T @ (limb.prev_pos[k] - limb.prev_pos[root])
            self.end_since = 0.0
        self.end_since += frame_s  # (seconds into the gap)
        if self.end_since < END_WAIT_S - frame_s / 2:  # to the nearest frame: stamps are rounded (QTM's to the
            return 0                                    # microsecond), sums of 1/rate inexact
        held = positions[idx[root]] + parent @ self.end_local
        if all_finite(held):  # a pose unlike those learned moves the end less far from where it was held
            point = held + weight * (point - held)
        bones = [af._length(limb.lengths, j, float(np.linalg.norm(limb.prev_pos[j + 1] - limb.prev_pos[j])))
                 for j in range(root, k)]  # as the swivel takes them
        reach = REACH_SHARE * sum(bones)
        out = point - positions[idx[root]]
        size = float(np.linalg.norm(out))
        if size > reach:  # a bent limb's joints cannot be placed between root and an end out of reach
            point = positions[idx[root]] + out * (reach / size)
        positions[idx[k]] = point
        status[idx[k]] = ESTIMATED
        return 1

"""Hip-marker interpolation (thesis 3.4.8, facts section 4).

SACR, L_IAS and R_IAS define the pelvis, and so the root of the whole skeleton. When some of them
are occluded they are predicted from the ones still seen and from the last frame in which all three
were seen:

- two seen: rotate the last-known vector between the two seen markers onto the current one, apply
  that rotation to the last-known vectors from each seen marker to the missing one, and average the
  two predictions;
- one seen: translate the last-known triangle with it;
- none seen: keep the previous frame's values (``when_lost="hold"``, the thesis), or, beyond the
  thesis (``when_lost="fit"``), move the last triangle with the rest of the body: the rigid motion
  that best carries the trunk's markers (TV12, TV2, sternum, head, shoulders) and, with a quarter
  of the weight, the knee markers from where they were in the last complete frame to where they
  are now (weighted least squares, Kabsch). With fewer than three of them seen, or all in a line,
  it falls back to holding; ``when_lost="missing"`` leaves the pelvis missing;
- each predicted marker moves at most ``max_step_m`` (0.02 m) from its previous value per frame.

Departure from the original code: before the first frame with all three markers there is no
last-known triangle, so nothing is predicted (the original starts from a default pose in Unity's
frame, which means nothing in a studio's world frame). Those frames keep their pelvis missing.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from mocap_core.geometry import rigid_fit, rotation_between
from mocap_core.profiles import LANDMARK_INDEX

HIP_LANDMARKS = ("SACR", "L_IAS", "R_IAS")
HIP_INDEX = np.array([LANDMARK_INDEX[n] for n in HIP_LANDMARKS])
# What carries the pelvis when every hip marker is lost (when_lost="fit"): the trunk, and the knees
# with less weight since they swing with the hips.
ANCHOR_LANDMARKS = ("TV12", "TV2", "SME", "SGL", "L_SAE", "R_SAE", "L_FLE", "R_FLE")
ANCHOR_INDEX = np.array([LANDMARK_INDEX[n] for n in ANCHOR_LANDMARKS])
ANCHOR_WEIGHTS = np.array([1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 0.25, 0.25])
MIN_SPREAD_M = 0.05  # the anchors seen must span a plane at least this wide
WhenLost = Literal["hold", "fit", "missing"]
WHEN_LOST_HELP = ("every hip marker lost: hold the last ones (the thesis), fit them to the trunk and knee markers "
                  "(beyond the thesis), or leave the pelvis missing")


@dataclass
class HipInterpolator:
    max_step_m: float = 0.02
    when_lost: WhenLost = "hold"                            # every hip marker lost: see the module doc
    last_anchors: np.ndarray | None = None                  # the anchors in the last complete frame
    last_known: np.ndarray | None = None                    # (3, 3): the last complete triangle
    previous: np.ndarray = field(default_factory=lambda: np.full((3, 3), np.nan))  # last output

    def fill(self, hips: np.ndarray, anchors: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """One frame: hips (3, 3) with NaN rows, and the ANCHOR_LANDMARKS (needed for
        when_lost="fit") -> (filled (3, 3), interpolated mask (3,))."""
        seen = ~np.isnan(hips).any(axis=1)
        out = hips.astype(np.float64, copy=True)
        interpolated = np.zeros(3, bool)
        if seen.all():
            self.last_known = out.copy()
            if self.when_lost == "fit" and anchors is not None:  # only a fit needs them
                self.last_anchors = np.array(anchors, np.float64)
        elif self.last_known is not None:
            lk = self.last_known
            idx = np.flatnonzero(seen)
            if len(idx) == 2:
                a, b = idx
                rot = rotation_between(lk[b] - lk[a], out[b] - out[a])
                for m in np.flatnonzero(~seen):
                    out[m] = 0.5 * ((out[a] + rot @ (lk[m] - lk[a])) + (out[b] + rot @ (lk[m] - lk[b])))
            elif len(idx) == 1:
                a = idx[0]
                out[~seen] = out[a] + (lk[~seen] - lk[a])
            else:
                fitted = self._fit(anchors) if self.when_lost == "fit" else None
                if fitted is not None:
                    out = fitted
                elif self.when_lost != "missing":
                    out = self.previous.copy()
            interpolated = ~seen & ~np.isnan(out).any(axis=1)
            for m in np.flatnonzero(interpolated):
                step = out[m] - self.previous[m]
                dist = float(np.linalg.norm(step))
                if np.isfinite(dist) and dist > self.max_step_m:
                    out[m] = self.previous[m] + step * (self.max_step_m / dist)
        self.previous = out
        return out, interpolated

    def _fit(self, anchors: np.ndarray | None) -> np.ndarray | None:
        if anchors is None or self.last_anchors is None:
            return None
        ok = np.isfinite(anchors).all(axis=1) & np.isfinite(self.last_anchors).all(axis=1)
        before = self.last_anchors[ok]
        if ok.sum() < 3 or np.linalg.svd(before - before.mean(axis=0), compute_uv=False)[1] < MIN_SPREAD_M:
            return None
        rot, t = rigid_fit(before, anchors[ok], ANCHOR_WEIGHTS[ok])
        return self.last_known @ rot.T + t

    def fill_landmarks(self, landmarks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Landmark frames (F, n_landmarks, 3) -> filled copy and an (F, 3) interpolated mask."""
        out = np.array(landmarks, dtype=np.float64, copy=True)
        flags = np.zeros((out.shape[0], 3), bool)
        for f in range(out.shape[0]):
            out[f, HIP_INDEX], flags[f] = self.fill(out[f, HIP_INDEX], out[f, ANCHOR_INDEX])
        return out, flags

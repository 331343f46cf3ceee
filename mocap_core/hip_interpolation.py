"""Hip-marker interpolation (thesis 3.4.8, facts section 4).

SACR, L_IAS and R_IAS define the pelvis, and so the root of the whole skeleton. When some of them
are occluded they are predicted from the ones still seen and from the last frame in which all three
were seen:

- two seen: rotate the last-known vector between the two seen markers onto the current one, apply
  that rotation to the last-known vectors from each seen marker to the missing one, and average the
  two predictions;
- one seen: translate the last-known triangle with it;
- none seen: keep the previous frame's values;
- each predicted marker moves at most ``max_step_m`` (0.02 m) from its previous value per frame.

Departure from the original code: before the first frame with all three markers there is no
last-known triangle, so nothing is predicted (the original starts from a default pose in Unity's
frame, which means nothing in a studio's world frame). Those frames keep their pelvis missing.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mocap_core.geometry import rotation_between
from mocap_core.profiles import LANDMARK_INDEX

HIP_LANDMARKS = ("SACR", "L_IAS", "R_IAS")
HIP_INDEX = np.array([LANDMARK_INDEX[n] for n in HIP_LANDMARKS])


@dataclass
class HipInterpolator:
    max_step_m: float = 0.02
    last_known: np.ndarray | None = None                    # (3, 3): the last complete triangle
    previous: np.ndarray = field(default_factory=lambda: np.full((3, 3), np.nan))  # last output

    def fill(self, hips: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One frame: hips (3, 3) with NaN rows -> (filled (3, 3), interpolated mask (3,))."""
        seen = ~np.isnan(hips).any(axis=1)
        out = hips.astype(np.float64, copy=True)
        interpolated = np.zeros(3, bool)
        if seen.all():
            self.last_known = out.copy()
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
                out = self.previous.copy()
            interpolated = ~seen & ~np.isnan(out).any(axis=1)
            for m in np.flatnonzero(interpolated):
                step = out[m] - self.previous[m]
                dist = float(np.linalg.norm(step))
                if np.isfinite(dist) and dist > self.max_step_m:
                    out[m] = self.previous[m] + step * (self.max_step_m / dist)
        self.previous = out
        return out, interpolated

    def fill_landmarks(self, landmarks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Landmark frames (F, n_landmarks, 3) -> filled copy and an (F, 3) interpolated mask."""
        out = np.array(landmarks, dtype=np.float64, copy=True)
        flags = np.zeros((out.shape[0], 3), bool)
        for f in range(out.shape[0]):
            out[f, HIP_INDEX], flags[f] = self.fill(out[f, HIP_INDEX])
        return out, flags

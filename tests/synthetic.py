"""A synthetic subject: markers built from known joint centres (Z up, facing +x, left = +y)."""
from __future__ import annotations

import numpy as np

from mocap_core.profiles import LANDMARK_INDEX, LANDMARKS

# Known joint centres of the left side; the right side mirrors y.
KNEE_L = np.array([0.0, 0.09, 0.50])
ANKLE_L = np.array([-0.02, 0.09, 0.08])
ELBOW_L = np.array([-0.02, 0.20, 1.10])
WRIST_L = np.array([0.0, 0.21, 0.85])
HEAD = np.array([0.0, 0.0, 1.65])
KNEE_WIDTH, ANKLE_WIDTH, ELBOW_WIDTH = 0.10, 0.07, 0.07


def _mirror(p):
    return p * np.array([1, -1, 1])


def landmarks(marker_radius: float = 0.007) -> np.ndarray:
    """(n_landmarks, 3) for one standing frame. Epicondyle markers sit width/2 + marker radius off centre."""
    lm = np.full((len(LANDMARKS), 3), np.nan)
    y = np.array([0, 1.0, 0])

    def put(name, p):
        lm[LANDMARK_INDEX[name]] = p

    put("SACR", [-0.10, 0.0, 1.0])
    put("L_IAS", [0.05, 0.12, 1.0])
    put("R_IAS", [0.05, -0.12, 1.0])
    put("TV12", [-0.11, 0.0, 1.25])
    put("TV2", [-0.09, 0.0, 1.50])
    put("SME", [0.08, 0.0, 1.45])
    put("SGL", [0.09, 0.0, 1.65])
    put("L_HEAD", HEAD + [0, 0.08, 0])
    put("R_HEAD", HEAD - [0, 0.08, 0])
    for side, sgn in (("L", 1), ("R", -1)):
        m = (lambda p: p) if sgn == 1 else _mirror
        k, a, e, w = m(KNEE_L), m(ANKLE_L), m(ELBOW_L), m(WRIST_L)
        off = sgn * y
        put(f"{side}_FLE", k + off * (KNEE_WIDTH / 2 + marker_radius))
        put(f"{side}_FME", k - off * (KNEE_WIDTH / 2 + marker_radius))
        put(f"{side}_TTC", k + [0.05, 0, -0.06])
        put(f"{side}_FAL", a + off * (ANKLE_WIDTH / 2 + marker_radius))
        put(f"{side}_TAM", a - off * (ANKLE_WIDTH / 2 + marker_radius))
        put(f"{side}_FCC", a + [-0.07, 0, -0.05])
        put(f"{side}_FM2", a + [0.15, 0, -0.06])
        put(f"{side}_SAE", m(np.array([-0.02, 0.19, 1.45])))
        put(f"{side}_HLE", e + off * (ELBOW_WIDTH / 2 + marker_radius))
        put(f"{side}_HME", e - off * (ELBOW_WIDTH / 2 + marker_radius))
        put(f"{side}_RSP", w + [0.02, 0, 0])
        put(f"{side}_USP", w - [0.02, 0, 0])
        put(f"{side}_HM2", w + [0.01, 0, -0.08])
    return lm


def without(lm: np.ndarray, *names: str) -> np.ndarray:
    out = lm.copy()
    for n in names:
        out[..., LANDMARK_INDEX[n], :] = np.nan
    return out

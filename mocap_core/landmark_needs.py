"""What each landmark is on the body, and which joints a set of landmarks cannot locate (with what would fix it).

Which joints a landmark set locates is asked of the localization itself, on a synthetic subject in T-pose
(mocap_core/rig.py) that has every landmark: the joints located with only the set's landmarks are what any take
of that set can give, and for each joint it cannot, the landmarks that alone would make it locatable are found
by trying each one. So the answer never drifts from what localization does.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from mocap_core.profiles import LANDMARK_INDEX, LANDMARKS
from mocap_core.skeleton import JOINTS

# Where each landmark is (the PAF running set's definitions, after Van Sint Jan's atlas).
SITES: dict[str, str] = {
    "SACR": "sacrum, midway between the posterior superior iliac spines",
    "IAS": "anterior superior iliac spine (front of the pelvis)",
    "TV12": "spinous process of the 12th thoracic vertebra",
    "TV2": "spinous process of the 2nd thoracic vertebra",
    "SME": "sternum, manubriosternal edge",
    "SGL": "glabella (forehead)",
    "HEAD": "side of the head, just above the ear",
    "SAE": "acromion, the shoulder's tip",
    "HLE": "humerus, lateral epicondyle (outside of the elbow)",
    "HME": "humerus, medial epicondyle (inside of the elbow)",
    "UOA": "ulna, olecranon (point of the elbow)",
    "RSP": "radius, styloid process (thumb side of the wrist)",
    "USP": "ulna, styloid process (little-finger side of the wrist)",
    "HM2": "head of the 2nd metacarpal (base of the forefinger)",
    "PAS": "above the patella, on the quadriceps tendon",
    "FLE": "femur, lateral epicondyle (outside of the knee)",
    "FME": "femur, medial epicondyle (inside of the knee)",
    "TTC": "tibial tuberosity (below the kneecap)",
    "FAL": "fibula, lateral malleolus (outside of the ankle)",
    "TAM": "tibia, medial malleolus (inside of the ankle)",
    "FCC": "calcaneus, at the Achilles tendon (heel)",
    "FM2": "head of the 2nd metatarsal (forefoot)",
}


# Joints that every solve but the thesis's places where no landmark locates them: the head on the neck, as the thesis's
# default skeleton has it (mocap_core.fit.calibration.default_head).
FOLLOW_THE_NECK = ("head", "head_top")


def site(landmark: str) -> str:
    stem = landmark.split("_", 1)[1] if landmark[:2] in ("L_", "R_") else landmark
    side = {"L_": "left ", "R_": "right "}.get(landmark[:2], "")
    return side + SITES[stem]


def _located(present: frozenset[str]) -> np.ndarray:
    from mocap_core.localization import Localizer
    from mocap_core.rig import t_pose_landmarks

    lm = t_pose_landmarks()
    keep = np.array([name in present for name in LANDMARKS])
    lm[~keep] = np.nan
    return Localizer().localize(lm).status[0] != 0


@lru_cache(maxsize=64)
def unlocatable(present: frozenset[str]) -> dict[str, list[tuple[str, ...]]]:
    """Joints that these landmarks cannot locate -> the absent landmarks any one of which would locate it, or
    failing that the pairs that would (empty when it takes more). Only joints the full landmark set locates."""
    full = _located(frozenset(LANDMARKS))
    got = _located(present)
    missing = [j for j in range(len(JOINTS)) if full[j] and not got[j]]
    if not missing:
        return {}
    fixes: dict[str, list[tuple[str, ...]]] = {JOINTS[j]: [] for j in missing}
    from mocap_core.rig import t_pose_landmarks

    modelled = np.isfinite(t_pose_landmarks()).all(axis=1)  # the synthetic subject lacks a few (UOA, PAS)
    available = [name for name in LANDMARKS if name not in present and modelled[LANDMARK_INDEX[name]]]
    for name in available:
        with_it = _located(present | {name})
        for j in missing:
            if with_it[j]:
                fixes[JOINTS[j]].append((name,))
    hard = [j for j in missing if not fixes[JOINTS[j]]]
    if hard:  # no one landmark does it: the pairs that do
        for k, a in enumerate(available):
            for b in available[k + 1:]:
                with_them = _located(present | {a, b})
                for j in hard:
                    if with_them[j]:
                        fixes[JOINTS[j]].append((a, b))
    return fixes


def describe_missing(fixes: dict[str, list[tuple[str, ...]]], shown: int = 3) -> list[str]:
    """One line per joint: 'knee_l: needs L_FLE (left femur, lateral epicondyle ...)', alternatives joined by or."""
    lines = []
    for joint, options in fixes.items():
        if not options:
            lines.append(f"{joint}: needs several landmarks more (`mocap profile explain` lists them)")
            continue
        said = [" and ".join(f"{n} ({site(n)})" for n in option) for option in options[:shown]]
        more = f" (or {len(options) - shown} other choices)" if len(options) > shown else ""
        lines.append(f"{joint}: needs " + " or ".join(said) + more)
    return lines


@lru_cache(maxsize=1)
def needed_by() -> dict[str, list[str]]:
    """Each landmark -> the joints that the full landmark set no longer locates without it."""
    full = frozenset(LANDMARKS)
    located = _located(full)
    out = {}
    for name in LANDMARKS:
        without = _located(full - {name})
        out[name] = [JOINTS[j] for j in range(len(JOINTS)) if located[j] and not without[j]]
    return out


def placed_by_subject(missing: dict[str, list], known: np.ndarray) -> tuple[list[str], dict[str, list]]:
    """Of the joints no landmark locates (``unlocatable``), those a calibrated subject knows (``known``: (J,) bool; its
    markers place them, as after a static trial) and the rest."""
    placed = [j for j in missing if known[JOINTS.index(j)]]
    return placed, {j: fixes for j, fixes in missing.items() if j not in placed}

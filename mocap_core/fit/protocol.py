"""The biomechanics protocol on a take (``mocap eval protocol``): a static trial calibrates the subject, movement trials
without the anatomical markers are solved with it, and the take's motion places the hips, knees and elbows.

From a take with every marker: its stillest second is the static trial (a standing subject sways, so "still" is every
marker within STILL_M of its mean); the movement trial is the take with the knee, ankle and elbow landmarks' markers
hidden from 1 s on (``landmarks_off``), with only the pelvis's markers and those no landmark names (``clusters``), or
with only the pelvis, head, hand and toe markers (``worst``, the thesis's worst case, as ``mocap eval rigid`` hides it),
and the worst case solved through the profile without the anatomical landmarks, as a movement trial's profile is
(``worst_movement``). Each is solved by the studio stages and by the fit, with the subject from the static trial and,
for comparison, from the complete take; the knees, ankles and elbows are measured against where the landmarks put them
in the complete take.
"""
from __future__ import annotations

import numpy as np

from mocap_core.experiments import localize_take
from mocap_core.fit.calibration import STILL_M, bone_of_each, calibrate, sway
from mocap_core.fit.compare import cases, solve
from mocap_core.fit.functional import functional_centres
from mocap_core.profiles import Profile
from mocap_core.recordings import Recording
from mocap_core.skeleton import INDEX


ANATOMICAL = ("HLE", "HME", "UOA", "FLE", "FME", "PAS", "TTC", "FAL", "TAM")
MEASURED = tuple(f"{j}_{s}" for j in ("knee", "ankle", "elbow") for s in "lr")
METHODS = ("studio_subject", "fit_subject")
VARIANTS = ("landmarks_off", "clusters", "worst", "worst_movement")
PELVIS = ("SACR", "L_IAS", "R_IAS")


def stillest_second(markers: np.ndarray, rate_hz: float) -> tuple[int, float]:
    """(first frame, its sway in metres: calibration.sway) of the take's stillest second with every marker seen."""
    n = max(1, int(round(rate_hz)))
    best = (-1, np.inf)
    for start in range(0, len(markers) - n + 1, max(1, n // 10)):
        window = markers[start:start + n]
        if np.isfinite(window).all():
            best = min(best, (start, sway(window)), key=lambda b: b[1])
    return best


def movement(markers: np.ndarray, profile: Profile, labels: list[str], variant: str, start: int) -> np.ndarray:
    """The take as a movement trial from ``start`` on: ``landmarks_off`` (the anatomical markers hidden), ``clusters``
    (only the pelvis's and the markers no landmark names: clusters, wands, tracking markers) or ``worst`` (only the
    pelvis, head, hand and toe markers; ``worst_movement`` too)."""
    col = list(profile.columns(labels))
    names = {n: lm for lm in profile.landmarks for n in profile.markers_of(lm)}
    if variant == "landmarks_off":
        hide = [k for k, x in enumerate(col) if names.get(x, "").rpartition("_")[2] in ANATOMICAL]
    elif variant == "clusters":
        hide = [k for k, x in enumerate(col) if x in names and names[x] not in PELVIS]
    else:
        worst = next(c for c in cases(profile, labels, start) if c.name == "worst")
        hide = [col.index(x) for x in worst.hidden]
    out = markers.copy()
    out[start:, hide] = np.nan
    return out


def without_anatomy(profile: Profile) -> Profile:
    """The profile of a movement trial: without the knee, ankle and elbow landmarks."""
    keep = {lm: v for lm, v in profile.landmarks.items() if lm.rpartition("_")[2] not in ANATOMICAL}
    return profile.model_copy(update={"name": f"{profile.name}_movement", "landmarks": keep})


def run_protocol(rec: Recording, profile: Profile) -> tuple[list[dict], list[dict]]:
    """(solve rows, functional-centre rows) for one take; no solve rows when it has no still second."""
    markers = rec.positions.astype(np.float64)
    located = localize_take(rec, profile)[0]
    complete = calibrate(markers, rec.labels, profile, rec.rate_hz)
    centres = []
    for found in functional_centres(markers, bone_of_each(profile, rec.labels, complete), INDEX, located):
        row = {"joint": found.joint, "found": not found.why, "why": found.why}
        if found.positions is not None:
            row["uncertainty_mm"] = float(found.centre.uncertainty_m.max() * 1000)
            row["from_landmarks_mm"] = found.apart_m(located, INDEX) * 1000
        centres.append(row)
    first, travel = stillest_second(markers, rec.rate_hz)
    if travel > STILL_M:  # (inf: no second sees every marker)
        return [{"static_s": float("nan"), "sway_mm": travel * 1000}], centres
    n = int(round(rec.rate_hz))
    static = calibrate(markers[first:first + n], rec.labels, profile, rec.rate_hz)
    rows = []
    for variant in VARIANTS:
        trial = movement(markers, profile, rec.labels, variant, n)
        through = without_anatomy(profile) if variant == "worst_movement" else profile
        for method in METHODS:
            for subject_from, subject in (("static", static), ("complete", complete)):
                pos = solve(method, trial, rec, through, subject)[0]
                row = {"static_s": first / rec.rate_hz, "sway_mm": travel * 1000, "variant": variant,
                       "method": method, "subject": subject_from,
                       "every_joint_pct": float(np.isfinite(pos[:, subject.known]).all(axis=(1, 2)).mean() * 100)}
                for j in MEASURED:
                    ok = np.isfinite(located[n:, INDEX[j]]).all(axis=1)
                    row[j] = float(np.nanmean(np.linalg.norm(pos[n:, INDEX[j]] - located[n:, INDEX[j]], axis=1)[ok])
                                   * 1000)
                rows.append(row)
    return rows, centres

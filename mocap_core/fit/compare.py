"""The thesis's method, the studio options and the fit side by side on one take (``mocap eval rigid``).

Each case hides markers (by label, so every method sees the same input) from a time on, solves the take
each way and measures the hidden joints against each way's solve of the complete take; with nothing
hidden it measures how much the bones' lengths wander. The fit calibrates from the same hidden take, as
``mocap solve --fit`` does; ``fit_subject`` is the studio's order, the subject calibrated first with every
marker seen (here: from the complete take, standing in for a range-of-motion take) and then fitted to the
hidden take, as ``mocap calibrate`` then ``mocap solve --fit --subject`` do; ``studio_subject`` the studio options
with that subject's bones, as ``mocap calibrate`` then ``mocap solve --subject`` (and a graph's ``subject`` param).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mocap_core.experiments import localize_take, real_gap_moves
from mocap_core.fit.subject import Subject
from mocap_core.fit.take import fit_take
from mocap_core.pipeline import SkeletonPipeline
from mocap_core.profiles import Profile
from mocap_core.recordings import Recording
from mocap_core.skeleton import INDEX, PARENT_INDEX

METHODS = ("thesis", "studio", "studio_subject", "fit", "fit_subject")
# The studio options lean on the profile's ``tracking:`` markers; the fit finds every marker's bone by itself.
NO_TRACKING = "studio_no_tracking"
# What the thesis's worst case keeps (thesis 4.3): the pelvis, head, hand and toe markers.
WORST_CASE_LANDMARKS = ("SACR", "L_IAS", "R_IAS", "SGL", "L_HEAD", "R_HEAD", "L_HM2", "R_HM2", "L_FM2", "R_FM2")
HIDE_LANDMARKS = {"elbow": ("HLE", "HME"), "knee_ankle": ("FLE", "FME", "TTC", "FAL", "TAM")}
MEASURED = {"elbow": ("elbow",), "knee_ankle": ("knee", "ankle")}
LIMB_BONES = tuple(INDEX[f"{j}_{s}"] for s in "lr" for j in ("elbow", "wrist", "hand", "knee", "ankle", "foot", "toe"))


@dataclass
class Case:
    name: str                 # all, worst, elbow_l, knee_ankle_r, ...
    hidden: list[str]         # labels hidden from ``start`` on
    measured: list[str]       # joints measured against the reference
    start: int


def cases(profile: Profile, labels: list[str], start: int) -> list[Case]:
    """The cases every take gets: nothing hidden, the thesis's worst case, each elbow, each knee and ankle."""
    clean = list(profile.columns(labels))

    def labels_of(landmarks):
        return sorted({n for lm in landmarks if lm in profile.landmarks for n in profile.markers_of(lm)})

    kept = set(labels_of(WORST_CASE_LANDMARKS))
    out = [Case("all", [], [], start),
           Case("worst", [x for x in clean if x not in kept], ["elbow_l", "elbow_r", "knee_l", "knee_r"], start)]
    for kind, names in HIDE_LANDMARKS.items():
        for side in "lr":
            hidden = labels_of([f"{side.upper()}_{n}" for n in names])
            if hidden:
                out.append(Case(f"{kind}_{side}", hidden, [f"{j}_{side}" for j in MEASURED[kind]], start))
    return out


def solve(method: str, markers: np.ndarray, rec: Recording, profile: Profile, subject: Subject | None = None):
    """(positions (F, J, 3), status (F, J), residual RMS per frame or None) of one method; ``subject``: the
    calibrated subject that ``fit_subject`` fits and whose bones ``studio_subject``'s rigid chains keep."""
    if method.startswith("fit"):
        chunk, residual, _ = fit_take(markers, rec.labels, profile, rec.rate_hz, subject)
        return chunk.positions, chunk.status, residual
    if method == NO_TRACKING:
        method, profile = "studio", profile.model_copy(update={"tracking": {}})
    pipe = SkeletonPipeline(profile, rec.labels, options=method.removesuffix("_subject"), rate_hz=rec.rate_hz)
    if subject is not None:
        pipe.use(subject)
    chunks = list(pipe.run(markers))
    return np.concatenate([c.positions for c in chunks]), np.concatenate([c.status for c in chunks]), None


def bone_lengths(positions: np.ndarray) -> np.ndarray:
    """(F, bones) the limb bones' lengths, NaN where an end is missing."""
    return np.linalg.norm(positions[:, LIMB_BONES] - positions[:, PARENT_INDEX[list(LIMB_BONES)]], axis=-1)


@dataclass
class Reference:
    positions: dict[str, np.ndarray]   # each method's solve of the complete take
    subject: Subject                   # calibrated from the complete take


def references(rec: Recording, profile: Profile) -> Reference:
    """Each method's solve of the complete take: the localization for the thesis's method (nothing to fill), the
    studio options' (their rigid chains move located joints onto the subject's bones), the fit calibrated on the
    complete take for the fit."""
    located = localize_take(rec, profile)[0]
    markers = rec.positions.astype(np.float64)
    studio = solve("studio", markers, rec, profile)[0]
    chunk, _, subject = fit_take(rec.positions, rec.labels, profile, rec.rate_hz)
    return Reference({"thesis": located, "studio": studio, NO_TRACKING: studio,
                      "studio_subject": solve("studio_subject", markers, rec, profile, subject)[0],
                      "fit": chunk.positions, "fit_subject": chunk.positions}, subject)


def run_case(case: Case, rec: Recording, profile: Profile, reference: Reference):
    """One row per method: hidden joints' mean / max error (mm) against the method's own solve of the complete
    take, and against the localization's (``loc_``); bone-length CV (%) and largest deviation from the bone's
    own median length (%); the fit's marker residual RMS (mm); and the share of hidden frames estimated."""
    markers = rec.positions.astype(np.float64)
    col = list(profile.columns(rec.labels))
    hide = [col.index(x) for x in case.hidden]
    markers[case.start:, hide] = np.nan
    rows = []
    # with nothing hidden the subject's fit is the fit
    methods = tuple(m for m in METHODS if case.hidden or not m.endswith("_subject"))
    methods += (NO_TRACKING,) if case.name.startswith("elbow") and profile.tracking else ()
    for method in methods:
        subject = reference.subject if method.endswith("_subject") else None
        pos, status, residual = solve(method, markers, rec, profile, subject)
        row = {"case": case.name, "method": method}
        lengths = bone_lengths(pos)
        with np.errstate(invalid="ignore", divide="ignore"):
            med = np.nanmedian(lengths, axis=0)
            row["bone_cv_pct"] = float(np.nanmean(np.nanstd(lengths, axis=0) / med) * 100)
            row["bone_dev_max_pct"] = float(np.nanmax(np.abs(lengths / med - 1)) * 100)
        row["residual_mm"] = float(np.nanmean(residual) * 1000) if residual is not None else float("nan")
        if case.measured:
            j = [INDEX[n] for n in case.measured]
            for prefix, ref in (("", reference.positions[method]), ("loc_", reference.positions["thesis"])):
                err = np.linalg.norm(pos[case.start:, j] - ref[case.start:, j], axis=-1) * 1000
                ok = np.isfinite(ref[case.start:, j]).all(axis=-1)
                row["estimated_pct"] = float(np.isfinite(err[ok]).mean() * 100)
                row[prefix + "mean_mm"] = float(np.nanmean(err[ok]))
                row[prefix + "max_mm"] = float(np.nanmax(err[ok]))
        if not case.hidden:  # the take's own gaps: a whole skeleton every frame, and no twitch where they begin or end
            known = np.isfinite(reference.positions[method]).all(axis=2).any(axis=0)
            row["complete_pct"] = float(np.isfinite(pos[:, known]).all(axis=2).all(axis=1).mean() * 100)
            moves = real_gap_moves(pos, status).row()
            row["changes_over_1_5"], row["changes_max"] = moves["paced_over_1_5"], moves["paced_max"]
        rows.append(row)
    return rows

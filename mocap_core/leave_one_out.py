"""What each studio option adds (``mocap eval options``): the studio options solved with each left out in turn, on
the cases a studio's occlusions make, the hidden joints measured against the studio options' own solve of the complete
take (their rigid chains move located joints too, as ``mocap eval rigid`` measures them).

An option is worth keeping where leaving it out makes some case on some take worse by more than ``KEEP_MM``.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from mocap_core.experiments import landmarks_of
from mocap_core.fit.compare import cases as rigid_cases, solve
from mocap_core.fill_options import FillOptions, HipOptions
from mocap_core.pipeline import SkeletonPipeline
from mocap_core.presets import PRESETS, Options
from mocap_core.profiles import Profile
from mocap_core.recordings import Recording
from mocap_core.skeleton import INDEX

KEEP_MM = 5.0
STUDIO = "studio"


def _off(field) -> object:
    """An option as the thesis leaves it: a switch off, a setting at zero, a choice at its default."""
    return {bool: False, float: 0.0}.get(field.annotation, field.default)


# Each option as the thesis leaves it; one that others steer is left out with them (STEERED_BY).
LEFT_OUT = {name: (stage, _off(field)) for stage, model in (("hips", HipOptions), ("ik", FillOptions))
            for name, field in model.model_fields.items()}
STEERED_BY = {need: {fill.option(): False for fill in FillOptions.fills if fill.needs == need}
              for need in {fill.needs for fill in FillOptions.fills if fill.needs}}


def without(option: str) -> Options:
    """The studio options with ``option`` off (``studio``: all on)."""
    studio = PRESETS[STUDIO]
    if option == STUDIO:
        return studio
    stage, value = LEFT_OUT[option]
    if stage == "hips":
        return replace(studio, hips=HipOptions(**{**studio.hips.model_dump(), option: value}))
    extra = STEERED_BY.get(option, {})
    return replace(studio, ik=FillOptions(**{**studio.ik.model_dump(), option: value, **extra}))


@dataclass
class Case:
    name: str               # elbow_l, short_elbow_l, arm_l, knee_ankle_l, worst, pelvis
    hidden: list[str]       # labels
    measured: list[str]     # joints
    frames: np.ndarray      # (F,) bool: the frames they are hidden in


def _every(n: int, start: int, length: int, period: int) -> np.ndarray:
    out = np.zeros(n, bool)
    for s in range(start, n, period):
        out[s:s + length] = True
    return out


def cases(profile: Profile, rec: Recording) -> list[Case]:
    """From 1 s on: each elbow hidden to the end, and 0.1 s in every 0.5 s; each arm (elbow, wrist and hand) lost 1 s
    in every 2 s; each knee with its ankle hidden to the end; the thesis's worst case; the pelvis lost 1 s in every
    2 s."""
    col = set(profile.columns(rec.labels))
    n, rate = rec.n_frames, rec.rate_hz
    start = int(round(rate))

    def labels(landmarks):
        return sorted({x for lm in landmarks if lm in profile.landmarks for x in profile.markers_of(lm)} & col)

    def every(length_s, period_s):
        return _every(n, start, int(round(length_s * rate)), int(round(period_s * rate)))

    out = []
    for c in rigid_cases(profile, rec.labels, start):
        if not c.hidden:
            continue
        to_end = np.arange(n) >= start
        out.append(Case(c.name, c.hidden, c.measured, to_end))
        if c.name.startswith("elbow"):
            side = c.name[-1]
            out.append(Case(f"short_{c.name}", c.hidden, c.measured, every(0.1, 0.5)))
            arm = [f"{j}_{side}" for j in ("elbow", "wrist", "hand")]
            out.append(Case(f"arm_{side}", labels([lm for j in arm for lm in landmarks_of(j)]), arm, every(1.0, 2.0)))
    out.append(Case("pelvis", labels(landmarks_of("pelvis")), ["pelvis", "spine0", "hip_l", "hip_r"], every(1.0, 2.0)))
    return out


def reference(rec: Recording, profile: Profile) -> np.ndarray:
    """The studio options' solve of the complete take (F, J, 3): what the hidden joints are measured against."""
    return solve(STUDIO, rec.positions.astype(np.float64), rec, profile)[0]


def score(rec: Recording, profile: Profile, options: list[str],
          complete: np.ndarray | None = None) -> dict[str, dict[str, float]]:
    """{option: {case: mean mm of the hidden joints}} on one take (``studio``: every option on); ``complete``: the
    take's ``reference``, if already solved."""
    complete = reference(rec, profile) if complete is None else complete
    col = list(profile.columns(rec.labels))
    out = {}
    for option in options:
        out[option] = {}
        for case in cases(profile, rec):
            markers = rec.positions.astype(np.float64)
            markers[np.ix_(case.frames, [col.index(x) for x in case.hidden])] = np.nan
            pipe = SkeletonPipeline(profile, rec.labels, rate_hz=rec.rate_hz, options=without(option))
            pos = np.concatenate([c.positions for c in pipe.run(markers)])
            j = [INDEX[x] for x in case.measured]
            err = np.linalg.norm(pos[case.frames][:, j] - complete[case.frames][:, j], axis=-1) * 1000
            seen = np.isfinite(complete[case.frames][:, j]).all(axis=-1)
            out[option][case.name] = float(np.nanmean(err[seen]))
    return out

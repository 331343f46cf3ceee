"""Marker-set profiles: map the landmarks that localization uses onto a recording's labels.

A profile is a YAML file (see profiles/*.yaml and the README's "Your own marker set"):

```yaml
name: cmu41
description: CMU 41-marker Vicon set
up_axis: z              # the vertical axis (+z, -y, ...) of recordings that do not say it themselves
strip_prefixes: true    # "male:LFWT" -> "LFWT" (actor/subject prefixes)
landmarks:              # PAF landmark -> one label, or mean(A, B, ...)
  SACR: mean(LBWT, RBWT)
  L_IAS: LFWT
tracking:               # optional: markers on one bone that no landmark names (clusters, wands)
  L_forearm: [LFRM]     # they help rebuild that bone's lost landmarks (hip_interpolation rebuild)
body:                   # measurements the fallbacks need (defaults shown)
  height_cm: null       # null = estimate from the markers
  elbow_width_mm: 70
```

Resolving a profile against a label list gives a :class:`LandmarkMap`, which turns a marker array
(frames x labels x 3) into landmark positions (frames x landmarks x 3) with one gather.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from mocap_core.world import DEFAULT_UP, normalize_up

SIDES = ("L", "R")
_SIDED = ("SAE", "HLE", "HME", "UOA", "RSP", "USP", "HM2", "PAS", "FLE", "FME", "TTC", "FAL", "TAM", "FCC", "FM2",
          "HEAD")
LANDMARKS: tuple[str, ...] = ("SACR", "L_IAS", "R_IAS", "TV12", "TV2", "SME", "SGL") + tuple(
    f"{side}_{name}" for name in _SIDED for side in SIDES)
LANDMARK_INDEX = {name: i for i, name in enumerate(LANDMARKS)}
# Bones whose extra markers a profile may list under ``tracking`` (mocap_core.segment_rebuild uses them).
TRACKING_BONES = ("upper_arm", "forearm", "thigh", "shank", "foot")
TRACKING_SEGMENTS: tuple[str, ...] = tuple(f"{side}_{bone}" for bone in TRACKING_BONES for side in SIDES)
# The body segment each landmark and tracking segment sits on, as the skeleton's bones (a bone is named after the joint
# it starts from: the shank is ``knee``), for a calibration that places markers on bones: the epicondyles are on the
# femur though they locate the knee, the malleoli on the shank though they locate the ankle. The foot is two bones of
# one segment, the trunk several; the spine's landmarks are left to the data.
SEGMENT_BONES = {"pelvis": ("pelvis",), "head": ("head",), "scapula": ("clavicle",), "upper_arm": ("shoulder",),
                 "forearm": ("elbow",), "hand": ("wrist",), "thigh": ("hip",), "shank": ("knee",),
                 "foot": ("ankle", "foot")}
LANDMARK_SEGMENT = {"SACR": "pelvis", "IAS": "pelvis", "SGL": "head", "HEAD": "head", "SAE": "scapula",
                    "HLE": "upper_arm", "HME": "upper_arm", "UOA": "forearm", "RSP": "forearm", "USP": "forearm",
                    "HM2": "hand", "FLE": "thigh", "FME": "thigh", "PAS": "shank", "TTC": "shank", "FAL": "shank",
                    "TAM": "shank", "FCC": "foot", "FM2": "foot"}
PROFILE_DIR = Path(__file__).resolve().parents[1] / "profiles"
_MEAN = re.compile(r"^mean\((.*)\)$")


class ProfileError(Exception):
    pass


class BodyMeasurements(BaseModel):
    """Subject measurements; None means "estimate from the markers" (facts 7.3)."""

    model_config = ConfigDict(extra="forbid")
    height_cm: float | None = Field(None, gt=50, lt=250)
    mass_kg: float | None = Field(None, gt=10, lt=300)
    marker_diameter_mm: float = Field(14.0, gt=0, lt=50)
    elbow_width_mm: float = Field(70.0, gt=0, lt=200)
    knee_width_mm: float = Field(100.0, gt=0, lt=250)
    ankle_width_mm: float = Field(70.0, gt=0, lt=200)


class Profile(BaseModel):
    model_config = ConfigDict(extra="forbid")
    name: str
    description: str = ""
    up_axis: str = DEFAULT_UP  # for recordings that do not say it (QTM and bags do)
    strip_prefixes: bool = True
    landmarks: dict[str, str]
    tracking: dict[str, list[str]] = {}  # segment (L_forearm, ...) -> labels of markers on that bone
    body: BodyMeasurements = BodyMeasurements()
    source_file: str = ""
    lines: dict[str, int] = {}  # landmark -> line in the YAML file, for error messages
    drafted: bool = False       # guessed from a recording's labels, not written (profile_for)

    @field_validator("up_axis")
    @classmethod
    def _up(cls, v: str) -> str:
        return normalize_up(v)

    @field_validator("landmarks")
    @classmethod
    def _one_marker_wrists(cls, v: dict[str, str]) -> dict[str, str]:
        """A set with one marker at a wrist (many running and gait sets) gives the wrist there: the styloid it lacks
        stands where the other is, so the forearm and hand are located (about half a wrist's width off its centre)."""
        out = dict(v)
        for side in SIDES:
            pair = (f"{side}_RSP", f"{side}_USP")
            have = [lm for lm in pair if lm in v]
            if len(have) == 1:
                out[pair[0] if have[0] == pair[1] else pair[1]] = v[have[0]]
        return out

    def where(self, landmark: str | None = None) -> str:
        line = self.lines.get(landmark) if landmark else None
        return f"profile {Path(self.source_file).name or self.name}" + (f" line {line}" if line else "")

    def columns(self, labels: list[str]) -> dict[str, int]:
        """A recording's labels as the profile names them (prefixes stripped if it says so) -> their columns.
        Several actors in one stream (their labels "actor1:LASI", "actor2:LASI") are refused: one skeleton is
        solved per stream."""
        if self.strip_prefixes:
            one_actor(labels)
        return {strip_prefix(x) if self.strip_prefixes else x: i for i, x in enumerate(labels)}

    def markers_of(self, landmark: str) -> list[str]:
        """The labels a landmark is the mean of (one for most)."""
        return parse_expression(self.landmarks[landmark], self.where(landmark))

    def marker_bones(self, labels: list[str]) -> list[tuple[str, ...]]:
        """For each label, the bones (joint names) of the body segment the profile puts it on: its landmark's
        (SEGMENT_BONES, LANDMARK_SEGMENT) or its tracking segment's; () for a marker the profile places nowhere."""
        where: dict[str, tuple[str, ...]] = {}
        for segment, names in self.tracking.items():
            side, _, part = segment.partition("_")
            for n in names:
                where[n] = tuple(f"{b}_{side.lower()}" for b in SEGMENT_BONES[part])
        for landmark in self.landmarks:
            side, _, name = landmark.rpartition("_")
            segment = LANDMARK_SEGMENT.get(name)
            if segment is None:
                continue
            bones = SEGMENT_BONES[segment]
            if segment not in ("pelvis", "head"):  # the others are a side's
                bones = tuple(f"{b}_{side.lower()}" for b in bones)
            for n in self.markers_of(landmark):
                where[n] = bones
        return [where.get(label, ()) for label in self.columns(labels)]

    def resolve(self, labels: list[str]) -> "LandmarkMap":
        index = self.columns(labels)
        clean = list(index)
        rows = []
        for landmark in self.landmarks:
            names = self.markers_of(landmark)
            missing = [n for n in names if n not in index]
            if missing:
                shown = ", ".join(clean[:60]) + (" ..." if len(clean) > 60 else "")
                raise ProfileError(f"{self.where(landmark)}: label {missing[0]} of {landmark} is not in the "
                                   f"recording (labels: {shown})")
            rows.append((LANDMARK_INDEX[landmark], [index[n] for n in names]))
        # Tracking markers only help: one the recording lacks is left out (and named), not an error.
        tracking = [(segment, index[n]) for segment, names in self.tracking.items() for n in names if n in index]
        absent = tuple(n for names in self.tracking.values() for n in names if n not in index)
        return LandmarkMap.build(rows, n_labels=len(labels), tracking=tracking, absent_tracking=absent)


def one_actor(labels: list[str]) -> None:
    several = actors(labels)
    if len(several) > 1:
        raise ProfileError(f"the stream holds {len(several)} actors ({', '.join(several)}), and this pipeline solves "
                           f"one: list them in the launch file's actors: (launch/qtm_actors.yaml) for a pipeline "
                           f"each")


def actors(labels: list[str]) -> list[str]:
    """The subject prefixes ("actor1:" ...) whose labels name the same markers as another prefix's."""
    by_prefix: dict[str, set[str]] = {}
    for label in labels:
        if ":" in label:
            by_prefix.setdefault(actor_of(label), set()).add(strip_prefix(label))
    shared = [p for p in by_prefix if any(len(by_prefix[p] & by_prefix[q]) >= 3 for q in by_prefix if q != p)]
    return sorted(shared)


def strip_prefix(label: str) -> str:
    return label.rsplit(":", 1)[-1].strip()


def actor_of(label: str) -> str:
    """The subject a label belongs to ("actor1:LASI" -> "actor1"; "" without a prefix)."""
    prefix, sep, _ = label.rpartition(":")
    return prefix.strip() if sep else ""


def parse_expression(expr: str, where: str) -> list[str]:
    expr = str(expr).strip()
    m = _MEAN.match(expr)
    names = [n.strip() for n in m.group(1).split(",")] if m else [expr]
    if not all(names) or any(re.search(r"[(),]", n) for n in names):
        raise ProfileError(f"{where}: bad expression {expr!r}: use one label or mean(A, B, ...)")
    return names


@dataclass
class LandmarkMap:
    """Landmark i = mean of markers idx[i, :count[i]]; landmarks the profile lacks stay NaN. The
    profile's tracking markers are kept apart: ``tracking_idx`` are their labels, ``tracking_of``
    the segment of each."""

    idx: np.ndarray     # (n_landmarks, k) int; padding points at the all-zero row appended at n_labels
    count: np.ndarray   # (n_landmarks,) float; 0 for an absent landmark
    n_labels: int
    tracking_idx: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    tracking_of: tuple[str, ...] = ()
    absent_tracking: tuple[str, ...] = ()  # the profile's tracking markers this recording lacks

    @classmethod
    def build(cls, rows: list[tuple[int, list[int]]], n_labels: int,
              tracking: list[tuple[str, int]] = (), absent_tracking: tuple[str, ...] = ()) -> "LandmarkMap":
        k = max((len(r) for _, r in rows), default=1)
        idx = np.full((len(LANDMARKS), k), n_labels, np.int64)
        count = np.zeros(len(LANDMARKS))
        for li, markers in rows:
            idx[li, : len(markers)] = markers
            count[li] = len(markers)
        return cls(idx, count, n_labels, np.array([i for _, i in tracking], np.int64),
                   tuple(segment for segment, _ in tracking), absent_tracking)

    def tracking(self, markers: np.ndarray) -> np.ndarray:
        """markers (..., n_labels, 3) -> the tracking markers (..., n_tracking, 3), float64."""
        return np.ascontiguousarray(markers[..., self.tracking_idx, :], dtype=np.float64)

    def present(self) -> set[str]:
        return {LANDMARKS[i] for i in np.flatnonzero(self.count)}

    def apply(self, markers: np.ndarray) -> np.ndarray:
        """markers (..., n_labels, 3) -> landmarks (..., n_landmarks, 3), float64."""
        if markers.shape[-2] != self.n_labels:
            raise ProfileError(f"frame has {markers.shape[-2]} markers, the profile was resolved for {self.n_labels}")
        from mocap_core.landmark_means import means  # (numba: loaded by what maps frames, not by what reads profiles)

        frames = np.ascontiguousarray(markers, np.float64).reshape(-1, self.n_labels, 3)
        out = np.empty((len(frames), len(self.count), 3))
        means(frames, self.idx, self.count, out)
        return out.reshape(markers.shape[:-2] + out.shape[1:])


def load_profile(name_or_path: str | Path) -> Profile:
    """A profile by path, or by name from the repository's profiles/ folder."""
    path = Path(name_or_path)
    if not path.exists() and not path.suffix:
        path = PROFILE_DIR / f"{name_or_path}.yaml"
    if not path.exists():
        known = ", ".join(shipped())
        raise ProfileError(f"profile {name_or_path!r} not found (shipped profiles: {known})")
    text = path.read_text()
    try:
        raw = yaml.safe_load(text)
        node = yaml.compose(text)
    except yaml.YAMLError as e:
        raise ProfileError(f"profile {path.name}: not valid YAML ({e})") from None
    if not isinstance(raw, dict):
        raise ProfileError(f"profile {path.name}: expected a mapping with name and landmarks")
    lines = {}
    for key, value in node.value:
        if key.value == "landmarks" and isinstance(value, yaml.MappingNode):
            lines = {k.value: k.start_mark.line + 1 for k, _ in value.value}
    raw.setdefault("name", path.stem)
    try:
        profile = Profile.model_validate({**raw, "source_file": str(path), "lines": lines})
    except ValidationError as e:
        err = e.errors()[0]
        raise ProfileError(f"profile {path.name}: {'.'.join(map(str, err['loc']))}: {err['msg']}") from None
    for landmark in profile.landmarks:
        if landmark not in LANDMARK_INDEX:
            raise ProfileError(f"{profile.where(landmark)}: unknown landmark {landmark!r} "
                               f"(landmarks: {', '.join(LANDMARKS)})")
        profile.markers_of(landmark)  # a bad expression is an error when the profile is loaded
    for segment in profile.tracking:
        if segment not in TRACKING_SEGMENTS:
            raise ProfileError(f"{profile.where()}: unknown tracking segment {segment!r} "
                               f"(segments: {', '.join(TRACKING_SEGMENTS)})")
    return profile


AUTO = "auto"


PROFILE_HELP = ("marker-set profile: a name from profiles/ or a YAML path (default auto: the shipped one the "
                "labels fit)")


def profile_for(name_or_path: str | None, labels: list[str], log=None) -> Profile:
    """``load_profile``, or with "auto" (or None) the shipped profile these labels fit (``detect_profile``),
    named in ``log`` when given."""
    if name_or_path not in (AUTO, None):
        return load_profile(name_or_path)
    one_actor(labels)
    profile = detect_profile(labels)
    if profile is not None:
        if log is not None:
            log.info("profile auto: %s fits the labels (another: --profile NAME or a YAML path)", profile.name)
        return profile
    profile = drafted_profile(labels)
    if profile is None:
        shown = ", ".join(labels[:30]) + (" ..." if len(labels) > 30 else "")
        raise ProfileError(f"no shipped profile fits these labels ({shown}; shipped: {', '.join(shipped())}) and no "
                           f"landmark could be guessed from them: draft one with `mocap profile init TAKE -o "
                           f"myset.yaml`, fill it in (README, 'Your own marker set') and give --profile myset.yaml")
    if log is not None:
        from mocap_core.landmark_needs import describe_missing, unlocatable

        log.warning("no shipped profile fits these labels: solving with one drafted from them, %d landmarks (%s); "
                    "`mocap profile init TAKE -o myset.yaml` writes it down to check and edit, then --profile "
                    "myset.yaml", len(profile.landmarks), ", ".join(profile.landmarks))
        for line in describe_missing(unlocatable(frozenset(profile.landmarks))):
            log.warning("the draft cannot locate %s", line)
    return profile


def drafted_profile(labels: list[str]) -> Profile | None:
    """A profile drafted from the labels by the common naming conventions (mocap_core.profile_draft), if any landmark
    is found and it resolves against them."""
    from mocap_core.profile_draft import draft

    landmarks = draft([strip_prefix(x) for x in labels])[0]
    if not landmarks:
        return None
    profile = Profile(name="draft", description="drafted from the labels", landmarks=landmarks, drafted=True)
    try:
        profile.resolve(labels)
    except ProfileError:
        return None
    return profile


def shipped() -> list[str]:
    """The names of the profiles that come with the project (profiles/)."""
    return sorted(p.stem for p in PROFILE_DIR.glob("*.yaml"))


def detect_profile(labels: list[str]) -> Profile | None:
    """The shipped profile that fits these labels: of those whose every landmark is in the stream, the
    one that uses the most labels. None when no shipped profile fits."""
    best, best_used = None, 0
    for name in shipped():
        profile = load_profile(name)
        try:
            profile.resolve(labels)
        except ProfileError:
            continue
        index = profile.columns(labels)
        used = len({n for lm in profile.landmarks for n in profile.markers_of(lm)}
                   | {n for names in profile.tracking.values() for n in names if n in index})
        if used > best_used:
            best, best_used = profile, used
    return best

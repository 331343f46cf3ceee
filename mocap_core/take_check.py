"""What a take's markers do wrong, before anything is solved: how long each one is lost, and where the markers of
one bone stop keeping their spacing (a label swapped, a ghost, a marker that slid or stands still).

Markers on one rigid bone keep their distances to within skin motion (a few per cent). Where a pair's distance is off
its usual one (the take's median) by more than ``TOLERANCE`` of it, and by ``FLOOR_M`` at least, one of the two is
not where its label says: the gap fills, which trust what is seen, cannot do better than that marker there. Which
markers share a bone comes from the segment rebuild's table (segment_rebuild.SEGMENTS, the profile's tracking markers
of that bone) and the pelvis's three landmarks.

On the shared recordings it finds toe markers off their spacing for seconds, a toe marker standing still and a
wrist marker elsewhere on the forearm than later (`mocap check TAKE` says where). The thresholds were chosen on
every shared recording together.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mocap_core.profiles import Profile
from mocap_core.segment_rebuild import SEGMENTS, segment_landmark, tracking_segment

TOLERANCE = 0.25  # a pair is off where its distance is off the usual one by more than this part of it,
FLOOR_M = 0.015   # and by this much at least (skin moves a few millimetres on a short pair of markers)
MERGE_S = 0.1     # stretches off closer than this are one
PELVIS = ("pelvis", ("SACR", "L_IAS", "R_IAS"), "")


@dataclass(frozen=True)
class Pair:
    bone: str  # "L_foot", "pelvis", ...
    a: str     # marker labels, as the profile names them (prefixes stripped)
    b: str
    ia: int    # their columns in the recording
    ib: int


@dataclass(frozen=True)
class Stretch:
    """Where a pair is off its usual spacing."""

    pair: Pair
    usual_m: float
    start_s: float
    end_s: float
    frames: int     # frames off within it
    low_m: float    # the spacing's range within it
    high_m: float


@dataclass(frozen=True)
class MarkerGaps:
    label: str
    lost: int        # frames
    gaps: int        # how many stretches
    longest_s: float


def bone_markers(profile: Profile, labels: list[str]) -> dict[str, list[str]]:
    """Each bone's markers the recording has (two at least), as the profile names them: its landmarks' markers and
    the profile's tracking markers of it."""
    column = profile.columns(labels)
    groups = [(_bone_name(side, bone, names + partners), [segment_landmark(side, name) for name in names + partners],
               tracking_segment(side, bone)) for side in "LR" for bone, names, partners in SEGMENTS]
    groups.append(PELVIS)
    out = {}
    for bone, landmarks, tracking in groups:
        markers = [m for lm in landmarks if lm in profile.landmarks for m in profile.markers_of(lm)]
        markers += profile.tracking.get(tracking, [])
        markers = [m for m in dict.fromkeys(markers) if m in column]
        if len(markers) >= 2 and bone not in out:  # (the thorax comes twice)
            out[bone] = markers
    return out


def rigid_pairs(profile: Profile, labels: list[str]) -> list[Pair]:
    """Every pair of markers on one bone, each pair once (the first bone that has it)."""
    column = profile.columns(labels)
    pairs, seen = [], set()
    for bone, markers in bone_markers(profile, labels).items():
        for i, a in enumerate(markers):
            for b in markers[i + 1:]:
                if frozenset((a, b)) not in seen:
                    seen.add(frozenset((a, b)))
                    pairs.append(Pair(bone, a, b, column[a], column[b]))
    return pairs


def spacing_faults(positions: np.ndarray, pairs: list[Pair], rate_hz: float) -> list[Stretch]:
    """The stretches where each pair is off its usual spacing, in time order per pair."""
    out = []
    for pair in pairs:
        d = np.linalg.norm(positions[:, pair.ia] - positions[:, pair.ib], axis=1)
        seen = np.isfinite(d)
        if not seen.any():
            continue
        usual = float(np.median(d[seen]))
        off = np.flatnonzero(seen & (np.abs(d - usual) > max(TOLERANCE * usual, FLOOR_M)))
        for run in _runs(off, max(1, round(MERGE_S * rate_hz))):
            within = d[run[0]:run[-1] + 1]
            out.append(Stretch(pair, usual, run[0] / rate_hz, run[-1] / rate_hz, len(run),
                               float(np.nanmin(within)), float(np.nanmax(within))))
    return out


def marker_gaps(positions: np.ndarray, markers: dict[str, int], rate_hz: float) -> list[MarkerGaps]:
    """How long each marker (label -> column) is lost, the longest gap first."""
    out = []
    for label, c in markers.items():
        lost = np.flatnonzero(~np.isfinite(positions[:, c]).all(axis=1))
        runs = _runs(lost, 1)
        out.append(MarkerGaps(label, len(lost), len(runs), max((len(r) for r in runs), default=0) / rate_hz))
    return sorted(out, key=lambda g: (-g.longest_s, -g.lost, g.label))


def used_markers(profile: Profile, labels: list[str]) -> dict[str, int]:
    """The markers the profile uses (its landmarks' and tracking markers) that the recording has: label -> column."""
    column = profile.columns(labels)
    names = [m for lm in profile.landmarks for m in profile.markers_of(lm)]
    names += [m for markers in profile.tracking.values() for m in markers]
    return {m: column[m] for m in dict.fromkeys(names) if m in column}


def _bone_name(side: str, bone: str, names: tuple[str, ...]) -> str:
    """A bone's name in the report, "L_foot"; the thorax, whose segment takes both acromia on either side, is one
    bone: "thorax"."""
    return bone if any(name.startswith("other ") for name in names) else f"{side}_{bone}"


def _runs(frames: np.ndarray, join: int) -> list[np.ndarray]:
    """Sorted frame numbers in runs: a frame more than ``join`` after the one before begins a new run."""
    if len(frames) == 0:
        return []
    return np.split(frames, np.flatnonzero(np.diff(frames) > join) + 1)

"""Calibrating a subject from a take's or a stream's own frames, without a calibration pose.

The thesis's localization (mocap_core.localization) locates joints and bone frames from the profile's
landmarks in every frame where they are seen. Over many such frames, robustly (medians):
- each joint's offset in its parent's bone frame, hence every bone's length; left and right bones get
  their mean length where both sides are seen;
- for every labelled marker, landmark or not, the bone it moves rigidly with: the bone in whose frame it
  strays least (the 90th percentile of its distance from its median offset there), and that offset. A marker that moves
  with no bone (a prop, the floor, a marker that slides) is left unassigned.
The profile's landmarks only seed the bone frames; every other marker (clusters, wands, extra markers)
is found from the data, so a profile needs no ``tracking:`` list for the fit. A static trial (every marker still)
cannot tell the bones near a marker apart by its stray: there the profile's anatomy says which it rides.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numba import njit

from mocap_core.fit.subject import Subject
from mocap_core.ik.kernels import mtv
from mocap_core.localization import Localizer
from mocap_core.profiles import Profile
from mocap_core.skeleton import END_SITES, INDEX, JOINTS, LOCATED, PARENT_INDEX


@dataclass
class CalibrationSettings:
    max_frames: int = 3000          # frames spread evenly over the input are enough for medians
    min_frames: int = 20            # a bone or marker seen in fewer frames is not calibrated
    max_spread_m: float = 0.04      # a marker straying more than this on its best bone rides no bone
    symmetric: bool = True          # left and right bones of one length where both are seen
    refinements: int = 1            # rounds of markers re-placed on the fitted bone frames


# A take whose every marker stays this close to its mean place is a static trial (a standing subject sways).
STILL_M = 0.03
# A marker's stray on a bone: how far from its median place it is in this share of the frames. Not the median:
# a static marker (a starting block) rides a limb that rests on it for half the take.
STRAY_PERCENTILE = 90
ROTATING = np.array([j not in END_SITES for j in JOINTS])
# Where no marker locates the head: above the neck as the thesis's default skeleton has it (H-Anim: the head 0.120 m
# from the neck and its top 0.08 m above it, on a spine of 0.421 m from spine0 to spine3), scaled to the subject's spine.
DEFAULT_NECK_TO_HEAD_M, DEFAULT_HEAD_TO_TOP_M, DEFAULT_SPINE_M = 0.120, 0.08, 0.421
_PAIRS = [(INDEX[j], INDEX[j[:-1] + "r"]) for j in JOINTS if j.endswith("_l")]


def calibrate(markers: np.ndarray, labels: list[str], profile: Profile, rate_hz: float,
              settings: CalibrationSettings | None = None, fit_settings=None) -> Subject:
    """``markers``: (F, M, 3) metres, NaN where not seen, columns named by ``labels``, at ``rate_hz``;
    ``fit_settings``: the fit's (FitSettings) that the refinement rounds use."""
    s = settings or CalibrationSettings()
    markers = np.asarray(markers, np.float64)[_spread(len(markers), s.max_frames)]
    landmark_map = profile.resolve(labels)
    loc = Localizer(profile.body).localize(landmark_map.apply(markers))
    static = is_static(markers)
    motion = () if static else from_motion(markers, labels, profile, loc.positions, loc.frames, s)
    offsets, known, rest = joint_offsets(loc.positions, loc.frames, s)
    segments = anatomy(profile, labels) if static else None
    bone, c, spread = marker_offsets(markers, loc.positions, loc.frames, known, s, segments)
    clean = list(profile.columns(labels))
    subject = Subject(profile.name, offsets, known, clean, bone, c, spread, len(markers), False, rest, motion)
    for _ in range(s.refinements):
        subject = refine(subject, markers, clean, rate_hz, s, fit_settings, segments)
    return subject


def from_motion(markers: np.ndarray, labels: list[str], profile: Profile, P: np.ndarray, R: np.ndarray,
                s: CalibrationSettings) -> tuple[str, ...]:
    """The hips, knees and elbows that no landmark locates, put in ``P`` and ``R`` (in place) where the take's motion
    finds them (mocap_core.fit.functional); their names. Each marker rides the bone its body segment names in the
    profile (a thigh cluster listed under tracking), else the one it strays least on."""
    from mocap_core.fit.functional import FUNCTIONAL, locate_from_motion

    wanted = [INDEX[f"{j}_{side}"] for j in FUNCTIONAL for side in "lr"]
    if np.isfinite(P[:, wanted]).all(axis=2).any(axis=0).all():
        return ()
    _, known, _ = joint_offsets(P, R, s)
    return locate_from_motion(markers, by_segment(profile, labels, marker_offsets(markers, P, R, known, s)[0]), P, R)


def is_static(markers: np.ndarray) -> bool:
    """A static trial: every marker stays within STILL_M of its mean place (a standing subject sways)."""
    return sway(markers) <= STILL_M


def sway(markers: np.ndarray) -> float:
    """The farthest any marker of (F, M, 3) strays from its mean place over the frames that see it (inf: none seen)."""
    seen = np.isfinite(markers).all(axis=-1)
    used = seen.any(axis=0)
    if not used.any():
        return float("inf")
    x = markers[:, used]
    mean = np.where(seen[:, used, None], x, 0).sum(axis=0) / seen[:, used].sum(axis=0)[:, None]
    return float(np.nanmax(np.linalg.norm(x - mean, axis=-1)))


def anatomy(profile: Profile, labels: list[str]) -> np.ndarray:
    """(M, J) the bones of each marker's body segment, where the profile places it (none where it does not)."""
    out = np.zeros((len(labels), len(JOINTS)), bool)
    for k, bones in enumerate(profile.marker_bones(labels)):
        out[k, [INDEX[b] for b in bones]] = True
    return out


def bone_of_each(profile: Profile, labels: list[str], subject: Subject) -> np.ndarray:
    """(M,) the bone each of ``labels`` rides: its body segment's where the profile names one bone for it, else the
    subject's (-1: none)."""
    rows = subject.marker_index(list(profile.columns(labels)))
    return by_segment(profile, labels, np.where(rows >= 0, subject.marker_bone[np.maximum(rows, 0)], -1))


def by_segment(profile: Profile, labels: list[str], bone: np.ndarray) -> np.ndarray:
    """``bone`` (M,) with each marker whose body segment the profile names one bone for on that bone (in place)."""
    for k, bones in enumerate(profile.marker_bones(labels)):
        if len(bones) == 1:
            bone[k] = INDEX[bones[0]]
    return bone


def calibrate_bones(P: np.ndarray, R: np.ndarray, name: str, settings: CalibrationSettings | None = None) -> Subject:
    """A subject of bones only (no marker placed) from located joints (F, J, 3) and bone frames (F, J, 3, 3): what the
    IK stage's rigid chains take (mocap_core.rigid_chain)."""
    s = settings or CalibrationSettings()
    keep = _spread(len(P), s.max_frames)
    P, R = P[keep], R[keep]
    offsets, known, rest = joint_offsets(P, R, s)
    return Subject(name, offsets, known, [], np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0), len(P), False, rest)


def _spread(n: int, most: int) -> np.ndarray | slice:
    """Which of n frames to calibrate from: all, or ``most`` spread evenly over them (plenty for medians)."""
    return np.linspace(0, n - 1, most).round().astype(int) if n > most else slice(None)


def joint_offsets(P: np.ndarray, R: np.ndarray, s: CalibrationSettings):
    """Each joint's median position in its parent's frame over the frames where both are located, and its
    typical rotation there (the chordal mean); the root is known where it is ever located."""
    n = P.shape[1]
    offsets, known, rest = np.zeros((n, 3)), np.zeros(n, bool), np.tile(np.eye(3), (n, 1, 1))
    known[0] = np.isfinite(P[:, 0]).all(axis=1).sum() >= s.min_frames
    for j in range(1, n):
        p = PARENT_INDEX[j]
        local = np.einsum("fba,fb->fa", R[:, p], P[:, j] - P[:, p])
        ok = np.isfinite(local).all(axis=1) & np.isfinite(R[:, p]).all(axis=(1, 2))
        if ok.sum() < s.min_frames or not known[p]:
            continue
        offsets[j], known[j] = np.median(local[ok], axis=0), True
        turns = np.einsum("fba,fbc->fac", R[ok, p], R[ok, j])
        turns = turns[np.isfinite(turns).all(axis=(1, 2))]
        if len(turns):
            u, _, vt = np.linalg.svd(turns.mean(axis=0))
            rest[j] = u @ np.diag([1, 1, np.linalg.det(u @ vt)]) @ vt
    offsets, known = finished(offsets, known, s)
    return offsets, known, rest


def finished(offsets: np.ndarray, known: np.ndarray, s: CalibrationSettings) -> tuple[np.ndarray, np.ndarray]:
    """The joints' offsets as a calibration gives them (new arrays): left and right bones of one length (with
    ``s.symmetric``), a head on the neck where no marker located it."""
    offsets, known = (symmetric(offsets, known) if s.symmetric else offsets.copy()), known.copy()
    default_head(offsets, known)
    return offsets, known


def default_head(offsets: np.ndarray, known: np.ndarray) -> None:
    """A head that follows the neck where no marker located it (in place): straight up the neck's frame."""
    neck, head, top = INDEX["neck"], INDEX["head"], INDEX["head_top"]
    if not known[neck] or known[head]:
        return
    spine = sum(np.linalg.norm(offsets[INDEX[j]]) for j in ("spine1", "spine3") if known[INDEX[j]])
    scale = spine / DEFAULT_SPINE_M if spine > 0 else 1.0
    offsets[head], offsets[top] = (0, DEFAULT_NECK_TO_HEAD_M * scale, 0), (0, DEFAULT_HEAD_TO_TOP_M * scale, 0)
    known[head] = known[top] = True


def symmetric(offsets: np.ndarray, known: np.ndarray) -> np.ndarray:
    """The offsets with each left and right bone scaled to their mean length where both are known."""
    out = offsets.copy()
    for left, right in _PAIRS:
        if known[left] and known[right]:
            a, b = np.linalg.norm(offsets[left]), np.linalg.norm(offsets[right])
            if a > 0 and b > 0:
                out[left] *= (a + b) / 2 / a
                out[right] *= (a + b) / 2 / b
    return out


class LiveBones:
    """``calibrate_bones`` over a stream, for some joints (a limb's and its mirror's): each joint's median place in
    its parent's bone frame over the frames where both were located, left and right bones of one length. The frames
    are kept spread evenly over all seen so far (at most ``most``: when full, every other is let go and every other
    frame kept from then on), so the bones converge to the whole stream's as a take's calibration does. The medians
    are re-taken one joint at a time (``retake``), so calibrating holds no frame."""

    def __init__(self, joints: np.ndarray, settings: CalibrationSettings | None = None, most: int = 2000):
        self.s = settings or CalibrationSettings()
        self.joints = np.asarray(joints, np.int64)
        self.parents = PARENT_INDEX[self.joints]
        self.local = np.full((most - most % 2, len(self.joints), 3), np.nan)
        self.kept, self.seen, self.stride, self.turn = 0, 0, 1, 0
        self.raw = np.zeros((len(JOINTS), 3))             # each joint's median offset so far
        self.raw_known = np.zeros(len(JOINTS), bool)
        self.offsets = np.zeros((len(JOINTS), 3))          # the bones: left and right of one length, a default head
        self.known = np.zeros(len(JOINTS), bool)

    def add(self, skeleton: tuple) -> None:
        """One frame (positions, frames, status of the whole skeleton)."""
        if self.seen % self.stride == 0:
            if self.kept == len(self.local):
                self.kept //= 2
                self.local[:self.kept] = self.local[::2].copy()
                self.stride *= 2
            if self.seen % self.stride == 0:
                _local_offsets(skeleton, self.joints, self.parents, self.local[self.kept])
                self.kept += 1
        self.seen += 1

    def retake(self) -> bool:
        """The next joint's median again; True when a round of all of them ended, or this joint is calibrated for the
        first time (``offsets`` then new: a bone first seen need not wait for the round)."""
        k, j = self.turn, self.joints[self.turn]
        self.turn = (k + 1) % len(self.joints)
        column = self.local[:self.kept, k]
        ok = np.isfinite(column[:, 0])
        first = False
        if ok.sum() >= self.s.min_frames:
            first = not self.raw_known[j]
            self.raw[j], self.raw_known[j] = np.median(column[ok], axis=0), True
        if self.turn and not first:
            return False
        self.offsets, self.known = finished(self.raw, self.raw_known, self.s)
        return True


@njit(cache=True)
def _local_offsets(skeleton, joints, parents, out):
    """Each joint's place in its parent's bone frame where both are located, NaN where not."""
    positions, frames, status = skeleton
    for k in range(joints.shape[0]):
        j, p = joints[k], parents[k]
        if status[j] == LOCATED and status[p] == LOCATED:
            out[k] = mtv(frames[p], positions[j] - positions[p])
        else:
            out[k] = np.nan


def marker_offsets(markers: np.ndarray, P: np.ndarray, R: np.ndarray, known: np.ndarray, s: CalibrationSettings,
                   segments: np.ndarray | None = None):
    """For every marker: the bone it strays least on, its median offset there and that stray (-1 / NaN: none).
    Two bones are compared on the frames where both are located with the marker seen: a bone located in a few
    frames only would otherwise win on the little it moved in them. A static trial (``segments`` given: (M, J) bool,
    the bones of each marker's body segment by the profile's anatomy) tells few bones apart, as every marker strays
    little on every bone near it: of the bones it strays on within TIE_M of the least, the marker rides the nearest of
    its segment's (an epicondyle rides the femur though it locates the knee), or the nearest of all where the profile
    places it nowhere."""
    m = markers.shape[1]
    candidates = np.flatnonzero(ROTATING & known)
    local = np.einsum("fbxa,fbmx->fbma", R[:, candidates], markers[:, None] - P[:, candidates, None])  # (F,B,M,3)
    ok = np.isfinite(local).all(axis=3)
    bone, offset, spread = np.full(m, -1, np.int64), np.zeros((m, 3)), np.full(m, np.nan)

    def stray(b, k, frames):
        pts = local[frames, b, k]
        return np.percentile(np.linalg.norm(pts - np.median(pts, axis=0), axis=1), STRAY_PERCENTILE)

    for k in range(m):
        seen = [b for b in range(len(candidates)) if ok[:, b, k].sum() >= s.min_frames]
        best = -1
        for b in seen:
            if best < 0:
                best = b
                continue
            both = ok[:, b, k] & ok[:, best, k]
            if both.sum() >= s.min_frames:
                if stray(b, k, both) < stray(best, k, both):
                    best = b
            elif ok[:, b, k].sum() > ok[:, best, k].sum():
                best = b
        if best < 0:
            continue
        tied = [b for b in seen if b == best or _tie(stray, ok, b, best, k, s)] if segments is not None else []
        if len(tied) > 1:
            tied = [b for b in tied if segments[k, candidates[b]]] or tied
            best = tied[int(np.argmin([_bone_distance(markers[:, k], P, candidates[b]) for b in tied]))]
        frames = ok[:, best, k]
        spread[k] = stray(best, k, frames)
        if spread[k] <= s.max_spread_m:
            bone[k], offset[k] = candidates[best], np.median(local[frames, best, k], axis=0)
    return bone, offset, np.where(bone >= 0, spread, np.nan)


# Strays closer than this (about a marker's wobble on the skin) do not tell two bones apart.
TIE_M = 0.005


def _tie(stray, ok, b, best, k, s) -> bool:
    both = ok[:, b, k] & ok[:, best, k]
    return both.sum() >= s.min_frames and stray(b, k, both) <= stray(best, k, both) + TIE_M


def _bone_distance(marker: np.ndarray, P: np.ndarray, j: int) -> float:
    """The median distance (over frames) of a marker's track from bone j: the segments from its joint to each child."""
    out = np.inf
    for c in np.flatnonzero(PARENT_INDEX == j):
        a, d = P[:, j], P[:, c] - P[:, j]
        t = np.clip(np.einsum("fx,fx->f", marker - a, d) / np.maximum(np.einsum("fx,fx->f", d, d), 1e-12), 0, 1)
        dist = np.linalg.norm(marker - a - t[:, None] * d, axis=1)
        if np.isfinite(dist).any():
            out = min(out, float(np.nanmedian(dist)))
    return out


def refine(subject: Subject, markers: np.ndarray, labels: list[str], rate_hz: float,
           s: CalibrationSettings, fit_settings=None, segments: np.ndarray | None = None) -> Subject:
    """The markers' bones and offsets again, from the fitted bone frames: the fit places every bone in every
    frame, so each marker is judged on every bone over the same frames, and on frames that its neighbours'
    markers fix (the localization's frames lean on a few landmarks each)."""
    from mocap_core.fit.fitter import SkeletonFitter
    P, R, _, _ = SkeletonFitter(subject, labels, fit_settings, rate_hz=rate_hz).fit_all(markers)
    bone, c, spread = marker_offsets(markers, P, R, subject.known, s, segments)
    return replace(subject, marker_bone=bone, marker_offsets=c, spread_m=spread)

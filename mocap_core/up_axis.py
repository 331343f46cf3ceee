"""Which axis points up in a take, from where its markers are.

A file may say its up axis (mocap_core.world); a profile's ``up_axis`` is a guess for files that do not, and a wrong
guess lays the BVH and the live avatar on their backs. So the frames are asked too. Up is the axis along which the
feet keep to one level, the floor: each frame's lowest foot landmark along it moves least over the take (walking,
dancing, a crouched start move the feet far more across the floor than off it). Its sign is where the head and
shoulders stand off the feet (a body leaning, even crouched, still has its head above its feet).
"""
from __future__ import annotations

import warnings

import numpy as np

from mocap_core.profiles import AUTO, LANDMARK_INDEX, Profile, ProfileError, profile_for
from mocap_core.recordings import Recording
from mocap_core.world import normalize_up

HIGH = ("SGL", "L_HEAD", "R_HEAD", "TV2", "SME", "L_SAE", "R_SAE")
LOW = ("L_FM2", "R_FM2", "L_FCC", "R_FCC", "L_FAL", "R_FAL", "L_TAM", "R_TAM")
CLEAR = 0.5              # the floor's axis moves at most this part of what the next axis does
MIN_HEIGHT_M = 0.3       # and the head stands at least this far off the feet along it
MOST_FRAMES = 2000       # frames spread over the take are plenty


def up_from_landmarks(landmarks: np.ndarray) -> str | None:
    """``landmarks`` (F, n_landmarks, 3) -> "+z", "-y", ...; None where the frames cannot say (no foot or head
    landmark seen, or no axis clearly the floor's)."""
    low = landmarks[:, [LANDMARK_INDEX[x] for x in LOW]]
    high = landmarks[:, [LANDMARK_INDEX[x] for x in HIGH]]
    with warnings.catch_warnings():  # (all-NaN slices: frames where those landmarks are lost)
        warnings.simplefilter("ignore", RuntimeWarning)
        moves = [min(_iqr(np.nanmin(low[..., a], axis=1)), _iqr(np.nanmax(low[..., a], axis=1))) for a in range(3)]
        order = np.argsort(moves)
        axis = int(order[0])
        height = np.nanmedian(np.nanmean(high[..., axis], axis=1) - np.nanmean(low[..., axis], axis=1))
    if not (np.isfinite(moves).all() and moves[axis] < CLEAR * moves[order[1]] and abs(height) >= MIN_HEIGHT_M):
        return None
    return ("+" if height > 0 else "-") + "xyz"[axis]


def _iqr(x: np.ndarray) -> float:
    return float(np.nanpercentile(x, 75) - np.nanpercentile(x, 25))


def take_up_axis(rec: Recording, profile: Profile, log=None) -> str:
    """The take's up axis: the file's word, else what its frames show, else the profile's; a stated axis (the
    file's or the profile's) that the frames contradict is said in ``log``."""
    found = _found(rec, profile)
    stated = rec.meta.get("up_axis")
    if stated:
        if found and found != normalize_up(stated) and log is not None:
            log.warning("%s says %s is up, but its head stands above its feet along %s: kept %s (tell the file "
                        "source otherwise with its up_axis param)", rec.source, stated, found, stated)
        return stated
    if found is None:
        return profile.up_axis
    if found != profile.up_axis and log is not None:
        log.warning("profile %s says %s is up, but the take's head stands above its feet along %s: using %s",
                    profile.name, profile.up_axis, found, found)
    return found


class StreamUpCheck:
    """A live stream's stated up axis (QTM's, a source's) against what its frames show: frames kept every
    ``SAMPLE_S`` for ``SPAN_S`` of capture time, then a look (the next span's, where these frames cannot say: an actor
    standing still). ``add`` returns a sentence once, where they disagree."""

    SAMPLE_S, SPAN_S = 0.05, 5.0

    def __init__(self):
        self.kept: list[np.ndarray] = []
        self.first_s = self.next_s = None
        self.done = False

    def add(self, landmarks: np.ndarray, stated: str, time_s: float) -> str | None:
        if self.done or not stated:
            return None
        if self.first_s is None:
            self.first_s = self.next_s = time_s
        if time_s >= self.next_s:
            self.kept.append(landmarks.copy())
            self.next_s = time_s + self.SAMPLE_S
        if time_s - self.first_s < self.SPAN_S:
            return None
        found = up_from_landmarks(np.stack(self.kept))
        self.kept, self.first_s = [], None
        if found is None:
            return None
        self.done = True
        if found == normalize_up(stated):
            return None
        return (f"the stream says {stated} is up, but its head stands above its feet along {found}: the avatar, BVH "
                f"and VMC will lie on their backs (set the source's up_axis param to {found})")


def recording_up_axis(rec: Recording, log=None) -> str | None:
    """A recording's up axis with no profile given (a file source, the QTM emulator, a draft): the file's word,
    else what its frames show with the profile its labels fit (a shipped one, else a draft); None if neither says."""
    if rec.meta.get("up_axis"):
        return rec.meta["up_axis"]
    try:
        profile = profile_for(AUTO, rec.labels)
    except ProfileError:
        return None
    found = _found(rec, profile)
    if found and log is not None:
        log.info("%s does not say which axis is up; its frames show %s", rec.source, found)
    return found


def _found(rec: Recording, profile: Profile) -> str | None:
    """What the take's frames (at most MOST_FRAMES, spread over it) show."""
    step = max(1, rec.n_frames // MOST_FRAMES)
    return up_from_landmarks(profile.resolve(rec.labels).apply(rec.positions[::step]))

"""The landmark-level gap fills, in their order: the pair guard (which drops a bony pair whose spacing jumped),
the segment rebuild (with the leg hinge), the pose memory, then the partial means (with the rebuild).

One place for how they go together, used by the hip node, the offline pipeline and `mocap eval gaps`:
each fills only what the ones before could not, and never learns from what they filled.
"""
from __future__ import annotations

from typing import Callable, Iterable, Sequence

import numpy as np

from mocap_core.leg_hinge import LegHinge
from mocap_core.pair_guard import PairGuard
from mocap_core.partial_means import PartialMeans
from mocap_core.pose_memory import PoseMemory
from mocap_core.profiles import LandmarkMap
from mocap_core.segment_rebuild import SegmentRebuilder


class LandmarkFills:
    """``tracking_of``: the segment of each tracking marker (LandmarkMap.tracking_of); ``present``: the
    landmark names the profile has (LandmarkMap.present()); ``means``: the landmark map, whose landmarks that are
    the mean of several markers are then kept, with the rebuild, while some of those are seen (PartialMeans:
    it needs the frame's markers); ``pair_guard``: drop the bony pairs whose spacing jumped (PairGuard). Keep one
    per actor: the fills keep state."""

    def __init__(self, rebuild: bool, pose_memory: bool, tracking_of: Sequence[str] = (),
                 present: Iterable[str] = (), means: LandmarkMap | None = None, pair_guard: bool = False):
        self.guard = PairGuard() if pair_guard else None
        self.rebuilder = SegmentRebuilder(tracking_of) if rebuild else None
        hinge = LegHinge(tracking_of) if rebuild else None
        self.leg_hinge = hinge if hinge is not None and hinge.active else None
        self.memory = PoseMemory(present, tracking_of) if pose_memory else None
        self.partial = PartialMeans(means) if rebuild and means is not None else None

    def fill(self, landmarks: np.ndarray, tracking: np.ndarray | None = None, time_s: float = np.nan,
             markers: np.ndarray | None = None) -> np.ndarray:
        """One frame, in place; the mask of the landmarks filled. ``tracking``: the profile's tracking markers
        (None: lost); ``time_s``: the frame's time (the pose memory finds poses by the toe's velocity too);
        ``markers``: the frame's markers as received (the partial means)."""
        if tracking is None and self.rebuilder is not None and self.rebuilder.n_tracking:
            tracking = np.full((self.rebuilder.n_tracking, 3), np.nan)
        if self.guard is not None:  # (lost now: what follows fills them like any other)
            self.guard.fill(landmarks, time_s)
        if self.rebuilder is not None:  # lost forearm, foot and shank landmarks from their segment
            filled = self.rebuilder.fill(landmarks, tracking, time_s)
        else:
            filled = np.zeros(len(landmarks), np.bool_)
        if self.leg_hinge is not None:  # lost knees and ankles from the hip and a shank marker
            filled |= self.leg_hinge.fill(landmarks, tracking, filled, time_s)
        if self.memory is not None:  # lost knees and ankles where the take's earlier poses had them
            filled |= self.memory.fill(landmarks, filled, tracking, time_s)
        if self.partial is not None and markers is not None:  # what is still lost
            filled |= self.partial.fill(landmarks, markers)
        return filled


def fill_take(fill: Callable[..., np.ndarray], landmarks: np.ndarray, **frames) -> tuple[np.ndarray, np.ndarray]:
    """A one-frame fill run over a take. ``fill(frame, **arguments)`` fills one frame of ``landmarks`` in place and
    returns the mask of what it filled; each keyword holds an argument's frames (F, ...), None leaving it at the
    fill's default. -> the filled copy of ``landmarks`` (F, n, 3) and the (F, n) mask."""
    given = {name: value for name, value in frames.items() if value is not None}
    out = np.array(landmarks, dtype=np.float64, copy=True)
    mask = np.zeros(out.shape[:2], bool)
    for f in range(len(out)):
        mask[f] = fill(out[f], **{name: value[f] for name, value in given.items()})
    return out, mask

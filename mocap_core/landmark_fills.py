"""The landmark-level gap fills (mocap_core.fills.LANDMARK_FILLS, in their order): the pair guard (which drops a
bony pair whose spacing jumped), the segment rebuild with the leg hinge, the pose memory, then the partial means.

One place for how they go together, used by the hip node, the offline pipeline and `mocap eval gaps`:
each fills only what the ones before could not, and never learns from what they filled.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from mocap_core.fill_units import LandmarkFill, MarkerSet


class LandmarkFills:
    """The fills ``options`` (HipOptions, or a node's params) turn on, for this actor's ``markers``. Keep one per
    actor: the fills keep state."""

    def __init__(self, options, markers: MarkerSet = MarkerSet()):
        made = (fill.for_marker_set(markers) for fill in options.fills if fill.wanted(options))
        self.fills: list[LandmarkFill] = [fill for fill in made if fill is not None]
        self.n_tracking = len(markers.tracking_of)

    def fill(self, landmarks: np.ndarray, tracking: np.ndarray | None = None, time_s: float = np.nan,
             markers: np.ndarray | None = None) -> np.ndarray:
        """One frame, in place (LandmarkFill.fill); the mask of the landmarks filled. ``tracking`` None: all lost."""
        if tracking is None and self.n_tracking:
            tracking = np.full((self.n_tracking, 3), np.nan)
        filled = np.zeros(len(landmarks), np.bool_)
        for fill in self.fills:
            filled |= fill.fill(landmarks, tracking, time_s, markers, filled)
        return filled

    def said(self) -> list[tuple[str, str]]:
        """What the last frame's fills did that the node should count and log: (kind, message) pairs."""
        return [said for fill in self.fills for said in fill.said()]


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

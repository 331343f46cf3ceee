"""What a gap fill is: a small class with typed settings and its own state, registered by name in mocap_core.fills.

Two stages run fills, each through one interface:

- the hip stage's :class:`LandmarkFill` fills lost landmarks of a frame, before any joint is located from them;
- the IK stage's :class:`LimbFill` acts on one limb's joints of a skeleton frame, ``before`` Algorithm 1 fills
  what is still lost or ``after`` it.

A fill's ``Settings`` (a pydantic model) are its fields in the stage's options (mocap_core.fill_options), and so
its node params, its preset values and its `mocap eval gaps` flags. The first field turns it on unless it says
otherwise (:meth:`Fill.wanted`).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, ClassVar, Iterable, NamedTuple, Sequence

import numpy as np
from pydantic import BaseModel, Field, create_model

if TYPE_CHECKING:
    from mocap_core.gapfill import LimbFiller
    from mocap_core.profiles import LandmarkMap


def switch(name: str, help: str) -> type[BaseModel]:
    """The settings of a fill that is only on or off: one bool, ``name``, off by default (the thesis's method)."""
    return create_model(f"{name}_settings", **{name: (bool, Field(False, description=help))})


class Fill:
    """What the stages ask of every fill's class."""
    Settings: ClassVar[type[BaseModel]]
    needs: ClassVar[str | None] = None  # a fill this one steers: it is refused without it

    @classmethod
    def option(cls) -> str:
        """The setting that names the fill (its first)."""
        return next(iter(cls.Settings.model_fields))

    @classmethod
    def wanted(cls, options) -> bool:
        """Whether ``options`` (the stage's, or a node's params) turn this fill on."""
        return bool(getattr(options, cls.option()))


class MarkerSet(NamedTuple):
    """What the landmark fills know of an actor's marker set: the segment of each tracking marker
    (LandmarkMap.tracking_of), the landmark names the profile has (LandmarkMap.present()) and the landmark map
    itself, when the fills may read the frame's markers (None: they may not)."""
    tracking_of: Sequence[str] = ()
    present: Iterable[str] = ()
    means: "LandmarkMap | None" = None


class LandmarkFill(Fill):
    """A fill of lost landmarks, frame by frame. Keep one per actor and marker set: fills learn."""

    @classmethod
    def for_marker_set(cls, markers: MarkerSet) -> "LandmarkFill | None":
        """The fill for this marker set; None where it has nothing to fill from."""
        return cls()

    def fill(self, landmarks: np.ndarray, tracking: np.ndarray | None = None, time_s: float = np.nan,
             markers: np.ndarray | None = None, filled: np.ndarray | None = None) -> np.ndarray:
        """One frame of landmarks (n_landmarks, 3) float64, NaN = lost, in place; returns the mask of the
        landmarks it put. ``tracking``: the profile's tracking markers (n_tracking, 3; None: none); ``time_s``: the
        frame's time (NaN: unknown); ``markers``: the frame's markers as received; ``filled``: what the fills
        before it put this frame (never learned from)."""
        raise NotImplementedError

    def said(self) -> list[tuple[str, str]]:
        """What the last frame did that the node should count and log: (kind, message) pairs."""
        return []


@dataclass(slots=True)
class LimbFrame:
    """One skeleton frame as a limb's fills see it: the whole skeleton's arrays, changed in place, and what the
    fills hand on within the frame."""
    positions: np.ndarray     # (J, 3)
    frames: np.ndarray        # (J, 3, 3)
    status: np.ndarray        # (J,) skeleton.MISSING ...
    out: np.ndarray           # [joints estimated, joints held, IK iterations, largest residual m]
    recalled: np.ndarray      # (n, 3) per limb joint, where the limb memory would have it (NaN: no say)
    modelled: np.ndarray      # (n, 3) and where the body model puts it,
    model_weight: np.ndarray  # (n,) with this weight (the swivel reads all three)
    markers: np.ndarray | None = None  # (M, 3) the frame's markers, where the stage has them (the rigid chain's)
    skeleton: tuple = field(init=False)  # (positions, frames, status), as the kernels take them

    def __post_init__(self):
        self.skeleton = (self.positions, self.frames, self.status)


class LimbFill(Fill):
    """A fill of one limb, frame by frame, beside the thesis's IK. ``limb`` is its LimbFiller: the chain
    (``joints``, ``parent_of_root``, ``other``: the mirrored limb's chain or None), the last whole output
    (``prev_pos``, ``prev_frames``, ``prev_parent_frame``, ``has_prev``), the learned bone ``lengths`` and the
    frame ``clock``."""
    mirrored: ClassVar[bool] = False  # learns from the mirrored limb: none on the torso

    def __init__(self, limb: "LimbFiller", options):
        self.limb = limb

    @classmethod
    def for_limb(cls, limb: "LimbFiller", options) -> "LimbFill | None":
        """The fill for this limb with these options; None where it has nothing to act on."""
        return cls(limb, options)

    def before(self, frame: LimbFrame) -> None:
        """Before Algorithm 1: put what this fill can of the limb's lost joints (counting them in frame.out)."""

    def after(self, frame: LimbFrame) -> None:
        """After it, on the limb's output."""

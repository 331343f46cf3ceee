"""The whole per-frame chain in one process, for offline commands (``mocap solve``, ``mocap eval``).

The node graph runs the same stages in separate processes; both call the same mocap_core code:
profile -> landmarks -> hip interpolation -> localization -> gap filling, with the state of each
stage owned here (hip triangle, body estimates, previous limb chains).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Iterator

import numpy as np

from mocap_core.blend import DEFAULT_FRAME_S
from mocap_core.fill_options import HipOptions
from mocap_core.fit.calibration import calibrate_bones
from mocap_core.fill_units import MarkerSet
from mocap_core.gapfill import GapFiller
from mocap_core.hip_interpolation import HipInterpolator
from mocap_core.ik.constraints import Constraints
from mocap_core.ik.solvers import SolverParams
from mocap_core.landmark_fills import LandmarkFills, fill_take
from mocap_core.localization import Localizer
from mocap_core.marker_gate import MarkerGate
from mocap_core.presets import PRESETS, Options
from mocap_core.profiles import Profile


@dataclass
class SolvedChunk:
    start: int                 # index of the first frame of the chunk
    positions: np.ndarray      # (F, J, 3)
    frames: np.ndarray         # (F, J, 3, 3)
    status: np.ndarray         # (F, J)


class SkeletonPipeline:
    def __init__(self, profile: Profile, labels: list[str], solver: str = "ccd",
                 params: SolverParams | None = None, constraints: Constraints | None = None,
                 fill_gaps: bool = True, rate_hz: float | None = None, options: Options | str | None = None):
        """``options``: the fills beyond the thesis, a preset's name (mocap_core.presets: ``studio``, the hips fitted
        to the body when all are lost, lost forearm and foot landmarks rebuilt, lost knees and ankles from the pose
        memory, bony pairs whose spacing jumped dropped, swivel, segment carry, the blends at loss and
        re-acquisition, the rigid chains; the default) or both stages' options; ``fill_gaps`` false: none (the
        thesis's hips, unless ``options`` says), and no IK. ``rate_hz``: the take's frame rate, which paces the
        blends (else blend.DEFAULT_FRAME_S a frame)."""
        self.frame_s = 1.0 / rate_hz if rate_hz else DEFAULT_FRAME_S
        self.landmark_map = profile.resolve(labels)
        self.labels = list(profile.columns(labels))
        self.gate = MarkerGate()
        options = options or ("studio" if fill_gaps else "thesis")
        options = PRESETS[options] if isinstance(options, str) else options
        hips = options.hips
        self.hips = HipInterpolator(when_lost=hips.when_lost)
        # the landmark fills are gap fills
        m = self.landmark_map
        self.fills = LandmarkFills(hips if fill_gaps else HipOptions(), MarkerSet(m.tracking_of, m.present(), m))
        self.localizer = Localizer(profile.body)
        self.filler = GapFiller(solver, params, constraints, options.ik) if fill_gaps else None
        self.profile_name = profile.name
        self.subject = None

    def landmarks(self, markers: np.ndarray) -> np.ndarray:
        """Marker frames (F, N, 3) -> landmark frames with the pelvis markers filled."""
        lm = self.landmark_map.apply(markers)
        lm, _ = self.hips.fill_landmarks(lm)
        return lm

    def solve_landmarks(self, landmarks: np.ndarray, start: int = 0, tracking: np.ndarray | None = None,
                        markers: np.ndarray | None = None) -> SolvedChunk:
        """``tracking``: the profile's tracking markers of the same frames (landmark_map.tracking), which
        help rebuild lost limb landmarks (the rebuild is a gap fill: on with ``beyond`` and ``fill_gaps``);
        ``markers``: the frames' markers, from which a landmark that is the mean of several, still lost, is kept
        while some of them are seen (mocap_core.partial_means; with the rebuild)."""
        times = (start + np.arange(len(landmarks))) * self.frame_s
        landmarks, rebuilt = fill_take(self.fills.fill, landmarks, tracking=tracking, time_s=times, markers=markers)
        loc = self.localizer.localize(landmarks, rebuilt)
        pos, frames, status = loc.positions, loc.frames, loc.status
        if self.filler is not None:
            with_markers = markers is not None and self.subject is not None
            for f in range(len(pos)):
                self.filler.fill(pos[f], frames[f], status[f], (start + f) * self.frame_s,
                                 markers[f] if with_markers else None)
        return SolvedChunk(start, pos, frames, status)

    def use(self, subject) -> None:
        """Solve with a calibrated subject's bones (mocap_core.fit.subject): the rigid chains keep them, fitted to
        the markers it places on them."""
        if self.filler is not None:
            self.filler.use(subject, self.labels if len(subject.labels) else None)
        self.subject = subject

    def calibrate(self, markers: np.ndarray):
        """The subject's bones from the joints that the take's landmarks locate (mocap_core.fit.calibration)."""
        frames = MarkerGate().filter_take(markers, self.frame_s)
        return self._calibrate(HipInterpolator(when_lost=self.hips.when_lost).fill_landmarks(
            self.landmark_map.apply(frames))[0])

    def _calibrate(self, landmarks: np.ndarray):
        loc = Localizer(self.localizer.body).localize(landmarks)  # (a fresh one: the solve's keeps its body estimates)
        return calibrate_bones(loc.positions, loc.frames, self.profile_name)

    def run(self, markers: np.ndarray, chunk: int = 250, calibrate: bool = True) -> Iterator[SolvedChunk]:
        """A take's frames, the markers no body could have put there dropped first (mocap_core.marker_gate). With
        rigid chains and no subject given, the subject's bones are calibrated from the whole take first
        (``calibrate`` false: learned frame by frame, as the graph's nodes learn them from a stream)."""
        frames = self.gate.filter_take(markers, self.frame_s)
        landmarks = self.landmarks(frames)  # (what the calibration localizes too: gated and hip-filled once)
        if calibrate and self.filler is not None and self.filler.rigid and self.subject is None:
            self.use(self._calibrate(landmarks))
        for start in range(0, len(markers), chunk):
            part = frames[start:start + chunk]
            yield self.solve_landmarks(landmarks[start:start + chunk], start, self.landmark_map.tracking(part), part)

"""A whole take through the fit, for offline commands (``mocap solve``, ``mocap calibrate``, ``mocap eval``)."""
from __future__ import annotations

import numpy as np

from mocap_core.fit.calibration import CalibrationSettings, calibrate
from mocap_core.fit.fitter import FitSettings, SkeletonFitter
from mocap_core.fit.subject import Subject
from mocap_core.marker_gate import MarkerGate
from mocap_core.pipeline import SolvedChunk
from mocap_core.profiles import Profile


def fit_take(markers: np.ndarray, labels: list[str], profile: Profile, rate_hz: float, subject: Subject | None = None,
             settings: FitSettings | None = None, calibration: CalibrationSettings | None = None,
             progress=None) -> tuple[SolvedChunk, np.ndarray, Subject]:
    """Fit every frame of ``markers`` (F, M, 3); without a ``subject``, calibrate one from these frames first.
    Returns the solved frames, each frame's marker residual RMS (metres) and the subject."""
    markers = MarkerGate().filter_take(markers, 1 / rate_hz)  # what no body could do, dropped first
    if subject is None:
        subject = calibrate(markers, labels, profile, rate_hz, calibration, settings)
    fitter = SkeletonFitter(subject, list(profile.columns(labels)), settings, rate_hz=rate_hz)
    pos, frames, status, residual = fitter.fit_all(markers, progress)
    return SolvedChunk(0, pos, frames, status), residual, subject

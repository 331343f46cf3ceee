"""The fit on a live stream: calibrate from the stream's first seconds, refine online, say when converged.

Until the first calibration the thesis's localization is what comes out (joints located where their landmarks
are seen, missing elsewhere). Then the subject is calibrated from the frames buffered so far, and again each
time the stream has run twice as long, until one calibration moves no joint by more than ``converged_m`` in its
parent's frame: the subject has converged and is kept (and can be saved for the next session). A calibration takes
0.4-1 s on a 2-core machine (1000 frames at most): with ``background`` (the node's way) it runs in a process of its
own while the frames go on being fitted with the subject so far, and is taken up at the first frame after it ends;
without, it holds the frame that started it. A studio that calibrates an actor once (``mocap calibrate``, or the
node's ``save_subject``) and gives the node the subject file has none.
"""
from __future__ import annotations

import multiprocessing
from concurrent.futures import Future, ProcessPoolExecutor
from dataclasses import dataclass

import numpy as np

from mocap_core.fit.calibration import CalibrationSettings, calibrate
from mocap_core.fit.fitter import FitFrame, FitSettings, SkeletonFitter
from mocap_core.fit.subject import Subject
from mocap_core.localization import Localizer
from mocap_core.marker_gate import MarkerGate
from mocap_core.profiles import Profile


@dataclass
class LiveSettings:
    first_s: float = 2.0            # the first calibration after this much of the stream
    buffer_frames: int = 1000       # frames kept for calibrating, spread evenly over the stream so far
    converged_m: float = 0.003      # a calibration that moves no joint more than this ends the refining
    background: bool = False        # calibrate in a process of its own, the frames fitted meanwhile


class LiveFit:
    def __init__(self, profile: Profile, labels: list[str], subject: Subject | None = None,
                 fit: FitSettings | None = None, live: LiveSettings | None = None):
        self.profile, self.labels = profile, labels
        self.clean = list(profile.columns(labels))
        self.fit_settings, self.live = fit or FitSettings(), live or LiveSettings()
        self.landmarks = profile.resolve(labels)
        self.localizer = Localizer(profile.body)
        self.subject = subject
        self.converged = subject is not None
        self.fitter: SkeletonFitter | None = None
        self._buffer: list[np.ndarray] = []
        self._times: list[float] = []
        self._stride, self._seen, self._next_s = 1, 0, self.live.first_s
        self.calibrations = 0
        self.gate = MarkerGate()
        self.dropped = np.zeros(len(labels), bool)
        self._pool: ProcessPoolExecutor | None = None
        self._pending: tuple[Future, float] | None = None  # the calibration running in the background, and its rate

    def add(self, markers: np.ndarray, time_s: float) -> FitFrame:
        """One frame's markers (M, 3) in metres at capture time ``time_s`` -> the skeleton (``self.dropped``: the
        markers of this frame that no body could have put there, dropped first)."""
        markers, self.dropped = self.gate.filter(markers, time_s)
        if self._pending is not None and self._pending[0].done():
            (done, rate), self._pending = self._pending, None
            self._adopt(done.result(), rate)
        if not self.converged:
            self._keep(markers, time_s)
            if self._times and time_s - self._times[0] >= self._next_s and self._pending is None:
                self._calibrate()
        if self.subject is None:
            loc = self.localizer.localize(self.landmarks.apply(markers[None]))
            return FitFrame(loc.positions[0], loc.frames[0], loc.status[0], float("nan"), 0)
        if self.fitter is None:
            self.fitter = SkeletonFitter(self.subject, self.clean, self.fit_settings, rate_hz=self._rate())
        return self.fitter.fit(markers)

    def _keep(self, markers: np.ndarray, time_s: float) -> None:
        """Every ``stride``-th frame; when the buffer is full, every other one of it goes and the stride doubles."""
        self._seen += 1
        if (self._seen - 1) % self._stride:
            return
        self._buffer.append(np.array(markers, np.float64))
        self._times.append(time_s)
        if len(self._buffer) >= self.live.buffer_frames:
            self._buffer, self._times, self._stride = self._buffer[::2], self._times[::2], self._stride * 2

    def _rate(self) -> float:
        steps = np.diff(self._times) / self._stride if len(self._times) > 1 else np.array([])
        return float(1 / np.median(steps)) if len(steps) and np.median(steps) > 0 else 120.0

    @property
    def calibrating(self) -> bool:
        """A calibration is running in the background."""
        return self._pending is not None

    def close(self) -> None:
        """End the background calibration's process, if any."""
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool, self._pending = None, None

    def _calibrate(self) -> None:
        rate = self._rate()
        args = (np.array(self._buffer), self.labels, self.profile, rate,
                CalibrationSettings(max_frames=self.live.buffer_frames), self.fit_settings)
        self._next_s *= 2
        if not self.live.background:
            self._adopt(calibrate(*args), rate)
            return
        if self._pool is None:  # (spawned, not forked: the node's process runs ZeroMQ's threads)
            self._pool = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"))
        self._pending = self._pool.submit(calibrate, *args), rate

    def _adopt(self, new: Subject, rate: float) -> None:
        """Fit with a new calibration from this frame on."""
        self.calibrations += 1
        if self.subject is not None:  # (a marker near a joint may go from one of its bones to the other: no matter)
            moved = np.linalg.norm(new.offsets - self.subject.offsets, axis=1).max()
            self.converged = bool(moved < self.live.converged_m)
        new.converged = self.converged
        self.subject = new
        old, self.fitter = self.fitter, SkeletonFitter(new, self.clean, self.fit_settings, rate_hz=rate)
        if old is not None and old.started:  # carry the pose over: no restart, no jump
            self.fitter.take_pose_from(old)
        if self.converged:
            self.close()

"""The rigid-skeleton fit as one node: every labelled marker in -> the whole skeleton -> ``skeleton/fitted``.

It takes the place of hip_interpolation, joint_localization and the five ik_gapfill nodes (docs/design.md: the studio
path); retarget with ``input: whole`` turns its output into ``skeleton/solved`` and ``rig/pose``. With
``subject:`` it fits that calibrated actor from the first frame; without, it calibrates from the stream's first
seconds (publishing the thesis's localization meanwhile), refines online, and writes ``save_subject`` once the
calibration has converged. Each calibration runs in a process of its own: no frame waits for it.
"""
from __future__ import annotations

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from messages import MarkerFrame, SkeletonFrame
from mocap_core.fit.fitter import FitSettings
from mocap_core.fit.live import LiveFit, LiveSettings
from mocap_core.fit.subject import load_subject
from mocap_core.profiles import AUTO, load_profile, profile_for
from mocap_core.warmup import FIT_PARTS
from nodes.runtime import Node
from nodes.skeleton_codec import to_message


class Params(BaseModel):
    model_config = ConfigDict(extra="forbid")
    profile: str = Field(AUTO, description="marker-set profile (seeds the calibration's bone frames); auto: the "
                                           "shipped one the stream's labels fit")
    subject: str | None = Field(None, description="subject file from `mocap calibrate`; none: calibrate live")
    save_subject: str | None = Field(None, description="write the live calibration here once it has converged")
    first_calibration_s: float = Field(2.0, gt=0, description="seconds of stream before the first calibration")
    limits: bool = Field(True, description="the thesis's cone and twist limits on what the motion task predicts")


class SkeletonFit(Node):
    kind = "skeleton_fit"
    Params = Params
    subscribes = {"markers/raw": MarkerFrame}
    publishes = {"skeleton/fitted": SkeletonFrame}

    @classmethod
    def kernels(cls, params):
        return FIT_PARTS

    def setup(self) -> None:
        if self.params.profile != AUTO:
            self.profile = load_profile(self.params.profile)  # a bad name fails here, before the graph is ready
            self.ctx.default_up_axis = self.profile.up_axis  # for sources that do not say it
        self.subject = load_subject(self.params.subject) if self.params.subject else None
        self.live: LiveFit | None = None
        self.labels: list[str] = []
        self.saved = False

    def on_message(self, topic, msg: MarkerFrame) -> None:
        if self.live is None or msg.labels != self.labels:  # the first frame, or a new marker set
            self.teardown()
            self.labels = list(msg.labels)
            if self.params.profile == AUTO:
                self.profile = profile_for(AUTO, self.labels, self.log)
                self.ctx.default_up_axis = self.profile.up_axis
            self.live = LiveFit(self.profile, self.labels, self.subject, FitSettings(limits=self.params.limits),
                                LiveSettings(first_s=self.params.first_calibration_s, background=True))
        calibrations = self.live.calibrations
        out = self.live.add(msg.positions.astype(float), msg.header.capture_time_s)
        for k in np.flatnonzero(self.live.dropped):
            self.ctx.count_error("marker_jump", f"{self.labels[k]} moved faster than a body can: dropped this frame")
        if self.live.calibrations != calibrations:
            self.log.info("calibrated the subject (%d frames)%s: fitted from frame %d on", self.live.subject.frames,
                          ", converged" if self.live.converged else "", msg.header.frame)
            if self.live.converged and self.params.save_subject and not self.saved:
                self.live.subject.save(self.params.save_subject)
                self.saved = True
                self.log.info("subject written to %s", self.params.save_subject)
        self.ctx.publish("skeleton/fitted", to_message(out.positions, out.frames, out.status), source=msg)

    def teardown(self) -> None:
        if self.live is not None:
            self.live.close()

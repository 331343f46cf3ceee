"""Stage 2: apply the marker-set profile and fill missing pelvis markers (thesis 3.4.8).

Reads ``markers/raw`` (the recording's own labels), drops the markers no body could have put there (counted as
``marker_jump``; mocap_core.marker_gate), and publishes ``markers/filled``: one marker per
landmark of the profile (the PAF names, mocap_core.profiles.LANDMARKS), so every later stage is
independent of the marker set. Flags: measured, interpolated (the pelvis markers this node
predicted, and with ``rebuild`` the forearm, foot, shank and acromion landmarks it rebuilt, with the help of
the profile's tracking markers, the knees and ankles the leg hinge put, and the landmarks still lost that are the
mean of several markers of which some are seen (mocap_core.partial_means); with ``pose_memory`` the
knee and ankle landmarks it recalled from the take's earlier poses) or missing (with ``pair_guard`` also a bony
pair whose spacing jumped, mocap_core.pair_guard).
"""
from __future__ import annotations

import numpy as np
from pydantic import ConfigDict, Field, model_validator

from messages import FLAG_INTERPOLATED, FLAG_MEASURED, FLAG_MISSING, MarkerFrame
from mocap_core.fill_options import HipOptions
from mocap_core.fill_units import MarkerSet
from mocap_core.hip_interpolation import ANCHOR_INDEX, HIP_INDEX, HipInterpolator
from mocap_core.landmark_fills import LandmarkFills
from mocap_core.landmark_needs import describe_missing, unlocatable
from mocap_core.marker_gate import MarkerGate
from mocap_core.presets import PRESET_HELP, Preset, with_preset
from mocap_core.profiles import AUTO, LANDMARKS, load_profile, profile_for
from mocap_core.up_axis import StreamUpCheck
from mocap_core.warmup import hip_parts
from nodes.runtime import Node


class Params(HipOptions):
    """The profile, the pelvis's largest step, and the fills beyond the thesis (HipOptions)."""
    model_config = ConfigDict(extra="forbid")
    profile: str = Field(AUTO, description="marker-set profile name (profiles/) or YAML path; auto: the shipped "
                                           "one the stream's labels fit")
    preset: Preset = Field("studio", description=PRESET_HELP)
    max_step_m: float = Field(0.02, gt=0, description="largest per-frame move of a predicted pelvis marker")

    @model_validator(mode="before")
    @classmethod
    def _preset(cls, values):
        return with_preset("hips", values)


class HipInterpolation(Node):
    kind = "hip_interpolation"
    Params = Params
    subscribes = {"markers/raw": MarkerFrame}
    publishes = {"markers/filled": MarkerFrame}

    @classmethod
    def kernels(cls, params):
        return hip_parts(params)

    def setup(self) -> None:
        if self.params.profile != AUTO:
            self._use(load_profile(self.params.profile))  # a bad name fails here, before the graph is ready
        self.hips = HipInterpolator(max_step_m=self.params.max_step_m, when_lost=self.params.when_lost)
        self.fills = None  # made when the profile is resolved: they need its tracking markers and landmarks
        self.labels: list[str] | None = None
        self.map = None
        self.gate = MarkerGate()  # markers no body could have put there never reach what the stages learn
        self.up_check = StreamUpCheck()

    def _use(self, profile) -> None:
        self.profile = profile
        self.ctx.default_up_axis = profile.up_axis  # for sources that do not say it

    def on_message(self, topic, msg: MarkerFrame) -> None:
        if msg.labels != self.labels:  # first frame, or the marker set changed: resolve again
            if self.params.profile == AUTO:  # a ProfileError is counted and logged by the runtime
                self._use(profile_for(AUTO, msg.labels, self.log))
            self.map = self.profile.resolve(msg.labels)
            self.labels = msg.labels
            # (new ones: what they learned was of the old marker set's landmarks)
            self.fills = LandmarkFills(self.params, MarkerSet(self.map.tracking_of, self.map.present(), self.map))
            if (self.params.rebuild or self.params.pose_memory) and self.map.absent_tracking:
                self.log.warning("tracking markers %s of profile %s are not in the stream: gaps filled "
                                 "without them", ", ".join(self.map.absent_tracking), self.profile.name)
            self.log.info("profile %s resolved against %d labels", self.profile.name, len(msg.labels))
            for line in describe_missing(unlocatable(frozenset(self.profile.landmarks))):
                self.log.warning("never located: %s", line)
        positions, dropped = self.gate.filter(msg.positions, msg.header.capture_time_s)
        for k in np.flatnonzero(dropped):
            self.ctx.count_error("marker_jump", f"{msg.labels[k]} moved faster than a body can: dropped this frame")
        lm = self.map.apply(positions)
        said = self.up_check.add(lm, msg.header.up_axis, msg.header.capture_time_s)
        if said:
            self.log.warning(said)
        hips, interpolated = self.hips.fill(lm[HIP_INDEX], lm[ANCHOR_INDEX])
        lm[HIP_INDEX] = hips
        rebuilt = self.fills.fill(lm, self.map.tracking(positions) if self.fills.fills else None,
                                  msg.header.capture_time_s, positions)
        for kind, said in self.fills.said():
            self.ctx.count_error(kind, said)
        flags = np.where(np.isnan(lm).any(axis=1), FLAG_MISSING, FLAG_MEASURED).astype(np.uint8)
        flags[HIP_INDEX[interpolated]] = FLAG_INTERPOLATED
        if rebuilt is not None:
            flags[rebuilt] = FLAG_INTERPOLATED
        self.ctx.publish("markers/filled", MarkerFrame(header=MarkerFrame.make_header(), labels=list(LANDMARKS),
                                                       positions=lm.astype(np.float32), flags=flags), source=msg)

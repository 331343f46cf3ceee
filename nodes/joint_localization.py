"""Stage 3: joint centres and bone frames from the landmarks (thesis 3.4) -> ``skeleton/localized``.

A limb joint whose landmarks hip_interpolation rebuilt (flag interpolated) is reported estimated.
"""
from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

from messages import FLAG_INTERPOLATED, MarkerFrame, SkeletonFrame
from mocap_core.localization import Localizer
from mocap_core.profiles import AUTO, LANDMARKS, load_profile
from nodes.runtime import Node
from nodes.skeleton_codec import to_message


class Params(BaseModel):
    model_config = ConfigDict(extra="forbid")
    profile: str = Field(AUTO, description="marker-set profile (its body measurements feed the fallbacks); auto: "
                                           "default measurements")


class JointLocalization(Node):
    kind = "joint_localization"
    Params = Params
    subscribes = {"markers/filled": MarkerFrame}
    publishes = {"skeleton/localized": SkeletonFrame}

    @classmethod
    def kernels(cls, params):
        return ("localization",)

    def setup(self) -> None:
        if self.params.profile == AUTO:  # hip_interpolation chose it and stamped its up axis
            self.localizer = Localizer()
        else:
            profile = load_profile(self.params.profile)
            self.localizer = Localizer(profile.body)
            self.ctx.default_up_axis = profile.up_axis  # for sources that do not say it

    def on_message(self, topic, msg: MarkerFrame) -> None:
        if msg.labels != list(LANDMARKS):
            raise ValueError("expected landmark frames from hip_interpolation (labels are the PAF landmarks)")
        # interpolated hip markers leave the pelvis located (the thesis): the limb table decides
        loc = self.localizer.localize(msg.positions[None], (msg.flags == FLAG_INTERPOLATED)[None])
        self.ctx.publish("skeleton/localized", to_message(loc.positions[0], loc.frames[0], loc.status[0]), source=msg)

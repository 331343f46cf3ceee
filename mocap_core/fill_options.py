"""The gap fills beyond the thesis, typed and checked once for the nodes, the offline pipeline and the evaluations:
the hip stage's (HipOptions) and the IK gap fill's (FillOptions). Every option off is the thesis's method.
docs/gap_filling.md says what each adds, measured by leaving it out on every shared take."""
from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field, model_validator

from mocap_core.body_model import BODY_MODEL_HELP, END_MODEL_HELP
from mocap_core.hip_interpolation import WHEN_LOST_HELP, WhenLost
from mocap_core.limb_memory import LIMB_MEMORY_HELP
from mocap_core.pair_guard import PAIR_GUARD_HELP
from mocap_core.pose_memory import POSE_MEMORY_HELP
from mocap_core.segment_rebuild import REBUILD_HELP

SWIVEL_HELP = ("beyond the thesis: missing joints between two located ones from bone lengths (each bone as long as on "
               "average while located) and the swivel angle carried in the next joint's or the limb parent's frame")
SEGMENT_CARRY_HELP = ("beyond the thesis: a lost ankle moves with its still-tracked foot (heel and toe markers), a "
                      "lost hand or toe with the last tracked bone before it")
REACQUIRE_HELP = ("beyond the thesis: close the gap to returning markers by at most this many metres a frame (0 = the "
                  "thesis's method: jump)")
BLEND_HELP = ("beyond the thesis: when a joint's markers are lost or come back, go on where the joint was heading and "
              "let the offset to the new source die out as a critically damped spring that halves it in this many "
              "seconds (0 = off: a jump at loss)")
BLEND_COURSE_HELP = ("with blend_half_life_s: after a loss, stay on the markers' course and leave it for the fill only "
                     "as it grows less trustworthy than the fill has been where the markers came back (learned per "
                     "joint; false: the spring alone)")


class _StageOptions(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)

    @classmethod
    def of(cls, params: BaseModel):
        """The options among a node's params (whose Params derive from this model)."""
        return cls(**{name: getattr(params, name) for name in cls.model_fields})


class HipOptions(_StageOptions):
    """The hip stage's fills: of the pelvis when every hip marker is lost, and of lost limb landmarks."""
    when_lost: WhenLost = Field("hold", description=WHEN_LOST_HELP)
    rebuild: bool = Field(False, description=REBUILD_HELP)
    pose_memory: bool = Field(False, description=POSE_MEMORY_HELP)
    pair_guard: bool = Field(False, description=PAIR_GUARD_HELP)


# The fills that learn from the mirrored limb: the torso, which has none, runs without them.
MIRROR_FILLS = ("body_model", "end_model")


class FillOptions(_StageOptions):
    """Which fills run beside the thesis's IK. The limb memory and the body model steer the swivel, so they need it;
    the body and end models act on the four limbs only (MIRROR_FILLS)."""
    swivel: bool = Field(False, description=SWIVEL_HELP)
    segment_carry: bool = Field(False, description=SEGMENT_CARRY_HELP)
    limb_memory: bool = Field(False, description=LIMB_MEMORY_HELP + " (with swivel)")
    body_model: bool = Field(False, description=BODY_MODEL_HELP)
    end_model: bool = Field(False, description=END_MODEL_HELP)
    reacquire_step_m: float = Field(0.0, ge=0, description=REACQUIRE_HELP)
    blend_half_life_s: float = Field(0.0, ge=0, description=BLEND_HELP)
    blend_course: bool = Field(True, description=BLEND_COURSE_HELP)

    @model_validator(mode="after")
    def _steers_the_swivel(self):
        idle = [name for name in ("limb_memory", "body_model") if getattr(self, name)]
        if idle and not self.swivel:
            raise ValueError(f"{' and '.join(idle)} steer the swivel, which is off: set swivel true, or "
                             f"{' and '.join(idle)} false")
        return self

    @staticmethod
    def idle_on(limb: str) -> tuple[str, ...]:
        """The fills that do nothing on ``limb``: on the torso, those that learn from a mirrored limb."""
        return MIRROR_FILLS if limb == "torso" else ()

    def for_limb(self, limb: str) -> "FillOptions":
        """These options as they act on ``limb``: without the fills idle there."""
        return self.model_copy(update=dict.fromkeys(self.idle_on(limb), False))

    def refuse_idle(self, limb: str) -> None:
        """A ValueError, saying what to do, when a fill is asked for on a limb where it does nothing."""
        idle = [name for name in self.idle_on(limb) if getattr(self, name)]
        if idle:
            names = " and ".join(idle)
            raise ValueError(f"{names} learn{'s' if len(idle) == 1 else ''} from the mirrored limb, which the torso "
                             f"has not: leave {names} out of the torso's params")


# The studio's choice (the ``studio`` preset, mocap_core.presets): every option on.
STUDIO_HIPS = HipOptions(when_lost="fit", rebuild=True, pose_memory=True, pair_guard=True)
STUDIO = FillOptions(swivel=True, segment_carry=True, limb_memory=True, body_model=True, end_model=True,
                     reacquire_step_m=0.01, blend_half_life_s=0.1)
HELP = {name: field.description for model in (HipOptions, FillOptions) for name, field in model.model_fields.items()}

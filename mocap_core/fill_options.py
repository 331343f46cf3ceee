"""The gap fills beyond the thesis as each stage's options, typed and checked once for the nodes, the offline
pipeline and the evaluations: the hip stage's (HipOptions) and the IK gap fill's (FillOptions). Each is made of
the settings of the fills registered in mocap_core.fills. Every option off is the thesis's method.
docs/gap_filling.md says what each adds, measured by leaving it out on every shared take."""
from __future__ import annotations

from typing import ClassVar

from pydantic import BaseModel, ConfigDict, Field, create_model, model_validator

from mocap_core.fill_units import Fill
from mocap_core.fills import LANDMARK_FILLS, LIMB_FILLS
from mocap_core.hip_interpolation import WHEN_LOST_HELP, WhenLost


class _StageOptions(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)
    fills: ClassVar[tuple[type[Fill], ...]] = ()  # the fills these options are made of, in their order

    @classmethod
    def of(cls, params: BaseModel):
        """The options among a node's params (whose Params derive from this model)."""
        return cls(**{name: getattr(params, name) for name in cls.model_fields})


def _options(name: str, base: type[_StageOptions], fills: tuple[type[Fill], ...], doc: str):
    """The options model of a stage: ``base``'s own fields and every fill's settings."""
    fields = {}
    for fill in fills:
        for field, info in fill.Settings.model_fields.items():
            fields.setdefault(field, (info.annotation, info))
    model = create_model(name, __base__=base, __module__=__name__, __doc__=doc, **fields)
    model.fills = fills
    return model


class _HipBase(_StageOptions):
    when_lost: WhenLost = Field("hold", description=WHEN_LOST_HELP)


def hip_options(fills: tuple[type[Fill], ...]):
    """The hip stage's options with these landmark fills."""
    return _options("HipOptions", _HipBase, fills,
                    "The hip stage's fills: of the pelvis when every hip marker is lost, and of lost limb landmarks.")


class _LimbBase(_StageOptions):
    @model_validator(mode="after")
    def _needs_on(self):
        for need in dict.fromkeys(fill.needs for fill in self.fills if fill.needs):
            idle = [fill.option() for fill in self.fills if fill.needs == need and fill.wanted(self)]
            if idle and not getattr(self, need):
                names = " and ".join(idle)
                raise ValueError(f"{names} steer{'s' if len(idle) == 1 else ''} the {need}, which is off: set {need} "
                                 f"true, or {names} false")
        return self

    @classmethod
    def idle_on(cls, limb: str) -> tuple[str, ...]:
        """The fills that do nothing on ``limb``: on the torso, those that learn from a mirrored limb."""
        return tuple(fill.option() for fill in cls.fills if fill.mirrored) if limb == "torso" else ()

    def for_limb(self, limb: str):
        """These options as they act on ``limb``: without the fills idle there."""
        return self.model_copy(update=dict.fromkeys(self.idle_on(limb), False))

    def refuse_idle(self, limb: str) -> None:
        """A ValueError, saying what to do, when a fill is asked for on a limb where it does nothing."""
        idle = [name for name in self.idle_on(limb) if getattr(self, name)]
        if idle:
            names = " and ".join(idle)
            raise ValueError(f"{names} learn{'s' if len(idle) == 1 else ''} from the mirrored limb, which the torso "
                             f"has not: leave {names} out of the torso's params")


def limb_options(fills: tuple[type[Fill], ...]):
    """The IK stage's options with these limb fills."""
    return _options("FillOptions", _LimbBase, fills,
                    "Which fills run beside the thesis's IK, on each limb. A fill that steers another (the limb "
                    "memory and the body model, the swivel) needs it on; those that learn from the mirrored limb "
                    "act on the four limbs only.")


HipOptions = hip_options(LANDMARK_FILLS)
FillOptions = limb_options(LIMB_FILLS)

# The studio's choice (the ``studio`` preset, mocap_core.presets): every option on.
STUDIO_HIPS = HipOptions(when_lost="fit", rebuild=True, pose_memory=True, pair_guard=True)
STUDIO = FillOptions(swivel=True, segment_carry=True, limb_memory=True, body_model=True, end_model=True,
                     reacquire_step_m=0.01, blend_half_life_s=0.1, rigid=True)

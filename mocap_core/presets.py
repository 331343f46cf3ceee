"""The two ways the graph's stages fill gaps, each named once: ``thesis`` (the thesis's method) and ``studio`` (the
options beyond it that `mocap solve` uses by default). A stage's ``preset`` param picks one for its section; a param
given beside it wins (``{preset: studio, end_model: false}``)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from mocap_core.fill_options import STUDIO, STUDIO_HIPS, FillOptions, HipOptions

Preset = Literal["thesis", "studio"]
PRESET_HELP = ("thesis: the thesis's method; studio: the gap filling beyond it (docs/gap_filling.md); a param "
               "given beside it wins")


@dataclass(frozen=True)
class Options:
    """Both stages' fills: the hip stage's and the IK gap fill's."""
    hips: HipOptions = HipOptions()
    ik: FillOptions = FillOptions()


PRESETS: dict[str, Options] = {"thesis": Options(), "studio": Options(STUDIO_HIPS, STUDIO)}


def with_preset(stage: str, params, leave: tuple[str, ...] = ()):
    """A node's raw params with its preset's values for ``stage`` ("hips", "ik") under the ones it gives, but for
    those named in ``leave`` (which do nothing where the node runs)."""
    if not isinstance(params, dict) or params.get("preset", "studio") not in PRESETS:
        return params  # pydantic says what is wrong
    preset = getattr(PRESETS[params.get("preset", "studio")], stage).model_dump(exclude=set(leave))
    return {**preset, **params}

"""The two ways the graph's stages fill gaps, each named once: ``thesis`` (the thesis's method) and ``studio`` (the
options beyond it that `mocap solve` uses by default). A stage's ``preset`` param picks one for its section; a param
given beside it wins (``{preset: studio, swivel: false}``)."""
from __future__ import annotations

from typing import Literal

from mocap_core.gapfill import BEYOND_THESIS

Preset = Literal["thesis", "studio"]
PRESET_HELP = ("thesis: the thesis's method; studio: the gap filling beyond it (docs/gap_filling.md); a param "
               "given beside it wins")
PRESETS: dict[str, dict[str, dict]] = {
    "thesis": {"hips": {}, "ik": {}},
    "studio": {"hips": {"when_lost": "fit", "rebuild": True, "pose_memory": True, "pair_guard": True},
               "ik": BEYOND_THESIS},
}


def with_preset(stage: str, params):
    """A node's raw params with its preset's values for ``stage`` ("hips", "ik") under the ones it gives."""
    if not isinstance(params, dict) or params.get("preset", "thesis") not in PRESETS:
        return params  # pydantic says what is wrong
    return {**PRESETS[params.get("preset", "thesis")][stage], **params}

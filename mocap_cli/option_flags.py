"""A stage's options (mocap_core.fill_options) as command-line flags, named from its fields: a switch
``pose_memory`` is ``--pose-memory``, one on by default ``blend_course`` is ``--no-blend-course``, a number
``blend_half_life_s`` is ``--blend-half-life S`` (its unit as the metavar)."""
from __future__ import annotations

import argparse

from pydantic import BaseModel

UNITS = {"_s": "S", "_m": "M"}


def _flag(name: str, field) -> tuple[str, str | None]:
    """(the flag, its metavar)."""
    unit = next((suffix for suffix in UNITS if name.endswith(suffix)), None)
    if field.annotation is bool:
        return f"--{'no-' if field.default else ''}{name.replace('_', '-')}", None
    stem = name.removesuffix(unit) if unit else name
    return f"--{stem.replace('_', '-')}", UNITS.get(unit, "X")


def add_option_flags(parser, model: type[BaseModel], skip: tuple[str, ...] = ()) -> None:
    for name, field in model.model_fields.items():
        if name in skip:
            continue
        flag, metavar = _flag(name, field)
        if field.annotation is bool:
            help = f"{name} false; by default, {field.description}" if field.default else field.description
            parser.add_argument(flag, dest=name, action="store_false" if field.default else "store_true",
                                help=help)
        else:
            parser.add_argument(flag, dest=name, type=field.annotation, default=field.default, metavar=metavar,
                                help=field.description)


def options_of(model: type[BaseModel], args: argparse.Namespace):
    """The options the parsed flags give (a ValueError, pydantic's, for a combination it refuses)."""
    return model(**{name: getattr(args, name) for name in model.model_fields})


def flags_text(models: tuple[type[BaseModel], ...], args: argparse.Namespace, skip: tuple[str, ...] = ()) -> list[str]:
    """The flags given that differ from the defaults, as they were written."""
    out = []
    for model in models:
        for name, field in model.model_fields.items():
            value = getattr(args, name)
            if name in skip or value == field.default:
                continue
            flag, _ = _flag(name, field)
            out.append(flag if field.annotation is bool else f"{flag} {value}")
    return out

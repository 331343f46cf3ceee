"""Joint limits from a user-editable YAML file (defaults: mocap_core/data/constraints.yaml)."""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from mocap_core.skeleton import INDEX, JOINTS

DEFAULT_FILE = Path(__file__).resolve().parents[1] / "data" / "constraints.yaml"
_ROT = re.compile(r"^rot([xyz]):(-?\d+(\.\d+)?)$")


class ConstraintsError(Exception):
    pass


class JointLimits(BaseModel):
    model_config = ConfigDict(extra="forbid")
    cone: list[float] | None = Field(None, min_length=4, max_length=4)
    twist: list[float] | None = Field(None, min_length=2, max_length=2)
    parent_pointer: list[str] = []

    @field_validator("cone")
    @classmethod
    def _cone_range(cls, v):
        if v is not None and not all(0 <= a <= 180 for a in v):
            raise ValueError(f"cone angles must be within 0..180 degrees, got {v}")
        return v

    @field_validator("twist")
    @classmethod
    def _twist_range(cls, v):
        if v is not None and not (-180 <= v[0] <= v[1] <= 180):
            raise ValueError(f"twist must be [min, max] within -180..180 with min <= max, got {v}")
        return v

    @field_validator("parent_pointer")
    @classmethod
    def _rotations(cls, v):
        for r in v:
            if not _ROT.match(r.replace(" ", "")):
                raise ValueError(f"parent_pointer entry {r!r}: write rotx:DEG, roty:DEG or rotz:DEG")
        return v


def _axis_rotation(axis: str, deg: float) -> np.ndarray:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return {"x": np.array([[1, 0, 0], [0, c, -s], [0, s, c]]),
            "y": np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
            "z": np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])}[axis]


@dataclass
class Constraints:
    """Per joint (model order): parent pointer, cone angles (radians), twist range (radians)."""

    pp: np.ndarray          # (J, 3, 3)
    cones: np.ndarray       # (J, 4)
    has_cone: np.ndarray    # (J,) bool
    twists: np.ndarray      # (J, 2)
    has_twist: np.ndarray   # (J,) bool
    source: str = ""


def load_constraints(path: str | Path | None = None) -> Constraints:
    path = Path(path) if path else DEFAULT_FILE
    try:
        raw = yaml.safe_load(path.read_text())
    except FileNotFoundError:
        raise ConstraintsError(f"constraints file {path} not found") from None
    except yaml.YAMLError as e:
        raise ConstraintsError(f"constraints file {path}: not valid YAML ({e})") from None
    if not isinstance(raw, dict) or not isinstance(raw.get("joints"), dict):
        raise ConstraintsError(f"constraints file {path}: expected a 'joints' mapping")
    n = len(JOINTS)
    c = Constraints(np.tile(np.eye(3), (n, 1, 1)), np.zeros((n, 4)), np.zeros(n, bool), np.zeros((n, 2)),
                    np.zeros(n, bool), str(path))
    for name, spec in raw["joints"].items():
        if name not in INDEX:
            raise ConstraintsError(f"constraints file {path}: unknown joint {name!r} (joints: {', '.join(JOINTS)})")
        try:
            lim = JointLimits.model_validate(spec or {})
        except ValidationError as e:
            err = e.errors()[0]
            raise ConstraintsError(f"constraints file {path}, joint {name}: {err['msg']}") from None
        j = INDEX[name]
        for r in lim.parent_pointer:
            axis, deg = _ROT.match(r.replace(" ", "")).group(1, 2)
            c.pp[j] = c.pp[j] @ _axis_rotation(axis, float(deg))
        if lim.cone is not None:
            c.cones[j] = np.radians(lim.cone)
            c.has_cone[j] = True
        if lim.twist is not None:
            c.twists[j] = np.radians(lim.twist)
            c.has_twist[j] = True
    return c

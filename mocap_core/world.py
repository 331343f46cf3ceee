"""The world a source's positions live in: which axis points up.

Worlds are right-handed and in metres everywhere in the graph (QTM's and every file format's are).
Only the up axis varies: QTM says it in its 3D parameters (``AxisUpwards``, "+Z" by default), a
recorded bag in its messages' headers, and a marker-set profile for files that say nothing. It is
written ``"+z"``, ``"-y"`` and so on; ``"z"`` is read as ``"+z"``.

Outputs that need a fixed convention turn the world to "canonical": right-handed, +Y up (BVH's,
and one Z flip from Unity's left-handed Y up).
"""
from __future__ import annotations

from typing import Literal, get_args

import numpy as np

UpAxis = Literal["+x", "-x", "+y", "-y", "+z", "-z"]
UP_AXES: tuple[str, ...] = get_args(UpAxis)
DEFAULT_UP: str = "+z"  # QTM's default
MAX_COORDINATE_M = 1000.0  # no capture volume reaches this far from its origin: a coordinate past it is a glitch


def normalize_up(text: str) -> str:
    """"Z", "+Z", "z" -> "+z"; "-Y" -> "-y". Raises ValueError on anything else."""
    s = str(text).strip().lower()
    if s in ("x", "y", "z"):
        s = "+" + s
    if s not in UP_AXES:
        raise ValueError(f"up axis {text!r}: expected one of {', '.join(UP_AXES)} (or x, y, z)")
    return s


def to_canonical(up_axis: str) -> np.ndarray:
    """The rotation from a right-handed world with this up axis to right-handed +Y up: the up axis
    goes to +Y and the world's x axis stays +X (its y axis when x is up)."""
    up = normalize_up(up_axis)
    axis, sign = "xyz".index(up[1]), 1.0 if up[0] == "+" else -1.0
    e = np.eye(3)
    new_y = sign * e[axis]
    new_x = e[1] if axis == 0 else e[0]
    new_z = np.cross(new_x, new_y)
    return np.array([new_x, new_y, new_z])  # rows: the canonical axes in source coordinates


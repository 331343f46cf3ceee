"""Typed numpy array fields for pydantic models.

On the wire an array is a msgpack map ``{"dtype": "<f4", "shape": [n, 3], "data": <bytes>}``
(docs/design.md: arrays travel as raw bytes plus dtype and shape, never as lists of floats).
``Array(dtype, shape)`` builds an annotated field type that accepts either a numpy array or that
map, and checks dtype and shape; ``None`` in a shape means "any length on this axis".
"""
from __future__ import annotations

from typing import Annotated, Any

import numpy as np
from pydantic import PlainSerializer, PlainValidator, WithJsonSchema

WIRE_JSON_SCHEMA = {
    "type": "object",
    "description": "numpy array: little-endian raw bytes plus dtype and shape",
    "properties": {
        "dtype": {"type": "string", "examples": ["<f4"]},
        "shape": {"type": "array", "items": {"type": "integer", "minimum": 0}},
        "data": {"type": "string", "contentEncoding": "base64"},
    },
    "required": ["dtype", "shape", "data"],
}


def to_wire(a: np.ndarray) -> dict:
    return {"dtype": a.dtype.str, "shape": list(a.shape), "data": a.tobytes()}  # tobytes is C order


def _from_wire(value: Any, dtype: np.dtype) -> np.ndarray:
    if type(value) is dict:
        try:
            wire_dtype, shape, data = value["dtype"], value["shape"], value["data"]
        except KeyError as e:
            raise ValueError(f"array map needs dtype, shape and data (no {e})") from None
        if wire_dtype != dtype.str:
            raise ValueError(f"dtype {wire_dtype!r}, expected {dtype.str}")
        count = 1
        for s in shape if isinstance(shape, (list, tuple)) else (None,):
            if type(s) is not int or s < 0:
                raise ValueError(f"bad shape {shape!r}")
            count *= s
        if type(data) is not bytes or len(data) != count * dtype.itemsize:
            size = len(data) if isinstance(data, (bytes, bytearray)) else "?"
            raise ValueError(f"data has {size} bytes, shape {list(shape)} of {dtype.str} needs {count * dtype.itemsize}")
        return np.frombuffer(data, dtype=dtype).reshape(shape)
    if isinstance(value, np.ndarray):
        return value if value.dtype == dtype else value.astype(dtype)
    if isinstance(value, (list, tuple)):  # convenient when building messages by hand
        try:
            return np.asarray(value, dtype=dtype)
        except (TypeError, ValueError, OverflowError) as e:  # ragged, out of range, not numbers
            raise ValueError(f"cannot make a {dtype.str} array: {e}") from None
    raise ValueError(f"expected an array, got {type(value).__name__}")


def Array(dtype: str | type, shape: tuple[int | None, ...]) -> Any:
    """Annotated numpy field with a fixed dtype and a shape pattern such as ``(None, 3)``."""
    dt = np.dtype(dtype).newbyteorder("<") if np.dtype(dtype).itemsize > 1 else np.dtype(dtype)

    ndim = len(shape)
    fixed = [(axis, want) for axis, want in enumerate(shape) if want is not None]

    def validate(value: Any) -> np.ndarray:
        a = _from_wire(value, dt)
        got = a.shape
        if len(got) != ndim or any(got[axis] != want for axis, want in fixed):
            pattern = "(" + ", ".join("n" if s is None else str(s) for s in shape) + ")"
            raise ValueError(f"shape {a.shape}, expected {pattern}")
        return a

    validate.array_spec = (dt, shape)  # messages.fastpath inlines the same checks
    return Annotated[
        np.ndarray,
        PlainValidator(validate),
        PlainSerializer(to_wire),
        WithJsonSchema(WIRE_JSON_SCHEMA),
    ]

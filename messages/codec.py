"""The one msgpack codec shared by every node, tool and bag (like Jupyter's single message spec).

A message is a msgpack map of its fields; arrays are maps of dtype, shape and raw bytes
(messages.arrays). Decoding checks the schema name, the version and every array's dtype and shape,
and raises :class:`DecodeError` naming the topic and the reason. Validation runs through checkers
compiled from the pydantic models (messages.fastpath) and falls back to pydantic itself.
"""
from __future__ import annotations

import msgpack
import numpy as np
from pydantic import ValidationError

from messages.arrays import to_wire
from messages.fastpath import fast_decode, fast_encode, header_decoder, peek_header
from messages.schemas import BY_SCHEMA, Header, Message

MAX_MESSAGE_BYTES = 16 * 1024 * 1024  # also set as ZMQ_MAXMSGSIZE on every socket
_fast_header = header_decoder(Header)


class DecodeError(Exception):
    """A message that cannot be decoded: bad bytes, foreign or wrong schema, bad version or shape."""

    def __init__(self, topic: str, reason: str, kind: str = "invalid"):
        super().__init__(f"topic {topic!r}: {reason}")
        self.topic, self.reason, self.kind = topic, reason, kind


def encode(msg: Message) -> bytes:
    return fast_encode(msg)


def peek_schema(payload: bytes) -> tuple[str, int] | None:
    """The (schema, version) of an encoded message, or None when it has no readable header."""
    header = peek_header(payload)
    schema, version = header.get("schema"), header.get("version")
    return (schema, version) if type(schema) is str and type(version) is int else None


def decode(payload: bytes, topic: str = "?", expected: type[Message] | None = None) -> Message:
    _check_size(payload, topic)
    cls = expected if expected is not None and expected is not Message else _by_schema(payload)
    if cls is not None:
        msg = fast_decode(cls, payload)
        if msg is not None and msg.header.schema_name == cls.SCHEMA and msg.header.version == cls.VERSION:
            return msg
    return _checked_decode(payload, topic, expected)


def decode_header(payload: bytes, topic: str = "?", expected: type[Message] | None = None) -> Header:
    """Check only a message's header (schema, version, the header's own fields), for a node that
    forwards or stores bytes without reading them; the arrays are checked by whoever decodes it.
    Raises the same :class:`DecodeError` as :func:`decode` for what it checks."""
    _check_size(payload, topic)
    h = _fast_header(payload)
    cls = BY_SCHEMA.get(h.schema_name) if h is not None else None
    if cls is not None and cls.VERSION == h.version and (expected is None or expected is Message or cls is expected):
        return h
    return _checked_header(payload, topic, expected)[2]  # raises, unless pydantic takes what msgspec did not


def _check_size(payload: bytes, topic: str) -> None:
    if len(payload) > MAX_MESSAGE_BYTES:
        raise DecodeError(topic, f"{len(payload)} bytes exceeds the {MAX_MESSAGE_BYTES}-byte limit", "oversized")


def _by_schema(payload: bytes) -> type[Message] | None:
    schema = peek_header(payload).get("schema")
    return BY_SCHEMA.get(schema) if type(schema) is str else None


def _checked_decode(payload: bytes, topic: str, expected: type[Message] | None) -> Message:
    """The authoritative path: every check in order, pydantic validation, a precise error."""
    cls, data, _ = _checked_header(payload, topic, expected)
    try:
        return cls.model_validate(data)
    except ValidationError as e:
        first = e.errors()[0]
        where = ".".join(str(p) for p in first["loc"]) or cls.SCHEMA
        raise DecodeError(topic, f"{cls.SCHEMA}.{where}: {first['msg']}", "invalid") from None


def _checked_header(payload: bytes, topic: str, expected: type[Message] | None) -> tuple[type[Message], dict, Header]:
    """(model class, msgpack map, header) of a message whose header is right; else the precise DecodeError."""
    try:
        data = msgpack.unpackb(payload, raw=False, strict_map_key=True)
    except Exception as e:  # msgpack raises several unrelated types on garbage
        raise DecodeError(topic, f"not msgpack ({type(e).__name__}: {e})", "garbage") from None
    if not isinstance(data, dict) or not isinstance(data.get("header"), dict):
        raise DecodeError(topic, "not a message: no header map", "foreign")
    schema = data["header"].get("schema")
    cls = BY_SCHEMA.get(schema) if isinstance(schema, str) else None
    if cls is None:
        raise DecodeError(topic, f"unknown schema {schema!r}", "foreign")
    if expected is not None and expected is not Message and cls is not expected:
        raise DecodeError(topic, f"schema {schema} on a topic of {expected.SCHEMA}", "wrong_schema")
    version = data["header"].get("version")
    if version != cls.VERSION:
        upgrade = UPGRADES.get((schema, version)) if type(version) is int else None
        if upgrade is None:
            raise DecodeError(topic, f"{schema} version {version!r}, this build reads {cls.VERSION}", "version")
        data = upgrade(data)
    try:
        header = Header.model_validate(data["header"])
    except ValidationError as e:
        first = e.errors()[0]
        where = ".".join(str(p) for p in first["loc"])
        raise DecodeError(topic, f"{schema}.header.{where}: {first['msg']}", "invalid") from None
    return cls, data, header


def _quaternions_to_rotations(data: dict) -> dict:
    """A version-1 skeleton or limb message, whose bone frames were quaternions (x, y, z, w) in ``orientations``,
    as version 2 (rotation matrices in ``rotations``). What is malformed is left for validation to name."""
    from mocap_core.ik.kernels import quats_to_frames

    wire = data.pop("orientations", None)
    try:
        quats = np.frombuffer(wire["data"], "<f4").reshape(wire["shape"]).astype(np.float64)
    except (KeyError, TypeError, ValueError):
        quats = None
    if quats is not None and quats.ndim == 2 and quats.shape[1] == 4:
        data["rotations"] = to_wire(quats_to_frames(quats).astype(np.float32))
    data["header"] = {**data["header"], "version": data["header"]["version"] + 1}
    return data


# Older versions this build still reads (recorded bags), each turned into the next: (schema, version) -> upgrade.
UPGRADES = {("mocap.SkeletonFrame", 1): _quaternions_to_rotations, ("mocap.LimbSolution", 1): _quaternions_to_rotations}


def json_schemas() -> dict[str, dict]:
    """JSON Schema of every message, keyed by schema name (bags and docs use these)."""
    return {name: cls.model_json_schema(by_alias=True) for name, cls in BY_SCHEMA.items()}

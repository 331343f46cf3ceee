"""The codec's hot path: msgspec decoders and builders generated from the pydantic models.

The pydantic models stay the one definition of every message, and pydantic stays the judge of
anything unusual. But validating a 35-marker frame with pydantic costs about half the codec's
20 us budget (the array fields need Python validators), so for each model this module derives,
once:

- a msgspec Struct with the same wire keys and types, so decoding the msgpack bytes and checking
  every type happens in one C pass (unknown keys are refused, as pydantic's extra="forbid" does);
- a generated function (the way ``dataclasses`` writes ``__init__``) that checks each array's
  dtype and shape, builds the pydantic instance directly and runs the model's "after" validators.

The fast path only accepts what pydantic accepts unchanged (no lax coercions beyond int -> float);
whatever it refuses goes to pydantic, which then gives the authoritative answer and error message.
tests/messages/test_fastpath.py checks the two agree.
"""
from __future__ import annotations

import typing
from typing import Any, Callable, Literal

import msgspec
import numpy as np
from pydantic import BaseModel, PlainValidator

from messages.arrays import to_wire

_IMMUTABLE = (str, int, float, bool, type(None))
Build = Callable[[bytes], BaseModel]


class _Reject(Exception):
    """The fast path will not decide; pydantic will."""


class ArrayWire(msgspec.Struct, forbid_unknown_fields=True):
    dtype: str
    shape: list[int]
    data: bytes


def _array_spec(metadata: list) -> tuple[np.dtype, tuple] | None:
    for m in metadata:
        if isinstance(m, PlainValidator):
            return getattr(m.func, "array_spec", None)  # set by messages.arrays.Array
    return None


class _Compiled:
    """One model's wire Struct and the source of its Struct -> pydantic builder."""

    def __init__(self, struct: type, build: Callable[[Any], BaseModel]):
        self.struct, self.build = struct, build
        self.decoder = msgspec.msgpack.Decoder(struct)


_COMPILED: dict[type, _Compiled | None] = {}


def _field(k: int, annotation: Any, metadata: list, ns: dict) -> tuple[Any, list[str]] | None:
    """(msgspec type, source lines turning ``v`` into the value to store) for one field;
    None when this module does not handle the type (the model then always goes to pydantic)."""
    spec = _array_spec(metadata)
    if spec is not None:
        dt, shape = spec
        ns[f"DT{k}"], ns[f"DS{k}"] = dt, dt.str
        lines = ["s = v.shape", f"if v.dtype != DS{k} or len(s) != {len(shape)}: raise _Reject", f"n = {dt.itemsize}"]
        for axis, want in enumerate(shape):
            test = "x < 0" if want is None else f"x != {want}"
            lines += [f"x = s[{axis}]", f"if {test}: raise _Reject", "n *= x"]
        lines += ["if len(v.data) != n: raise _Reject", f"v = _ndarray(tuple(s), DT{k}, v.data)"]
        return ArrayWire, lines
    if metadata:
        return None
    origin, args = typing.get_origin(annotation), typing.get_args(annotation)
    if annotation in (str, int, float, bool) or (origin is Literal and all(type(a) is str for a in args)) \
            or (origin is list and args == (str,)):
        return annotation, []  # msgspec checks these exactly (and turns an int into a float)
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        sub = compile_model(annotation)
        if sub is None:
            return None
        ns[f"B{k}"] = sub.build
        return sub.struct, [f"v = B{k}(v)"]
    return None


def compile_model(cls: type[BaseModel]) -> _Compiled | None:
    """The wire Struct and builder of a model, or None when pydantic has to handle it alone."""
    if cls in _COMPILED:
        return _COMPILED[cls]
    _COMPILED[cls] = None  # also the answer for a model that refers to itself
    decorators = cls.__pydantic_decorators__
    if decorators.field_validators or decorators.validators or decorators.root_validators \
            or any(d.info.mode != "after" for d in decorators.model_validators.values()) \
            or cls.model_config.get("extra") != "forbid":
        return None
    ns: dict[str, Any] = {"_Reject": _Reject, "_ndarray": np.ndarray, "_cls": cls, "UNSET": msgspec.UNSET,
                          "_set": object.__setattr__}
    required = [name for name, info in cls.model_fields.items() if info.is_required()]
    struct_fields, body, names = [], ["def build(w):", f"    given = {{{', '.join(map(repr, required))}}}" if required
                                      else "    given = set()"], []
    for k, (name, info) in enumerate(cls.model_fields.items()):
        compiled = _field(k, info.annotation, info.metadata, ns)
        if compiled is None:
            return None
        wire_type, lines = compiled
        key = info.alias or name
        body.append(f"    v = w.{key}")
        if info.is_required():
            struct_fields.append((key, wire_type))
            body += ["    " + line for line in lines]  # (in ``given`` from the start: always there)
        else:
            default = info.get_default(call_default_factory=True)
            if not isinstance(default, _IMMUTABLE):
                return None  # pydantic copies mutable defaults; leave those models to it
            struct_fields.append((key, wire_type | msgspec.UnsetType, msgspec.UNSET))
            ns[f"D{k}"] = default
            body += ["    if v is UNSET:", f"        v = D{k}", "    else:"]
            body += ["        " + line for line in lines] + [f"        given.add({name!r})"]
        body.append(f"    f{k} = v")
        names.append(name)
    values = ", ".join(f"{name!r}: f{k}" for k, name in enumerate(names))
    body += ["    inst = _cls.__new__(_cls)",
             f"    _set(inst, '__dict__', {{{values}}})",
             "    _set(inst, '__pydantic_fields_set__', given)",
             "    _set(inst, '__pydantic_extra__', None)",
             "    _set(inst, '__pydantic_private__', None)"]
    for j, dec in enumerate(decorators.model_validators.values()):
        ns[f"A{j}"] = dec.func
        body += ["    try:", f"        inst = A{j}(inst)", "    except ValueError:", "        raise _Reject from None"]
    body.append("    return inst")
    exec("\n".join(body), ns)  # noqa: S102 - source built above from the model's own fields
    struct = msgspec.defstruct(f"{cls.__name__}Wire", struct_fields, forbid_unknown_fields=True, kw_only=True)
    _COMPILED[cls] = _Compiled(struct, ns["build"])
    return _COMPILED[cls]


def fast_decode(cls: type[BaseModel], payload: bytes) -> BaseModel | None:
    """The decoded, validated instance, or None when pydantic has to decide."""
    compiled = _COMPILED[cls] if cls in _COMPILED else compile_model(cls)
    if compiled is None:
        return None
    try:
        return compiled.build(compiled.decoder.decode(payload))
    except Exception:  # _Reject, msgspec's errors, bad UTF-8...: the checked path classifies them
        return None


class _Peek(msgspec.Struct):  # only the header; every other key is skipped in C
    header: dict


_peek = msgspec.msgpack.Decoder(_Peek)


def header_decoder(header_cls: type[BaseModel]) -> Callable[[bytes], BaseModel | None]:
    """``read(payload)``: the checked header of an encoded message as a ``header_cls`` instance (the
    rest of the message is skipped, not checked), or None when it has no valid one."""
    compiled = compile_model(header_cls)
    decoder = msgspec.msgpack.Decoder(msgspec.defstruct("HeaderOnly", [("header", compiled.struct)]))

    def read(payload: bytes) -> BaseModel | None:
        try:
            return compiled.build(decoder.decode(payload).header)
        except Exception:  # garbage of any kind: the checked path says what is wrong
            return None

    return read


def peek_header(payload: bytes) -> dict:
    """The header map of an encoded message, or {} when it has none."""
    try:
        return _peek.decode(payload).header
    except Exception:  # garbage of any kind: no header
        return {}


_ARRAY_FIELDS: dict[type, tuple[str, ...]] = {}


def array_fields(cls: type[BaseModel]) -> tuple[str, ...]:
    """The names of a model's array fields (top level)."""
    got = _ARRAY_FIELDS.get(cls)
    if got is None:
        got = _ARRAY_FIELDS[cls] = tuple(n for n, f in cls.model_fields.items() if _array_spec(f.metadata))
    return got


# -- encoding ----------------------------------------------------------------------------------------
_PACKERS: dict[type, Callable[[BaseModel], dict]] = {}


def packer(cls: type[BaseModel]) -> Callable[[BaseModel], dict]:
    """``to_map(instance)``: the msgpack-ready map of a model (aliases as keys, arrays as wire maps)."""
    if cls in _PACKERS:
        return _PACKERS[cls]
    ns: dict[str, Any] = {"_to_wire": to_wire}
    items = []
    for k, (name, info) in enumerate(cls.model_fields.items()):
        value = f"d[{name!r}]"
        if _array_spec(info.metadata) is not None:
            value = f"_to_wire({value})"
        elif isinstance(info.annotation, type) and issubclass(info.annotation, BaseModel):
            ns[f"P{k}"] = packer(info.annotation)
            value = f"P{k}({value})"
        items.append(f"{(info.alias or name)!r}: {value}")
    exec(f"def to_map(m):\n    d = m.__dict__\n    return {{{', '.join(items)}}}", ns)  # noqa: S102
    _PACKERS[cls] = ns["to_map"]
    return ns["to_map"]


def _enc_hook(obj: Any) -> Any:
    """Values a node left as numpy types (a float32 residual, say) or models inside a dict."""
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return to_wire(obj)
    if isinstance(obj, BaseModel):
        return packer(type(obj))(obj)
    raise TypeError(f"cannot encode {type(obj).__name__}")


_encoder = msgspec.msgpack.Encoder(enc_hook=_enc_hook)


def prepare(cls: type[BaseModel]) -> None:
    """Build a model's decoder and packer now rather than on its first message (a few ms each)."""
    if cls not in _COMPILED:
        compile_model(cls)
    packer(cls)
    array_fields(cls)


def fast_encode(msg: BaseModel) -> bytes:
    return _encoder.encode(packer(type(msg))(msg))

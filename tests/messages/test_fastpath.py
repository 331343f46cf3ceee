"""The codec's generated fast path agrees with pydantic: whatever it accepts, pydantic accepts with
the same values; whatever pydantic rejects, the fast path hands over (so the error is pydantic's)."""
import msgpack
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pydantic import BaseModel, ValidationError

from messages import ALL_MESSAGES, DecodeError, Heartbeat, decode, encode
from messages.fastpath import compile_model, fast_decode
from tests.messages.test_codec import samples

HOT = [m for m in samples() if not isinstance(m, Heartbeat)]


def same(a, b):
    for name in type(a).model_fields:
        x, y = getattr(a, name), getattr(b, name)
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype and x.shape == y.shape
            np.testing.assert_array_equal(x, y)
        elif isinstance(x, BaseModel):  # a nested model (the header): field by field
            same(x, y)
        else:  # (NaN is a value like any other here: a header's time may be NaN)
            assert (x == y or (x != x and y != y)) and type(x) is type(y), name
    assert a.model_fields_set == b.model_fields_set


@pytest.mark.parametrize("msg", HOT, ids=lambda m: m.SCHEMA)
def test_hot_messages_take_the_fast_path(msg):
    # Every per-frame message is compiled, so decoding never falls back to pydantic for good input.
    assert compile_model(type(msg)) is not None
    fast = fast_decode(type(msg), encode(msg))
    assert fast is not None
    same(fast, type(msg).model_validate(msgpack.unpackb(encode(msg))))


def test_heartbeat_is_left_to_pydantic():
    assert compile_model(Heartbeat) is None  # dict fields with mutable defaults: pydantic copies them
    hb = samples()[-1]
    assert decode(encode(hb), "diagnostics", Heartbeat).rates_hz == {"a": 100.0}


def test_encode_is_plain_msgpack():
    for msg in samples():
        payload = encode(msg)
        assert msgpack.packb(msgpack.unpackb(payload), use_bin_type=True) == payload


def test_defaults_are_not_counted_as_given():
    msg = HOT[0]
    raw = msgpack.unpackb(encode(msg))
    del raw["source"], raw["header"]["seq"]
    fast = fast_decode(type(msg), msgpack.packb(raw))
    assert "source" not in fast.model_fields_set and "seq" not in fast.header.model_fields_set
    same(fast, type(msg).model_validate(raw))


# Mutations of a valid message's map: each field replaced by a value of another type, removed, or joined by
# an extra key. Whatever the fast path accepts, pydantic must accept with the same values.
VALUES = st.one_of(st.none(), st.booleans(), st.integers(-2**63, 2**64 - 1), st.floats(), st.text(max_size=5),
                   st.binary(max_size=16), st.lists(st.text(max_size=3), max_size=3),
                   st.lists(st.integers(-2, 40), max_size=3),
                   st.fixed_dictionaries({"dtype": st.sampled_from(["<f4", "|u1", "<f8"]),
                                          "shape": st.lists(st.integers(-1, 40), max_size=3),
                                          "data": st.binary(max_size=64)}))


@settings(max_examples=400, deadline=None)
@given(index=st.integers(0, len(HOT) - 1), where=st.integers(0, 50), value=VALUES,
       action=st.sampled_from(["replace", "delete", "extra", "header"]))
def test_fast_path_never_looser_than_pydantic(index, where, value, action):
    msg = HOT[index]
    raw = msgpack.unpackb(encode(msg))
    target = raw["header"] if action == "header" else raw
    key = sorted(target)[where % len(target)]
    if action == "delete":
        del target[key]
    elif action == "extra":
        target["unexpected"] = value
    else:
        target[key] = value
    try:
        payload = msgpack.packb(raw, use_bin_type=True)
    except (TypeError, ValueError, OverflowError):
        return
    fast = fast_decode(type(msg), payload)
    try:
        decode(payload, "t", type(msg))
    except DecodeError:
        pass  # the codec itself answers with its one error type, never another exception
    try:
        ref = type(msg).model_validate(msgpack.unpackb(payload))
    except ValidationError:
        assert fast is None, f"fast path accepted what pydantic rejects: {action} {key}={value!r}"
        return
    if fast is not None:
        same(fast, ref)


def test_every_message_class_is_known():
    assert {type(m) for m in samples()} == set(ALL_MESSAGES)

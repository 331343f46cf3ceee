"""Codec round trips and rejections, including property tests over random arrays and corrupt bytes."""
import msgpack
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from messages import (ALL_MESSAGES, DecodeError, Heartbeat, LimbSolution, MarkerFrame, MarkerSet, RigPose,
                      SkeletonFrame, decode, encode, json_schemas)
from messages.codec import MAX_MESSAGE_BYTES, decode_header
from mocap_core.skeleton import N_JOINTS


def marker_frame(n=35, frame=7):
    rng = np.random.default_rng(frame)
    pos = rng.normal(size=(n, 3)).astype(np.float32)
    pos[::5] = np.nan
    return MarkerFrame(header=MarkerFrame.make_header(frame, frame / 100, 123), labels=[f"M{i}" for i in range(n)],
                       positions=pos, flags=np.arange(n, dtype=np.uint8) % 3)


def samples():
    pos = np.arange(N_JOINTS * 3, dtype=np.float32).reshape(N_JOINTS, 3)
    ori = np.tile(np.float32([0, 0, 0, 1]), (N_JOINTS, 1))
    rot = np.tile(np.eye(3, dtype=np.float32), (N_JOINTS, 1, 1))
    return [
        MarkerSet(header=MarkerSet.make_header(), labels=["A", "B"], rate_hz=300, source="test"),
        marker_frame(),
        SkeletonFrame(header=SkeletonFrame.make_header(3), positions=pos, rotations=rot,
                      status=np.ones(N_JOINTS, np.uint8)),
        LimbSolution(header=LimbSolution.make_header(3), limb="left_arm", joints=["elbow_l", "wrist_l"],
                     positions=pos[:2], rotations=rot[:2], status=np.uint8([1, 2]), solver="ccd",
                     iterations=4, residual_m=0.001, solve_time_us=12.5),
        RigPose(header=RigPose.make_header(3), rig="unity", bones=["Hips"], root_position=np.float32([0, 1, 0]),
                rotations=ori[:1], positions=pos[:1], held=np.zeros(1, np.uint8)),
        Heartbeat(header=Heartbeat.make_header(), node="n", kind="k", pid=1, state="running", uptime_s=2.0,
                  rates_hz={"a": 100.0}, drops={"a": 2}, errors={"decode_garbage": 1}),
    ]


@pytest.mark.parametrize("msg", samples(), ids=lambda m: m.SCHEMA)
def test_round_trip_every_message(msg):
    back = decode(encode(msg), "t", type(msg))
    assert type(back) is type(msg)
    for name in type(msg).model_fields:
        a, b = getattr(msg, name), getattr(back, name)
        if isinstance(a, np.ndarray):
            assert a.dtype == b.dtype and a.shape == b.shape
            np.testing.assert_array_equal(a, b)
        else:
            assert a == b


def test_every_message_is_sampled():
    assert {type(m) for m in samples()} == set(ALL_MESSAGES)


def test_arrays_travel_as_bytes_dtype_shape():
    raw = msgpack.unpackb(encode(marker_frame(4)))
    assert raw["positions"]["dtype"] == "<f4" and raw["positions"]["shape"] == [4, 3]
    assert isinstance(raw["positions"]["data"], bytes) and len(raw["positions"]["data"]) == 4 * 3 * 4


@settings(max_examples=60, deadline=None)
@given(hnp.arrays(np.float32, hnp.array_shapes(min_dims=2, max_dims=2, min_side=0, max_side=60).map(
    lambda s: (s[0], 3))))
def test_marker_positions_round_trip_bit_exact(pos):
    n = pos.shape[0]
    msg = MarkerFrame(header=MarkerFrame.make_header(1), labels=[str(i) for i in range(n)], positions=pos,
                      flags=np.zeros(n, np.uint8))
    back = decode(encode(msg), "markers/raw", MarkerFrame)
    assert back.positions.tobytes() == pos.tobytes()  # NaN payloads and -0.0 included


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=400))
def test_random_bytes_raise_only_decode_error(payload):
    try:
        decode(payload, "markers/raw", MarkerFrame)
    except DecodeError as e:
        assert e.topic == "markers/raw" and e.reason
    else:  # the only way random bytes decode is by being a valid message, which is vanishingly rare
        pass


@settings(max_examples=200, deadline=None)
@given(st.data())
def test_corrupted_valid_message_never_escapes_as_other_error(data):
    payload = bytearray(encode(marker_frame(5)))
    for _ in range(data.draw(st.integers(1, 6))):
        i = data.draw(st.integers(0, len(payload) - 1))
        payload[i] = data.draw(st.integers(0, 255))
    cut = data.draw(st.integers(0, len(payload)))
    try:
        msg = decode(bytes(payload[:cut] if data.draw(st.booleans()) else payload), "t", MarkerFrame)
    except DecodeError:
        return
    assert msg.positions.shape == (len(msg.labels), 3)  # if it decodes, it is still consistent


def _raw(msg):
    return msgpack.unpackb(encode(msg))


def test_rejects_wrong_schema_on_topic():
    with pytest.raises(DecodeError, match="schema mocap.MarkerSet on a topic of mocap.MarkerFrame") as e:
        decode(encode(samples()[0]), "markers/raw", MarkerFrame)
    assert e.value.kind == "wrong_schema" and e.value.topic == "markers/raw"


def test_rejects_version_mismatch():
    raw = _raw(marker_frame())
    raw["header"]["version"] = 99
    with pytest.raises(DecodeError, match="version 99"):
        decode(msgpack.packb(raw), "t", MarkerFrame)


def test_reads_version_1_skeletons_with_their_quaternions_as_rotations():
    # bags recorded before version 2 carried each bone frame as a quaternion (x, y, z, w) in "orientations"
    from scipy.spatial.transform import Rotation

    turns = Rotation.random(N_JOINTS, random_state=3)
    for msg, n in ((samples()[2], N_JOINTS), (samples()[3], 2)):
        raw = _raw(msg)
        raw["header"]["version"] = 1
        del raw["rotations"]
        quats = turns.as_quat()[:n].astype("<f4")
        raw["orientations"] = {"dtype": "<f4", "shape": [n, 4], "data": quats.tobytes()}
        got = decode(msgpack.packb(raw), "t", type(msg))
        assert got.header.version == type(msg).VERSION == 2
        np.testing.assert_allclose(got.rotations, turns.as_matrix()[:n], atol=1e-6)
        assert decode_header(msgpack.packb(raw), "t", type(msg)).version == 2  # what forwards bytes takes it too
    raw["orientations"]["shape"] = [3, 4]  # malformed: validation names what is missing
    with pytest.raises(DecodeError, match="rotations"):
        decode(msgpack.packb(raw), "t", LimbSolution)


def test_rejects_unknown_schema_and_foreign_maps():
    raw = _raw(marker_frame())
    raw["header"]["schema"] = "ros.PointCloud2"
    with pytest.raises(DecodeError, match="unknown schema 'ros.PointCloud2'"):
        decode(msgpack.packb(raw), "t")
    with pytest.raises(DecodeError, match="no header"):
        decode(msgpack.packb([1, 2, 3]), "t")


def test_rejects_bad_shape_and_dtype_and_length():
    raw = _raw(marker_frame(4))
    raw["positions"]["shape"] = [3, 4]
    with pytest.raises(DecodeError, match="positions"):
        decode(msgpack.packb(raw), "t", MarkerFrame)
    raw = _raw(marker_frame(4))
    raw["positions"]["dtype"] = "<f8"
    with pytest.raises(DecodeError, match="dtype"):
        decode(msgpack.packb(raw), "t", MarkerFrame)
    raw = _raw(marker_frame(4))
    raw["positions"]["data"] = raw["positions"]["data"][:-4]
    with pytest.raises(DecodeError, match="bytes"):
        decode(msgpack.packb(raw), "t", MarkerFrame)
    raw = _raw(marker_frame(4))
    raw["labels"] = raw["labels"][:3]
    with pytest.raises(DecodeError, match="3 labels"):
        decode(msgpack.packb(raw), "t", MarkerFrame)


def test_skeleton_must_have_every_joint():
    raw = _raw(samples()[2])
    raw["positions"]["shape"] = [N_JOINTS - 1, 3]
    raw["positions"]["data"] = raw["positions"]["data"][:-12]
    with pytest.raises(DecodeError, match="expected"):
        decode(msgpack.packb(raw), "skeleton/solved", SkeletonFrame)


def test_rejects_oversized():
    with pytest.raises(DecodeError) as e:
        decode(b"\x00" * (MAX_MESSAGE_BYTES + 1), "t")
    assert e.value.kind == "oversized"


# -- header-only reading (raw_relay) ------------------------------------------------------------------
@pytest.mark.parametrize("msg", samples(), ids=lambda m: m.SCHEMA)
def test_header_only_reads_the_header_of_every_message(msg):
    h = decode_header(encode(msg), "t", type(msg))
    assert (h.schema_name, h.version, h.seq, h.frame, h.entry_time_ns) == (
        msg.SCHEMA, msg.VERSION, msg.header.seq, msg.header.frame, msg.header.entry_time_ns)


def test_header_only_rejects_what_decode_rejects_in_the_header():
    raw = _raw(marker_frame())
    raw["header"]["version"] = 99
    cases = [(b"\xc1garbage", "garbage"), (msgpack.packb([1, 2]), "foreign"), (msgpack.packb(raw), "version"),
             (encode(samples()[0]), "wrong_schema"), (encode(marker_frame())[:-5], "garbage")]
    bad_seq = _raw(marker_frame())
    bad_seq["header"]["seq"] = "x"
    cases.append((msgpack.packb(bad_seq), "invalid"))
    for payload, kind in cases:
        with pytest.raises(DecodeError) as e:
            decode_header(payload, "markers/raw", MarkerFrame)
        assert e.value.kind == kind and e.value.topic == "markers/raw", (payload[:20], e.value)
    with pytest.raises(DecodeError, match="header.seq"):
        decode_header(msgpack.packb(bad_seq), "t", MarkerFrame)


def test_header_only_leaves_the_arrays_to_whoever_reads_them():
    raw = _raw(marker_frame(4))
    raw["positions"]["shape"] = [3, 4]
    payload = msgpack.packb(raw)
    assert decode_header(payload, "t", MarkerFrame).frame == 7
    with pytest.raises(DecodeError, match="positions"):
        decode(payload, "t", MarkerFrame)


@settings(max_examples=200, deadline=None)
@given(st.data())
def test_header_only_accepts_every_message_decode_accepts(data):
    payload = bytearray(encode(marker_frame(5)))
    for _ in range(data.draw(st.integers(1, 4))):
        payload[data.draw(st.integers(0, len(payload) - 1))] = data.draw(st.integers(0, 255))
    payload = bytes(payload)
    try:
        msg = decode(payload, "t", MarkerFrame)
    except DecodeError:
        try:
            decode_header(payload, "t", MarkerFrame)
        except DecodeError:
            pass
        return
    h = decode_header(payload, "t", MarkerFrame)
    assert (h.publisher, h.seq, h.frame, h.entry_time_ns) == (
        msg.header.publisher, msg.header.seq, msg.header.frame, msg.header.entry_time_ns)


def test_json_schema_for_every_message():
    schemas = json_schemas()
    assert set(schemas) == {m.SCHEMA for m in ALL_MESSAGES}
    frame = schemas["mocap.MarkerFrame"]
    assert {"header", "labels", "positions", "flags"} <= set(frame["properties"])
    assert frame["properties"]["positions"]["properties"]["data"]["contentEncoding"] == "base64"

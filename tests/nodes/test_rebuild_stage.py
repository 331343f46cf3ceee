"""hip_interpolation with ``rebuild: true`` flags the landmarks it rebuilt, and joint_localization
reports the joints they give as estimated (the two nodes in one container, in-process hand-over)."""
import numpy as np
import pytest
import zmq

from messages import FLAG_INTERPOLATED, FLAG_MEASURED, FLAG_MISSING, MarkerFrame, SkeletonFrame
from mocap_core.landmark_fills import fill_take
from mocap_core.pipeline import SkeletonPipeline
from mocap_core.pose_memory import PoseMemory
from mocap_core.profiles import LANDMARK_INDEX, load_profile
from mocap_core.recordings import read_recording
from mocap_core.skeleton import INDEX, Status
from nodes.hip_interpolation import HipInterpolation
from nodes.joint_localization import JointLocalization
from nodes.runtime import Node, NodeLoop, wire_hand_over
from nodes.skeleton_codec import from_message
from nodes.spec import NodeSpec
from tests.conftest import data_file


class _Collect(Node):
    kind = "collect"
    subscribes = {"in": MarkerFrame}

    def setup(self):
        self.got = []

    def on_message(self, topic, msg):
        self.got.append(msg)


class _CollectSkeletons(_Collect):
    subscribes = {"in": SkeletonFrame}


@pytest.mark.parametrize("lost, joint", [
    (["L_FCC"], "foot_l"),                   # from the malleoli and the toe
    (["L_FLE", "L_FME", "L_TTC"], "knee_l"),  # from the malleoli and the shank's tracking markers (raw labels)
])
def test_rebuilt_landmarks_are_flagged_and_their_joint_is_estimated(lost, joint):
    take = read_recording(data_file("02_qualisys_walking_ezc3d_Qualisys.c3d"))
    hidden = [take.labels.index(name) for name in lost]  # the Qualisys labels are the landmark names
    zctx = zmq.Context()
    common = {"profile": "qualisys_sports"}
    specs = [
        (NodeSpec(id="hips", kind="hip_interpolation", params={**common, "rebuild": True},
                  remaps={"markers/raw": "markers/raw"}, pub_endpoint="inproc://rb-hips"), HipInterpolation),
        (NodeSpec(id="localize", kind="joint_localization", params=common, pub_endpoint="inproc://rb-loc",
                  local_topics=["markers/filled"]), JointLocalization),
        (NodeSpec(id="seen_markers", kind="collect", remaps={"in": "markers/filled"}, pub_endpoint="inproc://rb-c1",
                  local_topics=["markers/filled"]), _Collect),
        (NodeSpec(id="seen_joints", kind="collect", remaps={"in": "skeleton/localized"},
                  pub_endpoint="inproc://rb-c2", local_topics=["skeleton/localized"]), _CollectSkeletons),
    ]
    loops = [NodeLoop(spec, cls, zctx) for spec, cls in specs]
    wire_hand_over(loops)
    for loop in loops:
        loop.node.setup()
    hips, _, markers, joints = (loop.node for loop in loops)
    try:
        for f in range(30):
            pos = take.positions[f].astype(np.float32)
            if f >= 10:
                pos[hidden] = np.nan
            hips.on_message("markers/raw", MarkerFrame(header=MarkerFrame.make_header(f, f / take.rate_hz, 1),
                                                       labels=take.labels, positions=pos,
                                                       flags=np.zeros(len(take.labels), np.uint8)))
            for _ in range(2):
                for loop in loops:
                    loop.step({})
        assert len(markers.got) == 30 and len(joints.got) == 30
        for name in lost:
            k = LANDMARK_INDEX[name]
            assert [m.flags[k] for m in markers.got] == [FLAG_MEASURED] * 10 + [FLAG_INTERPOLATED] * 20
            assert all(np.isfinite(m.positions[k]).all() for m in markers.got)
            # within 2 cm of where the marker really was (skin moves over the bones)
            assert max(np.linalg.norm(m.positions[k] - take.positions[f, take.labels.index(name)])
                       for f, m in enumerate(markers.got)) < 0.02
        status = np.array([from_message(j)[2] for j in joints.got])
        assert (status[:10, INDEX[joint]] == Status.LOCATED).all()
        assert (status[10:, INDEX[joint]] == Status.ESTIMATED).all()
        other = "knee_l" if joint == "foot_l" else "foot_l"
        assert (status[:, INDEX[other]] == Status.LOCATED).all()
        assert FLAG_MISSING not in {int(m.flags[LANDMARK_INDEX["L_FAL"]]) for m in markers.got}
    finally:
        for loop in loops:
            loop.ctx.close()
        zctx.term()


def _hip_stage(params, name):
    """A hip_interpolation node and a collector of its ``markers/filled``, in one process, set up."""
    zctx = zmq.Context()
    specs = [
        (NodeSpec(id="hips", kind="hip_interpolation", params=params, pub_endpoint=f"inproc://{name}-hips"),
         HipInterpolation),
        (NodeSpec(id="seen_markers", kind="collect", remaps={"in": "markers/filled"}, pub_endpoint=f"inproc://{name}-c",
                  local_topics=["markers/filled"]), _Collect),
    ]
    loops = [NodeLoop(spec, cls, zctx) for spec, cls in specs]
    wire_hand_over(loops)
    for loop in loops:
        loop.node.setup()
    return zctx, loops


def _feed(loops, take, f, positions):
    """Frame f of the take, with these positions, into the hip node; every loop stepped once."""
    loops[0].node.on_message("markers/raw", MarkerFrame(header=MarkerFrame.make_header(f, f / take.rate_hz, 1),
                                                        labels=take.labels, positions=positions.astype(np.float32),
                                                        flags=np.zeros(len(take.labels), np.uint8)))
    for loop in loops:
        loop.step({})


def test_recalled_knee_and_ankle_are_flagged_interpolated():
    """hip_interpolation with ``pose_memory: true`` on the 28-marker dance set (nothing on shank or foot
    to rebuild from): the knee and ankle markers come back from the poses seen before they were lost."""
    take = read_recording(data_file("13_qualisys_dance_walk_mocaptoolbox_mcdemodata.mat"), "dance1")
    hidden = [take.labels.index(name) for name in ("Knee_L", "Ankle_L")]
    zctx, loops = _hip_stage({"profile": "dance28", "pose_memory": True}, "pm")
    markers = loops[1].node
    lost_from, frames = 300, 360
    try:
        for f in range(frames):
            pos = take.positions[f].copy()
            if f >= lost_from:
                pos[hidden] = np.nan
            _feed(loops, take, f, pos)
        assert len(markers.got) == frames
        for name, label in (("L_FLE", "Knee_L"), ("L_FAL", "Ankle_L")):
            k = LANDMARK_INDEX[name]
            flags = [int(m.flags[k]) for m in markers.got]
            assert flags == [FLAG_MEASURED] * lost_from + [FLAG_INTERPOLATED] * (frames - lost_from)
            err = [np.linalg.norm(markers.got[f].positions[k] - take.positions[f, take.labels.index(label)])
                   for f in range(lost_from, frames)]
            assert max(err) < 0.1 and np.mean(err) < 0.05, (name, max(err), np.mean(err))
        # the frames' capture times reach the memory (it finds the knee's poses by the toe's velocity too):
        # the node's knee is the core's with those times, not the core's without them
        pipe = SkeletonPipeline(load_profile("dance28"), take.labels, fill_gaps=False)
        raw = take.positions[:frames].copy()
        raw[lost_from:, hidden] = np.nan
        memory = [PoseMemory(pipe.landmark_map.present(), pipe.landmark_map.tracking_of) for _ in range(2)]
        timed, untimed = (fill_take(m.fill, pipe.landmarks(raw), tracking=pipe.landmark_map.tracking(raw), time_s=times)[0]
                          for m, times in zip(memory, (np.arange(frames) / take.rate_hz, None)))
        knee = LANDMARK_INDEX["L_FLE"]
        node_knee = np.array([m.positions[knee] for m in markers.got[lost_from:]])
        np.testing.assert_allclose(node_knee, timed[lost_from:, knee], atol=1e-4)
        assert np.abs(timed[lost_from:, knee] - untimed[lost_from:, knee]).max() > 1e-3
    finally:
        for loop in loops:
            loop.ctx.close()
        zctx.term()


def test_a_jumping_wrist_pair_is_dropped_and_said(caplog):
    """hip_interpolation with ``pair_guard: true`` on walk2, whose left wrist markers swing through 28-211 mm
    (74 apart elsewhere) from 4.2 s to 4.85 s: both flagged missing there, a warning says so, the rest is kept."""
    take = read_recording(data_file("13_qualisys_dance_walk_mocaptoolbox_mcdemodata.mat"), "walk2")
    zctx, loops = _hip_stage({"profile": "dance28", "pair_guard": True}, "pg")
    hips, markers = (loop.node for loop in loops)
    frames = range(int(3.5 * take.rate_hz), int(5.5 * take.rate_hz))
    try:
        with caplog.at_level("WARNING", logger="mocap.hips"):
            for f in frames:
                _feed(loops, take, f, take.positions[f])
        assert len(markers.got) == len(frames)
        times = np.array(frames) / take.rate_hz
        for name in ("L_RSP", "L_USP"):
            missing = np.array([m.flags[LANDMARK_INDEX[name]] == FLAG_MISSING for m in markers.got])
            assert missing[(times > 4.45) & (times < 4.8)].all()
            assert not missing[(times < 4.15) | (times > 4.95)].any()
        right = np.array([m.flags[LANDMARK_INDEX["R_RSP"]] == FLAG_MISSING for m in markers.got])
        assert not right[(times < 3.8) | (times > 3.9)].any()  # (its own one-frame jump at 3.83 s: 81 -> 126 mm)
        assert any("L_RSP and L_USP" in r.getMessage() for r in caplog.records), caplog.text
        assert hips.ctx.heartbeat("running", 0.0).errors == {"pair_dropped": 2}  # the right wrist's jump too
    finally:
        for loop in loops:
            loop.ctx.close()
        zctx.term()

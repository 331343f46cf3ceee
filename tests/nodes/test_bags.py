"""MCAP bags: byte-exact round trips, damaged files, clear errors, and the golden regression."""
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from messages import SkeletonFrame, decode
from nodes.bags import BagError, bag_info, read_bag
from tests.conftest import REPO, data_file, launched, wait_for

TAKE = "12_vicon_freeform_realgaps_nimble_nick_freeform_001.c3d"
GOLDEN = REPO / "tests" / "data" / "golden_solved.mcap"


def mocap(*args, timeout=180):
    return subprocess.run([sys.executable, "-m", "mocap_cli.main", *args], cwd=REPO, capture_output=True, text=True,
                          timeout=timeout)


@pytest.fixture(scope="module")
def raw_bag(tmp_path_factory):
    path = tmp_path_factory.mktemp("bags") / "raw.mcap"
    r = mocap("bag", "from-recording", str(data_file(TAKE)), "--frames", "240", "-o", str(path))
    assert r.returncode == 0, r.stderr
    return path


def test_info_lists_topics_counts_rates(raw_bag):
    info = bag_info(raw_bag)
    assert info["topics"]["markers/raw"]["count"] == 240
    assert info["topics"]["markers/raw"]["schema"] == "mocap.MarkerFrame"
    assert info["topics"]["markers/raw"]["rate_hz"] == pytest.approx(120, rel=1e-3)
    out = mocap("bag", "info", str(raw_bag))
    assert out.returncode == 0 and "markers/raw" in out.stdout and "120.0" in out.stdout


def test_record_play_record_again_is_byte_identical(raw_bag, tmp_path):
    again = tmp_path / "again.mcap"
    r = mocap("bag", "play", str(raw_bag), "--rate", "4", "--record", str(again), "--record-topics", "markers/raw",
              "markers/set")
    assert r.returncode == 0, r.stderr
    first = [m.data for m in read_bag(raw_bag, ["markers/raw"])]
    second = [m.data for m in read_bag(again, ["markers/raw"])]
    assert len(first) == 240 and first == second


def test_replay_keeps_the_recorded_spacing(raw_bag, tmp_path):
    again = tmp_path / "timed.mcap"
    assert mocap("bag", "play", str(raw_bag), "--record", str(again), "--record-topics", "markers/raw").returncode == 0
    t = np.array([m.log_time_ns for m in read_bag(again, ["markers/raw"])]) / 1e9
    gaps_ms = np.diff(t) * 1000
    assert len(t) == 240
    assert abs(np.median(gaps_ms) - 1000 / 120) < 0.5  # the benchmark reports the p99 (issue: 1 ms at 300 Hz)


def test_golden_regression_through_the_full_graph_in_lockstep(raw_bag, tmp_path):
    if not GOLDEN.exists():
        pytest.fail(f"{GOLDEN} is missing: make it with `make golden`")
    out = tmp_path / "solved.mcap"
    # lockstep: every limb comes; a long join wait keeps a pause of this shared machine from holding one
    r = mocap("bag", "play", str(raw_bag), "--launch", "launch/studio.yaml", "--lockstep", "--restamp", "--record",
              str(out), "--set", "viewer.port=0", "--set", "retarget.max_wait_ms=5000")
    assert r.returncode == 0, r.stderr
    got = {m.header.frame: m for m in (decode(x.data, "skeleton/solved", SkeletonFrame) for x in read_bag(out))}
    want = {m.header.frame: m for m in (decode(x.data, "skeleton/solved", SkeletonFrame) for x in read_bag(GOLDEN))}
    assert sorted(got) == sorted(want) == list(range(240))
    for f in want:
        np.testing.assert_array_equal(got[f].status, want[f].status, err_msg=f"frame {f}")
        # tolerance: float32 positions; IK is deterministic given the same frames in the same order
        np.testing.assert_allclose(got[f].positions, want[f].positions, atol=1e-4, err_msg=f"frame {f}")


def test_killed_recorder_leaves_a_readable_bag(tmp_path):
    bag = tmp_path / "killed.mcap"
    graph = f"""
nodes:
  - {{id: src, kind: synthetic_source, params: {{rate_hz: 500, frames: 0}}}}
  - {{id: rec, kind: recorder, respawn: false, params: {{path: {bag}, topics: [markers/raw]}}}}
"""
    with launched(tmp_path, graph) as g:
        wait_for(lambda: bag.exists() and bag.stat().st_size > 300_000, 30, "a few chunks on disk")
        os.kill(g.node_pids()["rec"], signal.SIGKILL)
        wait_for(lambda: "exited with code" in g.log() or "died" in g.log(), 10, "the launcher to notice")
    frames = [decode(m.data, m.topic).header.frame for m in read_bag(bag)]
    assert len(frames) > 100 and frames == list(range(len(frames)))


def test_a_restarted_recorder_keeps_the_take_and_goes_on_in_a_new_piece(tmp_path):
    """kill -9 of a recorder that the launcher restarts: everything recorded before the kill stays (the restart
    writes take.1.mcap beside it, never over it), and reading take.mcap reads both pieces as one take."""
    bag = tmp_path / "take.mcap"
    graph = f"""
nodes:
  - {{id: src, kind: synthetic_source, params: {{rate_hz: 500, frames: 0}}}}
  - {{id: rec, kind: recorder, params: {{path: {bag}, topics: [markers/raw]}}}}
"""
    with launched(tmp_path, graph) as g:
        wait_for(lambda: bag.exists() and bag.stat().st_size > 300_000, 30, "a few chunks on disk")
        os.kill(g.node_pids()["rec"], signal.SIGKILL)
        size = bag.stat().st_size
        second = tmp_path / "take.1.mcap"
        wait_for(lambda: second.exists() and second.stat().st_size > 100_000, 30, "the restarted recorder's piece")
    assert bag.stat().st_size == size  # not truncated, not written again
    frames = [decode(m.data, m.topic).header.frame for m in read_bag(bag)]  # both pieces
    assert frames[0] == 0
    cut = int(np.argmax(np.diff(frames) != 1)) + 1  # where the first piece ends and the second begins
    assert cut > 100 and frames[:cut] == list(range(cut)) and frames[cut] > frames[cut - 1]
    assert frames[cut:] == list(range(frames[cut], frames[cut] + len(frames) - cut))
    info = bag_info(bag)
    assert info["pieces"] == [str(bag), str(second)] and info["messages"] == len(frames)
    r = mocap("bag", "info", str(bag))
    assert r.returncode == 0 and "pieces:    2 (take.mcap, take.1.mcap), read as one" in r.stdout


def test_a_finished_source_still_delivers_its_last_frames_to_a_slow_subscriber(tmp_path):
    """A source that ends must not drop what it already sent but ZeroMQ has not yet delivered.

    The recorder is frozen (SIGSTOP) while the source sends everything: more than the socket buffers
    hold, so the source's last frames are still queued in it when it finishes. They must arrive
    once the recorder runs again (within the source's flush time)."""
    bag = tmp_path / "slow.mcap"
    graph = f"""
nodes:
  - {{id: src, kind: synthetic_source, params: {{rate_hz: 1000, frames: 400, markers: 5}}}}
  - {{id: rec, kind: recorder, respawn: false, params: {{path: {bag}, topics: [markers/raw]}}}}
"""
    with launched(tmp_path, graph) as g:
        wait_for(lambda: "starting sources" in g.log(), 30, "the sources to start")
        rec = g.node_pids()["rec"]
        os.kill(rec, signal.SIGSTOP)
        try:
            wait_for(lambda: "mocap.src: source finished" in g.log(), 30, "the source to send everything")
            time.sleep(0.2)
        finally:
            os.kill(rec, signal.SIGCONT)
        wait_for(lambda: "source src finished" in g.log(), 10, "the source process to exit")
    frames = [decode(m.data, m.topic).header.frame for m in read_bag(bag)]
    assert frames == list(range(400)), g.log()


def test_capture_times_that_run_backwards_are_recorded_whole(tmp_path):
    """A take that loops, or a QTM that restarts its clock, stamps capture times before zero or none: every frame is
    still written and read back (MCAP's publish time is unsigned; such a frame keeps its arrival time there)."""
    from messages import MarkerFrame, encode
    from nodes.bags import BagWriter

    times = [1.0, 2.0, -0.5, 0.1, float("nan")]
    writer = BagWriter(tmp_path / "t.mcap", {})
    for f, t in enumerate(times):
        msg = MarkerFrame(header=MarkerFrame.make_header(frame=f, capture_time_s=t), labels=["a"],
                          positions=np.zeros((1, 3), np.float32), flags=np.zeros(1, np.uint8))
        writer.write("markers/raw", encode(msg), 1000 + f, int(t * 1e9) if np.isfinite(t) else -1)
    writer.close()
    got = list(read_bag(tmp_path / "t.mcap"))
    assert [decode(m.data, m.topic).header.frame for m in got] == list(range(len(times)))
    assert [m.publish_time_ns for m in got] == [10 ** 9, 2 * 10 ** 9, 1002, 10 ** 8, 1004]


def test_missing_corrupt_and_foreign_files_give_clear_errors(tmp_path):
    with pytest.raises(BagError, match="bag not found"):
        bag_info(tmp_path / "none.mcap")
    (tmp_path / "foreign.mcap").write_text("not a bag at all")
    with pytest.raises(BagError, match="not an MCAP file"):
        bag_info(tmp_path / "foreign.mcap")
    r = mocap("bag", "play", str(tmp_path / "foreign.mcap"))
    assert r.returncode == 2 and "not an MCAP file" in r.stderr and "Traceback" not in r.stderr


def test_export_json_for_foxglove(raw_bag, tmp_path):
    import json

    from mcap.reader import make_reader

    out = tmp_path / "json.mcap"
    assert mocap("bag", "export", str(raw_bag), "--json", str(out)).returncode == 0
    with open(out, "rb") as f:
        msgs = list(make_reader(f).iter_messages(topics=["markers/raw"]))
    schema, channel, message = msgs[0]
    assert channel.message_encoding == "json" and schema.encoding == "jsonschema"
    body = json.loads(message.data)
    assert body["header"]["schema"] == "mocap.MarkerFrame"
    first = decode(next(iter(read_bag(raw_bag, ["markers/raw"]))).data, "markers/raw")
    got = np.array([[np.nan if v is None else v for v in p] for p in body["positions"]])  # numbers, not base64
    np.testing.assert_array_equal(got, first.positions)
    assert json.loads(schema.data)["properties"]["positions"]["type"] == "array"


def test_export_foxglove_puts_the_solved_joints_in_its_3d_scene(tmp_path):
    """`mocap solve`'s joints, as a graph's skeleton/solved bag from a Y-up take, exported in foxglove-sdk's schemas:
    the scene's spheres sit on the joints turned Z up, and log and publish times are one wall clock."""
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory
    import foxglove.messages as fm

    from mocap_core.joints_csv import read_joints_csv
    from mocap_core.skeleton import Status
    from mocap_core.world import to_canonical
    from nodes.bags import BagWriter
    from messages import encode

    csv_path, bag, out = tmp_path / "joints.csv", tmp_path / "solved.mcap", tmp_path / "foxglove.mcap"
    r = mocap("solve", str(data_file(TAKE)), "--profile", "vicon53", "--joints-out", str(csv_path), "--quiet")
    assert r.returncode == 0, r.stderr
    frames, _, positions, status = read_joints_csv(csv_path)
    t0 = time.time_ns()
    writer = BagWriter(bag)
    for f in range(100):
        msg = SkeletonFrame(header=SkeletonFrame.make_header(int(frames[f]), f / 120, t0 + f * 8_333_333, "+y"),
                            positions=positions[f].astype(np.float32), rotations=np.tile(np.eye(3, dtype=np.float32), (27, 1, 1)),
                            status=status[f].astype(np.uint8))
        writer.write("skeleton/solved", encode(msg), t0 + f * 8_333_333 + 500_000)
    writer.close()
    assert mocap("bag", "export", str(bag), "--foxglove", str(out)).returncode == 0
    z_up = to_canonical("+z").T @ to_canonical("+y")
    with open(out, "rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        scenes = [(s, m, d) for s, c, m, d in reader.iter_decoded_messages(topics=["/skeleton"])]
    assert len(scenes) == 100
    schema = scenes[0][0]
    assert (schema.name, schema.encoding) == ("foxglove.SceneUpdate", "protobuf")
    assert schema.data == fm.SceneUpdate.get_schema().data        # foxglove-sdk's own schema
    for f, (_, message, scene) in enumerate(scenes):
        assert message.log_time == message.publish_time == t0 + f * 8_333_333   # the frame's graph-entry time
        seen = status[f] != Status.MISSING
        want = positions[f][seen] @ z_up.T
        got = np.array([[s.pose.position.x, s.pose.position.y, s.pose.position.z] for s in scene.entities[0].spheres])
        np.testing.assert_allclose(got, want, atol=1e-6)
    assert np.median([s.entities[0].spheres[5].pose.position.z for _, _, s in scenes]) > 1.0  # the head, Z up


def test_a_bag_feeds_mocap_solve_and_the_qtm_emulator(raw_bag, tmp_path):
    from nodes.bags import read_take

    rec = read_take(raw_bag)
    direct = read_take(data_file(TAKE))
    assert rec.labels == direct.labels and rec.n_frames == 240 and rec.rate_hz == pytest.approx(120)
    np.testing.assert_array_equal(rec.positions, direct.positions[:240])
    out = tmp_path / "joints.csv"
    r = mocap("solve", str(raw_bag), "--profile", "vicon53", "--joints-out", str(out), "--quiet")
    assert r.returncode == 0 and len(out.read_text().splitlines()) == 241
    from mocap_cli.qtm_sim import QtmEmulator

    assert QtmEmulator(rec).rec.n_frames == 240  # `mocap qtm-sim BAG.mcap` replays it


def test_file_source_lockstep_waits_for_the_graph(tmp_path):
    out = tmp_path / "solved.csv"
    graph = f"""
nodes:
  - {{id: source, kind: file_source, params: {{path: {data_file(TAKE)}, max_frames: 60, rate_hz: 100000,
      lockstep_topic: markers/relayed}}}}
  - {{id: relay, kind: relay, remaps: {{in: markers/raw, out: markers/relayed}}}}
  - {{id: log, kind: frame_log, params: {{path: {out}}}, remaps: {{in: markers/relayed}}}}
"""
    with launched(tmp_path, graph, "--until-done") as g:
        g.proc.wait(timeout=60)
    frames = [int(line.split(",")[0]) for line in out.read_text().splitlines()[1:]]
    assert frames == list(range(60))

"""Several actors in one stream: the source splits it by the labels' subject, the launcher runs one pipeline per
actor, and each actor's skeleton is what solving that actor alone gives."""
import json
import logging
import time
import urllib.request

import numpy as np
import pytest

from messages import MarkerFrame, MarkerSet, decode
from mocap_cli.launch_file import LaunchError, load_launch_file
from mocap_cli.launcher import plan
from mocap_core.pipeline import SkeletonPipeline
from mocap_core.profiles import load_profile
from mocap_core.recordings import crowd, read_recording, write_c3d
from mocap_core.skeleton import JOINTS
from nodes.actor_split import ActorSplit
from nodes.bags import read_bag
from tests.conftest import REPO, data_file, emulator, free_port, launched, wait_for

KARATE = "08_cmu_135_02_karate_kata.c3d"
ACTORS_YAML = """
name: two
actors: {actor1: {}, actor2: {log.path: /tmp/second.csv}}
nodes:
  - id: source
    kind: file_source
    params: {path: take.c3d}
  - id: hips
    kind: hip_interpolation
    container: core
    per_actor: true
  - id: vmc
    kind: vmc_output
    per_actor: true
    params: {port: 40000}
  - id: log
    kind: frame_log
    per_actor: true
    params: {path: "/tmp/{actor}.csv"}
    remaps: {in: markers/filled}
"""


def test_the_launcher_runs_a_copy_of_each_per_actor_node_for_each_actor(tmp_path):
    path = tmp_path / "two.yaml"
    path.write_text(ACTORS_YAML)
    procs = {p.spec.id: p for p in plan(load_launch_file(path), str(tmp_path), "ipc://x")}
    assert set(procs) == {"source", "hips-actor1", "hips-actor2", "vmc-actor1", "vmc-actor2", "log-actor1",
                          "log-actor2"}
    assert procs["source"].spec.params["actors"] == ["actor1", "actor2"]          # the source splits for them
    assert procs["hips-actor2"].subscribes == ["mocap/actor2/markers/raw"]
    assert procs["hips-actor2"].spec.sub_endpoints["mocap/actor2/markers/raw"] == [procs["source"].spec.pub_endpoint]
    assert procs["source"].spec.expected_subscribers == {"mocap/actor1/markers/raw": 1, "mocap/actor2/markers/raw": 1}
    assert procs["hips-actor1"].container == "core-actor1"                         # a process per actor
    assert [procs[f"vmc-actor{i}"].spec.params["port"] for i in (1, 2)] == [40000, 40001]
    assert procs["log-actor1"].spec.params["path"] == "/tmp/actor1.csv"           # {actor} in text params
    assert procs["log-actor2"].spec.params["path"] == "/tmp/second.csv"           # the actor's own value wins
    assert procs["log-actor2"].subscribes == ["mocap/actor2/markers/filled"]
    again = plan(load_launch_file(path, ["actors=[alice, bob, carol]"]), str(tmp_path), "ipc://x")
    assert sorted(p.spec.id for p in again if p.spec.kind == "vmc_output") == ["vmc-alice", "vmc-bob", "vmc-carol"]


@pytest.mark.parametrize("change, said", [
    ("actors: [actor1]\n", "no node is per_actor"),
    ("actors: {actor1: {nope.port: 1}}\n", "'nope.port' is not NODE.PARAM of a per_actor node"),
    ("actors: [actor/1]\n", "letters, digits"),
])
def test_actor_mistakes_are_refused_with_the_fix(tmp_path, change, said):
    text = "name: x\n" + change + "nodes:\n  - id: hips\n    kind: hip_interpolation\n"
    if "nope" in change or "/" in change:
        text += "    per_actor: true\n"
    path = tmp_path / "x.yaml"
    path.write_text(text)
    with pytest.raises(LaunchError, match=said):
        load_launch_file(path)


class _Ctx:
    def __init__(self):
        self.sent = []

    def publish(self, topic, msg, source=None):
        self.sent.append((topic, msg))


def test_the_split_follows_the_labels_and_says_who_is_missing_or_unlisted(caplog):
    ctx = _Ctx()
    split = ActorSplit(ctx, ["actor1", "actor2"], logging.getLogger("t"))
    labels = ["actor1:A", "actor3:A", "actor1:B"]
    frame = MarkerFrame(header=MarkerFrame.make_header(7, 0.1, 1), labels=labels,
                        positions=np.arange(9, dtype=np.float32).reshape(3, 3), flags=np.zeros(3, np.uint8))
    with caplog.at_level(logging.INFO):
        split.publish("markers/raw", frame)
    assert [t for t, _ in ctx.sent] == ["markers/raw", "mocap/actor1/markers/raw"]
    part = ctx.sent[1][1]
    assert part.labels == ["actor1:A", "actor1:B"] and part.header.frame == 7
    assert part.positions.tolist() == [[0, 1, 2], [6, 7, 8]]
    assert "no markers of actor2" in caplog.text and "also holds actor3" in caplog.text
    # a subject that joins mid-take: QTM's labels change, and their pipeline is fed from then on
    ctx.sent.clear()
    split.publish("markers/set", MarkerSet(header=MarkerSet.make_header(), labels=labels + ["actor2:A"], rate_hz=100))
    assert [t for t, _ in ctx.sent] == ["markers/set", "mocap/actor1/markers/set", "mocap/actor2/markers/set"]
    assert ctx.sent[2][1].labels == ["actor2:A"]


@pytest.mark.timeout(300)
def test_two_actors_from_qtm_each_solve_as_if_alone(tmp_path):
    """The karate take and a copy 3 m away (actor2 walks out for a second and comes back), streamed by the QTM
    emulator to launch/qtm_actors.yaml: each actor's skeleton equals the offline solve of that actor's markers alone,
    over the frames the graph received."""
    rec = read_recording(data_file(KARATE)).slice(0, 1440)
    two = crowd(rec, ["actor1", "actor2"])
    gone = [i for i, x in enumerate(two.labels) if x.startswith("actor2:")]
    two.positions[900:1020, gone] = np.nan
    take = tmp_path / "two_actors.c3d"
    write_c3d(two, take)
    bag = tmp_path / "actors.mcap"
    text = (REPO / "launch" / "qtm_actors.yaml").read_text() + (
        f"  - id: rec\n    kind: recorder\n    params: {{path: {bag}, topics: [markers/raw], "
        f"actor_topics: [skeleton/solved]}}\n")
    with emulator(tmp_path, file=take) as (_, port):
        viewer = free_port()
        # retarget waits for every limb (on a busy machine a late limb is otherwise held, as live output should)
        with launched(tmp_path, text, "--set", f"qtm.port={port}", "--set", f"vmc.port={free_port()}",
                      "--set", f"viewer.port={viewer}", "--set", "foxglove.port=0",
                      "--set", "retarget.max_wait_ms=5000") as g:
            wait_for(lambda: " ready in " in g.log() or g.proc.poll() is not None, 120, "the graph")
            assert g.proc.poll() is None, g.log()
            time.sleep(4)
            state = json.loads(urllib.request.urlopen(f"http://127.0.0.1:{viewer}/state").read())
            assert set(state["skeletons"]) == {"actor1", "actor2"}   # the viewer shows everyone
            time.sleep(two.n_frames / two.rate_hz)
    raw, solved = {}, {}
    for m in read_bag(bag):
        msg = decode(m.data, m.topic)
        if m.topic == "markers/raw":
            raw[msg.header.frame] = msg
        else:
            solved.setdefault(m.topic.split("/")[1], {})[msg.header.frame] = np.asarray(msg.positions)
    frames = sorted(raw)
    # every frame from the first the graph was ready for, actor2's absence among them
    assert frames[0] < 900 and frames[-1] == two.n_frames - 1 and frames[-1] - frames[0] + 1 == len(frames)
    labels = raw[frames[0]].labels
    for actor in ("actor1", "actor2"):
        cols = [i for i, x in enumerate(labels) if x.startswith(f"{actor}:")]
        markers = np.stack([raw[f].positions[cols] for f in frames]).astype(np.float64)
        alone = SkeletonPipeline(load_profile("cmu41"), [labels[i] for i in cols], options="studio", rate_hz=two.rate_hz)
        want = np.concatenate([c.positions for c in alone.run(markers, calibrate=False)])  # bones learned as streamed
        # (a busy machine may stop the graph before it solved the last frames: every frame up to where it stopped)
        upto = next((k for k, f in enumerate(frames) if f not in solved[actor]), len(frames))
        assert frames[upto - 1] > 1100 and all(f not in solved[actor] for f in frames[upto:]), (actor, upto)
        got, want = np.stack([solved[actor][f] for f in frames[:upto]]), want[:upto]
        assert np.array_equal(np.isnan(got), np.isnan(want)), actor
        off = np.nan_to_num(np.abs(got - want)).max(axis=2)
        f, j = np.unravel_index(off.argmax(), off.shape)
        # the limb nodes learn each actor's bones from every frame they solved, some before the recording began: their
        # rigid chains may keep bones a little off those learned here from the recorded frames alone
        assert off.max() <= 0.005, (actor, off.max(), frames[f], JOINTS[j], int((off > 0.001).sum()), off.size)


@pytest.mark.timeout(300)
def test_actors_on_two_machines_over_curve(tmp_path):
    """One launch file, two launchers: actor1's pipeline on the machine named rack (127.0.0.2 stands in for it), the
    source, the recorder and actor2's pipeline on the one launched without --host; tcp with CURVE between them."""
    from nodes import curve
    from tests.nodes.test_security import free_base_port

    take = tmp_path / "two.c3d"
    two = crowd(read_recording(data_file(KARATE)).slice(0, 360), ["actor1", "actor2"])
    write_c3d(two, take)
    bag = tmp_path / "spread.mcap"
    text = f"""
transport: {{kind: tcp, base_port: {free_base_port()}, curve_keys: {curve.generate(tmp_path / "keys")}}}
hosts: {{rack: 127.0.0.2}}
actors: {{actor1: {{host: rack}}, actor2: {{}}}}
nodes:
  - {{id: source, kind: file_source, params: {{path: {take}}}}}
  - {{id: hips, kind: hip_interpolation, per_actor: true}}
  - {{id: localize, kind: joint_localization, per_actor: true}}
  - {{id: rec, kind: recorder, params: {{path: {bag}, topics: [], actor_topics: [skeleton/localized]}}}}
"""
    with launched(tmp_path, text, "--host", "rack", name="rack") as rack:
        wait_for(lambda: len(rack.registry().get("nodes", [])) == 2 if rack.registry_file.exists() else False, 60,
                 "the rack's nodes")
        assert {n["id"] for n in rack.registry()["nodes"]} == {"hips-actor1", "localize-actor1"}
        assert all(n["endpoint"].startswith("tcp://127.0.0.2:") for n in rack.registry()["nodes"])
        with launched(tmp_path, text, "--until-done", name="stage") as stage:
            stage.proc.wait(timeout=120)
            assert stage.proc.returncode == 0, stage.log()
    got = {}
    for m in read_bag(bag):
        msg = decode(m.data, m.topic)
        got.setdefault(m.topic.split("/")[1], {})[msg.header.frame] = np.asarray(msg.positions)
    assert len(got["actor1"]) == len(got["actor2"]) == two.n_frames      # every frame, from both machines
    diff = np.stack([got["actor2"][f] - got["actor1"][f] for f in got["actor1"]])
    assert np.nanmax(np.abs(diff - [3, 0, 0])) < 1e-5

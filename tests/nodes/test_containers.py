"""Containers: several nodes in one OS process, wired over inproc sockets (ROS 2's component containers).
Real processes over real sockets, as everywhere else."""
import os
import re
import signal
from pathlib import Path

import numpy as np
import pytest
import zmq

from messages import MarkerFrame
from mocap_cli.launch_file import LaunchError, load_launch_file
from mocap_cli.launcher import group, plan
from nodes.runtime import Node, NodeLoop, wire_hand_over
from nodes.spec import NodeSpec
from tests.conftest import launched, log_rows, pid_alive, wait_for

REPO = Path(__file__).resolve().parents[2]

# source -> a -> b -> log, with the two relays in one container; "tap" listens to a from outside it.
CHAIN = """
nodes:
  - id: source
    kind: synthetic_source
    params: {{rate_hz: {rate}, frames: {frames}}}
  - id: a
    kind: {relay}
    container: relays
    remaps: {{in: markers/raw, out: markers/a}}
  - id: b
    kind: {relay}
    container: relays
    remaps: {{in: markers/a, out: markers/b}}
  - id: log
    kind: frame_log
    params: {{path: {log}}}
    remaps: {{in: markers/b}}
  - id: tap
    kind: frame_log
    params: {{path: {tap}}}
    remaps: {{in: markers/a}}
"""


def read_frames(path):
    return [int(r["frame"]) for r in log_rows(path)]


def chain_file(tmp_path, relay="relay", **kw):
    f = tmp_path / "g.yaml"
    f.write_text(CHAIN.format(log=tmp_path / "log.csv", tap=tmp_path / "tap.csv", relay=relay, **kw))
    return f


def test_plan_hands_over_inside_a_container_and_wires_ipc_outside(tmp_path):
    procs = plan(load_launch_file(chain_file(tmp_path, rate=100, frames=10)), "/tmp/s", "ipc:///tmp/s/control")
    by_id = {p.spec.id: p for p in procs}
    assert by_id["b"].spec.local_topics == ["markers/a"]            # same container: the object itself
    assert by_id["b"].spec.sub_endpoints["markers/a"] == []         # ... and no socket for it
    assert by_id["tap"].spec.sub_endpoints["markers/a"] == [by_id["a"].spec.pub_endpoint]  # from outside
    assert by_id["a"].spec.sub_endpoints["markers/raw"] == [by_id["source"].spec.pub_endpoint]
    assert by_id["a"].spec.local_topics == [] and by_id["tap"].spec.local_topics == []
    assert by_id["a"].spec.expected_subscribers["markers/a"] == 1   # tap outside; b is not a socket peer
    processes = group(procs)
    assert [(p.name, [n.spec.id for n in p.nodes]) for p in processes] == [
        ("source", ["source"]), ("relays", ["a", "b"]), ("log", ["log"]), ("tap", ["tap"])]
    assert processes[1].argv().startswith("[") and processes[0].argv().startswith("{")


@pytest.mark.parametrize("entry, message", [
    ("{id: s, kind: synthetic_source, container: c}", "a source ends its process"),
    ("{id: r, kind: relay, container: c, replicas: 2}", "a container is one process"),
    ("{id: r, kind: relay, container: r2}\n  - {id: r2, kind: relay}", "has the name of a node"),
    ("{id: r, kind: relay, container: 'no spaces'}", "container"),
])
def test_bad_containers_are_refused_with_a_reason(tmp_path, entry, message):
    f = tmp_path / "g.yaml"
    f.write_text(f"nodes:\n  - {entry}\n")
    with pytest.raises(LaunchError, match=message):
        plan(load_launch_file(f), "/tmp/s", "ipc:///tmp/s/control")


def test_containers_and_curve_are_refused_together(tmp_path):
    f = tmp_path / "g.yaml"
    f.write_text("transport: {kind: tcp, curve_keys: keys}\nnodes:\n  - {id: r, kind: relay, container: c}\n")
    with pytest.raises(LaunchError, match="not supported with curve_keys"):
        load_launch_file(f)


@pytest.mark.parametrize("relay", ["relay", "raw_relay"])
def test_a_container_delivers_every_frame_inside_and_out(tmp_path, relay):
    f = chain_file(tmp_path, relay=relay, rate=500, frames=300)
    with launched(tmp_path, f.read_text(), "--until-done") as g:
        g.proc.wait(timeout=40)
        assert g.proc.returncode == 0, g.log()
    assert read_frames(tmp_path / "log.csv") == list(range(300)), "frames lost or reordered through the container"
    assert read_frames(tmp_path / "tap.csv") == list(range(300)), "an outside subscriber of an inner topic lost frames"
    assert "started 5 nodes in 4 processes" in g.log()


def test_a_killed_container_is_restarted_with_all_its_nodes(tmp_path):
    f = chain_file(tmp_path, rate=200, frames=0)
    log = tmp_path / "log.csv"
    with launched(tmp_path, f.read_text()) as g:
        wait_for(lambda: log.exists() and len(read_frames(log)) > 20, 20, "frames through the container")
        pids = g.node_pids()
        assert pids["a"] == pids["b"] != pids["source"], "a container's nodes share one process"
        listing = g.cli("node", "list", "--seconds", "1.5")
        rows = {line.split()[0]: line.split() for line in listing.stdout.splitlines()[1:]}
        assert rows["a"][3] == rows["b"][3] == "relays", listing.stdout
        assert "running" in rows["a"] and "running" in rows["b"], "every node of a container sends its heartbeat"
        assert rows["source"][3] == "source", listing.stdout
        os.kill(pids["a"], signal.SIGKILL)
        new = wait_for(lambda: (p := g.node_pids().get("a")) != pids["a"] and p, 8, "a restarted container")
        assert pid_alive(new) and g.node_pids()["b"] == new
        n = len(read_frames(log))
        wait_for(lambda: len(read_frames(log)) > n + 20, 8, "frames after the restart")
        assert "restarted container relays (a, b)" in g.log()
        took = g.stop()
        assert took < 2.0 and not pid_alive(new)


@pytest.mark.parametrize("plain_name, source_kind", [("studio", "file_source"), ("qtm_studio", "qtm_ingest"),
                                                     ("studio_fit", "file_source")])
def test_a_composed_studio_file_is_its_plain_twin_with_container_lines(plain_name, source_kind):
    """launch/<name>_composed.yaml must stay the same graph as launch/<name>.yaml."""
    plain = load_launch_file(REPO / "launch" / f"{plain_name}.yaml")
    composed = load_launch_file(REPO / "launch" / f"{plain_name}_composed.yaml")
    assert [n.model_dump(exclude={"container"}) for n in plain.nodes] == \
           [n.model_dump(exclude={"container"}) for n in composed.nodes]
    kinds = {n.kind: n.container for n in composed.nodes}
    assert kinds[source_kind] is None and kinds["viewer"] is None
    assert {n.container for n in composed.nodes if n.kind in ("ik_gapfill", "retarget", "hip_interpolation",
                                                              "joint_localization", "skeleton_fit")} == {"core"}
    assert re.search(r"container: core", (REPO / "launch" / f"{plain_name}_composed.yaml").read_text())


def test_compose_gives_a_composed_graph_one_service_per_node():
    from mocap_cli.compose import compose

    text = compose(str(REPO / "launch" / "studio_composed.yaml"))
    assert "inproc" not in text, "docker services cannot share inproc sockets"
    plain = compose(str(REPO / "launch" / "studio.yaml"))
    same = text.split("\n", 1)[1].replace("studio-composed", "studio").replace('"studio_composed"', '"studio"')
    assert same == plain.split("\n", 1)[1]


def test_capture_frames_missing_counts_gaps_anywhere_and_ignores_a_loop(tmp_path):
    from mocap_cli.measure import capture_frames_missing, frame_log_figures

    log = tmp_path / "log.csv"
    rows = [(0, 1), (1, 2), (4, 3), (5, 4), (0, 5), (2, 6)]  # (capture frame, seq): 2+0+1 frames lost, a loop
    log.write_text("frame,seq,publisher,schema,latency_us,estimated,held,missing\n" +
                   "".join(f"{f},{s},retarget,mocap.SkeletonFrame,1000,0,0,0\n" for f, s in rows))
    assert capture_frames_missing(log) == 3
    assert frame_log_figures(log)[1] == 0, "the last hop lost nothing"


class _Keep(Node):
    """Keeps what it gets and republishes it (a relay that remembers)."""
    kind = "keep"
    subscribes = {"in": MarkerFrame}
    publishes = {"out": MarkerFrame}

    def setup(self):
        self.got = []

    def on_message(self, topic, msg):
        self.got.append(msg)
        self.ctx.publish("out", msg, source=msg)


def test_hand_over_gives_neighbours_the_object_read_only_and_a_relay_stamps_a_copy():
    """In a container a message is handed over as the object itself: no codec, no socket. Its arrays
    are read-only (as decoded ones are), and a neighbour that republishes it does not change what the
    others hold."""
    zctx = zmq.Context()
    specs = [NodeSpec(id="a", kind="keep", remaps={"in": "m/raw", "out": "m/a"}, pub_endpoint="inproc://t-a"),
             NodeSpec(id="b", kind="keep", remaps={"in": "m/a", "out": "m/b"}, pub_endpoint="inproc://t-b",
                      local_topics=["m/a"]),
             NodeSpec(id="c", kind="keep", remaps={"in": "m/a", "out": "m/c"}, pub_endpoint="inproc://t-c",
                      local_topics=["m/a"])]
    loops = [NodeLoop(s, _Keep, zctx) for s in specs]
    wire_hand_over(loops)
    for loop in loops:
        loop.node.setup()
    a, b, c = (loop.node for loop in loops)
    try:
        frame = MarkerFrame(header=MarkerFrame.make_header(7, 0.07, 1), labels=["x"],
                            positions=np.zeros((1, 3), np.float32), flags=np.zeros(1, np.uint8))
        a.ctx.publish("out", frame)
        for _ in range(3):
            for loop in loops:
                loop.step({})
        assert b.got == [frame] and c.got == [frame] and b.got[0] is c.got[0] is frame, "not the object itself"
        assert frame.header.publisher == "a" and frame.header.seq == 1 and frame.header.frame == 7, \
            "b or c restamped the message a handed them"
        assert not frame.positions.flags.writeable
        try:
            b.got[0].positions[0, 0] = 1.0
            raise AssertionError("a neighbour could write into a handed-over array")
        except ValueError:
            pass
        assert b.ctx.stats.received["m/a"].count == 1 and b.ctx.stats.received["m/a"].drops == 0
        assert b.ctx.stats.published["m/b"].count == 1, "b's publish is counted even with nobody outside"
        assert a.ctx.local_readers.keys() == {"m/a"} and not b.ctx.local_readers
    finally:
        for loop in loops:
            loop.ctx.close()
        zctx.term()


def test_a_header_only_node_must_take_bytes():
    class Blind(Node):
        kind = "blind"
        subscribes = {"in": MarkerFrame}
        header_only = True

    with pytest.raises(TypeError, match="Blind is header_only, so it must handle bytes in on_raw"):
        NodeLoop(NodeSpec(id="b", kind="blind", remaps={"in": "m/a"}), Blind, zmq.Context.instance())

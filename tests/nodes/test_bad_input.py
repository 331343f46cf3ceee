"""Garbage, truncated, oversized and wrong-schema messages on every topic of the full graph: every
node keeps running, counts the errors, and the skeleton keeps coming."""
from tests.conftest import data_file, launched, pipeline_graph, wait_for

TOPICS = ["markers/raw", "markers/filled", "skeleton/localized", "skeleton/torso", "skeleton/limb/left_arm",
          "skeleton/limb/right_leg", "skeleton/solved"]


def test_every_node_survives_garbage_on_every_topic(tmp_path):
    out = tmp_path / "out.csv"
    extra = (f"  - {{id: log, kind: frame_log, params: {{path: {out}}}, remaps: {{in: skeleton/solved}}}}\n"
             f"  - {{id: fuzz, kind: tests.fixtures_nodes.fuzzer:Fuzzer, params: {{topics: {TOPICS}}}}}")
    take = data_file("02_qualisys_walking_ezc3d_Qualisys.c3d")
    graph = pipeline_graph(f"{{path: {take}, loop: true}}", extra=extra)
    with launched(tmp_path, graph) as g:
        wait_for(lambda: out.exists() and sum(1 for _ in open(out)) > 300, 90, "solved frames under fuzzing")
        pids = g.node_pids()
        hb = g.heartbeats()
        for node in ("hips", "localize", "torso", "left_arm", "right_leg", "retarget", "log"):
            assert sum(hb[node].errors.values()) > 0, f"{node} counted no bad message: {hb[node].errors}"
            assert hb[node].state == "running"
        assert "restarted node" not in g.log(), "a node died of bad input"
        assert g.node_pids() == pids
    log = g.log()
    assert "not msgpack" in log and "Traceback" not in log  # logged with reasons, never a crash

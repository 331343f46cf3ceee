"""Garbage, truncated, oversized and wrong-schema messages on every topic of the full graph: every
node keeps running, counts the errors, and the skeleton keeps coming."""
import os

from tests.conftest import data_file, launched, wait_for

TOPICS = ["markers/raw", "markers/filled", "skeleton/localized", "skeleton/torso", "skeleton/limb/left_arm",
          "skeleton/limb/right_leg", "skeleton/solved"]


def test_every_node_survives_garbage_on_every_topic(tmp_path):
    out = tmp_path / "out.csv"
    graph = f"""
nodes:
  - {{id: source, kind: file_source, params: {{path: {data_file('02_qualisys_walking_ezc3d_Qualisys.c3d')}, loop: true}}}}
  - {{id: hips, kind: hip_interpolation, params: {{profile: qualisys_sports}}}}
  - {{id: localize, kind: joint_localization, params: {{profile: qualisys_sports}}}}
  - {{id: torso, kind: ik_gapfill, params: {{limb: torso}}}}
  - {{id: left_arm, kind: ik_gapfill, params: {{limb: left_arm}}}}
  - {{id: right_arm, kind: ik_gapfill, params: {{limb: right_arm}}}}
  - {{id: left_leg, kind: ik_gapfill, params: {{limb: left_leg}}}}
  - {{id: right_leg, kind: ik_gapfill, params: {{limb: right_leg}}}}
  - {{id: retarget, kind: retarget, params: {{up_axis: z}}}}
  - {{id: log, kind: frame_log, params: {{path: {out}}}, remaps: {{in: skeleton/solved}}}}
  - {{id: fuzz, kind: tests.fixtures_nodes.fuzzer:Fuzzer, params: {{topics: {TOPICS}}}}}
"""
    with launched(tmp_path, graph) as g:
        wait_for(lambda: out.exists() and sum(1 for _ in open(out)) > 300, 90, "solved frames under fuzzing")
        pids = g.node_pids()
        from mocap_cli import topic_tools
        from mocap_cli.graph_registry import find_graph

        os.environ["MOCAP_RUN_DIR"] = str(g.run_dir)
        try:
            hb = topic_tools.collect_heartbeats(find_graph(g.name), 2.5)
        finally:
            del os.environ["MOCAP_RUN_DIR"]
        for node in ("hips", "localize", "torso", "left_arm", "right_leg", "retarget", "log"):
            assert sum(hb[node].errors.values()) > 0, f"{node} counted no bad message: {hb[node].errors}"
            assert hb[node].state == "running"
        assert "restarted node" not in g.log(), "a node died of bad input"
        assert g.node_pids() == pids
    log = g.log()
    assert "not msgpack" in log and "Traceback" not in log  # logged with reasons, never a crash

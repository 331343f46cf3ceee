import pytest

from mocap_cli.launch_file import LaunchError, load_launch_file, parse_override
from mocap_cli.launcher import plan


def test_override_parses_yaml_values():
    assert parse_override("solver.solver=fabrik") == ("solver", "solver", "fabrik")
    assert parse_override("src.rate_hz=300") == ("src", "rate_hz", 300)
    with pytest.raises(LaunchError, match="NODE.PARAM=VALUE"):
        parse_override("nonsense")


def test_plan_wires_publishers_to_subscribers(tmp_path):
    f = tmp_path / "g.yaml"
    f.write_text("""
namespace: mocap/actor1
nodes:
  - {id: src, kind: synthetic_source}
  - {id: relay, kind: relay, remaps: {in: markers/raw, out: markers/relayed}, replicas: 2}
  - {id: log, kind: frame_log, params: {path: /tmp/x}, remaps: {in: markers/relayed}}
""")
    lf = load_launch_file(f, ["src.rate_hz=300"])
    assert lf.nodes[0].params["rate_hz"] == 300
    procs = {p.spec.id: p for p in plan(lf, "/tmp/s", "ipc:///tmp/s/control")}
    assert set(procs) == {"src", "relay#0", "relay#1", "log"}
    assert procs["src"].publishes[0] == "mocap/actor1/markers/raw"
    # both replicas subscribe to the source, and the log hears both replicas
    assert procs["src"].spec.expected_subscribers["mocap/actor1/markers/raw"] == 2
    assert len(procs["log"].spec.sub_endpoints["mocap/actor1/markers/relayed"]) == 2


def test_bad_files(tmp_path):
    f = tmp_path / "g.yaml"
    f.write_text("nodes: [{id: a, kind: relay}, {id: a, kind: relay}]")
    with pytest.raises(LaunchError, match="duplicate node ids: a"):
        load_launch_file(f)
    f.write_text("nodes: [{id: a, kind: relay, colour: red}]")
    with pytest.raises(LaunchError, match="colour"):
        load_launch_file(f)
    with pytest.raises(LaunchError, match="not found"):
        load_launch_file(tmp_path / "none.yaml")
    f.write_text("nodes: [{id: a, kind: relay}]")
    with pytest.raises(LaunchError, match="no node 'b'"):
        load_launch_file(f, ["b.x=1"])

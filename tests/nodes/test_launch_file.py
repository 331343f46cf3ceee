import subprocess
import sys
import time

import pytest

from mocap_cli.launch_file import LaunchError, load_launch_file, parse_override
from mocap_cli.launcher import plan
from tests.conftest import REPO


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


def test_what_a_red_team_sent_is_a_clear_error_not_a_traceback(tmp_path):
    studio = REPO / "launch" / "studio.yaml"
    for setting, said in (("viewer.up_axis=@x", "not YAML .*quote a text value"),
                          ("viewer.port=&a [*a, *a, *a]", "expands to over"),
                          ("viewer.hwm=1e20", "hwm"), ("viewer.hwm=100000000000", "less than or equal"),
                          ("viewer.endpoint=builtins:print", "endpoint")):
        with pytest.raises(LaunchError, match=said):
            load_launch_file(studio, [setting])
    files = {"latin1.yaml": (b"name: x\nnodes: \xff\xfe\n", "not UTF-8"),
             "deep.yaml": (b"nodes: " + b"[" * 20000 + b"]" * 20000, "nested too deep"),
             "slash.yaml": (b"name: a/b\nnodes: [{id: s, kind: relay}]\n", "name"),
             "long.yaml": (b"name: " + b"a" * 300 + b"\nnodes: [{id: s, kind: relay}]\n", "name"),
             "listid.yaml": (b"nodes: [{id: [s], kind: relay}]\n", "nodes.0.id")}
    for name, (text, said) in files.items():
        (tmp_path / name).write_bytes(text)
        with pytest.raises(LaunchError, match=said):
            load_launch_file(tmp_path / name)


def test_overrides_get_the_files_checks_and_an_alias_bomb_is_refused(tmp_path):
    """`--set torso.kind=null` was a TypeError traceback, `replicas=1000` planned 1,010 processes, `replicas=0`
    dropped the node silently, and a 600-byte YAML alias bomb took 34 s and 4 GB before its error."""
    studio = REPO / "launch" / "studio.yaml"
    for setting, said in (("torso.kind=null", "nodes.3.kind"), ("torso.replicas=1000", "less than or equal to 64"),
                          ("torso.replicas=0", "greater than or equal to 1")):
        with pytest.raises(LaunchError, match=said):
            load_launch_file(studio, [setting])
    assert load_launch_file(studio, ["torso.replicas=2"]).nodes[3].replicas == 2
    bomb = "a: &a [x, x, x, x, x, x, x, x, x, x]\n" + "".join(
        f"{chr(98 + i)}: &{chr(98 + i)} [*{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}, "
        f"*{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}]\n"
        for i in range(8)) + "nodes: [{id: x, kind: relay, params: {p: *i}}]\n"
    (tmp_path / "bomb.yaml").write_text(bomb)
    t = time.monotonic()
    with pytest.raises(LaunchError, match="aliases"):
        load_launch_file(tmp_path / "bomb.yaml")
    assert time.monotonic() - t < 2
    r = subprocess.run([sys.executable, "-m", "mocap_cli.main", "launch", str(studio), "--plan", "--set",
                        "torso.kind=null"], cwd=REPO, capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "Traceback" not in r.stderr and "torso.kind=null" in r.stderr


@pytest.mark.parametrize("override, node, says", [
    ("hips.profile=nosuch", "hips", "ProfileError: profile 'nosuch' not found (shipped profiles: "),
    ("source.path=/nonexistent/take.c3d", "source", "RecordingError: /nonexistent/take.c3d: file not found"),
])
def test_a_node_that_cannot_start_stops_the_launch_with_one_line(tmp_path, override, node, says):
    """A mistake only a node's setup can see (a profile name, a missing file): the launch stops with exit 2 and
    one line naming the node and the fix, instead of restarting the node in a loop with tracebacks."""
    import os

    env = {**os.environ, "MOCAP_RUN_DIR": str(tmp_path)}
    t = time.monotonic()
    r = subprocess.run([sys.executable, "-m", "mocap_cli.main", "launch", "launch/studio.yaml", "--set", override,
                        "--set", "viewer.port=0"], cwd=REPO, env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 2, r.stderr[-2000:]
    line = next(x for x in r.stderr.splitlines() if "mocap.launch" in x and "could not start" in x)
    assert f"node {node} could not start: {says}" in line and f"--set {node}.PARAM=VALUE" in line
    assert "Traceback" not in r.stderr and "restart" not in r.stderr
    assert time.monotonic() - t < 60


def test_a_set_names_the_node_kinds_param_before_the_launch_file_key_of_that_name():
    # host: is also the machine a node runs on (hosts:); --set qtm.host is where QTM is, as the README says
    lf = load_launch_file(REPO / "launch/qtm_unity.yaml", ["qtm.host=192.168.0.10", "vmc.host=192.168.0.20"])
    nodes = {n.id: n for n in lf.nodes}
    assert nodes["qtm"].params["host"] == "192.168.0.10" and nodes["vmc"].params["host"] == "192.168.0.20"
    assert nodes["qtm"].host is None and nodes["vmc"].host is None
    assert load_launch_file(REPO / "launch/studio.yaml", ["hips.keep_last=true"]).nodes[1].keep_last


def test_preset_studio_is_the_gap_filling_beyond_the_thesis_and_a_param_beside_it_wins():
    from mocap_core.fill_options import STUDIO, FillOptions
    from nodes.hip_interpolation import Params as HipParams
    from nodes.ik_gapfill import Params as IkParams

    ik = IkParams.model_validate({"limb": "left_arm", "preset": "studio", "end_model": False})
    assert FillOptions.of(ik) == STUDIO.model_copy(update={"end_model": False})
    # the swivel off leaves the limb memory and the body model, which steer it, idle: refused, saying so
    with pytest.raises(ValueError, match="limb_memory and body_model steer the swivel, which is off"):
        IkParams.model_validate({"limb": "left_arm", "preset": "studio", "swivel": False})
    # the studio options by default (as mocap solve), the thesis's method by name
    assert FillOptions.of(IkParams.model_validate({"limb": "left_arm"})) == STUDIO
    assert FillOptions.of(IkParams.model_validate({"limb": "left_arm", "preset": "thesis"})) == FillOptions()
    assert HipParams.model_validate({}) == HipParams.model_validate({"preset": "studio"})
    # the body and end models learn from the mirrored limb: the torso's preset leaves them out, a param is refused
    assert FillOptions.of(IkParams.model_validate({"limb": "torso", "preset": "studio"})) == STUDIO.for_limb("torso")
    assert not STUDIO.for_limb("torso").body_model and not STUDIO.for_limb("torso").end_model
    with pytest.raises(ValueError, match="end_model learns from the mirrored limb, which the torso has not"):
        IkParams.model_validate({"limb": "torso", "preset": "studio", "end_model": True})
    hips = HipParams.model_validate({"preset": "studio"})
    assert (hips.when_lost, hips.rebuild, hips.pose_memory, hips.pair_guard) == ("fit", True, True, True)
    with pytest.raises(ValueError, match="preset"):
        IkParams.model_validate({"limb": "torso", "preset": "fast"})

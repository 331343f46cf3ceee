"""Real processes over real sockets: the launcher, readiness, restarts, shutdown, bad input."""
import os
import signal

import pytest

from tests.conftest import REPO, launched, log_rows, pid_alive, wait_for

SMOKE = """
nodes:
  - id: source
    kind: synthetic_source
    params: {{rate_hz: {rate}, frames: {frames}}}
  - id: relay
    kind: relay
    remaps: {{in: markers/raw, out: markers/relayed}}
  - id: log
    kind: frame_log
    params: {{path: {log}}}
    remaps: {{in: markers/relayed}}
"""


def read_frames(path):
    return [int(r["frame"]) for r in log_rows(path)]


def test_graph_delivers_every_frame_after_readiness(tmp_path):
    out = tmp_path / "frames.csv"
    with launched(tmp_path, SMOKE.format(rate=500, frames=300, log=out), "--until-done") as g:
        g.proc.wait(timeout=30)
        assert g.proc.returncode == 0, g.log()
    assert read_frames(out) == list(range(300)), "frames lost or reordered"
    assert "ready in" in g.log()


def test_killed_node_is_restarted_and_graph_resumes(tmp_path):
    out = tmp_path / "frames.csv"
    with launched(tmp_path, SMOKE.format(rate=200, frames=0, log=out)) as g:
        wait_for(lambda: out.exists() and len(read_frames(out)) > 20, 15, "frames through the graph")
        old = g.node_pids()["relay"]
        os.kill(old, signal.SIGKILL)
        new = wait_for(lambda: (p := g.node_pids().get("relay")) != old and p, 5, "a restarted relay")
        assert pid_alive(new)
        n = len(read_frames(out))
        wait_for(lambda: len(read_frames(out)) > n + 20, 5, "frames after the restart")
        assert "restarted node relay" in g.log()


def test_a_restarted_frame_log_goes_on_after_what_it_wrote(tmp_path):
    out = tmp_path / "frames.csv"
    with launched(tmp_path, SMOKE.format(rate=200, frames=0, log=out)) as g:
        wait_for(lambda: out.exists() and len(read_frames(out)) > 20, 15, "frames through the graph")
        old = g.node_pids()["log"]
        before = read_frames(out)
        os.kill(old, signal.SIGKILL)
        wait_for(lambda: (p := g.node_pids().get("log")) != old and p, 5, "a restarted log")
        wait_for(lambda: len(read_frames(out)) > len(before) + 20, 5, "frames after the restart")
    lines = out.read_text().splitlines()
    assert sum(line.startswith("frame,") for line in lines) == 1  # one header, the first run's
    assert read_frames(out)[:len(before)] == before                  # what the first run wrote is kept


def test_ctrl_c_stops_everything_within_two_seconds(tmp_path):
    out = tmp_path / "frames.csv"
    with launched(tmp_path, SMOKE.format(rate=200, frames=0, log=out)) as g:
        wait_for(lambda: out.exists() and len(read_frames(out)) > 5, 15, "frames through the graph")
        pids = list(g.node_pids().values())
        assert len(pids) == 3 and all(pid_alive(p) for p in pids)
        took = g.stop()
        assert took < 2.0, f"graph took {took:.2f} s to stop"
        assert not any(pid_alive(p) for p in pids), "a node process was left behind"
        assert not g.registry_file.exists()


@pytest.mark.parametrize("relay_kind", ["relay", "raw_relay"])
def test_malformed_messages_are_counted_and_skipped(tmp_path, relay_kind):
    out = tmp_path / "frames.csv"
    graph = f"""
nodes:
  - id: bad
    kind: tests.fixtures_nodes.garbage_source:GarbageSource
    params: {{frames: 80}}
  - id: relay
    kind: {relay_kind}
    remaps: {{in: markers/raw, out: markers/relayed}}
  - id: log
    kind: frame_log
    params: {{path: {out}}}
    remaps: {{in: markers/relayed}}
"""
    with launched(tmp_path, graph) as g:
        wait_for(lambda: out.exists() and len(read_frames(out)) >= 80, 15, "all valid frames")
        nodes = g.cli("node", "list", "--seconds", "1.5")
        assert nodes.returncode == 0, nodes.stderr
        relay = next(line for line in nodes.stdout.splitlines() if line.startswith("relay"))
        assert int(relay.split()[-1]) >= 60, relay  # errors column: every bad message counted
        assert g.proc.poll() is None and pid_alive(g.node_pids()["relay"])
    assert read_frames(out) == list(range(80))
    # A relay publishes frames as its own; a raw relay forwards the source's bytes, stamp included.
    publisher = "relay" if relay_kind == "relay" else "bad"
    assert {r["publisher"] for r in log_rows(out)} == {publisher}
    log = g.log()
    assert "not msgpack" in log and "no header map" in log and "on a topic of mocap.MarkerFrame" in log
    assert "topic 'markers/raw'" in log


def test_topic_tools_against_running_graph(tmp_path):
    out = tmp_path / "frames.csv"
    with launched(tmp_path, SMOKE.format(rate=100, frames=0, log=out)) as g:
        wait_for(lambda: out.exists() and len(read_frames(out)) > 5, 15, "frames")
        lst = g.cli("topic", "list")
        assert lst.returncode == 0, lst.stderr
        assert "markers/relayed" in lst.stdout and "publishers: relay" in lst.stdout
        echo = g.cli("topic", "echo", "markers/relayed", "--once", "--timeout", "5")
        assert echo.returncode == 0, echo.stderr
        assert "mocap.MarkerFrame" in echo.stdout and "positions: float32[35, 3]" in echo.stdout
        hz = g.cli("topic", "hz", "markers/raw", "--duration", "2.2")
        rates = [float(line.split()[1]) for line in hz.stdout.splitlines() if line.startswith("markers/raw:")]
        assert rates and 80 <= rates[-1] <= 120, hz.stdout
        missing = g.cli("topic", "echo", "no/such/topic", "--once")
        assert missing.returncode != 0 and "no node of graph" in missing.stderr


def test_bad_launch_file_gives_clear_error(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("nodes:\n  - id: x\n    kind: no_such_kind\n")
    from tests.conftest import REPO
    import subprocess, sys
    r = subprocess.run([sys.executable, "-m", "mocap_cli.main", "launch", str(bad)], cwd=REPO,
                       capture_output=True, text=True, timeout=30)
    assert r.returncode == 2 and "unknown node kind 'no_such_kind'" in r.stderr
    bad.write_text("nodes:\n  - id: x\n    kind: synthetic_source\n    params: {rate_hz: -1}\n")
    r = subprocess.run([sys.executable, "-m", "mocap_cli.main", "launch", str(bad)], cwd=REPO,
                       capture_output=True, text=True, timeout=30)
    assert r.returncode == 2 and "bad params" in r.stderr


def test_nodes_fork_from_one_warm_parent_that_dies_with_the_launcher(tmp_path):
    # Every node process is forked from one parent that loaded the graph's node kinds once (nodes.forkserver), a
    # child of the launcher, and so is a restarted one; kill -9 the launcher and that parent and every node go too.
    import psutil

    out = tmp_path / "frames.csv"
    with launched(tmp_path, SMOKE.format(rate=200, frames=0, log=out)) as g:
        wait_for(lambda: out.exists() and len(read_frames(out)) > 5, 15, "frames through the graph")
        pids = list(g.node_pids().values())
        parents = {psutil.Process(p).ppid() for p in pids}
        assert len(parents) == 1 and parents != {g.proc.pid}, parents
        parent = parents.pop()
        assert psutil.Process(parent).ppid() == g.proc.pid
        os.kill(g.node_pids()["relay"], signal.SIGKILL)  # a restart is a fork of the same parent
        new = wait_for(lambda: (p := g.node_pids().get("relay")) not in pids and p, 5, "a restarted relay")
        assert psutil.Process(new).ppid() == parent
        g.proc.kill()
        wait_for(lambda: not any(pid_alive(p) for p in [parent, new, *pids]), 5, "no node left behind")


def test_heartbeatpercentiles_match_numpy():
    import numpy as np

    from nodes.runtime import percentiles

    rng = np.random.default_rng(3)
    for n in (1, 2, 7, 1000):
        values = rng.exponential(2.0, n)
        assert np.allclose(percentiles(values, (50, 95, 99)), np.percentile(values, [50, 95, 99]))


def test_heartbeats_split_a_nodes_cpu_between_its_handlers_and_the_runtime(tmp_path, monkeypatch):
    # benchmarks/node_cpu.py reads these: the process's CPU, and with MOCAP_CPU_SPLIT=1 the part in the handlers
    # and, within them, in publishing.
    monkeypatch.setenv("MOCAP_CPU_SPLIT", "1")
    out = tmp_path / "frames.csv"
    with launched(tmp_path, SMOKE.format(rate=200, frames=0, log=out)) as g:
        wait_for(lambda: out.exists() and len(read_frames(out)) > 100, 15, "frames through the graph")
        cpu = g.heartbeats(1.5)["relay"].cpu
    assert cpu.process_s > cpu.handlers_s > cpu.publishing_s > 0, cpu


def _may_use_realtime() -> bool:
    import resource

    from nodes.priority import REALTIME_PRIORITY

    return os.geteuid() == 0 or resource.getrlimit(resource.RLIMIT_RTPRIO)[0] >= REALTIME_PRIORITY


def test_a_realtime_graph_runs_every_node_thread_under_sched_rr_restarts_included(tmp_path):
    # (launch/qtm_studio.yaml and the other studio files say realtime: true; where this user may not, the graph
    # runs at normal priority and the launcher says how to allow it)
    out = tmp_path / "frames.csv"
    with launched(tmp_path, "realtime: true\n" + SMOKE.format(rate=200, frames=0, log=out)) as g:
        wait_for(lambda: out.exists() and len(read_frames(out)) > 20, 15, "frames through the graph")
        wait_for(lambda: "realtime:" in g.log(), 5, "the launcher's word on real-time scheduling")
        os.kill(g.node_pids()["relay"], signal.SIGKILL)
        old = set(g.node_pids().values())
        wait_for(lambda: g.node_pids().get("relay") not in old, 5, "a restarted relay")
        n = len(read_frames(out))
        wait_for(lambda: len(read_frames(out)) > n + 20, 5, "frames after the restart")
        threads = [int(t) for pid in g.node_pids().values() for t in os.listdir(f"/proc/{pid}/task")]
        policies = {os.sched_getscheduler(t) for t in threads}
    assert len(threads) >= 6  # each node's own thread and zmq's I/O thread
    if _may_use_realtime():
        assert policies == {os.SCHED_RR}, policies
        assert "realtime: 3 node processes under SCHED_RR, priority 10" in g.log()
    else:
        assert policies == {os.SCHED_OTHER}, policies
        assert "run at normal priority" in g.log() and "rtprio" in g.log()


def test_no_realtime_on_the_command_line_runs_a_realtime_file_at_normal_priority(tmp_path):
    out = tmp_path / "frames.csv"
    with launched(tmp_path, "realtime: true\n" + SMOKE.format(rate=200, frames=0, log=out), "--no-realtime") as g:
        wait_for(lambda: out.exists() and len(read_frames(out)) > 20, 15, "frames through the graph")
        policies = {os.sched_getscheduler(pid) for pid in g.node_pids().values()}
    assert policies == {os.SCHED_OTHER}, policies
    assert "realtime:" not in g.log()


def test_realtime_scheduling_refused_is_a_reason_not_a_failure():
    # A user without an rtprio limit or CAP_SYS_NICE (here: root turned into nobody, which drops both)
    import subprocess
    import sys

    code = ("import os, resource\nfrom nodes.priority import use_realtime\n"
            "resource.setrlimit(resource.RLIMIT_RTPRIO, (0, 0))\n"
            "if os.geteuid() == 0:\n    os.setgid(65534); os.setuid(65534)\n"
            "print(repr(use_realtime())); print(os.sched_getscheduler(0) == os.SCHED_OTHER)")
    done = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    reason, normal = done.stdout.split("\n")[:2]
    assert "PermissionError" in reason and normal == "True", done.stdout

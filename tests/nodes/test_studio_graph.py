"""The full graph of launch/studio.yaml as real processes on a real take with real marker gaps."""
import csv
import subprocess
import sys

import numpy as np
import yaml

from mocap_core.joints_csv import read_joints_csv
from mocap_core.skeleton import INDEX, Status
from tests.conftest import REPO, data_file, launched, wait_for

TAKE = "12_vicon_freeform_realgaps_nimble_nick_freeform_001.c3d"


def studio(tmp_path, frames, solver="ccd"):
    lf = yaml.safe_load((REPO / "launch" / "studio.yaml").read_text())
    for node in lf["nodes"]:
        if node["id"] == "source":
            node["params"] = {"path": str(data_file(TAKE)), "max_frames": frames}
        if node["kind"] == "ik_gapfill":
            node["params"]["solver"] = solver
        if node["id"] == "log":
            node["params"]["path"] = str(tmp_path / "solved.csv")
        if node["id"] == "viewer":
            node["params"]["port"] = 0
        if node["id"] == "retarget":
            # every frame, not the live latency policy: on a shared 2-core host with 11 processes, the retarget
            # node can be starved past its 20 ms wait for a torso and drop that frame's limbs (seen once in CI)
            node.setdefault("params", {})["max_wait_ms"] = 2000
    return yaml.safe_dump(lf)


def test_full_graph_solves_every_frame(tmp_path):
    with launched(tmp_path, studio(tmp_path, 240, "fabrik"), "--until-done") as g:
        g.proc.wait(timeout=120)
        assert g.proc.returncode == 0, g.log()
    with open(tmp_path / "solved.csv") as f:
        rows = list(csv.DictReader(f))
    frames = [int(r["frame"]) for r in rows]
    assert frames == list(range(240)), "skeleton/solved lost or reordered frames"
    assert {r["publisher"] for r in rows} == {"retarget"}
    assert "Traceback" not in g.log()


def test_echo_solved_skeleton_from_the_running_graph(tmp_path):
    with launched(tmp_path, studio(tmp_path, 0)) as g:
        wait_for(lambda: (tmp_path / "solved.csv").exists() and (tmp_path / "solved.csv").stat().st_size > 500,
                 60, "solved frames")
        echo = g.cli("topic", "echo", "skeleton/solved", "--once", "--timeout", "10")
        assert echo.returncode == 0, echo.stderr
        assert "mocap.SkeletonFrame" in echo.stdout and "status: uint8[27]" in echo.stdout
        nodes = g.cli("node", "list")
        for node in ("hips", "localize", "torso", "left_arm", "right_leg", "retarget"):
            assert any(line.startswith(node) and "running" in line for line in nodes.stdout.splitlines()), nodes.stdout


def test_mocap_solve_fills_the_real_gaps(tmp_path):
    out = tmp_path / "joints.csv"
    r = subprocess.run([sys.executable, "-m", "mocap_cli.main", "solve", str(data_file(TAKE)), "--profile", "vicon53",
                        "--joints-out", str(out), "--quiet"], cwd=REPO, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    frames, times, pos, status = read_joints_csv(out)
    assert len(frames) == 1101 and times[1] == np.float64(1 / 120).round(6)
    assert (status == Status.ESTIMATED).any() and (status == Status.HELD).any()
    assert (status != Status.MISSING).mean() > 0.99
    assert np.isnan(pos[status == Status.MISSING]).all() and np.isfinite(pos[status != Status.MISSING]).all()
    # localization only leaves the gaps open
    r = subprocess.run([sys.executable, "-m", "mocap_cli.main", "solve", str(data_file(TAKE)), "--profile", "vicon53",
                        "--joints-out", str(out), "--no-ik", "--quiet"], cwd=REPO, capture_output=True, text=True,
                       timeout=300)
    _, _, _, status_loc = read_joints_csv(out)
    assert (status_loc == Status.MISSING).sum() > 1000 and not (status_loc == Status.ESTIMATED).any()
    assert (status_loc[:, INDEX["pelvis"]] == Status.LOCATED).all()


def test_solve_reports_bad_input_clearly(tmp_path):
    r = subprocess.run([sys.executable, "-m", "mocap_cli.main", "solve", str(data_file(TAKE)), "--profile", "cmu41",
                        "--joints-out", str(tmp_path / "x.csv")], cwd=REPO, capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "profile cmu41.yaml line" in r.stderr and "is not in the recording" in r.stderr

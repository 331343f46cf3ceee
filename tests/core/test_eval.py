"""`mocap eval` on real takes: the reports exist and say something that could be wrong."""
import csv
import subprocess
import sys

from tests.conftest import REPO, data_file


def mocap(*args):
    return subprocess.run([sys.executable, "-m", "mocap_cli.main", *args], cwd=REPO, capture_output=True, text=True,
                          timeout=600)


def test_eval_gaps_writes_table_csv_and_plots(tmp_path):
    r = mocap("eval", "gaps", "--take", str(data_file("02_qualisys_walking_ezc3d_Qualisys.c3d")), "--profile",
              "qualisys_sports", "--remove", "knee_l,ankle_l", "--from", "0.5", "--to", "1.2", "--solvers",
              "ccd,fabrik", "--constraints", "on", "--report", str(tmp_path))
    assert r.returncode == 0, r.stderr
    rows = list(csv.DictReader(open(tmp_path / "gaps.csv")))
    assert {(x["mode"], x["solver"], x["joint"]) for x in rows} == {
        (m, s, j) for m in ("markers", "joint") for s in ("ccd", "fabrik") for j in ("knee_l", "ankle_l")}
    for x in rows:
        assert 0 <= float(x["min"]) <= float(x["mean"]) <= float(x["max"]) < 1.0  # a leg length
        assert int(x["missing"]) == 0
    md = (tmp_path / "gaps.md").read_text()
    assert "Re-acquisition" in md and "| markers | ccd | on | knee_l |" in md
    for name in ("error_markers_constrained.png", "trajectory_joint_constrained.png"):
        assert (tmp_path / name).stat().st_size > 10_000


def test_eval_timing_reports_every_requested_solver(tmp_path):
    r = mocap("eval", "timing", "--take", str(data_file("02_qualisys_walking_ezc3d_Qualisys.c3d")), "--profile",
              "qualisys_sports", "--solvers", "ccd,dls", "--constraints", "on", "--report", str(tmp_path), "--json")
    assert r.returncode == 0, r.stderr
    rows = list(csv.DictReader(open(tmp_path / "timing.csv")))
    assert [x["solver"] for x in rows] == ["ccd", "dls"]
    for x in rows:
        assert int(x["frames"]) == 3 * 339 and 0 < float(x["min_ms"]) <= float(x["mean_ms"]) <= float(x["max_ms"])

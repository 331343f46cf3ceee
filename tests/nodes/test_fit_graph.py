"""The rigid-skeleton fit as a node (launch/studio_fit.yaml) and through `mocap solve --fit`, on the real take
with real gaps."""
import csv
import subprocess
import sys

import numpy as np
import yaml

from mocap_core.fit.compare import bone_lengths
from mocap_core.joints_csv import read_joints_csv
from mocap_core.skeleton import Status
from tests.conftest import REPO, data_file, launched

TAKE = "12_vicon_freeform_realgaps_nimble_nick_freeform_001.c3d"


def test_fit_graph_calibrates_live_and_then_solves_every_joint(tmp_path):
    lf = yaml.safe_load((REPO / "launch" / "studio_fit.yaml").read_text())
    for node in lf["nodes"]:
        if node["id"] == "source":
            node["params"] = {"path": str(data_file(TAKE)), "max_frames": 480}
        if node["id"] == "fit":
            node.setdefault("params", {})["save_subject"] = str(tmp_path / "actor.yaml")
        if node["id"] == "log":
            node["params"]["path"] = str(tmp_path / "solved.csv")
        if node["id"] == "viewer":
            node["params"]["port"] = 0
    with launched(tmp_path, yaml.safe_dump(lf), "--until-done") as g:
        g.proc.wait(timeout=180)
        assert g.proc.returncode == 0, g.log()
    with open(tmp_path / "solved.csv") as f:
        rows = list(csv.DictReader(f))
    assert [int(r["frame"]) for r in rows] == list(range(480))
    assert "calibrated the subject" in g.log()
    # localization alone before the first calibration (2 s): joints go missing in the real gaps; the fit after it
    # leaves none missing
    assert sum(int(r["missing"]) for r in rows[:240]) > 0
    assert sum(int(r["missing"]) for r in rows[260:]) == 0
    assert "Traceback" not in g.log()


def test_solve_fit_keeps_every_bone_and_reuses_a_subject(tmp_path):
    subject, out = tmp_path / "actor.yaml", tmp_path / "joints.csv"
    r = subprocess.run([sys.executable, "-m", "mocap_cli.main", "calibrate", str(data_file(TAKE)), "--profile",
                        "vicon53", "-o", str(subject)], cwd=REPO, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "markers on a bone" in r.stderr and yaml.safe_load(subject.read_text())["profile"] == "vicon53"
    r = subprocess.run([sys.executable, "-m", "mocap_cli.main", "solve", str(data_file(TAKE)), "--profile", "vicon53",
                        "--subject", str(subject), "--joints-out", str(out), "--quiet"], cwd=REPO,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    frames, _, pos, status = read_joints_csv(out)
    assert len(frames) == 1101 and (status != Status.MISSING).all()
    lengths = bone_lengths(pos)
    assert np.abs(lengths / np.median(lengths, axis=0) - 1).max() < 0.001  # float32 CSV, rigid bones
    r = subprocess.run([sys.executable, "-m", "mocap_cli.main", "solve", str(data_file(TAKE)), "--profile", "vicon53",
                        "--subject", str(tmp_path / "nobody.yaml"), "--joints-out", str(out)], cwd=REPO,
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "mocap calibrate" in r.stderr

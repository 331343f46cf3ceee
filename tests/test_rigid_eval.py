"""`mocap eval rigid` on a real take: the methods side by side, written as a report."""
import csv
import subprocess
import sys

from tests.conftest import REPO, data_file


def test_eval_rigid_reports_the_methods_side_by_side_on_a_real_take(tmp_path):
    data_file("02_qualisys_walking_ezc3d_Qualisys.c3d")  # fails loudly when the recording is missing
    r = subprocess.run([sys.executable, "-m", "mocap_cli.main", "eval", "rigid", "--takes", "qualisys_walk",
                        "--report", str(tmp_path)], cwd=REPO, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    rows = list(csv.DictReader(open(tmp_path / "rigid.csv")))
    by = {(x["case"], x["method"]): x for x in rows}
    assert {m for _, m in by} >= {"thesis", "studio", "studio_subject", "fit", "fit_subject"}
    assert ("all", "fit_subject") not in by   # nothing hidden: the subject's fit is the fit
    assert ("all", "studio_subject") not in by
    assert float(by["all", "fit"]["bone_cv_pct"]) < 1e-9 < float(by["all", "thesis"]["bone_cv_pct"])
    assert float(by["all", "fit"]["complete_pct"]) == 100
    for case in ("worst", "elbow_l", "knee_ankle_r"):
        assert float(by[case, "fit"]["estimated_pct"]) == 100
        assert float(by[case, "fit_subject"]["estimated_pct"]) == 100
        assert float(by[case, "fit_subject"]["bone_cv_pct"]) < 1e-9
        assert float(by[case, "studio_subject"]["bone_cv_pct"]) < 1e-9   # the subject's bones, rigid
    # the worst case: only the pelvis, head, hand and toe markers from 1 s; the rigid fit is nearer
    assert float(by["worst", "fit"]["mean_mm"]) < float(by["worst", "thesis"]["mean_mm"])
    text = (tmp_path / "rigid.md").read_text()
    row = next(line for line in text.splitlines() if line.startswith("| qualisys_walk | "))   # the summary
    assert [len(cell.split(" / ")) for cell in row.split(" | ")[1:]] == [5, 5, 5, 3]
    assert "| qualisys_walk | elbow_l | fit_subject |" in text

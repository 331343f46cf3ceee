"""Archive re-solves: several takes in a pool of processes, and on a local Dask cluster, each writing what a
serial run writes; a take that fails is reported and the others are finished."""
import filecmp
import subprocess
import sys

from tests.conftest import REPO, data_file

TAKES = ["02_qualisys_walking_ezc3d_Qualisys.c3d", "03_sprint_start_BTK_SprintMotion.trc",
         "12_vicon_freeform_realgaps_nimble_nick_freeform_001.c3d"]


def solve(*args):
    return subprocess.run([sys.executable, "-m", "mocap_cli.main", "solve", *args], cwd=REPO, capture_output=True,
                          text=True, timeout=600)


def same_outputs(a, b) -> bool:
    names = sorted(p.name for p in a.iterdir())
    return names == sorted(p.name for p in b.iterdir()) and all(filecmp.cmp(a / n, b / n, shallow=False)
                                                                for n in names)


def test_a_pool_writes_what_a_serial_run_writes_and_a_bad_take_is_reported(tmp_path):
    takes = [str(data_file(t)) for t in TAKES]
    missing = str(tmp_path / "gone.c3d")
    serial = solve(*takes, "--out-dir", str(tmp_path / "serial"), "--jobs", "1", "--bvh")
    assert serial.returncode == 0, serial.stderr
    pooled = solve(*takes, missing, "--out-dir", str(tmp_path / "pool"), "--jobs", "2", "--bvh")
    assert pooled.returncode == 1, pooled.stderr      # one take failed ...
    assert "gone  " in pooled.stdout and "failed: RecordingError" in pooled.stdout and "; 1 failed" in pooled.stdout
    assert same_outputs(tmp_path / "serial", tmp_path / "pool")   # ... and the others are all there, identical
    assert "4 takes, 2229 frames" in pooled.stdout


def test_a_local_dask_cluster_writes_what_a_serial_run_writes(tmp_path):
    takes = [str(data_file(t)) for t in TAKES[:2]]
    serial = solve(*takes, "--out-dir", str(tmp_path / "serial"), "--jobs", "1")
    dask = solve(*takes, "--out-dir", str(tmp_path / "dask"), "--cluster", "local")
    assert serial.returncode == 0 and dask.returncode == 0, dask.stderr[-3000:]
    assert same_outputs(tmp_path / "serial", tmp_path / "dask")


def test_a_solve_says_which_joints_it_left_missing_and_times_the_whole_solve(tmp_path, caplog):
    """A joint missing in over 10 % of the frames is named with its share; the timing line counts the solve, not
    only the writing (the fit's frames come all at once, before the writing)."""
    import argparse
    import time

    import numpy as np

    from mocap_cli.solve import _write
    from mocap_core.pipeline import SolvedChunk
    from mocap_core.profiles import load_profile
    from mocap_core.recordings import read_recording
    from mocap_core.skeleton import INDEX, N_JOINTS, Status
    from tests.conftest import data_file

    rec = read_recording(data_file("03_sprint_start_BTK_SprintMotion.trc")).slice(0, 100)
    status = np.full((100, N_JOINTS), Status.LOCATED, np.uint8)
    status[:30, INDEX["knee_l"]] = Status.MISSING   # 30 %: said
    status[:5, INDEX["knee_r"]] = Status.MISSING    # 5 %: not
    chunk = SolvedChunk(0, np.zeros((100, N_JOINTS, 3)), np.tile(np.eye(3), (100, N_JOINTS, 1, 1)), status)
    args = argparse.Namespace(joints_out=str(tmp_path / "out.csv"), bvh_out=None, bvh_names=None, quiet=True)
    with caplog.at_level("INFO", logger="mocap.solve"):
        got = _write(args, rec, load_profile("btk_sprint"), [chunk], time.perf_counter() - 2.0)
    assert "knee_l is missing in 30 % of the frames" in caplog.text and "knee_r is missing" not in caplog.text
    assert got["seconds"] >= 2.0

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

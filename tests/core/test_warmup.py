"""The numba kernel cache: a stamp says when this checkout's kernels are compiled, so the launcher
compiles once up front instead of in every node process at once."""
import os
import subprocess
import sys

from mocap_core import warmup
from mocap_core.ik.solvers import SOLVERS
from tests.conftest import REPO


def test_the_warm_up_parts_cover_every_solver():
    assert set(SOLVERS) <= set(warmup.PARTS)


def test_the_stamp_follows_the_kernel_sources(tmp_path, monkeypatch):
    monkeypatch.setattr(warmup, "STAMP", tmp_path / "stamp")
    assert not warmup.kernels_cached()  # no stamp yet
    warmup.warm_up(("localization",))
    assert not warmup.kernels_cached()  # a part is not the whole
    warmup.warm_up()
    assert warmup.kernels_cached()
    (tmp_path / "stamp").write_text("a fingerprint of other sources")
    assert not warmup.kernels_cached()


def test_the_launcher_compiles_up_front_when_the_cache_is_not_known_warm(tmp_path):
    stamp = tmp_path / "stamp"
    launch = tmp_path / "g.yaml"
    launch.write_text("nodes:\n  - {id: src, kind: synthetic_source, params: {rate_hz: 200, frames: 20}}\n")
    env = {**os.environ, "MOCAP_KERNEL_STAMP": str(stamp), "MOCAP_RUN_DIR": str(tmp_path)}
    run = lambda: subprocess.run([sys.executable, "-m", "mocap_cli.main", "launch", str(launch), "--until-done"],  # noqa: E731
                                 cwd=REPO, env=env, capture_output=True, text=True, timeout=240)
    first = run()
    assert first.returncode == 0, first.stderr
    assert "compiling the numba kernels" in first.stderr and "compiled and cached in" in first.stderr
    assert stamp.read_text() == warmup.fingerprint()
    second = run()
    assert second.returncode == 0 and "compiling the numba kernels" not in second.stderr

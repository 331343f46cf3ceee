"""The numba kernel cache: a stamp says when this checkout's kernels are compiled, so the launcher
compiles once up front instead of in every node process at once."""
import os
import subprocess
import sys

from mocap_core import warmup
from mocap_core.ik.solvers import SOLVERS
from tests.conftest import REPO


def test_the_solvers_part_solves_with_every_solver(monkeypatch):
    seen = []
    monkeypatch.setattr(warmup, "_warm_limb", lambda solver, options: seen.append(solver))
    warmup.warm_up(("solvers",), stamp=False)
    assert seen == list(SOLVERS)


def test_the_stamp_follows_the_kernel_sources(tmp_path, monkeypatch):
    monkeypatch.setattr(warmup, "STAMP", tmp_path / "stamp")
    assert not warmup.kernels_cached(("localization",))  # no stamp yet
    warmup.warm_up(("localization",))
    assert warmup.kernels_cached(("localization",))
    assert not warmup.kernels_cached()  # a part is not the whole
    warmup.warm_up()
    assert warmup.kernels_cached()
    (tmp_path / "stamp").write_text("a fingerprint of other sources\nlocalization\n")
    assert not warmup.kernels_cached(("localization",))


def test_kernels_compiled_for_another_cpu_do_not_count(tmp_path, monkeypatch):
    # numba keys its cache on the CPU: a checkout or an image moved to another machine has to compile again
    from numba.core.registry import cpu_target

    monkeypatch.setattr(warmup, "STAMP", tmp_path / "stamp")
    warmup.warm_up(("rotations",))
    assert warmup.kernels_cached(("rotations",))
    codegen = cpu_target.target_context.codegen()
    here = codegen.magic_tuple()
    monkeypatch.setattr(type(codegen), "magic_tuple", lambda self: (here[0], "another-cpu", here[2]))
    assert not warmup.kernels_cached(("rotations",))


def test_the_launcher_compiles_the_kernels_its_graph_runs_up_front(tmp_path):
    stamp = tmp_path / "stamp"
    launch = tmp_path / "g.yaml"
    launch.write_text("nodes:\n  - {id: src, kind: synthetic_source, params: {rate_hz: 200, frames: 20}}\n"
                      "  - {id: localize, kind: joint_localization}\n")
    env = {**os.environ, "MOCAP_KERNEL_STAMP": str(stamp), "MOCAP_RUN_DIR": str(tmp_path)}
    run = lambda: subprocess.run([sys.executable, "-m", "mocap_cli.main", "launch", str(launch), "--until-done"],  # noqa: E731
                                 cwd=REPO, env=env, capture_output=True, text=True, timeout=240)
    first = run()
    assert first.returncode == 0, first.stderr
    assert "compiling the numba kernels" in first.stderr and "compiled and cached in" in first.stderr
    assert stamp.read_text().splitlines() == [warmup.fingerprint(), "localization"]
    second = run()
    assert second.returncode == 0 and "compiling the numba kernels" not in second.stderr


def test_a_node_kind_and_a_solve_name_the_kernels_they_run():
    from nodes.registry import load_kind

    gapfill = load_kind("ik_gapfill")
    assert gapfill.kernels(gapfill.Params(limb="left_arm", preset="thesis", solver="fabrik")) == ("solvers",)
    assert gapfill.kernels(gapfill.Params(limb="left_arm"))[0] == "beyond"
    hips = load_kind("hip_interpolation")
    assert hips.kernels(hips.Params(preset="thesis")) == ("markers",)
    assert set(hips.kernels(hips.Params())) == {"markers", "rebuild", "pose_memory", "pair_guard"}
    for kind in ("ik_gapfill", "hip_interpolation", "joint_localization", "skeleton_fit", "retarget"):
        cls = load_kind(kind)
        params = cls.Params(limb="torso") if kind == "ik_gapfill" else cls.Params()
        assert set(cls.kernels(params)) <= set(warmup.PARTS), kind
    assert warmup.pipeline_parts("thesis") == ("localization", "markers", "solvers")
    assert set(warmup.pipeline_parts("studio")) == {"localization", "markers", "rebuild", "pose_memory",
                                                          "pair_guard", "beyond", "blend"}
    assert warmup.pipeline_parts("studio", fill_gaps=False) == ("localization", "markers")


def test_a_change_of_kernel_sources_drops_every_cached_kernel(tmp_path, monkeypatch):
    # a kernel's cache is checked against its own file only: one compiled against an older callee must go too
    package = tmp_path / "pkg"
    (package / "__pycache__").mkdir(parents=True)
    (package / "sub" / "__pycache__").mkdir(parents=True)
    caches = [package / "__pycache__" / "a.f-1.py311.nbi", package / "sub" / "__pycache__" / "b.g-2.py311.1.nbc"]
    for path in caches:
        path.write_bytes(b"x")
    monkeypatch.setattr(warmup, "PACKAGE", package)
    monkeypatch.setattr(warmup, "CACHED_SOURCES", package / "__pycache__" / "numba-sources")
    warmup._drop_stale_caches("sources 1")  # no record of what they were compiled from: dropped
    assert not any(path.exists() for path in caches)
    for path in caches:
        path.write_bytes(b"x")
    warmup._drop_stale_caches("sources 1")  # compiled from these sources: kept
    assert all(path.exists() for path in caches)
    warmup._drop_stale_caches("sources 2")
    assert not any(path.exists() for path in caches)


def test_the_hip_stages_parts_compile_every_kernel_its_fills_run():
    """In a fresh process: after its parts, each landmark fill's kernel has a compiled signature (a warm-up that
    calls a fill wrongly leaves its kernel to a node's first frame)."""
    code = ("from mocap_core import warmup, segment_rebuild, leg_hinge, partial_means, pose_memory, pair_guard\n"
            "warmup.warm_up(('rebuild', 'pose_memory', 'pair_guard'), stamp=False)\n"
            "kernels = (segment_rebuild.rebuild_frame, leg_hinge.fill_frame, partial_means._fill_means,\n"
            "           pose_memory.fill_frame, pair_guard.guard_frame)\n"
            "print([k.__name__ for k in kernels if not k.signatures])")
    done = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip() == "[]"


def test_a_node_kind_that_runs_no_kernel_loads_no_numba():
    """Sources, relays, the recorder and the outputs are light processes: importing one loads neither numba nor (but
    for the BVH writer's and Foxglove's rotation conversions) scipy."""
    kinds = ("synthetic_source", "file_source", "qtm_ingest", "bag_player", "relay", "raw_relay", "recorder",
             "frame_log", "vmc_output", "viewer", "bvh_writer", "foxglove_output")
    code = ("import sys\nfrom nodes.registry import load_kind\n"
            f"for kind in {kinds!r}:\n"
            "    load_kind(kind)\n"
            "print(sorted(m for m in ('numba', 'scipy') if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip() == "['scipy']"
    light = kinds[:-2]
    code = code.replace(repr(kinds), repr(light))
    done = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and done.stdout.strip() == "[]", done.stdout + done.stderr[-2000:]

"""Load (or compile) the numba kernels before the first real frame, so frame one is not late.

Nodes call this in setup(), before they report ready; offline commands call it once up front.
Loading from the on-disk cache takes well under a second; the very first compile on a machine
takes one to two minutes. The launcher compiles once, up front, when the cache is not known to be
warm (``kernels_cached``): otherwise every node process of a graph would compile the same kernels
at the same time on the same cores (a first `make demo` took 8.5 minutes that way, not 2).

    python -m mocap_core.warmup     # compile now (two processes in parallel), then load everything
"""
from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import time
from importlib.metadata import version
from pathlib import Path

import numpy as np

PACKAGE = Path(__file__).resolve().parent
# Where "this checkout's kernels are compiled" is remembered (next to numba's own cache files).
STAMP = Path(os.environ.get("MOCAP_KERNEL_STAMP", PACKAGE / "__pycache__" / "numba-kernels.stamp"))
# every solver among them (a test checks)
PARTS = ("localization", "rebuild", "pose_memory", "pair_guard", "ccd", "fabrik", "jacobian_transpose", "dls", "beyond",
         "fit")


def warm_up(parts: tuple[str, ...] = PARTS, say: bool = False) -> None:
    for part in parts:
        _warm(part)
        if say:  # progress for whoever waits on a first compile
            print(f"  kernels: {part} ready", file=sys.stderr, flush=True)
    if tuple(parts) == PARTS:
        _write_stamp()


def ensure_compiled(log) -> bool:
    """Before a command's first frame: compile the kernels up front, in parallel and saying so, when this
    checkout has not yet (else the first frames would sit compiling, one process, in silence). True if it did."""
    if kernels_cached():
        return False
    log.info("compiling the numba kernels for this checkout, once (about 2 minutes on 2 cores)...")
    log.info("numba kernels compiled and cached in %.0f s", compile_kernels())
    return True


def _warm(part: str) -> None:
    """Run one part's kernels once: localization, the segment rebuild (and the leg hinge), the pose memory, the
    pair guard, the fit, or one solve on a chain with a missing middle joint (a solver by name; "beyond": CCD with
    the analytic fills of the studio options)."""
    warm = {"rebuild": _warm_rebuild, "pose_memory": _warm_pose_memory, "pair_guard": _warm_pair_guard,
            "fit": _warm_fit, "localization": _warm_localization}.get(part)
    if warm is not None:
        warm()
    else:
        _warm_solver(part)


def _warm_rebuild() -> None:
    from mocap_core.leg_hinge import LegHinge
    from mocap_core.partial_means import PartialMeans
    from mocap_core.profiles import LANDMARK_INDEX, LANDMARKS, load_profile
    from mocap_core.segment_rebuild import SegmentRebuilder

    rng = np.random.default_rng(0)
    rebuilder = SegmentRebuilder(("L_upper_arm",))
    lm, upper = rng.normal(size=(len(LANDMARKS), 3)), rng.normal(size=(1, 3))
    rebuilder.fill(lm.copy(), upper)
    lm[LANDMARK_INDEX["L_HLE"]] = np.nan  # rebuilt: Kabsch and the distances (LAPACK's first calls) run now
    rebuilder.fill(lm, upper)
    hinge, lm = LegHinge(("L_shank",)), rng.normal(size=(len(LANDMARKS), 3))  # (the rebuild's second part)
    hinge.fill(lm.copy(), upper)
    lm[[LANDMARK_INDEX[f"L_{name}"] for name in ("FLE", "FME", "FAL")]] = np.nan  # put, one malleolus kept
    hinge.fill(lm, upper)
    lm = rng.normal(size=(len(LANDMARKS), 3))
    lm[LANDMARK_INDEX["L_FAL"]] = np.nan
    hinge.fill(lm, upper)
    profile = load_profile("qualisys_sports")  # (the third: landmarks that are means; SACR is one there)
    labels = sorted({n for landmark in profile.landmarks for n in profile.markers_of(landmark)})
    means = PartialMeans(profile.resolve(labels))
    markers = rng.normal(size=(len(labels), 3))
    means.fill(markers, np.full((len(LANDMARKS), 3), np.nan))


def _warm_pose_memory() -> None:  # one call compiles the whole kernel, recall included
    from mocap_core.pose_memory import PoseMemory
    from mocap_core.profiles import LANDMARKS

    lm = np.random.default_rng(0).normal(size=(len(LANDMARKS), 3))
    PoseMemory(["SACR", "L_IAS", "R_IAS", "L_FM2", "L_FLE"]).fill(lm)


def _warm_pair_guard() -> None:
    from mocap_core.pair_guard import PairGuard
    from mocap_core.profiles import LANDMARKS

    PairGuard().fill(np.random.default_rng(0).normal(size=(len(LANDMARKS), 3)))


def _warm_fit() -> None:  # the rigid-skeleton fit: a start, then a frame warm-started from it
    from mocap_core.fit.fitter import SkeletonFitter
    from mocap_core.fit.subject import Subject
    from mocap_core.skeleton import N_JOINTS

    offsets = np.tile([0.0, 0.1, 0.0], (N_JOINTS, 1))
    markers = np.eye(3) * 0.1
    subject = Subject("warm_up", offsets, np.ones(N_JOINTS, bool), ["a", "b", "c"], np.zeros(3, np.int64),
                      markers, np.zeros(3))
    fitter = SkeletonFitter(subject, ["a", "b", "c"])
    fitter.fit(markers)
    fitter.fit(markers)


def _warm_localization() -> None:
    from mocap_core.ik.kernels import frames_to_quats, quats_to_frames
    from mocap_core.localization import Localizer
    from mocap_core.profiles import LANDMARKS
    from mocap_core.skeleton import N_JOINTS

    Localizer().localize(np.full((1, len(LANDMARKS), 3), np.nan))
    quats_to_frames(frames_to_quats(np.tile(np.eye(3), (N_JOINTS, 1, 1))))


def _warm_solver(part: str) -> None:
    from mocap_core.body_model import MIN_SAMPLES
    from mocap_core.fill_options import STUDIO, FillOptions
    from mocap_core.gapfill import LimbFiller
    from mocap_core.skeleton import N_JOINTS, Status

    solver, options = ("ccd", STUDIO) if part == "beyond" else (part, FillOptions())
    filler = LimbFiller("left_leg", solver, options=options)
    pos = np.zeros((N_JOINTS, 3))
    frames = np.tile(np.eye(3), (N_JOINTS, 1, 1))
    status = np.full(N_JOINTS, Status.LOCATED, np.uint8)
    for k, j in enumerate(filler.joints):
        pos[j] = [0.0, 0.1, 1.0 - 0.2 * k]
    for _ in range(MIN_SAMPLES if filler.body_model is not None else 1):  # until the body model predicts
        filler.fill(pos, frames, status)
    status[filler.joints[1]] = Status.MISSING
    pos[filler.joints[1]] = np.nan
    filler.fill(pos, frames, status)
    status[filler.joints[1:]] = Status.LOCATED
    filler.fill(pos, frames, status)


def fingerprint() -> str:
    """The kernel sources (every module with cached numba code), numba's and Python's versions."""
    h = hashlib.sha256(f"{version('numba')} {sys.version}".encode())
    for path in sorted(PACKAGE.rglob("*.py")):
        text = path.read_bytes()
        if b"cache=True" in text:
            h.update(path.relative_to(PACKAGE).as_posix().encode() + b"\0" + text)
    return h.hexdigest()


def kernels_cached() -> bool:
    try:
        return STAMP.read_text() == fingerprint()
    except OSError:
        return False


def _write_stamp() -> None:
    try:
        STAMP.parent.mkdir(parents=True, exist_ok=True)
        STAMP.write_text(fingerprint())
    except OSError:
        pass  # a read-only checkout: the launcher will just compile (or load) up front each time


def compile_kernels(workers: int | None = None) -> float:
    """Compile every kernel into the on-disk cache, the parts spread over the cores; returns seconds.

    The parts share helper kernels, so some are compiled twice; two processes saving the same
    cache index at once may lose an entry, which the final pass (one process) puts back.
    """
    started = time.monotonic()
    workers = max(1, min(workers or os.cpu_count() or 1, len(PARTS)))
    groups = [PARTS[i::workers] for i in range(workers)]
    procs = [subprocess.Popen([sys.executable, "-c",
                               f"from mocap_core.warmup import warm_up; warm_up({g!r}, say=True)"]) for g in groups]
    for p in procs:
        if p.wait():
            raise subprocess.CalledProcessError(p.returncode, p.args)
    subprocess.run([sys.executable, "-c", "from mocap_core.warmup import warm_up; warm_up()"], check=True)
    return time.monotonic() - started


if __name__ == "__main__":
    print(f"numba kernels compiled and cached in {compile_kernels():.0f} s")

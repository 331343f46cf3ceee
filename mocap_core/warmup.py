"""Load (or compile) the numba kernels before the first real frame, so frame one is not late.

The kernels come in parts (PARTS); a node kind says which it runs (``Node.kernels``), and the node
loop loads those before setup(). Offline commands load what they use once up front. Loading from
the on-disk cache takes well under a second; the first compile on a machine takes a minute or two.
The launcher compiles the parts its graph uses once, up front, in parallel, when the cache is not
known to hold them (``kernels_cached``): otherwise every node process of a graph would compile the
same kernels at the same time on the same cores (a first `make demo` took 8.5 minutes that way).

    python -m mocap_core.warmup [PART ...]   # compile now (one process per core), then load them
"""
from __future__ import annotations

import hashlib
import os
import selectors
import subprocess
import sys
import time
from importlib.metadata import version
from pathlib import Path

import numpy as np

PACKAGE = Path(__file__).resolve().parent
# Which parts of this checkout's kernels are compiled (next to numba's own cache files): the sources'
# fingerprint on the first line, a part a line after it.
STAMP = Path(os.environ.get("MOCAP_KERNEL_STAMP", PACKAGE / "__pycache__" / "numba-kernels.stamp"))
# The fingerprint of the sources that numba's cache files were compiled from. numba checks a cached kernel against
# its own file only: one that calls a kernel of another file keeps the copy it was compiled with, and loaded beside
# that kernel's newer cache it can crash ("'descr' is NULL"). So a change of any kernel source drops them all.
CACHED_SOURCES = PACKAGE / "__pycache__" / "numba-sources"
# The longest to compile come first, so that spread over the cores the last one to finish starts early.
PARTS = ("beyond", "rebuild", "localization", "fit", "pose_memory", "blend", "solvers", "markers", "pair_guard",
         "rotations")
# One limb-fill kernel serves every solver and option (the solver and the fills are its arguments): these
# parts compile it once, in one process, or two processes would compile the same kernel at the same time.
FILL_PARTS = ("beyond", "solvers")
FIT_PARTS = ("fit", "localization", "markers")  # the fit localizes the frames that calibrate it, gated first


def warm_up(parts: tuple[str, ...] = PARTS, say: bool = False, stamp: bool = True) -> None:
    for part in parts:
        _warm(part)
        if say:  # progress for whoever waits on a first compile
            print(f"  kernels: {part} ready", file=sys.stderr, flush=True)
    if stamp:
        _write_stamp(parts)


def hip_parts(options) -> tuple[str, ...]:
    """The kernels the hip stage runs with these options (mocap_core.fill_options.HipOptions, or params that
    derive from it): the marker gate and the landmark map ("markers"), and its fills'."""
    return ("markers",) + tuple(part for part in ("rebuild", "pose_memory", "pair_guard") if getattr(options, part))


def fill_parts(options) -> tuple[str, ...]:
    """The IK stage's, with these options (FillOptions, or params that derive from it): the fill kernel runs less
    of itself with the thesis's options (a solver alone) than with any other."""
    from mocap_core.fill_options import FillOptions

    fills = FillOptions.of(options)
    if fills == FillOptions():
        return ("solvers",)
    return ("beyond", "blend") if fills.reacquire_step_m > 0 or fills.blend_half_life_s > 0 else ("beyond",)


def pipeline_parts(preset: str, fill_gaps: bool = True) -> tuple[str, ...]:
    """What mocap_core.pipeline.SkeletonPipeline runs with these arguments."""
    from mocap_core.fill_options import HipOptions
    from mocap_core.presets import PRESETS

    hips = PRESETS[preset].hips if fill_gaps else HipOptions()  # (without the fills: the gate and the map still run)
    return ("localization",) + hip_parts(hips) + (fill_parts(PRESETS[preset].ik) if fill_gaps else ())


def ensure_compiled(log, parts: tuple[str, ...] = PARTS) -> bool:
    """Before a command's first frame: compile these kernels up front, in parallel and saying so, when this
    checkout has not yet (else the first frames would sit compiling, one process, in silence). True if it did."""
    if kernels_cached(parts):
        return False
    log.info("compiling the numba kernels for this checkout, once (%s; a minute or two on 2 cores)...",
             ", ".join(parts))
    log.info("numba kernels compiled and cached in %.0f s", compile_kernels(parts))
    return True


def _warm(part: str) -> None:
    """Run one part's kernels once: localization, the marker gate and the landmark map ("markers"), the segment
    rebuild (and the leg hinge), the pose memory, the pair guard, the fit, the rotation conversions of the rig's pose,
    the blend at a gap's ends, a solve on a chain with a missing middle joint by every solver ("solvers"), or by CCD
    with the analytic fills of the studio options ("beyond")."""
    {"rebuild": _warm_rebuild, "pose_memory": _warm_pose_memory, "pair_guard": _warm_pair_guard,
     "markers": _warm_markers,
     "fit": _warm_fit, "localization": _warm_localization, "rotations": _warm_rotations,
     "blend": _warm_blend, "solvers": _warm_solvers, "beyond": _warm_beyond}[part]()


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
    means.fill(np.full((len(LANDMARKS), 3), np.nan), markers=markers)


def _warm_pose_memory() -> None:  # one call compiles the whole kernel, recall included
    from mocap_core.pose_memory import PoseMemory
    from mocap_core.profiles import LANDMARKS

    lm = np.random.default_rng(0).normal(size=(len(LANDMARKS), 3))
    PoseMemory(["SACR", "L_IAS", "R_IAS", "L_FM2", "L_FLE"]).fill(lm)


def _warm_pair_guard() -> None:
    from mocap_core.pair_guard import PairGuard
    from mocap_core.profiles import LANDMARKS

    PairGuard().fill(np.random.default_rng(0).normal(size=(len(LANDMARKS), 3)))


def _warm_markers() -> None:
    """The marker gate (a first frame: every marker new, so the body's median; then a marker too fast) and the landmark
    map (one frame, as a node maps it, and a take's)."""
    from mocap_core.marker_gate import MarkerGate
    from mocap_core.profiles import load_profile

    gate, markers = MarkerGate(), np.random.default_rng(0).normal(size=(4, 3))
    gate.filter(markers, 0.0)
    markers[0] += 10.0
    gate.filter(markers, 0.01)
    profile = load_profile("qualisys_sports")
    labels = sorted({n for landmark in profile.landmarks for n in profile.markers_of(landmark)})
    landmarks = profile.resolve(labels)
    landmarks.apply(np.zeros((len(labels), 3), np.float32))
    landmarks.apply(np.zeros((2, len(labels), 3)))


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
    from mocap_core.localization import Localizer
    from mocap_core.profiles import LANDMARKS

    Localizer().localize(np.full((1, len(LANDMARKS), 3), np.nan))


def _warm_rotations() -> None:  # frames <-> quaternions, as the rig's pose carries them
    from mocap_core.ik.kernels import frames_to_quats, quats_to_frames
    from mocap_core.skeleton import N_JOINTS

    quats_to_frames(frames_to_quats(np.tile(np.eye(3), (N_JOINTS, 1, 1))))


def _warm_blend() -> None:
    from mocap_core.blend import BlendState
    from mocap_core.fill_options import STUDIO
    from mocap_core.skeleton import N_JOINTS, Status

    blend = BlendState.empty(3, STUDIO.reacquire_step_m, STUDIO.blend_half_life_s, STUDIO.blend_course)
    pos, frames = np.zeros((N_JOINTS, 3)), np.tile(np.eye(3), (N_JOINTS, 1, 1))
    status, idx = np.full(N_JOINTS, Status.LOCATED, np.uint8), np.arange(3, dtype=np.int64)
    blend.blend(pos, status, idx, frames)


def _warm_solvers() -> None:
    from mocap_core.fill_options import FillOptions
    from mocap_core.ik.solvers import SOLVERS

    for solver in SOLVERS:
        _warm_limb(solver, FillOptions())


def _warm_beyond() -> None:
    from mocap_core.fill_options import STUDIO

    # the studio's fills; their blend is a part of its own, compiled beside them
    _warm_limb("ccd", STUDIO.model_copy(update={"reacquire_step_m": 0.0, "blend_half_life_s": 0.0}))


def _warm_limb(solver: str, options) -> None:
    from mocap_core.body_model import MIN_SAMPLES, BodyModelSteer
    from mocap_core.gapfill import LimbFiller
    from mocap_core.skeleton import N_JOINTS, Status

    filler = LimbFiller("left_leg", solver, options=options)
    pos = np.zeros((N_JOINTS, 3))
    frames = np.tile(np.eye(3), (N_JOINTS, 1, 1))
    status = np.full(N_JOINTS, Status.LOCATED, np.uint8)
    for k, j in enumerate(filler.joints):
        pos[j] = [0.0, 0.1, 1.0 - 0.2 * k]
    for _ in range(MIN_SAMPLES if filler.get(BodyModelSteer) else 1):  # until the body model predicts
        filler.fill(pos, frames, status)
    status[filler.joints[1]] = Status.MISSING
    pos[filler.joints[1]] = np.nan
    filler.fill(pos, frames, status)
    status[filler.joints[1:]] = Status.LOCATED
    filler.fill(pos, frames, status)


def fingerprint() -> str:
    """The kernel sources (every module with cached numba code), numba's and Python's versions and the CPU the
    kernels are compiled for: numba keys its cache on the CPU's name and features too, so a checkout (or an image)
    moved to another CPU finds none of its kernels, and would compile them in every node process at once."""
    from numba.core.registry import cpu_target

    cpu = cpu_target.target_context.codegen().magic_tuple()  # (starts LLVM: numba needs it to load kernels anyway)
    h = hashlib.sha256(f"{version('numba')} {sys.version} {cpu}".encode())
    for path in sorted(PACKAGE.rglob("*.py")):
        text = path.read_bytes()
        if b"cache=True" in text:
            h.update(path.relative_to(PACKAGE).as_posix().encode() + b"\0" + text)
    return h.hexdigest()


def kernels_cached(parts: tuple[str, ...] = PARTS) -> bool:
    return set(parts) <= _stamped()


def _stamped(sources: str | None = None) -> set[str]:
    """The parts the stamp says are compiled for these very sources (their fingerprint, if already taken)."""
    try:
        lines = STAMP.read_text().splitlines()
    except OSError:
        return set()
    return set(lines[1:]) if lines and lines[0] == (sources or fingerprint()) else set()


def _write_stamp(parts: tuple[str, ...]) -> None:
    try:
        STAMP.parent.mkdir(parents=True, exist_ok=True)
        part = STAMP.with_name(f"{STAMP.name}.{os.getpid()}")  # then renamed: node processes read it meanwhile
        sources = fingerprint()  # (reads every kernel module: once)
        part.write_text("\n".join([sources, *sorted(_stamped(sources) | set(parts))]) + "\n")
        os.replace(part, STAMP)
    except OSError:
        pass  # a read-only checkout: the launcher will just compile (or load) up front each time


def compile_kernels(parts: tuple[str, ...] = PARTS, workers: int | None = None) -> float:
    """Compile these kernels into the on-disk cache, spread over the cores; returns seconds.

    A process per core takes the next part (the longest first) whenever it is free. The parts share helper
    kernels, so some are compiled twice; two processes saving the same cache index at once may lose an entry,
    which the final pass (one process, loading) puts back.
    """
    started = time.monotonic()
    _drop_stale_caches(fingerprint())
    fill = tuple(p for p in PARTS if p in parts and p in FILL_PARTS)
    tasks = [fill] if fill else []
    tasks += [(p,) for p in PARTS if p in parts and p not in FILL_PARTS]
    workers = max(1, min(workers or os.cpu_count() or 1, len(tasks)))
    procs = [subprocess.Popen([sys.executable, "-m", "mocap_core.warmup", "--worker"], stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, text=True) for _ in range(workers)]
    with selectors.DefaultSelector() as sel:
        for p in procs:
            sel.register(p.stdout, selectors.EVENT_READ, p)
            _hand_out(p, tasks)
        while sel.get_map():
            for key, _ in sel.select():
                p = key.data
                if p.stdout.readline():  # a part done
                    _hand_out(p, tasks)
                else:  # no more work, or it died
                    sel.unregister(p.stdout)
                    if p.wait():
                        for q in procs:
                            q.kill()
                        raise subprocess.CalledProcessError(p.returncode, p.args)
    subprocess.run([sys.executable, "-c", f"from mocap_core.warmup import warm_up; warm_up({tuple(parts)!r})"],
                   check=True)
    return time.monotonic() - started


def _drop_stale_caches(sources: str) -> None:
    """Delete numba's cache files when they were compiled from other kernel sources than these (CACHED_SOURCES)."""
    try:
        if CACHED_SOURCES.read_text() == sources:
            return
    except OSError:
        pass
    try:
        for path in PACKAGE.rglob("*.nb[ic]"):
            path.unlink(missing_ok=True)
        CACHED_SOURCES.parent.mkdir(parents=True, exist_ok=True)
        CACHED_SOURCES.write_text(sources)
    except OSError:
        pass  # a read-only checkout: numba cannot write its cache there either


def _hand_out(worker: subprocess.Popen, tasks: list[tuple[str, ...]]) -> None:
    if tasks:
        worker.stdin.write(" ".join(tasks.pop(0)) + "\n")
        worker.stdin.flush()
    else:
        worker.stdin.close()


def _compile_worker() -> None:
    """One compiling process: the parts of each line on stdin, then "done" on stdout."""
    for line in sys.stdin:
        warm_up(tuple(line.split()), say=True, stamp=False)
        print("done", flush=True)


if __name__ == "__main__":
    if sys.argv[1:] == ["--worker"]:
        _compile_worker()
    else:
        unknown = set(sys.argv[1:]) - set(PARTS)
        if unknown:
            sys.exit(f"unknown part(s) {', '.join(sorted(unknown))}; the parts: {', '.join(PARTS)}")
        chosen = tuple(sys.argv[1:]) or PARTS
        print(f"numba kernels compiled and cached in {compile_kernels(chosen):.0f} s")

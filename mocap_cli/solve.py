"""`mocap solve`: a recording through the whole chain offline, to a joints CSV and/or a BVH file."""
from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from mocap_core.bvh import NAMINGS, BvhWriter
from mocap_core.ik.constraints import load_constraints
from mocap_core.ik.solvers import SOLVERS, SolverParams
from mocap_core.joints_csv import JointsCsvWriter
from mocap_core.pipeline import SkeletonPipeline
from mocap_core.landmark_needs import FOLLOW_THE_NECK, describe_missing, placed_by_subject, unlocatable
from mocap_core.profiles import AUTO, PROFILE_HELP, actors, profile_for
from mocap_core.skeleton import JOINTS, Status
from mocap_core.up_axis import take_up_axis
from mocap_core.warmup import FIT_PARTS, ensure_compiled, pipeline_parts
from nodes.bags import read_take

log = logging.getLogger("mocap.solve")


def add_parser(sub) -> None:
    s = sub.add_parser("solve", help="solve a recording offline into a joints CSV",
                       description="Read a C3D/TRC/MAT recording, locate the joints, fill gaps with IK and "
                                   "write the joints CSV (frame, time, then x, y, z and status of every joint) "
                                   "and/or a BVH.")
    s.add_argument("file", nargs="+", help="recording: .c3d, .trc, .mat (file.mat:take picks a take) or a bag; "
                                          "several, folders or globs with --out-dir (an archive re-solve)")
    s.add_argument("--profile", default=AUTO, help=PROFILE_HELP)
    s.add_argument("--solver", default="ccd", choices=sorted(SOLVERS), help="IK solver for gaps (default ccd)")
    s.add_argument("--no-constraints", action="store_true", help="solve without joint limits")
    s.add_argument("--no-ik", action="store_true",
                   help="localization only: leave missing joints missing (nothing rebuilt)")
    s.add_argument("--thesis", action="store_true",
                   help="fill gaps exactly as the thesis did (default: with the improvements the studio launch files "
                        "use: hips fitted to the body, lost forearm and foot markers rebuilt, swivel, segment carry, "
                        "re-acquisition blend)")
    s.add_argument("--fit", action="store_true",
                   help="fit a calibrated rigid skeleton to every marker each frame (calibrated from this take, "
                        "or from --subject); bones keep their lengths")
    s.add_argument("--subject", help="subject file from `mocap calibrate`: its bones and the markers on them for "
                                     "every limb's rigid chain (or, with --fit, the subject the fit fits)")
    s.add_argument("--constraints", help="joint-limit YAML (default: the thesis's values)")
    s.add_argument("--max-iterations", type=int, default=140)
    s.add_argument("--stop-distance", type=float, default=0.01, help="IK stop distance in metres")
    s.add_argument("--joints-out", help="output joints CSV")
    s.add_argument("--bvh-out", help="output BVH (Y up, metres, T-pose rest; see docs/graph.md)")
    s.add_argument("--bvh-names", choices=sorted(NAMINGS), default="mocap",
                   help="joint names in the BVH: the skeleton model's, or a common rig's (default mocap)")
    s.add_argument("--allow-missing", action="store_true",
                   help="solve even when the profile's landmarks cannot locate some joints in any frame")
    s.add_argument("--quiet", action="store_true", help="no progress bar")
    a = s.add_argument_group("several takes (an archive)")
    a.add_argument("--out-dir", help="write each take's TAKE.csv (and TAKE.bvh with --bvh) here")
    a.add_argument("--bvh", action="store_true", help="with --out-dir: a BVH per take too")
    a.add_argument("--jobs", type=int, help="takes solved at once in local processes (default: one per core)")
    a.add_argument("--cluster", metavar="ADDRESS",
                   help="solve on a Dask cluster instead: its scheduler's address (tcp://host:8786), or 'local' "
                        "for a local one (needs dask[distributed]; every worker must see the files)")
    s.set_defaults(func=run)


def run(args) -> int:
    from mocap_cli.archive import expand, solve_archive

    takes = expand(args.file)
    if args.out_dir:
        return solve_archive(takes, args)
    if len(takes) > 1:
        raise SystemExit(f"mocap solve: {len(takes)} takes: give --out-dir DIR for their outputs")
    args.file = takes[0]
    if not args.joints_out and not args.bvh_out:
        raise SystemExit("mocap solve: give --joints-out OUT.csv and/or --bvh-out OUT.bvh")
    solve_take(args)
    return 0


def solve_take(args) -> dict:
    """One take, as the arguments say; returns what it counted (frames, per-status shares, seconds). A take of
    several actors (labels "actor1:LASI", "actor2:LASI") is solved one actor at a time, each to files of its own
    (out.csv -> out.actor1.csv, out.actor2.csv)."""
    rec = read_take(args.file)
    ensure_compiled(log, FIT_PARTS if args.fit else
                    pipeline_parts("thesis" if args.thesis else "studio", fill_gaps=not args.no_ik)
                    + (("fit",) if args.subject else ()))
    several = actors(rec.labels)
    if len(several) < 2:
        return _solve(args, rec)
    log.info("%d actors in the take (%s): each solved on their own", len(several), ", ".join(several))
    counts = [_solve(_for_actor(args, a), rec.actor(a)) for a in several]
    return {k: sum(c[k] for c in counts) / (1 if k in ("frames", "seconds") else len(counts)) for k in counts[0]}


def actor_path(path: str | None, actor: str) -> str | None:
    """An output named for one actor of a take of several: out.csv -> out.actor1.csv."""
    return str(Path(path).with_suffix(f".{actor}{Path(path).suffix}")) if path else path


def _for_actor(args, actor: str):
    """The arguments with each output named for ``actor``, and {actor} in a subject file's path replaced."""
    subject = args.subject.replace("{actor}", actor) if args.subject else args.subject
    return argparse.Namespace(**{**vars(args), "joints_out": actor_path(args.joints_out, actor),
                                 "bvh_out": actor_path(args.bvh_out, actor), "subject": subject})


def _solve(args, rec) -> dict:
    started = time.perf_counter()
    profile = profile_for(args.profile, rec.labels, log)
    profile.resolve(rec.labels)  # a label the profile names and the take lacks, or several actors: said first
    missing = unlocatable(frozenset(profile.landmarks))
    if not (args.thesis or args.no_ik):  # (the rigid chains put a head no marker locates on the neck)
        missing = {j: fixes for j, fixes in missing.items() if j not in FOLLOW_THE_NECK}
    subject = None
    if args.subject:
        from mocap_core.fit.subject import load_subject
        subject = load_subject(args.subject)
        # A movement trial's profile may lack the landmarks a static trial had: the subject's markers place them.
        placed, missing = placed_by_subject(missing, subject.known)
        if placed:
            log.info("no landmark of profile %s locates %s: solved from subject %s's markers", profile.name,
                     ", ".join(placed), args.subject)
    never = describe_missing(missing)
    if never and not args.allow_missing and not profile.drafted:  # (a draft's log has said what it lacks)
        raise SystemExit(f"mocap solve: profile {profile.name} cannot locate these joints in any frame:\n  "
                         + "\n  ".join(never) + "\nAdd the landmarks to the profile, or give --allow-missing to "
                         "solve without them.")
    for line in never:
        log.warning("never located: %s", line)
    if (args.fit or args.subject) and (args.thesis or args.no_ik):
        raise SystemExit("mocap solve: --fit and --subject solve with a rigid skeleton; drop --thesis/--no-ik")
    if args.fit:
        return _write(args, rec, profile, _fitted(args, rec, profile, subject), started)
    params = SolverParams(max_iterations=args.max_iterations, stop_distance_m=args.stop_distance,
                          constraints=not args.no_constraints)
    pipe = SkeletonPipeline(profile, rec.labels, args.solver, params, load_constraints(args.constraints),
                            fill_gaps=not args.no_ik, options="thesis" if args.thesis else "studio", rate_hz=rec.rate_hz)
    if subject is not None:  # (as an ik_gapfill node's subject param)
        pipe.use(subject)
    return _write(args, rec, profile, pipe.run(rec.positions), started)


def _fitted(args, rec, profile, subject):
    """The fit's frames, as one chunk (calibrating first unless a ``subject`` is given)."""
    from mocap_core.fit.fitter import FitSettings
    from mocap_core.fit.take import fit_take

    if subject is None:
        log.info("calibrating the subject from the take (save one with `mocap calibrate` to reuse it)")
    settings = FitSettings(limits=not args.no_constraints)
    with tqdm(total=rec.n_frames, unit="frame", disable=args.quiet, desc=f"fitting {rec.source.split('/')[-1]}") as bar:
        chunk, _, _ = fit_take(rec.positions, rec.labels, profile, rec.rate_hz, subject, settings,
                                progress=bar.update)
    return [chunk]


def _write(args, rec, profile, chunks, started: float) -> int:
    """The solve's frames to the outputs as they come; ``started``: when the solve began (for the timing line)."""
    times = rec.times()
    counts = {s: 0 for s in Status}
    missing = np.zeros(len(JOINTS), np.int64)
    out = JointsCsvWriter(args.joints_out) if args.joints_out else None
    up = take_up_axis(rec, profile, log)
    bvh = BvhWriter(args.bvh_out, rec.rate_hz, up, names=args.bvh_names) if args.bvh_out else None
    with tqdm(total=rec.n_frames, unit="frame", disable=args.quiet,
              desc=f"solving {rec.source.split('/')[-1]}") as bar:
        for chunk in chunks:
            at = np.arange(chunk.start, chunk.start + len(chunk.positions))
            if out:
                out.write_frames(rec.first_frame + at, times[at], chunk.positions, chunk.status)
            if bvh:
                bvh.add_frames(chunk.positions, chunk.frames)
            for s in Status:
                counts[s] += int((chunk.status == s).sum())
            missing += (chunk.status == Status.MISSING).sum(axis=0)
            bar.update(len(chunk.positions))
    if out:
        out.close()
    if bvh:
        bvh.close()
    took = time.perf_counter() - started
    for j in np.flatnonzero((missing > 0.1 * rec.n_frames) & (missing < rec.n_frames)):
        log.warning("%s is missing in %.0f %% of the frames: no landmark located it there and no fill could",
                    JOINTS[j], 100 * missing[j] / rec.n_frames)
    total = sum(counts.values())
    log.info("%d frames in %.1f s (%.0f frames/s): %s -> %s", rec.n_frames, took, rec.n_frames / took,
             ", ".join(f"{s.name.lower()} {100 * c / total:.1f}%" for s, c in counts.items()),
             " and ".join(x for x in (args.joints_out, args.bvh_out) if x))
    return {"frames": rec.n_frames, "seconds": took,
            **{s.name.lower(): counts[s] / max(total, 1) for s in Status}}

"""`mocap eval`: the thesis's experiments (chapter 4), and ours."""
from __future__ import annotations

import argparse
import csv
import json
import logging
import time
from dataclasses import replace
from pathlib import Path
from typing import get_args

from tqdm import tqdm

from mocap_cli.measure import LAYOUTS
from mocap_core.experiments import (PACE_WINDOW, THESIS_TIMING_MS, Gap, GapTake, blend_lag, gap_run, gap_windows,
                                    localize_take, measured_joints, real_gap_moves, transition_moves,
                                    worst_case_timing)
from mocap_cli.option_flags import add_option_flags, flags_text, options_of
from mocap_core.fill_options import STUDIO, FillOptions, HipOptions
from mocap_core.hip_interpolation import WhenLost
from mocap_core.ik.solvers import SOLVERS, SolverParams
from mocap_core.landmark_fills import fill_take
from mocap_core.profiles import load_profile
from mocap_core.partial_means import PartialMeans
from mocap_core.presets import PRESETS
from mocap_core.warmup import ensure_compiled, warm_up
from nodes.bags import read_take

REPO = Path(__file__).resolve().parents[1]
DEFAULT_TAKE = str(REPO.parent / "shared" / "data" / "03_sprint_start_BTK_SprintMotion.trc")
log = logging.getLogger("mocap.eval")


def add_parser(sub) -> None:
    s = sub.add_parser("eval", help="reproduce the thesis's experiments")
    esub = s.add_subparsers(dest="experiment", required=True)
    t = esub.add_parser("timing", help="IK execution time in the worst case (thesis Tables 4.2 and 4.3)",
                        description="Every joint but the pelvis segment and the end effectors is removed after "
                                    "localization of a sprinting take; the full body is then gap-filled every "
                                    "frame by each solver, with and without constraints.")
    t.add_argument("--take", default=DEFAULT_TAKE, help="recording (default: the BTK sprint start)")
    t.add_argument("--profile", default="btk_sprint")
    t.add_argument("--solvers", default="all", help="comma-separated, or all")
    t.add_argument("--constraints", choices=["on", "off", "both"], default="both")
    t.add_argument("--beyond", action="store_true",
                   help="with the gap-filling options beyond the thesis (swivel, segment carry, re-acquisition blend)")
    t.add_argument("--repeats", type=int, default=3, help="passes over the take (more = steadier figures; default 3)")
    t.add_argument("--report", default="reports/timing", help="directory for timing.md and timing.csv")
    t.add_argument("--json", action="store_true", help="also print the rows as JSON")
    t.set_defaults(func=run_timing)

    g = esub.add_parser("gaps", help="accuracy of gap filling (thesis 4.2, Table 4.1, Figures 4.2-4.10)",
                        description="Localize the complete take as the reference, hide joints from --from to --to "
                                    "(by deleting their markers and, as the thesis did, by deleting the localized "
                                    "joint), fill them with each solver and compare.")
    g.add_argument("--take", default=DEFAULT_TAKE, help="recording (default: the BTK sprint start)")
    g.add_argument("--profile", default="btk_sprint")
    g.add_argument("--remove", default="elbow_l", help="joint(s) to hide, comma-separated (e.g. knee_l,ankle_l; "
                   "pelvis hides every hip marker and reports the pelvis, spine0 and both hips; a landmark name "
                   "such as L_UOA hides that marker too; landmarks alone, such as L_USP, report the joints they "
                   "locate, here the wrist)")
    g.add_argument("--from", dest="start_s", type=float, default=1.0, help="gap start, seconds (default 1)")
    g.add_argument("--to", dest="stop_s", type=float, help="gap end, seconds (default: the end of the take)")
    g.add_argument("--solvers", default="all", help="comma-separated, or all")
    g.add_argument("--constraints", choices=["on", "off", "both"], default="both")
    g.add_argument("--mode", choices=["markers", "joint", "both"], default="both",
                   help="hide the markers that define the joint, or the localized joint (the thesis's way)")
    g.add_argument("--report", default="reports/gaps",
                   help="directory for gaps.md, gaps.csv, transitions.csv (moves at loss and return) and the plots")
    g.add_argument("--no-plots", action="store_true")
    g.add_argument("--hips-lost", dest="when_lost", choices=list(get_args(WhenLost)), default="hold",
                   help=f"(with --remove pelvis) {HipOptions.model_fields['when_lost'].description}")
    for model in (HipOptions, FillOptions):
        add_option_flags(g, model, skip=("when_lost",))
    g.add_argument("--gap-length", type=float, metavar="S",
                   help="short gaps instead of one: hide the joints for S seconds at a time, one gap every "
                        "--gap-every seconds from --from to --to (a studio's occlusions are mostly short)")
    g.add_argument("--gap-every", type=float, default=0.5, metavar="S",
                   help="with --gap-length: seconds from one gap's start to the next's (default 0.5)")
    g.set_defaults(func=run_gaps)

    rg = esub.add_parser("real-gaps", help="smoothness of the fill on a take's own gaps (no truth needed)",
                         description="Solve a take with its own gaps three ways (the thesis's method, the studio "
                                     "graphs' options without the blend, and with it) and report how the filled "
                                     "joints move where their status changes (markers lost or found, a fill handed "
                                     "to another) and on every move into or out of a filled frame, next to each "
                                     "joint's normal per-frame motion (95th percentile of its located moves) "
                                     "and, at a change of status, to its own pace in the located frames on "
                                     "either side (a twitch is faster than both); and how the filled joints' bone "
                                     "frames turn there (what a rig streams), next to each joint's normal turn.")
    rg.add_argument("--take", default=str(REPO.parent / "shared" / "data" /
                                          "12_vicon_freeform_realgaps_nimble_nick_freeform_001.c3d"),
                    help="recording with gaps (default: the Vicon free-form take, 6.6%% of its markers missing)")
    rg.add_argument("--profile", default="vicon53")
    rg.add_argument("--report", default="reports/real_gaps", help="directory for real_gaps.md, .csv and the plot")
    rg.add_argument("--no-plots", action="store_true")
    rg.set_defaults(func=run_real_gaps)

    lt = esub.add_parser("latency", help="end-to-end latency of the full graph fed by the QTM emulator",
                         description="Starts the QTM emulator and the full graph (qtm_ingest to retarget), logs "
                                     "skeleton/solved, and reports latency from the frame entering qtm_ingest to it "
                                     "leaving retarget, and dropped frames, next to a bare pyzmq relay chain with the "
                                     "same number of hops measured in the same run.")
    lt.add_argument("--rate", type=float, default=300, help="capture rate to replay at (Hz)")
    lt.add_argument("--seconds", type=float, default=30)
    lt.add_argument("--take", default=str(REPO.parent / "shared" / "data" / "08_cmu_135_02_karate_kata.c3d"))
    lt.add_argument("--profile", default="cmu41")
    lt.add_argument("--report", default="reports/latency")
    lt.add_argument("--layout", choices=sorted(LAYOUTS), default="processes",
                    help="where the solving nodes run: a process each (default), one container "
                         "(launch/studio_composed.yaml) or two containers")
    lt.add_argument("--realtime", action=argparse.BooleanOptionalAction, default=True,
                    help="the graph's node processes under real-time scheduling, as launch/qtm_studio.yaml runs them "
                         "(--no-realtime: normal scheduling)")
    lt.add_argument("--fit", action="store_true",
                    help="solve with the rigid-skeleton fit (one skeleton_fit node, the subject calibrated from the "
                         "take first) instead of hip interpolation, localization and the five IK nodes")
    lt.set_defaults(func=run_latency)

    tg = esub.add_parser("targets", help="the gap-filling targets, met or not, from the reports under docs/results",
                         description="Read the reports that `make results results-beyond results-short` write and "
                                     "check each gap-filling target on each of its cases (elbow hidden from 1 s, "
                                     "knee and ankle hidden together, every solver within 1.5x of the best, moves at "
                                     "re-acquisition, the full-body frame's time). Runs nothing; prints the table "
                                     "and writes targets.md, targets.csv and a plot.")
    tg.add_argument("--results", default=str(REPO / "docs" / "results"), help="where the reports are "
                    "(default: docs/results)")
    tg.add_argument("--report", default="reports/targets",
                    help="directory for targets.md, targets.csv and targets.png (each case as a share of its limit)")
    tg.add_argument("--no-plots", action="store_true")
    tg.set_defaults(func=run_targets)

    from mocap_cli import options_eval, protocol_eval, rigid_eval
    rigid_eval.register(esub)
    options_eval.register(esub)
    protocol_eval.register(esub)


def run_timing(args) -> int:
    rec = read_take(args.take)
    localized = localize_take(rec, load_profile(args.profile))
    solvers = list(SOLVERS) if args.solvers == "all" else args.solvers.split(",")
    modes = {"on": [True], "off": [False], "both": [False, True]}[args.constraints]
    t0 = time.perf_counter()
    ensure_compiled(log)
    warm_up()
    warmup_s = time.perf_counter() - t0
    rows = []
    for constrained in modes:
        for solver in tqdm(solvers, desc=f"constraints {'on' if constrained else 'off'}", unit="solver"):
            rows.append(worst_case_timing(localized, solver, constrained, SolverParams(), args.repeats,
                                          STUDIO if args.beyond else FillOptions()))
    out = Path(args.report)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "timing.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0].as_dict()))
        w.writeheader()
        w.writerows(r.as_dict() for r in rows)
    md = [f"Worst-case full-body gap fill{' with swivel, segment carry, limb memory, body model and blend' if args.beyond else ''}, "
          f"{rec.source.split('/')[-1]} ({rows[0].frames} frames, "
          f"{args.repeats} pass(es)), ms per frame. Kernel load/compile before timing: {warmup_s:.2f} s. "
          "\"max, best of passes\": the largest of each frame's fastest pass (every pass does the same work; "
          "the plain max includes the pauses of a shared machine).", "",
          "| solver | constraints | min | max | max, best of passes | mean | median | std | iterations | residual mm "
          "| thesis mean | thesis max |",
          "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        th = THESIS_TIMING_MS.get((r.solver, r.constraints))
        md.append(f"| {r.solver} | {'on' if r.constraints else 'off'} | {r.min_ms:.3f} | {r.max_ms:.3f} | "
                  f"{r.max_best_ms:.3f} | "
                  f"{r.mean_ms:.3f} | {r.median_ms:.3f} | {r.std_ms:.3f} | {r.mean_iterations:.1f} | "
                  f"{r.mean_residual_mm:.1f} | {th[2] if th else '-'} | {th[1] if th else '-'} |")
    (out / "timing.md").write_text("\n".join(md) + "\n")
    print("\n".join(md))
    if args.json:
        print(json.dumps([r.as_dict() for r in rows], indent=2))
    log.info("wrote %s and %s", out / "timing.md", out / "timing.csv")
    return 0


def run_gaps(args) -> int:
    joints = [j.strip() for j in args.remove.split(",") if j.strip()]
    try:
        for mode in ["markers", "joint"] if args.mode == "both" else [args.mode]:
            measured_joints(joints, mode)
    except ValueError as e:
        raise SystemExit(f"--remove {args.remove}: {e}") from None
    rec = read_take(args.take)
    profile = load_profile(args.profile)
    from mocap_core.pipeline import SkeletonPipeline

    pipe = SkeletonPipeline(profile, rec.labels, fill_gaps=False)
    landmarks = pipe.landmark_map.apply(rec.positions)
    reference = pipe.solve_landmarks(pipe.landmarks(rec.positions)).positions
    start = int(round(args.start_s * rec.rate_hz))
    stop = rec.n_frames if args.stop_s is None else min(rec.n_frames, int(round(args.stop_s * rec.rate_hz)))
    if not 0 < start < stop:
        raise SystemExit(f"--from {args.start_s} / --to {args.stop_s}: the gap must start after frame 0 and end "
                         f"after it starts (take: {rec.n_frames / rec.rate_hz:.2f} s)")
    short_gaps = None
    if args.gap_length is not None:
        short_gaps = (int(round(args.gap_length * rec.rate_hz)), int(round(args.gap_every * rec.rate_hz)))
        try:
            gap_windows(start, stop, *short_gaps)
        except ValueError as e:
            raise SystemExit(f"--gap-length {args.gap_length} / --gap-every {args.gap_every} at "
                             f"{rec.rate_hz:g} Hz: {e}") from None
    try:
        options, hips = options_of(FillOptions, args), options_of(HipOptions, args)
    except ValueError as e:
        raise SystemExit(f"mocap eval gaps: {e.errors()[0]['msg'].removeprefix('Value error, ')}") from None
    solvers = list(SOLVERS) if args.solvers == "all" else args.solvers.split(",")
    modes = ["markers", "joint"] if args.mode == "both" else [args.mode]
    cons = {"on": [True], "off": [False], "both": [False, True]}[args.constraints]
    ensure_compiled(log)
    warm_up()
    runs = []
    tracking = pipe.landmark_map.tracking(rec.positions)  # the same for every run
    partial = None
    if args.rebuild:  # (the studio's: a landmark that is the mean of several markers kept while some are seen)
        partial = fill_take(PartialMeans(pipe.landmark_map).fill, landmarks, markers=rec.positions)
    take = GapTake(landmarks, reference, profile, rec.rate_hz, tracking, pipe.landmark_map.tracking_of, partial)
    combos = [(m, c, s) for m in modes for c in cons for s in solvers]
    for mode, constrained, solver in tqdm(combos, desc="gap runs", unit="run"):
        runs.append(gap_run(take, Gap(joints, start, stop, mode, short_gaps), solver, constrained, hips, options))
    out = Path(args.report)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for r in runs:
        for k, joint in enumerate(r.joints):
            rows.append({"mode": r.mode, "solver": r.solver, "constraints": "on" if r.constraints else "off",
                         "joint": joint, **r.stats(k)})
    with open(out / "gaps.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    gap_s = (stop - start) / rec.rate_hz
    hidden = (f"hidden from {start / rec.rate_hz:.2f} s for {gap_s:.2f} s ({stop - start} frames)" if short_gaps is None
              else f"hidden {args.gap_length:g} s ({short_gaps[0]} frames) in every {args.gap_every:g} s from "
                   f"{start / rec.rate_hz:.2f} s to {stop / rec.rate_hz:.2f} s ({len(runs[0].windows)} gaps, "
                   f"{len(runs[0].frames)} frames)")
    md = [f"{', '.join(joints)} {hidden} of {rec.source.split('/')[-1]}; distance to the localized reference, "
          "metres.",
          "", f"Options: {options_text(args)}.", "",
          "| removed by | solver | constraints | joint | min | max | mean | median | std | variance |",
          "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        md.append(f"| {r['mode']} | {r['solver']} | {r['constraints']} | {r['joint']} | {r['min']:.3f} | "
                  f"{r['max']:.3f} | {r['mean']:.3f} | {r['median']:.3f} | {r['std']:.3f} | {r['variance']:.4f} |")
    md += ["", "Loss and re-acquisition: the largest per-frame move within 3 frames of where the markers go and "
           "come back (over every gap), next to the joint's normal per-frame motion (95th percentile of the "
           "reference); \"added\": the largest move the fill adds to the reference's own there "
           "(|step of the estimate - step of the reference|), which leaves out the actor's own fast moves.", "",
           "| removed by | solver | constraints | joint | normal mm | loss move mm | loss ratio | loss added "
           "| return move mm | return ratio | return added |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    moves = [{"mode": r.mode, "solver": r.solver, "constraints": "on" if r.constraints else "off", **j}
             for r in runs for j in transition_moves(r, reference)]
    for j in moves:
        md.append(f"| {j['mode']} | {j['solver']} | {j['constraints']} | {j['joint']} | "
                  f"{j['normal_step_m'] * 1000:.1f} | {j['loss_move_m'] * 1000:.1f} | {j['loss_ratio']:.2f} | "
                  f"{j['loss_added_ratio']:.2f} | {j['return_move_m'] * 1000:.1f} | {j['return_ratio']:.2f} | "
                  f"{j['return_added_ratio']:.2f} |")
    with open(out / "transitions.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(moves[0]))
        w.writeheader()
        w.writerows(moves)
    (out / "gaps.md").write_text("\n".join(md) + "\n")
    print("\n".join(md))
    if not args.no_plots:
        from mocap_cli.plots import error_plot, trajectory_plot

        for mode in modes:
            for constrained in cons:
                sel = [r for r in runs if r.mode == mode and r.constraints == constrained]
                tag = f"{mode}_{'constrained' if constrained else 'unconstrained'}"
                error_plot(sel, rec.rate_hz, out / f"error_{tag}.png",
                           f"{joints[0]} hidden ({mode}), constraints {'on' if constrained else 'off'}")
                trajectory_plot(sel, reference, start, stop, out / f"trajectory_{tag}.png",
                                f"{joints[0]} ({mode}), constraints {'on' if constrained else 'off'}")
    log.info("wrote %s", out)
    return 0


def run_real_gaps(args) -> int:
    from mocap_core.pipeline import SkeletonPipeline
    from mocap_core.skeleton import Status

    import numpy as np

    rec = read_take(args.take)
    profile = load_profile(args.profile)
    studio = PRESETS["studio"]
    variants = {"thesis's method": PRESETS["thesis"],
                "studio options without the blend": replace(studio, ik=studio.ik.model_copy(
                    update={"blend_half_life_s": 0.0})),
                "studio options": studio}
    ensure_compiled(log)
    warm_up()
    results, solved = {}, {}
    for name, options in tqdm(variants.items(), desc="solving", unit="variant"):
        pipe = SkeletonPipeline(profile, rec.labels, rate_hz=rec.rate_hz, options=options)
        chunks = list(pipe.run(rec.positions))
        status = np.concatenate([c.status for c in chunks])
        positions, frames = np.concatenate([c.positions for c in chunks]), np.concatenate([c.frames for c in chunks])
        solved[name] = (positions, status, frames)
        results[name] = real_gap_moves(positions, status, frames=frames)
    (blended, blended_status, blended_frames), (plain, plain_status, plain_frames) = (
        solved["studio options"], solved["studio options without the blend"])
    lag = blend_lag(blended, blended_status, plain, plain_status, blended_frames, plain_frames)
    missing = float(np.mean(~np.isfinite(rec.positions).all(axis=2)))
    filled = float(np.mean(np.isin(status, (Status.ESTIMATED, Status.HELD))))
    md = [f"{rec.source.split('/')[-1]} ({rec.n_frames} frames at {rec.rate_hz:g} Hz, {missing:.1%} of its markers "
          f"missing; with the studio options {filled:.1%} of the joints are filled). Moves of the filled joints, each "
          "over its normal per-frame motion (95th percentile of its moves between located frames): at a change of "
          "status (lost, found, or handed from one fill to another), and on every move into or out of a filled "
          "frame. The actor's own fast moves are in both: a joint moves faster than its 95th percentile in 5 % of "
          "frames. \"Beyond its own pace\" leaves them out: a move at a change of status over the larger of the "
          "normal motion and the joint's own moves between located frames nearest before and after it (within "
          f"{PACE_WINDOW} frames), so a twitch, a move faster than the joint moved on either side of it.", "",
          "| fill | changes of status | over 1.5x | largest | beyond its own pace: over 1.5x | largest "
          "| moves of filled joints | over 1.5x | over 3x | largest | worst changes (joint, frame) |",
          "|---|---|---|---|---|---|---|---|---|---|---|"]
    rows = []

    def ratio(x: float) -> str:
        return f"{x:.2f}x" if np.isfinite(x) else "-"

    for name, r in results.items():
        row = r.row()
        lagged = lag.row() if name == "studio options" else dict.fromkeys(lag.row(), "")
        rows.append({"fill": name, **row, **lagged})
        worst = ", ".join(f"{joint} {frame}: {x:.1f}x" for x, joint, frame in r.worst[:3])
        md.append(f"| {name} | {row['changes']} | {row['changes_over_1_5']} | {ratio(row['changes_max'])} | "
                  f"{row['paced_over_1_5']} | {ratio(row['paced_max'])} | "
                  f"{row['filled_moves']} | {row['filled_over_1_5']} | {row['filled_over_3']} | "
                  f"{ratio(row['filled_max'])} | {worst} |")
    md += ["", "Turns of the filled joints' bone frames (what the rig streams) on every move into or out of a filled "
           "frame, each over its normal per-frame turn (95th percentile of its turns between located frames), and "
           "in degrees:", "",
           "| fill | turns | over 1.5x | over 3x | over 30 degrees | largest |", "|---|---|---|---|---|---|"]
    for name, r in results.items():
        row = r.row()
        md.append(f"| {name} | {row['turns']} | {row['turns_over_1_5']} | {row['turns_over_3']} | "
                  f"{row['turns_over_30_deg']} | {row['turns_max_deg']:.0f} |")
    md += ["", lag.sentence()]
    if not any(len(r.filled) for r in results.values()):
        md += ["", "No joint was filled in any frame: the take has no gaps to measure (mocap eval gaps hides some)."]
        log.warning("%s: no joint was filled in any frame, nothing to measure; mocap eval gaps makes gaps to fill",
                    args.take)
    out = Path(args.report)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "real_gaps.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    (out / "real_gaps.md").write_text("\n".join(md) + "\n")
    print("\n".join(md))
    if not args.no_plots and any(len(r.changes) for r in results.values()):
        from mocap_cli.plots import move_ratio_plot

        move_ratio_plot({name: r.changes for name, r in results.items()}, out / "moves_at_changes.png",
                        f"moves where a joint's status changes: {rec.source.split('/')[-1][:40]}")
    log.info("wrote %s", out)
    return 0


def options_text(args) -> str:
    on = flags_text((HipOptions, FillOptions), args, skip=("when_lost",))
    if args.when_lost != "hold":
        on.append(f"--hips-lost {args.when_lost}")
    return " ".join(on) or "none beyond the thesis"


def run_latency(args) -> int:
    import signal
    import tempfile

    import numpy as np

    from mocap_cli.bare_chain import bare_chain
    from mocap_cli.launcher import Launcher
    from mocap_cli.measure import capture_frames_missing, frame_log_figures, live_graph
    from mocap_cli.qtm_sim import start_emulator

    solved = Path(tempfile.mkdtemp(prefix="mocap-latency-")) / "solved.csv"
    subject = None
    if args.fit:  # a studio calibrates an actor once: the node gets the subject file, not a live calibration
        from mocap_core.fit.calibration import calibrate

        rec = read_take(args.take)
        subject = str(solved.parent / "subject.yaml")
        calibrate(rec.positions, rec.labels, load_profile(args.profile), rec.rate_hz).save(subject)
    sim, port = start_emulator(args.take, "--rate", str(args.rate), "--loop")
    try:
        lf = live_graph(port, args.profile, solved, f"latency-{int(time.time())}",
                        layout=args.layout, subject=subject)
        lf.realtime = args.realtime
        Launcher(lf).run(duration_s=args.seconds)
    finally:
        sim.send_signal(signal.SIGINT)
        sim.wait()
    lat, drops = frame_log_figures(solved)
    missing = capture_frames_missing(solved)
    frames_out = len(lat)
    if frames_out < 10:
        log.error("only %d frames reached skeleton/solved in %.0f s: run longer (--seconds)", frames_out, args.seconds)
        return 1
    lat = lat[len(lat) // 10:]  # leave out the first 10% (start-up)
    hops = 3 if args.fit else 6  # ingest -> fit -> retarget -> log; ingest -> hips -> localize -> torso -> limb -> ...
    bare = bare_chain(hops, min(3000, int(args.rate * 10)), args.rate) / 1000
    layout = {"processes": "one process per node", "one": "solving nodes in one container",
              "two": "solving nodes in two containers"}[args.layout]
    layout += ", the rigid-skeleton fit" if args.fit else ""
    layout += ", real-time scheduling" if args.realtime else ", normal scheduling"
    md = [f"Full graph ({layout}) fed by the QTM emulator at {args.rate:.0f} Hz for {args.seconds:.0f} s "
          f"({frames_out} frames out of skeleton/solved); latency from entering qtm_ingest to leaving retarget, ms.", "",
          "| chain | hops | p50 | p99 | max | dropped (last hop) | capture frames missing |",
          "|---|---|---|---|---|---|---|",
          f"| mocap graph | {hops} | {np.percentile(lat, 50):.2f} | {np.percentile(lat, 99):.2f} | {lat.max():.2f} | "
          f"{drops} | {missing} |",
          f"| bare pyzmq relays | {hops} | {np.percentile(bare, 50):.2f} | {np.percentile(bare, 99):.2f} | "
          f"{bare.max():.2f} | - | - |", "",
          f"ratio (p50): {np.percentile(lat, 50) / np.percentile(bare, 50):.2f}"]
    out = Path(args.report)
    out.mkdir(parents=True, exist_ok=True)
    name = (f"latency_{args.rate:.0f}hz{'' if args.layout == 'processes' else '_' + args.layout}"
            f"{'_fit' if args.fit else ''}{'' if args.realtime else '_normal'}")
    (out / f"{name}.md").write_text("\n".join(md) + "\n")
    print("\n".join(md))
    return 0


def run_targets(args) -> int:
    from mocap_cli.targets import TargetsError, check, write

    try:
        checks = check(Path(args.results))
    except TargetsError as e:
        log.error("%s", e)
        return 1
    print(write(checks, Path(args.report), plot=not args.no_plots), end="")
    log.info("wrote %s", args.report)
    return 0

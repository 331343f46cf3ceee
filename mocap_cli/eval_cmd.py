"""`mocap eval`: the thesis's experiments (chapter 4), and ours."""
from __future__ import annotations

import csv
import json
import logging
import time
from pathlib import Path

from tqdm import tqdm

from mocap_core.experiments import THESIS_TIMING_MS, localize_take, worst_case_timing
from mocap_core.ik.solvers import SOLVERS, SolverParams
from mocap_core.profiles import load_profile
from mocap_core.recordings import read_recording
from mocap_core.warmup import warm_up

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
    t.add_argument("--repeats", type=int, default=1, help="passes over the take (more = steadier figures)")
    t.add_argument("--report", default="reports/timing", help="directory for timing.md and timing.csv")
    t.add_argument("--json", action="store_true", help="also print the rows as JSON")
    t.set_defaults(func=run_timing)


def run_timing(args) -> int:
    rec = read_recording(args.take)
    localized = localize_take(rec, load_profile(args.profile))
    solvers = list(SOLVERS) if args.solvers == "all" else args.solvers.split(",")
    modes = {"on": [True], "off": [False], "both": [False, True]}[args.constraints]
    t0 = time.perf_counter()
    warm_up()
    warmup_s = time.perf_counter() - t0
    rows = []
    for constrained in modes:
        for solver in tqdm(solvers, desc=f"constraints {'on' if constrained else 'off'}", unit="solver"):
            rows.append(worst_case_timing(localized, solver, constrained, SolverParams(), args.repeats))
    out = Path(args.report)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "timing.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0].as_dict()))
        w.writeheader()
        w.writerows(r.as_dict() for r in rows)
    md = [f"Worst-case full-body gap fill, {rec.source.split('/')[-1]} ({rows[0].frames} frames, "
          f"{args.repeats} pass(es)), ms per frame. Kernel load/compile before timing: {warmup_s:.2f} s.", "",
          "| solver | constraints | min | max | mean | median | std | iterations | residual mm | thesis mean | thesis max |",
          "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        th = THESIS_TIMING_MS.get((r.solver, r.constraints))
        md.append(f"| {r.solver} | {'on' if r.constraints else 'off'} | {r.min_ms:.3f} | {r.max_ms:.3f} | "
                  f"{r.mean_ms:.3f} | {r.median_ms:.3f} | {r.std_ms:.3f} | {r.mean_iterations:.1f} | "
                  f"{r.mean_residual_mm:.1f} | {th[2] if th else '-'} | {th[1] if th else '-'} |")
    (out / "timing.md").write_text("\n".join(md) + "\n")
    print("\n".join(md))
    if args.json:
        print(json.dumps([r.as_dict() for r in rows], indent=2))
    log.info("wrote %s and %s", out / "timing.md", out / "timing.csv")
    return 0

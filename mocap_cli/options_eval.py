"""`mocap eval options`: what each studio option adds, each left out in turn on every take (mocap_core.leave_one_out)."""
from __future__ import annotations

import csv
import logging
import os
from functools import lru_cache
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from tqdm import tqdm

from mocap_cli.rigid_eval import add_take_args, load_take, take_names
from mocap_core.leave_one_out import KEEP_MM, LEFT_OUT, STUDIO, reference, score


def register(esub) -> None:
    r = esub.add_parser("options", help="what each studio option adds: each left out in turn, every take",
                        description="The studio options solved with each left out in turn on every take: each elbow "
                                    "hidden from 1 s, and 0.1 s in every 0.5 s; each arm lost 1 s in every 2 s; each "
                                    "knee and ankle hidden from 1 s; the thesis's worst case; the pelvis lost 1 s in "
                                    "every 2 s. The hidden joints against the studio options' solve of the complete take; an "
                                    f"option is kept where leaving it out makes some case worse by over {KEEP_MM:g} mm.")
    add_take_args(r)
    r.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="processes (default: one per core)")
    r.add_argument("--report", default="docs/results/options", help="folder for options.md and options.csv")
    r.set_defaults(func=run)


def _take(name: str, seconds: float, option: str) -> tuple[str, str, dict[str, float]]:
    rec, profile = load_take(name, seconds)
    return name, option, score(rec, profile, [option], _reference(name, seconds))[option]


@lru_cache(maxsize=None)
def _reference(name: str, seconds: float):
    """A take's complete studio solve, once per worker process (each solves the take for several options)."""
    return reference(*load_take(name, seconds))


def run(args) -> int:
    from mocap_core.warmup import ensure_compiled

    names = take_names("mocap eval options", args.takes)
    ensure_compiled(logging.getLogger("mocap.eval"))
    jobs = [(name, args.seconds, option) for name in names for option in (STUDIO, *LEFT_OUT)]
    rows = []
    with ProcessPoolExecutor(max(1, args.jobs)) as pool:
        for name, option, means in tqdm(pool.map(_take, *zip(*jobs)), total=len(jobs), desc="solves", unit="run"):
            rows += [{"take": name, "option_left_out": option, "case": case, "mean_mm": round(mm, 2)}
                     for case, mm in means.items()]
    out = Path(args.report)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "options.csv", "w", newline="") as f:
        w = csv.DictWriter(f, ["take", "option_left_out", "case", "mean_mm"])
        w.writeheader()
        w.writerows(rows)
    table = render(rows)
    (out / "options.md").write_text(table)
    print(table)
    return 0


def render(rows: list[dict]) -> str:
    """One line per option: how many cases grow worse by over KEEP_MM without it, the largest change each way, the
    summed change, and whether it is kept."""
    base = {(r["take"], r["case"]): r["mean_mm"] for r in rows if r["option_left_out"] == STUDIO}
    lines = ["Each studio option left out in turn: change of the hidden joints' mean error (mm) on each take and case "
             f"against all options on; kept where some case grows worse by over {KEEP_MM:g} mm.", "",
             f"| left out | cases worse by > {KEEP_MM:g} mm | largest worsening | largest improvement | summed change mm | |",
             "|---|---|---|---|---|---|"]
    for option in LEFT_OUT:
        delta = {(r["take"], r["case"]): r["mean_mm"] - base[r["take"], r["case"]]
                 for r in rows if r["option_left_out"] == option and (r["take"], r["case"]) in base}
        if not delta:
            continue
        worst = max(delta, key=delta.get)
        best = min(delta, key=delta.get)
        worse = sum(d > KEEP_MM for d in delta.values())
        lines.append(f"| {option} | {worse} of {len(delta)} | {delta[worst]:+.1f} ({' '.join(worst)}) | "
                     f"{delta[best]:+.1f} ({' '.join(best)}) | {sum(delta.values()):+.1f} | "
                     f"{'kept' if worse else 'redundant'} |")
    return "\n".join(lines) + "\n"

"""`mocap eval protocol`: a static trial, movement trials without the anatomical markers, and functional joint
centres, on every take (mocap_core.fit.protocol)."""
from __future__ import annotations

import csv
import math
from pathlib import Path

from tqdm import tqdm

from mocap_cli.rigid_eval import add_take_args, load_take, take_names
from mocap_core.fit.functional import TOLERANCE_M
from mocap_core.fit.protocol import MEASURED, STILL_M, run_protocol


def register(esub) -> None:
    r = esub.add_parser("protocol", help="a static trial calibrates, movement trials without the anatomical markers "
                                         "are solved; functional hip, knee and elbow centres, every take",
                        description="On each take: its stillest second calibrates a subject (a take with none is "
                                    "said); the take with the knee, ankle and elbow markers hidden from 1 s, and the "
                                    "thesis's worst case, are solved with it by the studio stages and the fit; the "
                                    "knees, ankles and elbows measured against the complete take's landmarks. And "
                                    "where the take's motion puts the hips, knees and elbows.")
    add_take_args(r)
    r.add_argument("--report", default="docs/results/protocol", help="folder for protocol.md and protocol.csv")
    r.set_defaults(func=run)


def run(args) -> int:
    solves, centres = [], []
    for name in tqdm(take_names("mocap eval protocol", args.takes), desc="takes", unit="take"):
        rec, profile = load_take(name, args.seconds)
        rows, found = run_protocol(rec, profile)
        solves += [{"take": name, **r} for r in rows]
        centres += [{"take": name, **r} for r in found]
    out = Path(args.report)
    out.mkdir(parents=True, exist_ok=True)
    columns = ["take", "static_s", "sway_mm", "variant", "method", "subject", "every_joint_pct", *MEASURED]
    with open(out / "protocol.csv", "w", newline="") as f:
        w = csv.DictWriter(f, columns, extrasaction="ignore")
        w.writeheader()
        w.writerows(solves)
    text = render(solves, centres)
    (out / "protocol.md").write_text(text)
    print(text)
    return 0


def _mm(x) -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.0f}"


def render(solves: list[dict], centres: list[dict]) -> str:
    lines = [f"Static trial: each take's stillest second (every marker within {STILL_M * 1000:.0f} mm of its mean). "
             "Movement trials from 1 s: `landmarks_off` (knee, ankle and elbow markers hidden), `clusters` (only the "
             "pelvis's markers and those no landmark names), `worst` (pelvis, head, hand and toe markers only), "
             "`worst_movement` (the same, solved through the profile without the knee, ankle and elbow landmarks). "
             "Mean mm from where the landmarks put each joint in the complete take; the subject from the static "
             "trial, or from the complete take for comparison.", "",
             "| take | static trial | variant | method | subject | every joint % | " + " | ".join(MEASURED) + " |",
             "|---|---|---|---|---|---|" + "---|" * len(MEASURED)]
    for r in solves:
        if "variant" not in r:
            why = (f"stillest second sways {r['sway_mm']:.0f} mm" if math.isfinite(r["sway_mm"])
                   else "no second sees every marker")
            lines.append(f"| {r['take']} | none ({why}) |" + " |" * (4 + len(MEASURED)))
            continue
        cells = [r["take"], f"{r['static_s']:.1f} s ({r['sway_mm']:.0f} mm)", r["variant"], r["method"], r["subject"],
                 f"{r['every_joint_pct']:.0f}", *(_mm(r[j]) for j in MEASURED)]
        lines.append("| " + " | ".join(cells) + " |")
    lines += ["", "Functional centres from each take's motion: how far from the landmarks' centre, and how far off the "
              "fit's own residuals say it could be (found where that is within "
              f"{TOLERANCE_M * 1000:.0f} mm).", "",
              "| take | joint | found | from the landmarks' mm | could be off by mm | why not |",
              "|---|---|---|---|---|---|"]
    for r in centres:
        why = r["why"].partition(": ")[2].partition(",")[0]
        lines.append(f"| {r['take']} | {r['joint']} | {'yes' if r['found'] else 'no'} | "
                     f"{_mm(r.get('from_landmarks_mm'))} | {_mm(r.get('uncertainty_mm'))} | {why} |")
    return "\n".join(lines) + "\n"

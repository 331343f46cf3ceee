"""`mocap eval rigid`: the thesis's method, the studio options and the rigid-skeleton fit side by side, on every
take (mocap_core.fit.compare)."""
from __future__ import annotations

import csv
import math
from pathlib import Path

from tqdm import tqdm

from mocap_core.fit.compare import cases, references, run_case
from mocap_core.profiles import load_profile
from mocap_core.recordings import read_recording

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
DANCE = "13_qualisys_dance_walk_mocaptoolbox_mcdemodata.mat"
# Every recording in ../shared/data with its shipped profile.
TAKES = {"qualisys_walk": ("02_qualisys_walking_ezc3d_Qualisys.c3d", "qualisys_sports"),
         "sprint": ("03_sprint_start_BTK_SprintMotion.trc", "btk_sprint"),
         "karate": ("08_cmu_135_02_karate_kata.c3d", "cmu41"),
         "vicon": ("12_vicon_freeform_realgaps_nimble_nick_freeform_001.c3d", "vicon53"),
         **{take: (f"{DANCE}:{take}", "dance28") for take in ("dance1", "dance2", "walk1", "walk2")}}
COLUMNS = ["take", "case", "method", "mean_mm", "max_mm", "loc_mean_mm", "loc_max_mm", "estimated_pct",
           "bone_cv_pct", "bone_dev_max_pct", "residual_mm", "complete_pct", "changes_over_1_5", "changes_max"]


def register(esub) -> None:
    r = esub.add_parser("rigid", help="the thesis's method, the studio options and the rigid fit, every take",
                        description="On each take: nothing hidden (bone-length CV, the take's own gaps), the "
                                    "thesis's worst case (only the pelvis, head, hand and toe markers from 1 s), "
                                    "each elbow hidden from 1 s, each knee and ankle hidden from 1 s; the hidden "
                                    "joints measured against each method's solve of the complete take and against "
                                    "the localization's.")
    add_take_args(r)
    r.add_argument("--report", default="docs/results/rigid", help="folder for rigid.md and rigid.csv")
    r.set_defaults(func=run)


def add_take_args(parser) -> None:
    """--takes and --seconds, for the commands that run every shared take."""
    parser.add_argument("--takes", default=",".join(TAKES), help=f"comma-separated, of: {', '.join(TAKES)}")
    parser.add_argument("--seconds", type=float, default=20.0, help="at most this much of each take (default 20)")


def take_names(program: str, takes: str) -> list[str]:
    """The --takes list, an unknown name refused with the known ones."""
    names = [t.strip() for t in takes.split(",") if t.strip()]
    unknown = [t for t in names if t not in TAKES]
    if unknown:
        raise SystemExit(f"{program}: unknown take {unknown[0]!r} (takes: {', '.join(TAKES)})")
    return names


def load_take(name: str, seconds: float):
    """(the recording, at most ``seconds`` of it; its shipped profile) of a shared take by name."""
    file, profile_name = TAKES[name]
    path, _, take = file.partition(":")
    rec = read_recording(DATA / path, take or None)
    return rec.slice(0, min(rec.n_frames, int(seconds * rec.rate_hz))), load_profile(profile_name)


def run(args) -> int:
    rows = []
    for name in tqdm(take_names("mocap eval rigid", args.takes), desc="takes", unit="take"):
        rec, profile = load_take(name, args.seconds)
        reference = references(rec, profile)
        for case in cases(profile, rec.labels, int(round(rec.rate_hz))):
            rows += [{"take": name, **row} for row in run_case(case, rec, profile, reference)]
    out = Path(args.report)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "rigid.csv", "w", newline="") as f:
        w = csv.DictWriter(f, COLUMNS, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    table = summary(rows) + "\n" + render(rows)
    (out / "rigid.md").write_text(table)
    print(table)
    return 0


SUMMARY_METHODS = ("thesis", "studio", "studio_subject", "fit", "fit_subject")
CV_METHODS = ("thesis", "studio", "fit")  # (with nothing hidden a subject's solve is the method's own)


def summary(rows: list[dict]) -> str:
    """One line per take: the worst case, the elbows and the knees with ankles, each as the mean mm over both sides
    (against the method's own complete solve) of the thesis's method / the studio options / the studio options with
    a subject calibrated first / the fit / the fit of that subject; and the limb bones' length CV with every marker
    seen."""
    def mean(take, method, prefix):
        got = [r["mean_mm"] for r in rows
               if r["take"] == take and r["method"] == method and r["case"].startswith(prefix)]
        return f"{sum(got) / len(got):.0f}" if got else "-"

    def cv(take, method):
        return _f(next((r["bone_cv_pct"] for r in rows if r["take"] == take and r["method"] == method
                        and r["case"] == "all"), float("nan")), 1) or "-"

    lines = [f"Mean mm over both sides; each cell {' / '.join(SUMMARY_METHODS)} (bone CV: {' / '.join(CV_METHODS)}).",
             "",
             "| take | worst case | elbow hidden | knee + ankle hidden | bone CV % |", "|---|---|---|---|---|"]
    for take in dict.fromkeys(r["take"] for r in rows):
        cells = [" / ".join(mean(take, m, case) for m in SUMMARY_METHODS) for case in ("worst", "elbow", "knee_ankle")]
        lines.append(f"| {take} | {' | '.join(cells)} | {' / '.join(cv(take, m) for m in CV_METHODS)} |")
    return "\n".join(lines) + "\n"


def _f(x, digits=1) -> str:
    return "" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.{digits}f}"


def render(rows: list[dict]) -> str:
    """The hidden-joint cases as mean / max mm (against each method's own complete solve, and the localization's),
    and the bones and the take's own gaps from the case with nothing hidden."""
    lines = ["Hidden joints, mm (mean / max) against each method's solve of the complete take; in brackets against "
             "the localization's. Bones: CV of the limb bones' lengths and their largest deviation from their median "
             "(%). Fit residual: RMS of the seen markers off their calibrated places (mm).", "",
             "| take | case | method | hidden joints | (vs localization) | estimated % | bone CV % | bone max dev % | "
             "fit residual mm | whole skeleton % | twitches > 1.5x | largest |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        hidden = f"{_f(r.get('mean_mm'))} / {_f(r.get('max_mm'))}" if "mean_mm" in r else ""
        loc = f"({_f(r.get('loc_mean_mm'))} / {_f(r.get('loc_max_mm'))})" if "loc_mean_mm" in r else ""
        lines.append(f"| {r['take']} | {r['case']} | {r['method']} | {hidden} | {loc} | "
                     f"{_f(r.get('estimated_pct'), 0)} | {_f(r['bone_cv_pct'], 2)} | {_f(r['bone_dev_max_pct'])} | "
                     f"{_f(r['residual_mm'])} | {_f(r.get('complete_pct'))} | {r.get('changes_over_1_5', '')} | {_f(r.get('changes_max'), 2)} |")
    return "\n".join(lines) + "\n"

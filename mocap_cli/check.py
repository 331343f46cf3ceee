"""`mocap check`: what a take's markers do wrong, before it is solved (mocap_core.take_check)."""
from __future__ import annotations

import logging
from pathlib import Path

from mocap_core.fit.subject import load_subject
from mocap_core.landmark_needs import describe_missing, placed_by_subject, unlocatable
from mocap_core.profiles import AUTO, PROFILE_HELP, profile_for
from mocap_core.recordings import Recording
from mocap_core.take_check import (FLOOR_M, TOLERANCE, MarkerGaps, Stretch, marker_gaps, rigid_pairs, spacing_faults,
                                   used_markers)
from nodes.bags import read_take

log = logging.getLogger("mocap.check")
SHOWN_GAPS = 12  # the markers with the longest gaps in the table; check.md lists them all


def add_parser(sub) -> None:
    s = sub.add_parser("check", help="what a take's markers do wrong: gaps, and markers of one bone off their spacing",
                       description="Read a recording and report, before anything is solved, how long each marker the "
                                   "profile uses is lost, and where two markers of one bone (forearm, foot, shank, "
                                   "thorax, pelvis) are off their usual distance by more than "
                                   f"{TOLERANCE * 100:.0f} percent of it ({FLOOR_M * 1000:.0f} mm at least): a label "
                                   "swapped, a ghost, a marker that slid or stands still. The gap fills trust what is "
                                   "seen, so a fill near such a marker can be no better than it. Writes check.md and "
                                   "check.png (each faulty pair's distance over time).")
    s.add_argument("file", help="recording: .c3d, .trc, .mat (file.mat:take picks a take) or an MCAP bag")
    s.add_argument("--profile", default=AUTO, help=PROFILE_HELP)
    s.add_argument("--subject", help="a subject file (`mocap calibrate` of a static trial): the joints its markers "
                                     "place are not missing")
    s.add_argument("--report", default="reports/check", help="directory for check.md and check.png")
    s.add_argument("--no-plots", action="store_true")
    s.set_defaults(func=run)


def run(args) -> int:
    rec = read_take(args.file)
    profile = profile_for(args.profile, rec.labels, log)
    profile.resolve(rec.labels)  # a label the profile needs and the take lacks is an error here, as in solve
    gaps = [g for g in marker_gaps(rec.positions, used_markers(profile, rec.labels), rec.rate_hz) if g.lost]
    faults = spacing_faults(rec.positions, rigid_pairs(profile, rec.labels), rec.rate_hz)
    out = Path(args.report)
    out.mkdir(parents=True, exist_ok=True)
    missing, placed = unlocatable(frozenset(profile.landmarks)), []
    if args.subject:  # (a movement trial's profile, and the subject of its static trial)
        subject = load_subject(args.subject)
        placed, missing = placed_by_subject(missing, subject.known)
    never = describe_missing(missing) + [
        f"{j}: placed by subject {args.subject}'s markers"
        + (" (its centre found from the calibration take's motion)" if j in subject.from_motion else "")
        for j in placed]
    text = report(rec, profile.name, gaps, faults, never=never)
    (out / "check.md").write_text(text)
    print(report(rec, profile.name, gaps[:SHOWN_GAPS], faults, left_out=len(gaps) - SHOWN_GAPS, never=never))
    if faults and not args.no_plots:
        from mocap_cli.plots import spacing_plot

        spacing_plot(rec, faults, out / "check.png", f"{_name(rec)}: markers of one bone off their spacing")
    log.info("%d markers lost at times, %d stretches off their spacing -> %s", len(gaps), len(faults), out)
    return 0


def report(rec: Recording, profile: str, gaps: list[MarkerGaps], faults: list[Stretch], left_out: int = 0,
           never: list[str] | None = None) -> str:
    lines = [f"# {_name(rec)}: what its markers do wrong", "",
             f"{rec.n_frames} frames at {rec.rate_hz:g} Hz ({rec.n_frames / rec.rate_hz:.1f} s), profile {profile}.",
             "", "## Joints the profile cannot locate", ""]
    lines += [f"- {line}" for line in never] if never else ["None: its landmarks locate every joint."]
    lines += ["", "## Markers lost", ""]
    if gaps:
        lines += ["| marker | frames lost | gaps | longest |", "|---|---|---|---|"]
        lines += [f"| {g.label} | {g.lost} ({100 * g.lost / rec.n_frames:.1f} %) | {g.gaps} | {g.longest_s:.2f} s |"
                  for g in gaps]
        if left_out > 0:
            lines += ["", f"({left_out} more in check.md)"]
    else:
        lines.append("None: every marker the profile uses is seen in every frame.")
    lines += ["", f"## Markers of one bone off their spacing (by over {TOLERANCE * 100:.0f} % of it, "
                  f"{FLOOR_M * 1000:.0f} mm at least)", ""]
    if faults:
        lines += ["| bone | markers | usual | when | frames off | distance there |", "|---|---|---|---|---|---|"]
        lines += [f"| {f.pair.bone} | {f.pair.a}, {f.pair.b} | {f.usual_m * 1000:.0f} mm | "
                  f"{f.start_s:.2f}-{f.end_s:.2f} s | {f.frames} | {f.low_m * 1000:.0f}-{f.high_m * 1000:.0f} mm |"
                  for f in faults]
    else:
        lines.append("None: every pair of markers on one bone keeps its spacing.")
    return "\n".join(lines) + "\n"


def _name(rec: Recording) -> str:
    return rec.source.split("/")[-1]

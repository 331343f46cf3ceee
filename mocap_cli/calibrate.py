"""`mocap calibrate`: a subject's skeleton and marker offsets from a take, as a subject file (YAML)."""
from __future__ import annotations

import logging

import numpy as np

from mocap_cli.solve import actor_path
from mocap_core.fit.calibration import STILL_M, calibrate, is_static
from mocap_core.profiles import AUTO, PROFILE_HELP, actors, profile_for
from mocap_core.warmup import ensure_compiled
from mocap_core.skeleton import INDEX, JOINTS
from nodes.bags import read_take

log = logging.getLogger("mocap.calibrate")


def add_parser(sub) -> None:
    s = sub.add_parser("calibrate", help="calibrate a subject (bones, marker offsets) from a take",
                       description="Learn the actor's bone lengths and, for every labelled marker, the bone it "
                                   "rides and its offset there, from the take's own frames (no calibration "
                                   "pose needed), and write a subject file for `mocap solve --subject` and the "
                                   "skeleton_fit node.")
    s.add_argument("file", help="recording: .c3d, .trc or .mat (file.mat:take picks a take)")
    s.add_argument("--profile", default=AUTO, help=PROFILE_HELP)
    s.add_argument("-o", "--out", required=True, help="subject file to write (YAML)")
    s.add_argument("--seconds", type=float, help="learn from the first SECONDS only (default: the whole take)")
    s.set_defaults(func=run)


def run(args) -> int:
    rec = read_take(args.file)
    ensure_compiled(log)
    if args.seconds:
        rec = rec.slice(0, max(1, int(args.seconds * rec.rate_hz)))
    several = actors(rec.labels)
    if len(several) < 2:
        _calibrate(rec, args.profile, args.out)
        return 0
    log.info("%d actors in the take (%s): a subject file each", len(several), ", ".join(several))
    for actor in several:  # actor.yaml -> actor.alice.yaml: `mocap solve --subject 'actor.{actor}.yaml'` reads them
        _calibrate(rec.actor(actor), args.profile, actor_path(args.out, actor))
    return 0


def _calibrate(rec, profile_name: str, out: str) -> None:
    profile = profile_for(profile_name, rec.labels, log)
    static = is_static(rec.positions)
    if static:
        log.info("a static trial (every marker within %.0f mm of its mean place): each marker rides the nearest bone "
                 "of its body segment, by profile %s's landmarks and tracking lists", STILL_M * 1000, profile.name)
    subject = calibrate(rec.positions, rec.labels, profile, rec.rate_hz)
    subject.save(out)
    lengths = subject.lengths()
    named = [f"{j} {lengths[i] * 1000:.0f}" for i, j in enumerate(JOINTS) if subject.known[i] and i > 0]
    unassigned = [x for x, b in zip(subject.labels, subject.marker_bone) if b < 0]
    log.info("%s: %d frames, %d of %d markers on a bone (median stray %.1f mm)%s; bones (mm): %s",
             out, subject.frames, int((subject.marker_bone >= 0).sum()), len(subject.labels),
             float(np.nanmedian(subject.spread_m) * 1000),
             f", on none: {', '.join(unassigned)}" if unassigned else "", ", ".join(named))
    missing = [j for i, j in enumerate(JOINTS) if not subject.known[i]]
    if missing:
        log.warning("never located, so not solved: %s (the profile lacks their landmarks)", ", ".join(missing))
    if not static:  # (a static trial has no motion to find joints from)
        _from_motion(rec, profile, subject)


def _from_motion(rec, profile, subject) -> None:
    """Say where the take's motion puts the hips, knees and elbows (functional centres), beside the landmarks'."""
    from mocap_core.experiments import localize_take
    from mocap_core.fit.calibration import bone_of_each
    from mocap_core.fit.functional import functional_centres

    located = localize_take(rec, profile)[0]
    markers = rec.positions.astype(np.float64)
    for found in functional_centres(markers, bone_of_each(profile, rec.labels, subject), INDEX, located):
        if found.why:
            log.info("from motion: %s", found.why)
            continue
        apart = found.apart_m(located, INDEX)
        where = (f"{apart * 1000:.0f} mm from where the landmarks put it" if np.isfinite(apart)
                 else "no landmark locates it: the subject has it from here"
                 if found.joint in subject.from_motion else "no landmark locates it")
        log.info("from motion: %s found (to within %.0f mm by its fit), %s", found.joint,
                 found.centre.uncertainty_m.max() * 1000, where)

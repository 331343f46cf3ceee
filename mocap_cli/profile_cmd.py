"""`mocap profile explain`: the landmarks, where each is on the body, and what each one locates."""
from __future__ import annotations

from mocap_core.landmark_needs import needed_by, site
from mocap_core.profiles import LANDMARKS, load_profile


def add_parser(sub) -> None:
    p = sub.add_parser("profile", help="marker-set profiles: what the landmarks are")
    psub = p.add_subparsers(dest="profile_command", required=True)
    e = psub.add_parser("explain", help="each landmark: where it is on the body, the joints that need it, and "
                                        "(with --profile) the labels a profile gives it")
    e.add_argument("--profile", help="a profile to show against the landmarks (a name from profiles/ or a path)")
    e.set_defaults(func=cmd_explain)


def cmd_explain(args) -> int:
    profile = load_profile(args.profile) if args.profile else None
    needs = needed_by()
    print("Landmarks (the PAF running set's names; a profile maps each onto your labels):\n")
    for name in LANDMARKS:
        joints = ", ".join(needs[name]) or "none alone (other landmarks stand in)"
        line = f"{name:7s} {site(name)}\n        without it: {joints}"
        if profile is not None:
            line += f"\n        {profile.name}: {profile.landmarks.get(name, '(not in the profile)')}"
        print(line)
    return 0

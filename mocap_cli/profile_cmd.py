"""`mocap profile init`: a profile drafted from a recording's labels; `mocap profile explain`: the landmarks,
where each is on the body, and what each one locates."""
from __future__ import annotations

from pathlib import Path

from mocap_core.landmark_needs import describe_missing, needed_by, placed_by_subject, site, unlocatable
from mocap_core.profile_draft import draft_yaml
from mocap_core.profiles import DEFAULT_UP, LANDMARKS, load_profile, shipped
from mocap_core.up_axis import recording_up_axis
from nodes.bags import read_take


def add_parser(sub) -> None:
    p = sub.add_parser("profile", help="marker-set profiles: what the landmarks are")
    psub = p.add_subparsers(dest="profile_command", required=True)
    e = psub.add_parser("explain", help="each landmark: where it is on the body, the joints that need it, and "
                                        "(with --profile) the labels a profile gives it")
    e.add_argument("--profile", help="a profile to show against the landmarks (a name from profiles/ or a path)")
    e.add_argument("--subject", help="a subject file (`mocap calibrate`): which joints come from the profile's "
                                     "landmarks and which from the subject's markers")
    e.add_argument("--markdown", action="store_true", help="the page docs/landmarks.md is: a table, with the labels "
                                                           "of every shipped profile")
    e.set_defaults(func=cmd_explain)
    i = psub.add_parser("init", help="draft a profile for a recording's marker set from the common naming "
                                     "conventions, every guess commented for you to check")
    i.add_argument("file", help="recording: .c3d, .trc, .mat (file.mat:take) or a bag")
    i.add_argument("-o", "--output", required=True, help="the profile to write (YAML)")
    i.add_argument("--name", help="the profile's name (default: the output file's stem)")
    i.set_defaults(func=cmd_init)


def cmd_explain(args) -> int:
    if args.markdown:
        print(landmarks_page(), end="")
        return 0
    profile = load_profile(args.profile) if args.profile else None
    needs = needed_by()
    print("Landmarks (the PAF running set's names; a profile maps each onto your labels):\n")
    for name in LANDMARKS:
        joints = ", ".join(needs[name]) or "none alone (other landmarks stand in)"
        line = f"{name:7s} {site(name)}\n        without it: {joints}"
        if profile is not None:
            line += f"\n        {profile.name}: {profile.landmarks.get(name, '(not in the profile)')}"
        print(line)
    if profile is not None:  # (what `mocap check` says of it, word for word)
        never = describe_missing(unlocatable(frozenset(profile.landmarks)))
        print(f"\nJoints {profile.name} cannot locate:")
        print("\n".join(f"- {line}" for line in never) if never else "None: its landmarks locate every joint.")
        if args.subject:
            print(joint_sources(profile, args.subject))
    return 0


def joint_sources(profile, subject_path: str) -> str:
    """Where each joint comes from when a take is solved with this profile and subject."""
    from mocap_core.fit.subject import load_subject
    from mocap_core.skeleton import JOINTS

    never = unlocatable(frozenset(profile.landmarks))
    subject = load_subject(subject_path)
    placed, nowhere = placed_by_subject(never, subject.known)
    landmarks = [j for j in JOINTS if j not in never]
    motion = [j for j in placed if j in subject.from_motion]
    placed = [j for j in placed if j not in motion]
    return (f"\nWith subject {subject_path}:\n- from {profile.name}'s landmarks (and, where they are lost, the "
            f"subject's markers): {', '.join(landmarks)}\n- from the subject's markers alone: "
            f"{', '.join(placed) or 'none'}\n- from the subject's markers, where the calibration take's motion put "
            f"the joint (no landmark did): {', '.join(motion) or 'none'}\n- nowhere (neither locates them): "
            f"{', '.join(nowhere) or 'none'}")


def landmarks_page() -> str:
    """docs/landmarks.md: every landmark, where it is, what is lost without it, and its labels in the shipped
    profiles (made by this function: `mocap profile explain --markdown > docs/landmarks.md`)."""
    profiles = [load_profile(name) for name in shipped()]
    needs = needed_by()
    lines = ["# Landmarks", "",
             "Localization works on these landmarks (the PAF running set's names); a profile maps each onto a "
             "recording's labels (README, \"Your own marker set\"). \"Without it\": the joints that a profile "
             "lacking only this landmark cannot locate (other landmarks stand in for the rest). The shipped profiles' "
             "labels show how other marker sets name the same places. Made by `mocap profile explain --markdown`.", "",
             "| landmark | where on the body | without it | " + " | ".join(f"`{p.name}`" for p in profiles) + " |",
             "|---|---|---|" + "---|" * len(profiles)]
    for name in LANDMARKS:
        labels = [f"`{p.landmarks[name]}`" if name in p.landmarks else "" for p in profiles]
        lines.append(f"| `{name}` | {site(name)} | {', '.join(needs[name]) or '-'} | " + " | ".join(labels) + " |")
    return "\n".join(lines) + "\n"


def cmd_init(args) -> int:
    rec = read_take(args.file)
    out = Path(args.output)
    if out.exists():
        raise SystemExit(f"mocap profile init: {out} exists; give another -o (a draft never overwrites)")
    up = recording_up_axis(rec) or DEFAULT_UP
    text = draft_yaml(args.name or out.stem, rec.labels, up, Path(rec.source).name)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text)
    profile = load_profile(out)  # the draft is a valid profile, and resolves against its recording
    profile.resolve(rec.labels)
    print(f"wrote {out}: {len(profile.landmarks)} of {len(LANDMARKS)} landmarks guessed from {len(rec.labels)} labels")
    never = describe_missing(unlocatable(frozenset(profile.landmarks)))
    print("Every joint can be located with it." if not never else
          "Joints it cannot locate yet:\n  " + "\n  ".join(never))
    print(f"Check each guess in {out}, then: mocap solve {args.file} --profile {out} --joints-out out.csv")
    return 0

"""How well could any solver place the hidden joints of `mocap eval rigid`'s cases? Three generous guessers, each
given far more than a solver has, measured like the methods (mean / max mm after the first second, against the fit
of the complete take):

- swivel: an elbow (knee) with its shoulder and wrist (hip and ankle) placed exactly and its bones at their exact
  lengths, so that only its turn about the shoulder-wrist line is unknown; that turn taken from the 5 frames of the
  complete take, more than 1 s away, whose wrist sits most alike in the chest (pelvis) frame;
- memory: the worst case's four joints (elbows, knees) from the 5 frames of the complete take, more than 1 s away,
  whose kept markers sit most alike in the pelvis frame;
- ankle circle: where hiding the knee and ankle leaves two markers below the knee (the 28-marker set's toes), the
  ankle on its exact circle about their line, its angle there taken from the 5 most alike frames as above.

They learn from the whole complete take, hidden joints and all, which no solver may; where even they miss a target
of `mocap eval rigid`, the markers kept do not determine the joint that closely.

    python benchmarks/hidden_joint_bounds.py [--takes karate,vicon]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from mocap_cli.rigid_eval import add_take_args, load_take, take_names  # noqa: E402
from mocap_core.fit.compare import cases  # noqa: E402
from mocap_core.fit.take import fit_take  # noqa: E402
from mocap_core.skeleton import INDEX, PARENT_INDEX, children  # noqa: E402

NEIGHBOURS = 5
# The middle joint: the bone whose frame describes the end's place, and the axis of that frame (columns x left,
# y up, z forward) that a turn about the line is measured from: down for an elbow, forward for a knee.
CHAINS = {"elbow": ("spine3", 1, -1.0), "knee": ("pelvis", 2, 1.0)}


def alike(features: np.ndarray, away: int) -> tuple[np.ndarray, np.ndarray]:
    """(F, NEIGHBOURS) for each frame the frames most alike in ``features`` more than ``away`` frames from it,
    and (F,) whether the frame has its features (a frame without has no neighbours)."""
    frames = np.arange(len(features))
    seen = np.isfinite(features).all(axis=1)
    out = np.zeros((len(features), NEIGHBOURS), np.int64)
    for f in frames[seen]:
        far = frames[(np.abs(frames - f) > away) & seen]
        out[f] = far[np.argsort(np.linalg.norm(features[far] - features[f], axis=1))[:NEIGHBOURS]]
    return out, seen


def circle_guess(centre, normal, point, reference, features, away):
    """``point`` (F, 3) placed on its exact circle about ``normal`` through ``centre``, at the angle (from the
    body's ``reference`` direction) of its most alike frames; returns the distance (m) from the true point."""
    n = normal / np.linalg.norm(normal, axis=1, keepdims=True)
    c = centre + n * np.einsum("fi,fi->f", point - centre, n)[:, None]
    r = point - c
    radius = np.linalg.norm(r, axis=1)
    u = reference - n * np.einsum("fi,fi->f", reference, n)[:, None]
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(n, u)
    angle = np.arctan2(np.einsum("fi,fi->f", r, v), np.einsum("fi,fi->f", r, u))
    near, seen = alike(features, away)
    guess = np.angle(np.exp(1j * angle)[near].mean(axis=1))
    placed = c + radius[:, None] * (np.cos(guess)[:, None] * u + np.sin(guess)[:, None] * v)
    return np.where(seen, np.linalg.norm(placed - point, axis=1), np.nan)


def in_frame(P, R, bone: int, points):
    """``points`` (F, ..., 3) in bone ``bone``'s frame."""
    rel = points - P[:, bone].reshape((len(P),) + (1,) * (points.ndim - 2) + (3,))
    return np.einsum("fba,f...b->f...a", R[:, bone], rel)


def swivel(P, R, middle: str, side: str, away: int) -> np.ndarray:
    mid = INDEX[f"{middle}_{side}"]
    root, end = PARENT_INDEX[mid], INDEX[children(f"{middle}_{side}")[0]]
    body, axis, sign = CHAINS[middle]
    b = INDEX[body]
    return circle_guess(P[:, root], P[:, end] - P[:, root], P[:, mid], sign * R[:, b, :, axis],
                        in_frame(P, R, b, P[:, end]), away)


def memory(P, R, kept_markers, joints, away) -> np.ndarray:
    features = in_frame(P, R, 0, kept_markers).reshape(len(P), -1)
    target = in_frame(P, R, 0, P[:, joints])
    near, seen = alike(features, away)
    return np.where(seen[:, None], np.linalg.norm(target[near].mean(axis=1) - target, axis=2), np.nan)


def ankle_circle(P, R, markers, side: str, away: int) -> np.ndarray | None:
    if len(markers) != 2:
        return None
    a, b = markers
    return circle_guess(a, b - a, P[:, INDEX[f"ankle_{side}"]], R[:, 0, :, 1], in_frame(P, R, 0, (a + b) / 2), away)


def report(errors: np.ndarray, start: int) -> str:
    e = errors[start:] * 1000
    return f"{np.nanmean(e):.0f} / {np.nanmax(e):.0f}"


def main() -> int:
    np.seterr(invalid="ignore", divide="ignore")  # frames where a marker is lost: NaN, left out of the figures
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_take_args(ap)
    args = ap.parse_args()
    print("mean / max mm after 1 s; targets: worst case 60 / 150, elbow 15 / 50, knee + ankle mean 20")
    for name in take_names("hidden_joint_bounds", args.takes):
        rec, profile = load_take(name, args.seconds)
        markers = rec.positions.astype(np.float64)
        chunk, _, subject = fit_take(markers, rec.labels, profile, rec.rate_hz)
        P, R = chunk.positions, chunk.frames
        second = int(round(rec.rate_hz))
        col = list(profile.columns(rec.labels))
        if rec.n_frames < 3 * second:
            print(f"{name}: too short to leave a second out ({rec.n_frames} frames)")
            continue
        line = [f"swivel {m}_{s} {report(swivel(P, R, m, s, second), second)}" for m in CHAINS for s in "lr"]
        by_case = {c.name: c for c in cases(profile, rec.labels, second)}
        worst = by_case["worst"]
        kept = [i for i, x in enumerate(col) if x not in worst.hidden]
        joints = [INDEX[j] for j in worst.measured]
        line.append(f"memory worst {report(memory(P, R, markers[:, kept], joints, second), second)}")
        for side in "lr":
            case = by_case.get(f"knee_ankle_{side}")
            below = {INDEX[f"{j}_{side}"] for j in ("knee", "ankle", "foot")}
            left = [markers[:, i] for i, x in enumerate(col) if case and x not in case.hidden
                    and x in subject.labels and subject.marker_bone[subject.labels.index(x)] in below]
            e = ankle_circle(P, R, left, side, second)
            if e is not None:
                line.append(f"ankle circle {side} {report(e, second)}")
        print(f"{name}: " + " | ".join(line), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

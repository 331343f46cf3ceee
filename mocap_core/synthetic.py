"""A synthetic running take in the PAF marker set, driven by a parametric skeleton.

For the demo on a machine without recordings, and as ground truth for tests: the generator knows
the exact joint centres it placed the markers around. A runner on a treadmill (Z up, facing +X,
left = +Y) with a 1.4 Hz stride: hips, knees and ankles flex in a running pattern, arms swing
opposite to the legs with bent elbows. Markers sit at fixed offsets on their segments, with
soft-tissue motion (smooth drifts of a few millimetres) and measurement noise; occlusions are
the medial elbow markers while the arm is behind the trunk, plus random dropouts.

``read_recording("synthetic:running")`` (and ``synthetic:running?seconds=30&rate=300&seed=2``)
returns the take; :func:`running_take` also returns the true joint centres.
"""
from __future__ import annotations

import math

import numpy as np

from mocap_core.skeleton import INDEX, N_JOINTS

# The 35 markers of the PAF Running set (thesis appendix): no medial knee or ankle markers.
LABELS = ("SACR", "L_IAS", "R_IAS", "TV12", "TV2", "SME", "SGL", "L_HEAD", "R_HEAD",
          "L_SAE", "L_HLE", "L_HME", "L_UOA", "L_RSP", "L_USP", "L_HM2", "L_PAS", "L_FLE", "L_TTC",
          "L_FAL", "L_FCC", "L_FM2",
          "R_SAE", "R_HLE", "R_HME", "R_UOA", "R_RSP", "R_USP", "R_HM2", "R_PAS", "R_FLE", "R_TTC",
          "R_FAL", "R_FCC", "R_FM2")
# Clusters (the movement trials of a biomechanics protocol): three markers on a plate on each thigh, shank, upper arm
# and forearm.
CLUSTERS = tuple(f"{s}_{part}{k}" for s in "LR" for part in ("THI", "SHK", "UAR", "FAR") for k in (1, 2, 3))
STRIDE_HZ = 1.4
# Each joint's flexion, degrees: (mean, amplitude) over a stride. A range-of-motion trial bends them further.
SWING = {"running": {"hip": (20, 28), "knee": (45, 40), "shoulder": (0, -35), "elbow": (90, 15)},
         "range_of_motion": {"hip": (25, 50), "knee": (70, 65), "shoulder": (0, -60), "elbow": (75, 70)}}
# A cluster's three markers: (along the segment, out to the side, ahead) in metres.
PLATE = ((0.18, 0.09, 0.03), (0.26, 0.10, -0.03), (0.30, 0.07, 0.05))
ARM_PLATE = ((0.14, 0.05, 0.02), (0.19, 0.06, -0.02), (0.22, 0.04, 0.03))
THIGH, SHANK, UPPER_ARM, FOREARM = 0.44, 0.42, 0.29, 0.26


def _ry(angle: float) -> np.ndarray:
    """Rotation about +Y (the subject's left): positive turns +X (forward) towards -Z (down)."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, 0, s], [0, 1.0, 0], [-s, 0, c]])


def _down(angle: float) -> np.ndarray:
    """A segment pointing down, swung forward by ``angle`` radians."""
    return np.array([math.sin(angle), 0.0, -math.cos(angle)])


def _pose(t: float, swing=SWING["running"]):
    """Joint centres and markers (dicts of name -> 3-vector) at time t; ``swing``: the joints' (SWING)."""
    w = 2 * math.pi * STRIDE_HZ
    p = np.array([0.0, 0.01 * math.sin(w * t), 0.95 + 0.03 * math.sin(2 * w * t)])   # pelvis centre
    lean = math.radians(8)
    up_t = np.array([math.sin(lean), 0.0, math.cos(lean)])                          # trunk axis
    joints, m = {}, {}
    _pelvis(p, joints, m)
    _trunk(p, up_t, joints, m)
    for s, S, sgn, phase in (("l", "L", 1.0, 0.0), ("r", "R", -1.0, math.pi)):
        ph = w * t + phase
        _leg(s, sgn, ph, swing, joints, m)
        _arm(s, sgn, ph, swing, p + 0.53 * up_t, joints, m)
    behind = {s: math.sin(w * t + ph0) > 0.5 for s, ph0 in (("L", 0.0), ("R", math.pi))}  # arm swung back
    return joints, m, behind


def _pelvis(p, joints, m) -> None:
    """The pelvis markers; the hip centres follow Harrington et al. from them (as the truth, by construction)."""
    m["SACR"] = p + np.array([-0.15, 0, 0.06])
    m["L_IAS"], m["R_IAS"] = p + np.array([0.03, 0.12, 0.07]), p + np.array([0.03, -0.12, 0.07])
    mid = 0.5 * (m["L_IAS"] + m["R_IAS"])
    pw, pd = 240.0, float(np.linalg.norm(mid - m["SACR"]) * 1000)
    fwd = mid - m["SACR"]
    fwd /= np.linalg.norm(fwd)
    lat = (0.33 * pw + 7.3) / 1000
    down_back = np.array([0, 0, 1.0]) * (-0.30 * pw - 10.9) / 1000 + fwd * (-0.24 * pd - 9.9) / 1000
    for s, sgn in (("l", 1.0), ("r", -1.0)):
        joints[f"hip_{s}"] = mid + np.array([0, sgn * lat, 0]) + down_back
    joints["pelvis"] = 0.5 * (joints["hip_l"] + joints["hip_r"])


def _trunk(p, up_t, joints, m) -> None:
    m["TV12"] = p + 0.30 * up_t + np.array([-0.12, 0, 0])
    m["TV2"] = p + 0.56 * up_t + np.array([-0.10, 0, 0])
    m["SME"] = p + 0.52 * up_t + np.array([0.08, 0, 0])
    head = p + 0.74 * up_t
    m["SGL"] = head + np.array([0.09, 0, 0])
    m["L_HEAD"], m["R_HEAD"] = head + np.array([0, 0.08, 0]), head + np.array([0, -0.08, 0])
    joints["head"] = head


def _leg(s: str, sgn: float, ph: float, swing, joints, m) -> None:
    """One leg in a running flexion pattern at phase ph."""
    S, side = s.upper(), np.array([0, sgn, 0])
    (hip_mean, hip_amp), (knee_mean, knee_amp) = swing["hip"], swing["knee"]
    hip_flex = math.radians(hip_mean + hip_amp * math.sin(ph))
    knee_flex = math.radians(knee_mean + knee_amp * math.sin(ph - 1.2))
    ankle = math.radians(8 * math.sin(ph + 0.6))
    hip = joints[f"hip_{s}"]
    knee = hip + THIGH * _down(hip_flex)
    shank_dir = _down(hip_flex - knee_flex)
    ank = knee + SHANK * shank_dir
    foot_rot = _ry(-(hip_flex - knee_flex) + ankle)
    joints[f"knee_{s}"], joints[f"ankle_{s}"] = knee, ank
    shank_fwd = np.cross(side * sgn, shank_dir) * -1  # forward, perpendicular to the shank
    shank_fwd /= np.linalg.norm(shank_fwd)
    m[f"{S}_FLE"] = knee + 0.057 * side
    m[f"{S}_TTC"] = knee + 0.045 * shank_fwd + 0.07 * shank_dir
    m[f"{S}_PAS"] = knee + 0.05 * shank_fwd - 0.07 * shank_dir
    m[f"{S}_FAL"] = ank + 0.042 * side
    _plate(m, f"{S}_THI", hip, (knee - hip) / THIGH, side, PLATE)
    _plate(m, f"{S}_SHK", knee, shank_dir, side, PLATE)
    m[f"{S}_FCC"] = ank + foot_rot @ np.array([-0.07, 0, -0.05])
    m[f"{S}_FM2"] = ank + foot_rot @ np.array([0.15, 0, -0.06])
    joints[f"toe_{s}"] = m[f"{S}_FM2"]


def _plate(m, name: str, origin, along, side, plate) -> None:
    """A cluster's markers on a segment from ``origin`` along the unit vector ``along``."""
    ahead = np.cross(along, np.abs(side))  # forward, perpendicular to the segment
    for k, (a, out, fwd) in enumerate(plate):
        m[f"{name}{k + 1}"] = origin + a * along + out * side + fwd * ahead


def _arm(s: str, sgn: float, ph: float, swing, chest, joints, m) -> None:
    """One arm swinging opposite to the same side's leg, elbow bent; ``chest``: the trunk at shoulder height."""
    S, side = s.upper(), np.array([0, sgn, 0])
    (sh_mean, sh_amp), (el_mean, el_amp) = swing["shoulder"], swing["elbow"]
    sh_flex = math.radians(sh_mean + sh_amp * math.sin(ph))
    el_flex = math.radians(el_mean + el_amp * math.sin(ph + 0.5))
    sae = chest + np.array([-0.02, sgn * 0.19, 0])
    shoulder = sae + np.array([0, -sgn * 0.01, -0.05])
    elbow = shoulder + UPPER_ARM * _down(sh_flex)
    fore = _down(sh_flex + el_flex)
    wrist = elbow + FOREARM * fore
    joints[f"shoulder_{s}"], joints[f"elbow_{s}"], joints[f"wrist_{s}"] = shoulder, elbow, wrist
    radial = np.cross(fore, np.array([0, 1.0, 0]))  # thumbs up while running
    radial /= np.linalg.norm(radial)
    m[f"{S}_SAE"] = sae
    m[f"{S}_HLE"], m[f"{S}_HME"] = elbow + 0.035 * side, elbow - 0.035 * side
    m[f"{S}_UOA"] = elbow - 0.03 * fore + 0.02 * np.cross(side, fore)
    m[f"{S}_RSP"], m[f"{S}_USP"] = wrist + 0.025 * radial, wrist - 0.025 * radial
    m[f"{S}_HM2"] = wrist + 0.08 * fore
    joints[f"hand_{s}"] = m[f"{S}_HM2"]
    _plate(m, f"{S}_UAR", shoulder, (elbow - shoulder) / UPPER_ARM, side, ARM_PLATE)
    _plate(m, f"{S}_FAR", elbow, fore, side, ARM_PLATE)


def running_take(seconds: float = 20.0, rate_hz: float = 200.0, seed: int = 0, clusters: bool = False,
                 swing: str = "running", skin_m: float = 0.002):
    """-> (Recording in the PAF marker set, true joint centres (F, J, 3) with NaN for joints not placed);
    ``clusters``: with a cluster of three markers on each thigh, shank, upper arm and forearm (CLUSTERS) after them;
    ``swing``: how far the joints bend (SWING); ``skin_m``: the most a marker's skin drifts along each of its three slow waves."""
    from mocap_core.recordings import Recording

    rng = np.random.default_rng(seed)
    n = int(seconds * rate_hz)
    t = np.arange(n) / rate_hz
    labels = LABELS + (CLUSTERS if clusters else ())
    pos = np.empty((n, len(labels), 3))
    truth = np.full((n, N_JOINTS, 3), np.nan)
    hidden = np.zeros((n, len(labels)), bool)
    for f in range(n):
        joints, markers, behind = _pose(t[f], SWING[swing])
        for k, label in enumerate(labels):
            pos[f, k] = markers[label]
        for name, p in joints.items():
            truth[f, INDEX[name]] = p
        for S in "LR":
            if behind[S]:
                hidden[f, LABELS.index(f"{S}_HME")] = True  # the medial elbow is behind the trunk
    # soft tissue: a smooth drift per marker (three slow sinusoids, 1-2 mm each by default) plus 0.3 mm noise
    for k in range(len(labels)):
        for _ in range(3):
            amp, freq, ph = rng.uniform(skin_m / 2, skin_m, 3), rng.uniform(0.5, 4.0), rng.uniform(0, 2 * np.pi, 3)
            pos[:, k] += amp * np.sin(2 * np.pi * freq * t[:, None] + ph)
    pos += rng.normal(0, 0.0003, pos.shape)
    # random dropouts: about one 0.05-0.3 s gap per marker every 8 s (pelvis markers included)
    for k in range(len(labels)):
        for _ in range(rng.poisson(seconds / 8)):
            start = int(rng.integers(0, n))
            hidden[start:start + int(rng.uniform(0.05, 0.3) * rate_hz), k] = True
    pos[hidden] = np.nan
    rec = Recording(list(labels), pos.astype(np.float32), float(rate_hz), f"synthetic:running(seed={seed})",
                    meta={"up_axis": "+z"})
    return rec, truth


def from_spec(spec: str):
    """``synthetic:running[?seconds=S&rate=R&seed=N&clusters=1&swing=range_of_motion]`` -> Recording."""
    from urllib.parse import parse_qs

    kind, _, query = spec.partition(":")[2].partition("?")
    if kind != "running":
        raise ValueError(f"unknown synthetic take {kind!r} (synthetic:running)")
    q = {k: v[0] for k, v in parse_qs(query).items()}
    return running_take(float(q.get("seconds", 20)), float(q.get("rate", 200)), int(q.get("seed", 0)),
                        q.get("clusters", "0") not in ("0", ""), q.get("swing", "running"))[0]

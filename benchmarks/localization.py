"""Per-frame cost of the stages that run on every frame (the budget: localization <= 50 us).

    python benchmarks/localization.py
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np


sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from mocap_core.hip_interpolation import HIP_INDEX, HipInterpolator  # noqa: E402
from mocap_core.leg_hinge import LegHinge  # noqa: E402
from mocap_core.localization import Localizer  # noqa: E402
from mocap_core.pair_guard import PairGuard  # noqa: E402
from mocap_core.pose_memory import CAPACITY, PoseMemory  # noqa: E402
from mocap_core.profiles import LANDMARK_INDEX  # noqa: E402
from mocap_core.profiles import load_profile  # noqa: E402
from mocap_core.recordings import read_recording  # noqa: E402
from mocap_core.partial_means import PartialMeans  # noqa: E402
from mocap_core.segment_rebuild import SegmentRebuilder  # noqa: E402
from mocap_core.warmup import warm_up  # noqa: E402

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def per_call_us(fn, n, repeats=5):
    best = float("inf")
    for _ in range(repeats):
        t = time.perf_counter()
        for i in range(n):
            fn(i)
        best = min(best, (time.perf_counter() - t) / n * 1e6)
    return best


def main():
    warm_up()
    for file, profile in [("02_qualisys_walking_ezc3d_Qualisys.c3d", "qualisys_sports"),
                          ("08_cmu_135_02_karate_kata.c3d", "cmu41")]:
        rec = read_recording(DATA / file)
        prof = load_profile(profile)
        lmap = prof.resolve(rec.labels)
        lm = lmap.apply(rec.positions[:300])
        loc = Localizer(prof.body)
        hips = HipInterpolator()
        n = len(lm)
        print(f"{file} ({len(rec.labels)} markers), best of 5 passes over {n} frames, us per frame:")
        print(f"  profile -> landmarks       {per_call_us(lambda i: lmap.apply(rec.positions[i]), n):7.1f}")
        print(f"  hip interpolation          {per_call_us(lambda i: hips.fill(lm[i][HIP_INDEX]), n):7.1f}")
        guard, copy = PairGuard(), lm.copy()
        print(f"  pair guard                 {per_call_us(lambda i: guard.fill(copy[i], time_s=i / rec.rate_hz), n):7.1f}")
        print(f"  localization, one frame    {per_call_us(lambda i: loc.localize(lm[i]), n):7.1f}  (target <= 50)")
        batch = per_call_us(lambda i: loc.localize(lm), 1) / n
        print(f"  localization, batch of {n}  {batch:7.1f}")
    pose_memory_cost()
    rebuild_cost()
    leg_hinge_cost()
    partial_means_cost()


def rebuild_cost():
    """The segment rebuild: nothing lost, one elbow rebuilt and refined. On the sprint (59 markers) from the
    olecranon and the styloids; on karate (41) from the wrist bar and the forearm's marker, then rolled by the upper
    arm's (ROLL_FIRM_FROM)."""
    for file, profile, name in [("03_sprint_start_BTK_SprintMotion.trc", "btk_sprint", "sprint"),
                                ("08_cmu_135_02_karate_kata.c3d", "cmu41", "karate")]:
        _rebuild_cost(file, profile, name)


def _rebuild_cost(file, profile, name):
    rec = read_recording(DATA / file)
    lmap = load_profile(profile).resolve(rec.labels)
    lm, tracking = lmap.apply(rec.positions[:600]).astype(np.float64), lmap.tracking(rec.positions[:600])
    rebuilder = SegmentRebuilder(lmap.tracking_of)
    for f in range(300):  # learn the references and distances
        rebuilder.fill(lm[f].copy(), tracking[f], f / rec.rate_hz)
    lost = lm.copy()
    lost[:, [LANDMARK_INDEX["L_HLE"], LANDMARK_INDEX["L_HME"]]] = np.nan
    seen = per_call_us(lambda i: rebuilder.fill(lm[300 + i].copy(), tracking[300 + i], (300 + i) / rec.rate_hz), 300)
    elbow = per_call_us(lambda i: rebuilder.fill(lost[300 + i].copy(), tracking[300 + i], (300 + i) / rec.rate_hz),
                        300)
    print(f"segment rebuild ({name}), us per frame: nothing lost {seen:.1f}, one elbow rebuilt {elbow:.1f}")


def leg_hinge_cost():
    """The leg hinge on the Vicon take (53 markers): the legs seen (their shape taken), one leg's knee
    and ankle put from its shank marker, and one knee's roll settled (rebuilt from the wand and the ankle)."""
    rec = read_recording(DATA / "12_vicon_freeform_realgaps_nimble_nick_freeform_001.c3d")
    lmap = load_profile("vicon53").resolve(rec.labels)
    lm, tracking = lmap.apply(rec.positions[:600]).astype(np.float64), lmap.tracking(rec.positions[:600])
    tracking = np.ascontiguousarray(tracking)  # (as a live frame's)
    hinge = LegHinge(lmap.tracking_of)
    for f in range(300):
        hinge.fill(lm[f].copy(), tracking[f])
    lost = lm.copy()
    lost[:, [LANDMARK_INDEX[f"R_{name}"] for name in ("FLE", "FME", "FAL", "TAM")]] = np.nan
    seen = per_call_us(lambda i: hinge.fill(lm[300 + i].copy(), tracking[300 + i]), 300)
    filled = per_call_us(lambda i: hinge.fill(lost[300 + i].copy(), tracking[300 + i]), 300)
    # the right knee as the rebuild puts it from the wand and the ankle alone: its roll settled from the hip
    rebuilt = np.zeros(lm.shape[1], bool)
    rebuilt[[LANDMARK_INDEX["R_FLE"], LANDMARK_INDEX["R_FME"]]] = True
    rolled = per_call_us(lambda i: hinge.fill(lm[300 + i].copy(), tracking[300 + i], filled=rebuilt), 300)
    print(f"leg hinge (Vicon), us per frame: legs seen {seen:.1f}, one leg's knee and ankle put {filled:.1f}, "
          f"one knee's roll settled {rolled:.1f}")


def pose_memory_cost():
    """The pose memory full (CAPACITY poses a leg) and one knee and ankle recalled in every frame, the
    ankle turned with the toe markers' line (the profile's tracking markers), the knee's poses found by the
    toe's velocity too (the frames' times)."""
    rec = read_recording(DATA / "13_qualisys_dance_walk_mocaptoolbox_mcdemodata.mat", "dance1")
    lmap = load_profile("dance28").resolve(rec.labels)
    lm, tracking = lmap.apply(rec.positions), lmap.tracking(rec.positions)
    memory = PoseMemory(lmap.present(), lmap.tracking_of)
    rng = np.random.default_rng(0)
    for f in range(CAPACITY + 100):  # the take's poses, jittered so that every one is kept
        frame = lm[f % len(lm)].copy()
        frame[LANDMARK_INDEX["L_FM2"]] += rng.normal(0, 0.01, 3)
        memory.fill(frame, tracking[f % len(lm)], f / rec.rate_hz)
    lost = lm.copy()
    lost[:, [LANDMARK_INDEX["L_FLE"], LANDMARK_INDEX["L_FAL"]]] = np.nan
    n, t0 = 300, (CAPACITY + 100) / rec.rate_hz
    seen = per_call_us(lambda i: memory.fill(lm[i].copy(), tracking[i], t0 + i / rec.rate_hz), n)
    recalled = per_call_us(lambda i: memory.fill(lost[i].copy(), tracking[i], t0 + i / rec.rate_hz), n)
    print(f"pose memory ({CAPACITY} poses a leg), us per frame: legs seen {seen:.1f}, "
          f"one leg's knee and ankle recalled {recalled:.1f}")


def partial_means_cost():
    """The partial means on the Vicon take (its ten mean landmarks): every marker seen, and one shoulder marker
    lost in every frame (its acromion kept from the other and turned with the 4 markers nearest it)."""
    rec = read_recording(DATA / "12_vicon_freeform_realgaps_nimble_nick_freeform_001.c3d")
    lmap = load_profile("vicon53").resolve(rec.labels)
    whole = np.isfinite(rec.positions).all(axis=2)
    frames = np.flatnonzero(whole[:, lmap.idx[LANDMARK_INDEX["L_SAE"]][:2]].all(axis=1))[:300]
    means = PartialMeans(lmap)
    back = [label.split(":")[-1] for label in rec.labels].index("LBSH")
    lost = rec.positions.copy()
    lost[:, back] = np.nan
    seen = per_call_us(lambda i: means.fill(lmap.apply(rec.positions[frames[i]]), markers=rec.positions[frames[i]]),
                       len(frames))
    kept = per_call_us(lambda i: means.fill(lmap.apply(lost[frames[i]]), markers=lost[frames[i]]), len(frames))
    print(f"partial means (Vicon), us per frame: all seen {seen:.1f}, one shoulder marker lost {kept:.1f} "
          "(the map's own gather included)")


if __name__ == "__main__":
    main()

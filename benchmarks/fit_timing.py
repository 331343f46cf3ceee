"""Per-frame cost of the whole solve, markers in -> skeleton out: the rigid-skeleton fit beside the thesis's method
and the studio options, with every marker seen and in the thesis's worst case (from 1 s only the pelvis, head,
hand and toe markers). Each frame's fastest of 3 passes (every pass does the same work, so that is its cost
without the pauses of a shared machine); the fit's target is 0.25 ms mean and 1 ms max. The first frame is shown
apart: there the fit starts from the subject's rest pose (about a hundred iterations, once a session).

    python benchmarks/fit_timing.py
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from mocap_core.fit.calibration import calibrate  # noqa: E402
from mocap_core.fit.compare import cases  # noqa: E402
from mocap_core.fit.fitter import SkeletonFitter  # noqa: E402
from mocap_core.pipeline import SkeletonPipeline  # noqa: E402
from mocap_core.profiles import load_profile  # noqa: E402
from mocap_core.recordings import read_recording  # noqa: E402
from mocap_core.warmup import warm_up  # noqa: E402

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
TAKES = [("03_sprint_start_BTK_SprintMotion.trc", "btk_sprint"), ("08_cmu_135_02_karate_kata.c3d", "cmu41"),
         ("12_vicon_freeform_realgaps_nimble_nick_freeform_001.c3d", "vicon53")]
PASSES = 3
FRAMES = 1200


def per_frame_ms(make, markers) -> np.ndarray:
    """Each frame's fastest of PASSES passes, each pass with a fresh solver from ``make()``."""
    best = np.full(len(markers), np.inf)
    for _ in range(PASSES):
        solve = make()
        for f in range(len(markers)):
            t = time.perf_counter()
            solve(markers[f])
            best[f] = min(best[f], time.perf_counter() - t)
    return best * 1000


def main() -> None:
    warm_up()
    for file, profile_name in TAKES:
        rec = read_recording(DATA / file).slice(0, FRAMES)
        profile = load_profile(profile_name)
        worst = next(c for c in cases(profile, rec.labels, int(rec.rate_hz)) if c.name == "worst")
        cols = list(profile.columns(rec.labels))
        inputs = {"every marker": rec.positions.astype(float)}
        inputs["worst case"] = inputs["every marker"].copy()
        inputs["worst case"][worst.start:, [cols.index(x) for x in worst.hidden]] = np.nan
        print(f"{file} ({len(rec.labels)} markers, {len(rec.positions)} frames at {rec.rate_hz:g} Hz), ms per frame, "
              f"each frame's fastest of {PASSES} passes:")
        for name, markers in inputs.items():
            subject = calibrate(markers, rec.labels, profile, rec.rate_hz)

            def fit():
                return SkeletonFitter(subject, cols, rate_hz=rec.rate_hz).fit

            def pipeline(beyond):
                def make():
                    pipe = SkeletonPipeline(profile, rec.labels, options="studio" if beyond else "thesis", rate_hz=rec.rate_hz)
                    return lambda x: pipe.solve_landmarks(pipe.landmarks(x[None]), 0,
                                                          pipe.landmark_map.tracking(x[None]), x[None])
                return make

            times = {"thesis's method": per_frame_ms(pipeline(False), markers),
                     "studio options": per_frame_ms(pipeline(True), markers), "rigid fit": per_frame_ms(fit, markers)}
            base = times["thesis's method"][1:].mean()
            for method, t in times.items():  # the first frame apart: the fit's start from the rest pose
                print(f"  {name:13s} {method:16s} mean {t[1:].mean():6.3f}  median {np.median(t[1:]):6.3f}  max "
                      f"{t[1:].max():6.3f}  first frame {t[0]:6.3f}  ({t[1:].mean() / base:4.2f}x the thesis's mean)")


if __name__ == "__main__":
    main()

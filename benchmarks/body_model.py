"""Per-frame cost of the body model in the IK stage (issue 9's budget: a full-body frame within the IK
budget, 0.3 ms mean and 1 ms max).

CMU karate (43 s at 120 Hz): the left elbow's marker is hidden from 20 s. Before the gap the model
learns two poses a frame (its own arm's and the other's, mirrored); in the gap it predicts every frame
and is refitted every body_model.REFIT_SAMPLES new poses. Prints the left arm filler's time per frame
with the studio options (gapfill.BEYOND_THESIS) with and without the model, and one refit.

    python benchmarks/body_model.py
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from mocap_core.gapfill import BEYOND_THESIS, LimbFiller  # noqa: E402
from mocap_core.hip_interpolation import HipInterpolator  # noqa: E402
from mocap_core.localization import Localizer  # noqa: E402
from mocap_core.profiles import LANDMARK_INDEX, load_profile  # noqa: E402
from mocap_core.recordings import read_recording  # noqa: E402
from mocap_core.warmup import warm_up  # noqa: E402

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def main() -> None:
    path = DATA / "08_cmu_135_02_karate_kata.c3d"
    if not path.exists():
        raise SystemExit(f"{path} is missing: the benchmark reads the real recording from ../shared/data")
    warm_up()
    rec = read_recording(path)
    prof = load_profile("cmu41")
    lm, _ = HipInterpolator().fill_landmarks(prof.resolve(rec.labels).apply(rec.positions))
    start = int(20 * rec.rate_hz)
    lm[start:, LANDMARK_INDEX["L_HLE"]] = np.nan
    loc = Localizer(prof.body).localize(lm)
    for model in (False, True):
        filler = LimbFiller("left_arm", **(BEYOND_THESIS | {"body_model": model}))
        pos, frames, status = loc.positions.copy(), loc.frames.copy(), loc.status.copy()
        took = np.empty(len(pos))
        for f in range(len(pos)):
            t = time.perf_counter()
            filler.fill(pos[f], frames[f], status[f], f / rec.rate_hz)
            took[f] = (time.perf_counter() - t) * 1e6
        gap, before = took[start:], took[:start]
        print(f"left arm, elbow lost from 20 s, body model {'on ' if model else 'off'}: per frame before the gap "
              f"median {np.median(before):.0f} us, p99 {np.percentile(before, 99):.0f} us; in the gap median "
              f"{np.median(gap):.0f} us, p99 {np.percentile(gap, 99):.0f} us, max {gap.max():.0f} us")
        if model:
            refits = []
            for _ in range(20):
                t = time.perf_counter()
                filler.body_model._fit()
                refits.append((time.perf_counter() - t) * 1e6)
            print(f"  poses learned: {int(filler.body_model.n[0])}; one refit ({len(filler.body_model.mu)} features): "
                  f"median {np.median(refits):.0f} us")


if __name__ == "__main__":
    main()

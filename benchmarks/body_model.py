"""Per-frame cost of the body model in the IK stage (the budget: a full-body frame within the IK
budget, 0.3 ms mean and 1 ms max).

CMU karate (43 s at 120 Hz): the left elbow's marker is hidden from 20 s. Before the gap the model
learns two poses a frame (its own arm's and the other's, mirrored); in the gap it predicts every frame
and is refitted every body_model.REFIT_SAMPLES new poses. Prints the left arm filler's time per frame
with the studio options (fill_options.STUDIO) with and without the model, and one refit.

    python benchmarks/body_model.py
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from karate_elbow import karate_elbow_lost  # noqa: E402
from mocap_core.body_model import BodyModelSteer  # noqa: E402
from mocap_core.fill_options import STUDIO  # noqa: E402
from mocap_core.gapfill import LimbFiller  # noqa: E402


def main() -> None:
    loc, start, rate_hz = karate_elbow_lost()
    for model in (False, True):
        filler = LimbFiller("left_arm", options=STUDIO.model_copy(update={"body_model": model}))
        pos, frames, status = loc.positions.copy(), loc.frames.copy(), loc.status.copy()
        took = np.empty(len(pos))
        for f in range(len(pos)):
            t = time.perf_counter()
            filler.fill(pos[f], frames[f], status[f], f / rate_hz)
            took[f] = (time.perf_counter() - t) * 1e6
        gap, before = took[start:], took[:start]
        print(f"left arm, elbow lost from 20 s, body model {'on ' if model else 'off'}: per frame before the gap "
              f"median {np.median(before):.0f} us, p99 {np.percentile(before, 99):.0f} us; in the gap median "
              f"{np.median(gap):.0f} us, p99 {np.percentile(gap, 99):.0f} us, max {gap.max():.0f} us")
        if model:
            refits, body_model = [], filler.get(BodyModelSteer).model
            for _ in range(20):
                t = time.perf_counter()
                body_model._fit()
                refits.append((time.perf_counter() - t) * 1e6)
            print(f"  poses learned: {int(body_model.n[0])}; one refit ({len(body_model.mu)} features): "
                  f"median {np.median(refits):.0f} us")


if __name__ == "__main__":
    main()

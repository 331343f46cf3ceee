"""Per-frame cost of the limb memory in the IK stage (the budget: a full-body frame within the IK
budget, 0.3 ms mean and 1 ms max).

CMU karate (43 s at 120 Hz): the left elbow's marker is hidden from 20 s, so by then both arms'
memories are full of poses and every frame of the gap recalls the lost elbow from them (a search of
up to 2 x 4000 poses). Prints the left arm filler's time per frame with and without the memory.

    python benchmarks/limb_memory.py
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from karate_elbow import karate_elbow_lost  # noqa: E402
from mocap_core.fill_options import FillOptions  # noqa: E402
from mocap_core.gapfill import LimbFiller  # noqa: E402
from mocap_core.limb_memory import LimbMemory  # noqa: E402


def main() -> None:
    loc, start, _ = karate_elbow_lost()
    for memory in (False, True):
        filler = LimbFiller("left_arm", options=FillOptions(swivel=True, segment_carry=True, limb_memory=memory,
                                                                reacquire_step_m=0.01))
        pos, frames, status = loc.positions.copy(), loc.frames.copy(), loc.status.copy()
        took = np.empty(len(pos))
        for f in range(len(pos)):
            t = time.perf_counter()
            filler.fill(pos[f], frames[f], status[f])
            took[f] = (time.perf_counter() - t) * 1e6
        gap = took[start:]
        kept = "" if not memory else f", poses remembered (own, mirrored): {tuple(filler.get(LimbMemory).state[2, :, 0])}"
        print(f"left arm, elbow lost from 20 s, limb memory {'on ' if memory else 'off'}: per frame in the gap "
              f"median {np.median(gap):.0f} us, p99 {np.percentile(gap, 99):.0f} us, max {gap.max():.0f} us; "
              f"before the gap median {np.median(took[:start]):.0f} us{kept}")


if __name__ == "__main__":
    main()

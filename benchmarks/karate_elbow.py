"""The take both IK-stage benchmarks time: CMU karate (43 s at 120 Hz), localized, with the left elbow's
marker hidden from 20 s on (benchmarks/limb_memory.py, benchmarks/body_model.py)."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from mocap_core.hip_interpolation import HipInterpolator  # noqa: E402
from mocap_core.localization import Localized, Localizer  # noqa: E402
from mocap_core.profiles import LANDMARK_INDEX, load_profile  # noqa: E402
from mocap_core.recordings import read_recording  # noqa: E402
from mocap_core.warmup import warm_up  # noqa: E402

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
LOST_FROM_S = 20.0


def karate_elbow_lost() -> tuple[Localized, int, float]:
    """(the localized take, the first frame without the elbow, the take's rate); kernels warmed up."""
    path = DATA / "08_cmu_135_02_karate_kata.c3d"
    if not path.exists():
        raise SystemExit(f"{path} is missing: the benchmark reads the real recording from ../shared/data")
    warm_up()
    rec = read_recording(path)
    prof = load_profile("cmu41")
    lm, _ = HipInterpolator().fill_landmarks(prof.resolve(rec.labels).apply(rec.positions))
    start = int(LOST_FROM_S * rec.rate_hz)
    lm[start:, LANDMARK_INDEX["L_HLE"]] = np.nan
    return Localizer(prof.body).localize(lm), start, rec.rate_hz

"""Soak (not run in CI): the full graph fed by the QTM emulator at 1000 Hz for 10 minutes.
Reports drops, throughput and each node's RSS at the start and the end (memory must stay flat).

    python benchmarks/soak.py [--minutes 10] [--rate 1000] [--layout one|processes|two]

--layout: the solving nodes in one container (the default: launch/qtm_studio_composed.yaml, the
layout for 1000 Hz), one process per node (launch/qtm_studio.yaml; about two cores' worth at
1000 Hz), or two containers.
"""
from __future__ import annotations

import argparse
import signal
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import psutil

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from mocap_cli.launcher import Launcher  # noqa: E402
from mocap_cli.measure import LAYOUTS, capture_frames_missing, frame_log_figures, live_graph, usage  # noqa: E402
from mocap_cli.qtm_sim import start_emulator  # noqa: E402

TAKE = REPO.parent / "shared" / "data" / "08_cmu_135_02_karate_kata.c3d"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--minutes", type=float, default=10)
    ap.add_argument("--rate", type=float, default=1000)
    ap.add_argument("--layout", choices=sorted(LAYOUTS), default="one",
                    help="where the solving nodes run (mocap_cli/measure.py LAYOUTS)")
    args = ap.parse_args()
    sim, port = start_emulator(str(TAKE), "--rate", str(args.rate), "--loop", cwd=str(REPO))
    out = Path(tempfile.mkdtemp()) / "solved.csv"
    lf = live_graph(port, "cmu41", out, "soak", layout=args.layout)
    seconds = args.minutes * 60
    samples = {}

    def sample():
        time.sleep(15)
        samples["start"] = usage("soak"), time.time()
        time.sleep(max(0, seconds - 30))
        samples["end"] = usage("soak"), time.time()

    threading.Thread(target=sample, daemon=True).start()
    try:
        Launcher(lf).run(duration_s=seconds)
    finally:
        sim.send_signal(signal.SIGINT)
        sim.wait()
    lat, gaps = frame_log_figures(out)
    received = np.loadtxt(out, delimiter=",", skiprows=1, usecols=-1, ndmin=1) / 1e9  # (wall clock, s)
    print(f"{len(lat)} skeletons in {seconds:.0f} s; QTM at {args.rate:.0f} Hz; sequence gaps at the sink: {gaps}; "
          f"capture frames missing at the sink (lost anywhere, QTM's stream included): {capture_frames_missing(out)}")
    if "end" not in samples:
        return
    (start, t0), (end, t1) = samples["start"], samples["end"]
    # what came through between the two samples: a graph that falls behind slows QTM's TCP stream (nothing is
    # missing then, but fewer frames a second come through)
    frames_per_s = int(((received >= t0) & (received < t1)).sum()) / (t1 - t0)
    print(f"between the samples: {frames_per_s:.0f} skeletons a second ({100 * frames_per_s / args.rate:.0f} % of "
          f"QTM's rate)")
    print(f"{'process':<12} {'RSS start MB':>13} {'RSS end MB':>11} {'PSS end MB':>11} {'CPU %':>6} "
          f"{'CPU us/frame':>13}  (CPU of one core between the two samples; per frame that came through)")
    total = 0.0
    for node, (rss0, _, cpu0) in start.items():
        rss1, pss1, cpu1 = end.get(node, (float("nan"),) * 3)
        share = (cpu1 - cpu0) / (t1 - t0)
        total += share
        print(f"{node:<12} {rss0:>13.1f} {rss1:>11.1f} {pss1:>11.1f} {100 * share:>6.0f} "
              f"{1e6 * share / frames_per_s:>13.0f}")
    print(f"graph memory at the end: {sum(v[1] for v in end.values()):.0f} MB (PSS summed; RSS summed, which counts "
          f"each shared page once per process: {sum(v[0] for v in end.values()):.0f} MB)")
    print(f"whole graph: {1e3 * total / frames_per_s:.1f} ms of CPU per frame, so {args.rate:.0f} Hz needs "
          f"{total / frames_per_s * args.rate:.1f} cores at this cost (this machine: {psutil.cpu_count()})")


if __name__ == "__main__":
    main()

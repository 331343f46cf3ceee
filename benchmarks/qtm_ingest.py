"""QTM emulator -> qtm_ingest -> subscriber at 1000 Hz: drops and latency.

    python benchmarks/qtm_ingest.py [--seconds 60] [--rate 1000]

Latency is from the moment the ingest node received the frame from QTM (the header's entry time)
to the subscriber; drops are gaps in the publisher's sequence numbers plus frames the emulator
sent that never arrived.
"""
from __future__ import annotations

import argparse
import os
import signal
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from mocap_cli.launch_file import LaunchFile  # noqa: E402
from mocap_cli.launcher import Launcher  # noqa: E402
from mocap_cli.measure import frame_log_figures  # noqa: E402
from mocap_cli.qtm_sim import start_emulator  # noqa: E402

TAKE = REPO.parent / "shared" / "data" / "08_cmu_135_02_karate_kata.c3d"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=60)
    ap.add_argument("--rate", type=float, default=1000)
    args = ap.parse_args()
    sim, port = start_emulator(str(TAKE), "--rate", str(args.rate), "--loop", cwd=str(REPO))
    out = Path(tempfile.mkdtemp()) / "raw.csv"
    lf = LaunchFile.model_validate({"name": f"bench-qtm-{os.getpid()}", "nodes": [
        {"id": "qtm", "kind": "qtm_ingest", "params": {"port": port}},
        {"id": "sink", "kind": "frame_log", "params": {"path": str(out)}, "remaps": {"in": "markers/raw"}}]})
    try:
        Launcher(lf).run(duration_s=args.seconds)
    finally:
        sim.send_signal(signal.SIGINT)
        sim.wait()
    lat_ms, gaps = frame_log_figures(out)
    lat = lat_ms * 1000
    print(f"{len(lat)} frames in {args.seconds:.0f} s at {args.rate:.0f} Hz requested "
          f"({len(lat) / args.seconds:.0f} Hz received over the run, including start-up)")
    print(f"dropped between ingest and subscriber (sequence gaps): {gaps} of {len(lat) + gaps}")
    print(f"latency ingest -> subscriber: p50 {np.percentile(lat, 50):.0f} us, p99 {np.percentile(lat, 99):.0f} us, "
          f"max {lat.max():.0f} us")


if __name__ == "__main__":
    main()

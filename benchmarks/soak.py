"""Soak (issue 10; not run in CI): the full graph fed by the QTM emulator at 1000 Hz for 10 minutes.
Reports drops, throughput and each node's RSS at the start and the end (memory must stay flat).

    python benchmarks/soak.py [--minutes 10] [--rate 1000]
"""
from __future__ import annotations

import argparse
import json
import signal
import sys
import tempfile
import threading
import time
from pathlib import Path

import psutil

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from mocap_cli.graph_registry import registry_path  # noqa: E402
from mocap_cli.launcher import Launcher  # noqa: E402
from mocap_cli.measure import frame_log_figures, live_graph  # noqa: E402
from mocap_cli.qtm_sim import start_emulator  # noqa: E402

TAKE = REPO.parent / "shared" / "data" / "08_cmu_135_02_karate_kata.c3d"


def rss_mb(graph: str) -> dict[str, float]:
    data = json.loads(registry_path(graph).read_text())
    out = {}
    for n in data["nodes"]:
        try:
            out[n["id"]] = psutil.Process(n["pid"]).memory_info().rss / 2**20
        except (psutil.Error, TypeError):
            out[n["id"]] = float("nan")
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--minutes", type=float, default=10)
    ap.add_argument("--rate", type=float, default=1000)
    args = ap.parse_args()
    sim, port = start_emulator(str(TAKE), "--rate", str(args.rate), "--loop", cwd=str(REPO))
    out = Path(tempfile.mkdtemp()) / "solved.csv"
    lf = live_graph(port, "cmu41", out, "soak")
    seconds = args.minutes * 60
    samples = {}

    def sample():
        time.sleep(15)
        samples["start"] = rss_mb("soak")
        time.sleep(max(0, seconds - 30))
        samples["end"] = rss_mb("soak")

    threading.Thread(target=sample, daemon=True).start()
    try:
        Launcher(lf).run(duration_s=seconds)
    finally:
        sim.send_signal(signal.SIGINT)
        sim.wait()
    lat, gaps = frame_log_figures(out)
    print(f"{len(lat)} skeletons in {seconds:.0f} s ({len(lat) / seconds:.0f} Hz; QTM at {args.rate:.0f} Hz); "
          f"sequence gaps at the sink: {gaps}")
    print(f"{'node':<12} {'RSS start MB':>13} {'RSS end MB':>11}")
    for node in samples.get("start", {}):
        print(f"{node:<12} {samples['start'][node]:>13.1f} {samples.get('end', {}).get(node, float('nan')):>11.1f}")


if __name__ == "__main__":
    main()

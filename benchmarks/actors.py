"""How many actors one machine solves live (not run in CI): launch/qtm_actors.yaml fed by the QTM emulator with
1, 2, 3 ... copies of the karate take 3 m apart (labels actor1:..., actor2:...), at 120 Hz, for each layout: the
solving nodes of an actor composed in one process (the file's layout) and one process per node. Prints, per run, the
worst actor's end-to-end latency (entering qtm_ingest to leaving retarget), how much it grew from the run's first
third to its last (a graph that keeps up stays near 1) and, over all actors, the frames dropped and the capture
frames missing; the one-actor run of a layout is the baseline of its ratios.

    python benchmarks/actors.py [--max-actors 4] [--seconds 20] [--rate 120] [--layouts composed,processes]

Goal: the largest number of actors with 0 dropped, 0 missing and a latency that does not grow, per layout.
"""
from __future__ import annotations

import argparse
import signal
import sys
import tempfile
import threading
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from mocap_cli.launch_file import NodeEntry, load_launch_file  # noqa: E402
from mocap_cli.launcher import Launcher  # noqa: E402
from mocap_cli.measure import capture_frames_missing, frame_log_figures  # noqa: E402
from mocap_cli.qtm_sim import start_emulator  # noqa: E402
from mocap_core.recordings import crowd, read_recording, write_c3d  # noqa: E402

TAKE = REPO.parent / "shared" / "data" / "08_cmu_135_02_karate_kata.c3d"
# Median latency over the run's last third this many times its first third: the queues grow, the machine is not
# keeping up (a short run shows no drops yet; a long one would). Runs that keep up stay within 0.8-1.05.
FALLING_BEHIND = 1.25


def run(actors: int, layout: str, seconds: float, rate: float, work: Path) -> dict:
    names = [f"actor{i + 1}" for i in range(actors)]
    take = work / f"crowd{actors}.c3d"
    if not take.exists():
        write_c3d(crowd(read_recording(TAKE).slice(0, int(30 * 120)), names), take)
    sim, port = start_emulator(str(take), "--rate", str(rate), "--loop")
    logs = work / f"{layout}{actors}"
    try:
        lf = load_launch_file(REPO / "launch" / "qtm_actors.yaml", [f"qtm.port={port}", f"actors={names}"])
        lf.nodes = [n for n in lf.nodes if n.kind != "vmc_output"]
        if layout == "processes":
            for n in lf.nodes:
                n.container = None
        lf.nodes.append(NodeEntry(id="log", kind="frame_log", per_actor=True, params={"path": f"{logs}/{{actor}}.csv"},
                                  remaps={"in": "skeleton/solved"}))
        lf.name = f"bench-actors-{layout}-{actors}"

        def stop_later():  # the seconds count from the graph's start, after every process has loaded
            threading.Timer(seconds, lambda: setattr(launcher, "stop_requested", True)).start()

        launcher = Launcher(lf, on_ready=stop_later)
        launcher.run()
    finally:
        sim.send_signal(signal.SIGINT)
        sim.wait()
    p50, p99, growth, dropped, missing = [], [], [], 0, 0
    for name in names:
        lat, drops = frame_log_figures(logs / f"{name}.csv")
        if len(lat) < 30:
            raise SystemExit(f"{name}: only {len(lat)} skeletons in {seconds:.0f} s")
        lat = lat[len(lat) // 10:]  # the start-up left out
        p50.append(np.percentile(lat, 50))
        p99.append(np.percentile(lat, 99))
        third = len(lat) // 3  # a graph that keeps up has the same latency at the end as at the start
        growth.append(np.median(lat[-third:]) / np.median(lat[:third]))
        dropped += drops
        missing += capture_frames_missing(logs / f"{name}.csv")
    return {"p50": max(p50), "p99": max(p99), "growth": max(growth), "dropped": dropped, "missing": missing}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--max-actors", type=int, default=4)
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--rate", type=float, default=120.0)
    ap.add_argument("--layouts", default="composed,processes", help="of: composed, processes")
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="mocap-actors-"))
    print(f"QTM emulator at {args.rate:.0f} Hz, {args.seconds:.0f} s a run; latency ms of the worst actor")
    print("| layout | actors | p50 | p99 | p50 / 1 actor | p99 / 1 actor | latency end / start | dropped | missing |")
    print("|---|---|---|---|---|---|---|---|---|")
    kept = {}
    for layout in args.layouts.split(","):
        base, kept[layout] = None, 0
        for n in range(1, args.max_actors + 1):
            r = run(n, layout, args.seconds, args.rate, work)
            base = base or r
            print(f"| {layout} | {n} | {r['p50']:.2f} | {r['p99']:.2f} | {r['p50'] / base['p50']:.2f} | "
                  f"{r['p99'] / base['p99']:.2f} | {r['growth']:.2f} | {r['dropped']} | {r['missing']} |", flush=True)
            if r["dropped"] or r["missing"] or r["growth"] > FALLING_BEHIND:
                break
            kept[layout] = n
    for layout, n in kept.items():
        print(f"{layout}: {n} actors at {args.rate:.0f} Hz with 0 dropped, 0 missing and a steady latency"
              + (" (the most tried)" if n == args.max_actors else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Kill benchmark (not run in CI): the studio graph, one process per node, fed by the QTM emulator at 120 Hz,
with a recorder and a BVH writer; every few seconds one process is SIGKILLed (the recorder, the BVH writer, then
each solving node) and the launcher restarts it. Prints, per kill, the skeleton frames lost at the sink and how
long the gap lasted, and what the recorder's bag and the BVH writer's file kept of the frames before the kill.

    python benchmarks/kill_recovery.py [--every 4] [--rate 120]

Goal: every frame recorded before a kill kept; no more missing than the restart's own gap (under 0.5 s).
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import signal
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from mocap_cli.graph_registry import registry_path  # noqa: E402
from mocap_cli.launch_file import NodeEntry  # noqa: E402
from mocap_cli.launcher import Launcher  # noqa: E402
from mocap_cli.measure import live_graph  # noqa: E402
from mocap_cli.qtm_sim import start_emulator  # noqa: E402

TAKE = REPO.parent / "shared" / "data" / "08_cmu_135_02_karate_kata.c3d"
TARGETS = ("recorder", "bvh", "hips", "localize", "torso", "left_arm", "retarget")
GRAPH = "kill"


def killer(every_s: float, kills: list, log: Path) -> None:
    while not log.exists() or log.stat().st_size < 40_000:  # the graph streaming for a few seconds
        time.sleep(0.2)
    for node in TARGETS:
        pid = next(n["pid"] for n in json.loads(registry_path(GRAPH).read_text())["nodes"] if n["id"] == node)
        kills.append((node, time.time()))
        os.kill(pid, signal.SIGKILL)
        time.sleep(every_s)


def stop_after_kills(launcher: Launcher, kills: list, every_s: float) -> None:
    while len(kills) < len(TARGETS):
        time.sleep(0.2)
    time.sleep(every_s)
    launcher.stop_requested = True


def logged(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(capture frame, wall time of arrival) per skeleton the sink logged."""
    with open(path) as f:
        rows = list(csv.DictReader(f))
    return np.array([int(r["frame"]) for r in rows]), np.array([int(r["received_ns"]) / 1e9 for r in rows])


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--every", type=float, default=4.0, help="seconds between kills")
    ap.add_argument("--rate", type=float, default=120.0)
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="mocap-kill-"))
    sim, port = start_emulator(str(TAKE), "--rate", str(args.rate), "--loop", cwd=str(REPO))
    out, bag, bvh = work / "solved.csv", work / "take.mcap", work / "take.bvh"
    lf = live_graph(port, "cmu41", out, GRAPH, layout="processes")
    lf.nodes.append(NodeEntry(id="recorder", kind="recorder",
                              params={"path": str(bag), "topics": ["markers/raw", "skeleton/solved"]}))
    lf.nodes.append(NodeEntry(id="bvh", kind="bvh_writer", params={"path": str(bvh), "rate_hz": args.rate}))
    kills: list = []
    launcher = Launcher(lf)
    threading.Thread(target=killer, args=(args.every, kills, out), daemon=True).start()
    threading.Thread(target=stop_after_kills, args=(launcher, kills, args.every), daemon=True).start()
    try:
        launcher.run()
    finally:
        sim.send_signal(signal.SIGINT)
        sim.wait()
    report(out, bag, bvh, kills, args.rate)


def report(out: Path, bag: Path, bvh: Path, kills: list, rate: float) -> None:
    from messages import decode
    from nodes.bags import read_bag

    frames, arrived = logged(out)
    print(f"{'killed':<10} {'skeleton frames lost':>21} {'longest gap s':>14}")
    ends = [t for _, t in kills[1:]] + [arrived[-1]]
    for (node, t), end in zip(kills, ends):
        window = (arrived >= t - 0.5) & (arrived < end)
        steps = np.diff(frames[window])
        steps = steps[steps > 0]
        lost = int((steps - 1).sum()) if len(steps) else 0
        gap = float((steps.max() - 1) / rate) if len(steps) else float("nan")
        print(f"{node:<10} {lost:>21} {gap:>14.2f}")
    kill_t = dict(kills)
    raw = [decode(m.data, m.topic) for m in read_bag(bag, ["markers/raw"])]
    before = [m.header.frame for m in raw if m.header.entry_time_ns / 1e9 < kill_t["recorder"] - 0.2]
    sent_before = frames[arrived < kill_t["recorder"] - 0.2]
    print(f"recorder: the bag (its pieces: {len(list(bag.parent.glob('take*.mcap')))}) holds {len(raw)} marker frames; "
          f"{len(before)} from before the kill, of {len(set(sent_before))} skeletons solved before it")
    pieces = sorted(bvh.parent.glob("take*.bvh"), key=lambda p: (len(p.suffixes), p.name))  # take, take.1, ...
    counts = []
    for p in pieces:
        text = p.read_text().split("MOTION", 1)[1]
        counts.append(int(text.split("Frames:")[1].split()[0]))
    solved_before = int((arrived < kill_t["bvh"]).sum())
    print(f"BVH: pieces {[p.name for p in pieces]} with {counts} frames; the first holds {counts[0]} of the "
          f"{solved_before} skeletons solved before its kill (at most a second's worth may be lost)")


if __name__ == "__main__":
    main()

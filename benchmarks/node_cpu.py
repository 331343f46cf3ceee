"""Where a frame's CPU goes, per node kind (not run in CI): the studio graph, one process per node, fed by the QTM
emulator; each node's CPU a frame split into the runtime's own loop (receive, decode, statistics, encode, send; its
publishing, encoding and sending, also shown apart) and the node's algorithm (its handler, publishing excluded), with
MOCAP_CPU_SPLIT=1; the graph's memory; and, in the same run, a bare pyzmq relay chain's CPU a frame per process
(receive and send the bytes, nothing else).

    python benchmarks/node_cpu.py [--rate 500] [--seconds 60]

Targets (issue: a lean frame path): the runtime's own CPU a frame at most 100 us per node; the graph's memory at
most 1 GB.
"""
from __future__ import annotations

import argparse
import collections
import json
import os
import resource
import signal
import sys
import tempfile
import threading
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from mocap_cli.bare_chain import bare_chain  # noqa: E402
from mocap_cli.graph_registry import registry_path  # noqa: E402
from mocap_cli.launcher import Launcher  # noqa: E402
from mocap_cli.measure import live_graph, usage  # noqa: E402
from mocap_cli.qtm_sim import start_emulator  # noqa: E402
from mocap_cli.topic_tools import collect_heartbeats  # noqa: E402

TAKE = REPO.parent / "shared" / "data" / "08_cmu_135_02_karate_kata.c3d"
HOPS = 5


def bare_relay_cpu_us(rate: float, seconds: float) -> float:
    """CPU a frame of one process of a bare pyzmq chain (the source, HOPS relays), from their rusage."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    frames = int(rate * seconds)
    bare_chain(HOPS, frames, rate)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    return 1e6 * cpu / frames / (HOPS + 1)


def frames_of(hb) -> int:
    """The frames a node handled: what it received on its busiest input (retarget reads five messages a frame), or
    for a source what it published."""
    return max(hb.received.values(), default=0) or max(hb.published.values(), default=0)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rate", type=float, default=500)
    ap.add_argument("--seconds", type=float, default=60)
    args = ap.parse_args()
    bare_us = bare_relay_cpu_us(args.rate, 20)
    os.environ["MOCAP_CPU_SPLIT"] = "1"
    sim, port = start_emulator(str(TAKE), "--rate", str(args.rate), "--loop", cwd=str(REPO))
    out = Path(tempfile.mkdtemp()) / "solved.csv"
    lf = live_graph(port, "cmu41", out, "nodecpu")
    samples = {}

    def beats():
        return collect_heartbeats(json.loads(registry_path("nodecpu").read_text()), 1.2)

    def sample():
        time.sleep(15)
        samples["start"] = beats()
        time.sleep(max(0, args.seconds - 30))
        samples["end"] = beats()
        samples["memory"] = usage("nodecpu")

    threading.Thread(target=sample, daemon=True).start()
    try:
        Launcher(lf).run(duration_s=args.seconds)
    finally:
        sim.send_signal(signal.SIGINT)
        sim.wait()
    if "memory" not in samples:
        sys.exit("the graph stopped before the second sample")
    by_kind = collections.defaultdict(list)
    for node, end in samples["end"].items():
        start = samples["start"].get(node)
        frames = frames_of(end) - frames_of(start) if start else 0
        if frames <= 0:
            continue
        cpu = end.cpu.process_s - start.cpu.process_s
        handlers = end.cpu.handlers_s - start.cpu.handlers_s
        publishing = end.cpu.publishing_s - start.cpu.publishing_s
        algorithm = handlers - publishing
        by_kind[end.kind].append((1e6 * (cpu - algorithm) / frames, 1e6 * publishing / frames, 1e6 * algorithm / frames,
                                  1e6 * cpu / frames))
    print(f"{args.rate:.0f} Hz from the QTM emulator, {args.seconds:.0f} s, one process per node; CPU a frame (us), "
          f"mean over the nodes of a kind:")
    print(f"{'node kind':<20} {'nodes':>5} {'runtime':>8} {'(publishing)':>13} {'algorithm':>10} {'whole':>7}")
    for kind, rows in sorted(by_kind.items()):
        runtime, publishing, algorithm, whole = (sum(r[k] for r in rows) / len(rows) for k in range(4))
        print(f"{kind:<20} {len(rows):>5} {runtime:>8.0f} {publishing:>13.0f} {algorithm:>10.0f} {whole:>7.0f}")
    print(f"{'bare pyzmq relay':<20} {HOPS + 1:>5} {bare_us:>8.0f} {'':>13} {0:>10.0f} {bare_us:>7.0f}   "
          f"(the same run, {HOPS} hops at {args.rate:.0f} Hz: receive and send the bytes)")
    memory = samples["memory"]
    print(f"graph memory: {sum(v[1] for v in memory.values()):.0f} MB PSS over {len(memory)} processes (RSS summed, "
          f"shared pages counted once a process: {sum(v[0] for v in memory.values()):.0f} MB)")


if __name__ == "__main__":
    main()

"""`mocap demo`: the whole graph on a built-in take, with the live viewer, then a short summary."""
from __future__ import annotations

import csv
import logging
import tempfile
from pathlib import Path

import numpy as np

from mocap_cli.launch_file import add_realtime_flag, load_launch_file
from mocap_cli.launcher import Launcher

REPO = Path(__file__).resolve().parents[1]
DEMO_LAUNCH = REPO / "launch" / "demo.yaml"
log = logging.getLogger("mocap.demo")


def add_parser(sub) -> None:
    s = sub.add_parser("demo", help="run the full graph on a built-in take, with the live viewer",
                       description="Launch launch/demo.yaml: a synthetic running take in the PAF marker set "
                                   "(made on the fly: no recording needed) through every node, with the web viewer; "
                                   "--launch launch/studio.yaml runs a real Vicon take instead. Repeats the take until Ctrl-C "
                                   "(--once: one pass; --seconds: stop earlier), then prints frames, latency and "
                                   "how many joints IK estimated.")
    s.add_argument("--launch", default=str(DEMO_LAUNCH), help="launch file (default launch/demo.yaml)")
    s.add_argument("--set", action="append", metavar="NODE.PARAM=VALUE", help="override a node param")
    s.add_argument("--once", action="store_true", help="one pass of the take, then stop")
    s.add_argument("--seconds", type=float, help="stop after this many seconds")
    s.add_argument("--port", type=int, default=8090, help="viewer port (default 8090)")
    add_realtime_flag(s)
    s.set_defaults(func=run)


def run(args) -> int:
    out = Path(tempfile.mkdtemp(prefix="mocap-demo-")) / "solved.csv"
    overrides = list(args.set or []) + [f"log.path={out}", f"viewer.port={args.port}"]
    overrides += [] if args.once else ["source.loop=true"]
    lf = load_launch_file(args.launch, overrides)
    lf.name = "demo"
    if args.realtime is not None:
        lf.realtime = args.realtime

    def serving():  # said when the viewer serves, not before a first run's compile
        print(f"\nviewer: http://127.0.0.1:{args.port}/   (Ctrl-C stops the graph)\n", flush=True)

    Launcher(lf, args.launch, on_ready=serving).run(duration_s=args.seconds, until_done=args.once)
    if not out.exists():
        log.error("no frame reached skeleton/solved")
        return 1
    with open(out) as f:
        rows = list(csv.DictReader(f))
    if not rows:
        log.error("no frame reached skeleton/solved")
        return 1
    lat = np.array([float(r["latency_us"]) for r in rows]) / 1000
    est = np.array([int(r["estimated"] or 0) for r in rows])
    held = np.array([int(r["held"] or 0) for r in rows])
    print(f"\nskeleton/solved: {len(rows)} frames; end-to-end latency p50 {np.percentile(lat, 50):.1f} ms, "
          f"p99 {np.percentile(lat, 99):.1f} ms")
    print(f"IK estimated joints in {np.mean(est > 0) * 100:.0f}% of frames ({est.sum()} joint-frames), held "
          f"{held.sum()} joint-frames (frame log: {out})")
    return 0

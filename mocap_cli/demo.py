"""`mocap demo`: the whole graph on a built-in take, then a summary of what came out."""
from __future__ import annotations

import csv
import logging
import tempfile
from pathlib import Path

import numpy as np

from mocap_cli.launch_file import load_launch_file
from mocap_cli.launcher import Launcher

REPO = Path(__file__).resolve().parents[1]
DEMO_LAUNCH = REPO / "launch" / "studio.yaml"
log = logging.getLogger("mocap.demo")


def add_parser(sub) -> None:
    s = sub.add_parser("demo", help="run the full graph on a built-in take",
                       description="Launch launch/studio.yaml (a real Vicon take with real marker gaps, "
                                   "../shared/data) through every node, then print what came out.")
    s.add_argument("--launch", default=str(DEMO_LAUNCH), help="launch file (default launch/studio.yaml)")
    s.add_argument("--set", action="append", metavar="NODE.PARAM=VALUE", help="override a node param")
    s.add_argument("--loop", action="store_true", help="replay the take forever (Ctrl-C to stop)")
    s.set_defaults(func=run)


def run(args) -> int:
    out = Path(tempfile.mkdtemp(prefix="mocap-demo-")) / "solved.csv"
    overrides = list(args.set or []) + [f"log.path={out}"] + (["source.loop=true"] if args.loop else [])
    lf = load_launch_file(args.launch, overrides)
    lf.name = "demo"
    Launcher(lf, args.launch).run(until_done=not args.loop)
    if not out.exists():
        log.error("no frame reached skeleton/solved")
        return 1
    with open(out) as f:
        lat = np.array([float(r["latency_us"]) for r in csv.DictReader(f)]) / 1000
    print(f"\nskeleton/solved: {len(lat)} frames; end-to-end latency p50 {np.percentile(lat, 50):.1f} ms, "
          f"p99 {np.percentile(lat, 99):.1f} ms (frame log: {out})")
    return 0

"""What a frame's work costs when it runs once a frame, as a node's does, next to the same work run back to back.

A node sleeps between frames; when the next one comes, its Python code runs on cold caches and costs several
times what a tight timing loop says. The bare relay of `mocap eval latency` does almost nothing a hop (receive
bytes, send them), so it pays little of this; every solving node pays it on its whole frame's work. Figures: CPU
time of the thread (time.thread_time), median, for:

- "relay": what a bare relay does with a frame (a send and a receive of the bytes);
- "read": decoding and checking a 41-marker frame (what a node does with its input);
- "build": making and encoding a message from a node's arrays (what it does with its output);
- "localize": locating one frame's joints (the localization node's own work).

    python benchmarks/cold_work.py [--rate 300] [--frames 600]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import zmq

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from messages import MarkerFrame, codec  # noqa: E402
from mocap_core.localization import Localizer  # noqa: E402
from mocap_core.profiles import load_profile  # noqa: E402
from mocap_core.recordings import read_recording  # noqa: E402
from mocap_core.warmup import warm_up  # noqa: E402

TAKE = REPO.parent / "shared" / "data" / "08_cmu_135_02_karate_kata.c3d"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rate", type=float, default=300, help="frames a second: the pause between runs")
    ap.add_argument("--frames", type=int, default=600)
    args = ap.parse_args()
    warm_up(("localization",), stamp=False)
    rec = read_recording(str(TAKE))
    landmark_map = load_profile("cmu41").resolve(rec.labels)
    localizer = Localizer(load_profile("cmu41").body)
    landmarks = landmark_map.apply(rec.positions)

    zctx = zmq.Context()
    pub, sub = zctx.socket(zmq.PAIR), zctx.socket(zmq.PAIR)
    pub.bind("inproc://relay")
    sub.connect("inproc://relay")

    def frame(i: int) -> MarkerFrame:
        pos = rec.positions[i % rec.n_frames].astype(np.float32)
        return MarkerFrame(header=MarkerFrame.make_header(i), labels=rec.labels, positions=pos,
                           flags=np.zeros(len(pos), np.uint8))

    payloads = [codec.encode(frame(i)) for i in range(args.frames)]

    def relay(i):  # a send and a receive of the bytes
        pub.send(payloads[i])
        sub.recv()

    work = {"relay": relay,
            "read": lambda i: codec.decode(payloads[i], "markers/raw", MarkerFrame),
            "build": lambda i: codec.encode(frame(i)),
            "localize": lambda i: localizer.localize(landmarks[i % rec.n_frames][None])}
    print(f"CPU time of one frame's work, median of {args.frames} (us): once every {1000 / args.rate:.1f} ms "
          f"(as in a node) / back to back")
    for name, run in work.items():
        cold, hot = [], []
        for i in range(args.frames):
            time.sleep(1 / args.rate)
            t = time.thread_time_ns()
            run(i)
            cold.append(time.thread_time_ns() - t)
        for i in range(args.frames):
            t = time.thread_time_ns()
            run(i)
            hot.append(time.thread_time_ns() - t)
        c, h = np.median(cold) / 1000, np.median(hot) / 1000
        print(f"  {name:9s} {c:7.1f} / {h:6.1f}   ({c / h:.1f}x)")


if __name__ == "__main__":
    main()

"""Timed bag replay: a 300 Hz bag played back and recorded again; how far each message's
spacing strays from the recorded spacing (target: within 1 ms at p99).

    python benchmarks/bag_timing.py [--seconds 20] [--rate-hz 300]
"""
from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from messages import MarkerFrame, encode  # noqa: E402
from nodes.bags import BagWriter, read_bag  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=20)
    ap.add_argument("--rate-hz", type=float, default=300)
    ap.add_argument("--spin-ms", type=float, default=1.0, help="the player's busy-wait before each message")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp())
    src, out = tmp / "src.mcap", tmp / "replayed.mcap"
    bag = BagWriter(src)
    t0 = time.time_ns()
    labels = [f"M{i:02d}" for i in range(35)]
    for i in range(int(args.seconds * args.rate_hz)):
        t = i / args.rate_hz
        m = MarkerFrame(header=MarkerFrame.make_header(i, t, t0), labels=labels,
                        positions=np.random.rand(35, 3).astype(np.float32), flags=np.zeros(35, np.uint8))
        bag.write("markers/raw", encode(m), t0 + int(t * 1e9), int(t * 1e9))
    bag.close()
    run = subprocess.run([sys.executable, "-m", "mocap_cli.main", "bag", "play", str(src), "--record", str(out),
                          "--record-topics", "markers/raw", "--spin-ms", str(args.spin_ms)],
                         cwd=REPO, check=True, capture_output=True, text=True)
    player = re.search(r"timed replay of .*", run.stderr)
    sent = np.array([m.log_time_ns for m in read_bag(out)], dtype=np.float64) / 1e6
    want = np.arange(len(sent)) * 1000 / args.rate_hz
    err = np.abs(np.diff(sent) - np.diff(want))
    drift = (sent - sent[0]) - want
    steady = err[int(args.rate_hz):]
    print(f"{len(sent)} of {int(args.seconds * args.rate_hz)} messages replayed at {args.rate_hz:.0f} Hz, "
          "received by a recorder in another process")
    print(f"spacing error: p50 {np.percentile(err, 50):.3f} ms, p99 {np.percentile(err, 99):.3f} ms, "
          f"max {err.max():.3f} ms (target p99 <= 1 ms)")
    print(f"  after the first second (the other processes have settled): p50 {np.percentile(steady, 50):.3f} ms, "
          f"p99 {np.percentile(steady, 99):.3f} ms")
    print(f"the player's own send times (its log): {player.group(0) if player else '?'}")
    print(f"cumulative drift at the end: {drift[-1]:+.3f} ms")
    print(f"this machine's floor: time.sleep(1/{args.rate_hz:.0f}) wakes late by p99 {sleep_floor(args.rate_hz):.3f} ms")
    print(f"  and bare pyzmq, a spinning sender and a SUB in another process: received spacing error p99 "
          f"{bare_floor(args.rate_hz, tmp):.3f} ms")


def bare_floor(rate_hz: float, tmp: Path, n: int = 3000) -> float:
    """The same spacing measured with plain pyzmq and no runtime: what any receiver here can expect."""
    import multiprocessing

    import zmq

    endpoint = f"ipc://{tmp}/floor"
    q = multiprocessing.Queue()
    rx = multiprocessing.Process(target=_bare_receiver, args=(endpoint, n, q))
    rx.start()
    pub = zmq.Context.instance().socket(zmq.PUB)
    pub.bind(endpoint)
    time.sleep(1.0)  # slow joiner: a bare chain has no handshake (the runtime's does)
    t0 = time.monotonic()
    for i in range(n):
        due = t0 + i / rate_hz
        if due - time.monotonic() > 0.001:
            time.sleep(due - time.monotonic() - 0.001)
        while time.monotonic() < due:
            pass
        pub.send(b"x" * 1000)
    got = np.array(q.get(timeout=30))
    rx.join()
    pub.close(linger=1000)
    return float(np.percentile(np.abs(np.diff(got) * 1000 - 1000 / rate_hz), 99))


def _bare_receiver(endpoint: str, n: int, q) -> None:
    import zmq

    sub = zmq.Context.instance().socket(zmq.SUB)
    sub.subscribe(b"")
    sub.connect(endpoint)
    times = []
    while len(times) < n:
        if not sub.poll(5000):
            break
        sub.recv()
        times.append(time.monotonic())
    q.put(times)


def sleep_floor(rate_hz: float, n: int = 600) -> float:
    """How late a plain sleep wakes on this machine (a shared VM: often over a millisecond at p99)."""
    late = []
    for _ in range(n):
        t = time.perf_counter()
        time.sleep(1 / rate_hz)
        late.append((time.perf_counter() - t - 1 / rate_hz) * 1000)
    return float(np.percentile(late, 99))


if __name__ == "__main__":
    main()

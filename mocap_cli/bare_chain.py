"""A bare pyzmq PUB/SUB relay chain: the yardstick our runtime's latency is compared with."""
from __future__ import annotations

import multiprocessing as mp
import tempfile
import time

import numpy as np
import zmq


def _bare_source(endpoint, frames, rate, ready):
    ctx = zmq.Context()
    s = ctx.socket(zmq.XPUB)
    s.bind(endpoint)
    s.recv()  # the first hop's subscription: wired, no sleep
    ready.wait()
    t0 = time.perf_counter()
    for i in range(frames):
        delay = t0 + i / rate - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
        s.send_multipart([b"t", time.time_ns().to_bytes(8, "little") + bytes(700)])
    s.send_multipart([b"t", b"END"])
    time.sleep(0.2)


def _bare_relay(src, dst):
    ctx = zmq.Context()
    i, o = ctx.socket(zmq.SUB), ctx.socket(zmq.XPUB)
    o.bind(dst)
    o.recv()
    i.connect(src)
    i.setsockopt(zmq.SUBSCRIBE, b"t")
    while True:
        parts = i.recv_multipart()
        o.send_multipart(parts)
        if parts[1] == b"END":
            time.sleep(0.2)
            return


def bare_chain(hops: int, frames: int, rate: float) -> np.ndarray:
    d = tempfile.mkdtemp()
    eps = [f"ipc://{d}/{k}" for k in range(hops + 1)]
    ready = mp.Event()
    procs = [mp.Process(target=_bare_source, args=(eps[0], frames, rate, ready))]
    procs += [mp.Process(target=_bare_relay, args=(eps[k], eps[k + 1])) for k in range(hops)]
    for p in procs:
        p.start()
    ctx = zmq.Context()
    sink = ctx.socket(zmq.SUB)
    sink.connect(eps[-1])
    sink.setsockopt(zmq.SUBSCRIBE, b"t")
    time.sleep(0.5)  # benchmark only: let the chain subscribe before the source starts
    ready.set()
    lat = []
    while True:
        _, payload = sink.recv_multipart()
        if payload == b"END":
            break
        lat.append((time.time_ns() - int.from_bytes(payload[:8], "little")) / 1e3)
    for p in procs:
        p.join()
    return np.array(lat)



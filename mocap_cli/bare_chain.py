"""Bare pyzmq PUB/SUB relay chains: the yardsticks our runtime's latency is compared with.

``bare_chain`` forwards bytes and nothing else (the issue's yardstick). ``codec_chain`` is the same
loop with our codec in every relay: it decodes and validates each 35-marker frame and encodes it
again, as any node that reads its input must. Between the two lies what decoding costs on the
host; between it and the runtime, what the runtime's own loop costs.
"""
from __future__ import annotations

import multiprocessing as mp
import tempfile
import time

import numpy as np
import zmq

END = b"END"


def marker_frame():
    """A 35-marker frame of random positions (the benchmarks' message)."""
    from messages import MarkerFrame

    return MarkerFrame(header=MarkerFrame.make_header(), labels=[f"M{i:02d}" for i in range(35)],
                       positions=np.random.rand(35, 3).astype(np.float32), flags=np.zeros(35, np.uint8))


def _source(endpoint, frames, rate, ready, codec):
    if codec:
        from messages import encode

        msg = marker_frame()
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
        if codec:
            h = msg.header.__dict__
            h["frame"], h["seq"], h["entry_time_ns"] = i, i + 1, time.time_ns()
            s.send_multipart([b"t", encode(msg)])
        else:
            s.send_multipart([b"t", time.time_ns().to_bytes(8, "little") + bytes(700)])
    s.send_multipart([b"t", END])
    time.sleep(0.2)


def _relay(src, dst, codec):
    if codec:
        from messages import MarkerFrame, decode, encode
    ctx = zmq.Context()
    i, o = ctx.socket(zmq.SUB), ctx.socket(zmq.XPUB)
    o.bind(dst)
    o.recv()
    i.connect(src)
    i.setsockopt(zmq.SUBSCRIBE, b"t")
    while True:
        parts = i.recv_multipart()
        if parts[1] == END:
            o.send_multipart(parts)
            time.sleep(0.2)
            return
        if codec:
            msg = decode(parts[1], "t", MarkerFrame)
            msg.header.__dict__["publisher"] = "relay"  # a new publisher's stamp, as the runtime writes it
            parts[1] = encode(msg)
        o.send_multipart(parts)


def _chain(hops: int, frames: int, rate: float, codec: bool) -> np.ndarray:
    if codec:
        from messages.fastpath import peek_header
    d = tempfile.mkdtemp()
    eps = [f"ipc://{d}/{k}" for k in range(hops + 1)]
    ready = mp.Event()
    procs = [mp.Process(target=_source, args=(eps[0], frames, rate, ready, codec))]
    procs += [mp.Process(target=_relay, args=(eps[k], eps[k + 1], codec)) for k in range(hops)]
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
        now = time.time_ns()  # at arrival, before reading the payload
        if payload == END:
            break
        sent = peek_header(payload)["entry_time_ns"] if codec else int.from_bytes(payload[:8], "little")
        lat.append((now - sent) / 1e3)
    for p in procs:
        p.join()
    return np.array(lat)


def bare_chain(hops: int, frames: int, rate: float) -> np.ndarray:
    """One-way latencies (µs) through ``hops`` relays that forward the bytes they receive."""
    return _chain(hops, frames, rate, codec=False)


def codec_chain(hops: int, frames: int, rate: float) -> np.ndarray:
    """The same, with relays that decode, validate and re-encode every frame with our codec."""
    return _chain(hops, frames, rate, codec=True)

"""`mocap topic list|echo|hz` and `mocap node list`: ROS 2-style introspection of a running graph."""
from __future__ import annotations

import sys
import time
from collections import defaultdict
from typing import Iterator, TextIO

import numpy as np
import zmq

from messages import DecodeError, Heartbeat, Message, decode
from mocap_cli.graph_registry import publishers_of
from nodes.runtime import DIAGNOSTICS


def subscribe(graph: dict, topic: str, zctx: zmq.Context) -> zmq.Socket:
    endpoints = publishers_of(graph, topic)
    if not endpoints:
        topics = sorted({t for n in graph["nodes"] for t in n["publishes"]})
        raise SystemExit(f"no node of graph {graph['name']!r} publishes {topic!r} (topics: {', '.join(topics)})")
    sock = zctx.socket(zmq.SUB)
    sock.setsockopt(zmq.LINGER, 0)
    if graph.get("curve_keys"):
        from nodes.curve import secure_subscriber

        secure_subscriber(sock, graph["curve_keys"])
    sock.setsockopt(zmq.SUBSCRIBE, topic.encode())
    for e in endpoints:
        sock.connect(e)
    return sock


def messages(sock: zmq.Socket, topic: str, timeout_s: float | None) -> Iterator[tuple[bytes, Message | DecodeError]]:
    deadline = None if timeout_s is None else time.monotonic() + timeout_s
    while deadline is None or time.monotonic() < deadline:
        if not sock.poll(100):
            continue
        wire, payload = sock.recv_multipart()[:2]
        if wire.decode() != topic:
            continue
        try:
            yield payload, decode(payload, topic)
        except DecodeError as e:
            yield payload, e


def topic_list(graph: dict, out: TextIO = sys.stdout) -> None:
    pubs, subs = defaultdict(list), defaultdict(list)
    for n in graph["nodes"]:
        for t in n["publishes"]:
            pubs[t].append(n["id"])
        for t in n["subscribes"]:
            subs[t].append(n["id"])
    for t in sorted(set(pubs) | set(subs)):
        out.write(f"{t}\n    publishers: {', '.join(pubs[t]) or '-'}\n    subscribers: {', '.join(subs[t]) or '-'}\n")


def _readable(value, indent: str = "  ") -> str:
    if isinstance(value, np.ndarray):
        with np.printoptions(precision=4, suppress=True, threshold=200, linewidth=110):
            body = np.array2string(value, separator=", ")
        return f"{value.dtype}{list(value.shape)}\n{indent}  " + body.replace("\n", f"\n{indent}  ")
    return repr(value)


def format_message(msg: Message) -> str:
    h = msg.header
    lines = [f"--- {h.schema_name} v{h.version} frame {h.frame} t={h.capture_time_s:.4f}s "
             f"seq {h.seq} from {h.publisher}"]
    for name in type(msg).model_fields:
        if name != "header":
            lines.append(f"  {name}: {_readable(getattr(msg, name))}")
    return "\n".join(lines)


def topic_echo(graph: dict, topic: str, once: bool, timeout_s: float | None, out: TextIO = sys.stdout) -> int:
    zctx = zmq.Context.instance()
    sock = subscribe(graph, topic, zctx)
    try:
        for _payload, msg in messages(sock, topic, timeout_s):
            if isinstance(msg, DecodeError):
                out.write(f"!!! undecodable message: {msg}\n")
            else:
                out.write(format_message(msg) + "\n")
            out.flush()
            if once:
                return 0
    finally:
        sock.close()
    return 0 if not once else 1


def topic_hz(graph: dict, topic: str, window_s: float, duration_s: float | None, out: TextIO = sys.stdout) -> list[float]:
    zctx = zmq.Context.instance()
    sock = subscribe(graph, topic, zctx)
    rates, times = [], []
    start = time.monotonic()
    next_report = start + window_s
    try:
        while duration_s is None or time.monotonic() - start < duration_s:
            if sock.poll(20):
                while True:
                    try:
                        wire = sock.recv_multipart(zmq.NOBLOCK)[0]
                    except zmq.Again:
                        break
                    if wire.decode() == topic:
                        times.append(time.monotonic())
            now = time.monotonic()
            if now >= next_report:
                recent = [t for t in times if t >= now - window_s]
                rate = len(recent) / window_s
                gaps = np.diff(recent) * 1000 if len(recent) > 2 else np.zeros(1)
                out.write(f"{topic}: {rate:.1f} Hz  (period mean {gaps.mean():.2f} ms, std {gaps.std():.2f} ms, "
                          f"max {gaps.max():.2f} ms, n={len(recent)})\n")
                out.flush()
                rates.append(rate)
                times = recent
                next_report += window_s
    finally:
        sock.close()
    return rates


def collect_heartbeats(graph: dict, seconds: float = 1.5) -> dict[str, Heartbeat]:
    zctx = zmq.Context.instance()
    sock = subscribe(graph, DIAGNOSTICS, zctx)
    latest: dict[str, Heartbeat] = {}
    try:
        for _payload, msg in messages(sock, DIAGNOSTICS, seconds):
            if isinstance(msg, Heartbeat):
                latest[msg.node] = msg
    finally:
        sock.close()
    return latest


def node_list(graph: dict, seconds: float = 1.5, out: TextIO = sys.stdout) -> dict[str, Heartbeat]:
    beats = collect_heartbeats(graph, seconds)
    out.write(f"{'node':<20} {'kind':<18} {'pid':>7} {'process':<12} {'state':<9} {'in Hz':>8} {'out Hz':>8} "
              f"{'p50 ms':>7} {'p99 ms':>7} {'drops':>6} {'errors':>6}\n")
    for n in graph["nodes"]:
        hb = beats.get(n["id"])
        process = n.get("process", n["id"])  # a container's name, or the node's own
        if hb is None:
            out.write(f"{n['id']:<20} {n['kind']:<18} {str(n['pid']):>7} {process:<12} {'silent':<9}\n")
            continue
        rin = sum(v for t, v in hb.rates_hz.items() if t in hb.received)
        rout = sum(v for t, v in hb.rates_hz.items() if t in hb.published)
        out.write(f"{hb.node:<20} {hb.kind:<18} {hb.pid:>7} {process:<12} {hb.state:<9} {rin:>8.1f} {rout:>8.1f} "
                  f"{hb.latency.p50_ms:>7.2f} {hb.latency.p99_ms:>7.2f} {sum(hb.drops.values()):>6} "
                  f"{sum(hb.errors.values()):>6}\n")
    return beats

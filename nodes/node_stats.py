"""What a node's heartbeat reports: per topic counts, rates, sequence gaps and restarts, latency from the graph's
entry, and errors counted by reason."""
from __future__ import annotations

import collections
import logging
import os
import time

import numpy as np

from messages import Cpu, Header, Heartbeat, Latency

DIAGNOSTICS = "diagnostics"


class TopicStats:
    __slots__ = ("count", "drops", "last_seq", "last_frame", "lost_frames", "rate_mark")

    def __init__(self):
        self.count = 0
        self.drops = 0
        self.last_seq: dict[str, int] = {}
        self.last_frame: dict[str, int] = {}
        self.lost_frames = 0                # frames a restarted publisher never sent
        self.rate_mark = (time.monotonic(), 0)

    def rate(self, now: float) -> float:
        """Messages per second since the last call (once per heartbeat: no per-message bookkeeping)."""
        then, count = self.rate_mark
        self.rate_mark = (now, self.count)
        return (self.count - count) / (now - then) if now > then else 0.0


class NodeStats:
    """One node's counters, read once a heartbeat (no per-message bookkeeping beyond the counts)."""

    def __init__(self, log: logging.Logger):
        self.log = log
        self.published: dict[str, TopicStats] = collections.defaultdict(TopicStats)
        self.received: dict[str, TopicStats] = collections.defaultdict(TopicStats)
        self.latency_ns: list[int] = []
        self.errors: collections.Counter[str] = collections.Counter()
        self.last_error = ""
        self.handlers_cpu_s = 0.0     # (counted with MOCAP_CPU_SPLIT=1 only: two clock reads a call)
        self.publishing_cpu_s = 0.0

    def count_error(self, reason: str, text: str, n: int = 1) -> None:
        """Count ``n`` of ``reason``; the text logged for the first few of each reason and then every 1000th, so a
        flood cannot fill the disk."""
        before = self.errors[reason]
        self.errors[reason] += n
        self.last_error = text
        after = self.errors[reason]
        if before < 5 or after // 1000 > before // 1000:
            self.log.warning("%s (%s #%d)", text, reason, after)

    def arrived(self, wire: str, h: Header) -> None:
        """A message received: sequence gaps (drops), a publisher's restart (the frames it never sent), latency."""
        st = self.received[wire]
        st.count += 1
        last = st.last_seq.get(h.publisher)
        if last is not None and h.seq > last + 1:
            st.drops += h.seq - last - 1
        elif last is not None and h.seq <= last:  # the publisher restarted: count the frames it missed
            gap = h.frame - st.last_frame.get(h.publisher, h.frame) - 1
            st.lost_frames += max(0, gap)
        st.last_seq[h.publisher] = h.seq
        st.last_frame[h.publisher] = h.frame
        if h.entry_time_ns:
            self.latency_ns.append(time.time_ns() - h.entry_time_ns)

    def heartbeat(self, node: str, kind: str, state: str, started_at: float) -> Heartbeat:
        now = time.monotonic()
        lat = np.asarray(self.latency_ns, dtype=np.float64) / 1e6
        self.latency_ns = []
        latency = Latency()
        if lat.size:
            p50, p95, p99 = percentiles(lat, (50, 95, 99))
            latency = Latency(p50_ms=p50, p95_ms=p95, p99_ms=p99, max_ms=float(lat.max()), samples=int(lat.size))
        rates = {t: s.rate(now) for t, s in {**self.received, **self.published}.items()}
        return Heartbeat(
            header=Heartbeat.make_header(entry_time_ns=time.time_ns()),
            node=node, kind=kind, pid=os.getpid(), state=state,
            uptime_s=now - started_at, rates_hz=rates,
            received={t: s.count for t, s in self.received.items()},
            published={t: s.count for t, s in self.published.items() if t != DIAGNOSTICS},
            drops={t: s.drops for t, s in self.received.items()},
            lost_frames={t: s.lost_frames for t, s in self.received.items() if s.lost_frames},
            errors=dict(self.errors), latency=latency, last_error=self.last_error[:500],
            cpu=Cpu(process_s=time.process_time(), handlers_s=self.handlers_cpu_s,
                    publishing_s=self.publishing_cpu_s),
        )


def percentiles(values, qs: tuple[float, ...]) -> list[float]:
    """np.percentile's default (linear) percentiles. np.percentile itself lazily imports half of
    numpy on its first call: a 35 ms stall of every node's message loop a second into each run."""
    s = np.sort(values)
    out = []
    for q in qs:
        pos = q / 100 * (len(s) - 1)
        lo = int(pos)
        hi = min(lo + 1, len(s) - 1)
        out.append(float(s[lo] + (s[hi] - s[lo]) * (pos - lo)))
    return out

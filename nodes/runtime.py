"""The small runtime every node shares: typed params, typed pub/sub, heartbeat, clean shutdown.

A node is a class with ``Params`` (a pydantic model), the topics it reads (``subscribes``) and
writes (``publishes``), and handlers. The runtime owns the sockets and the loop:

- one XPUB socket per node (bound at the endpoint the launcher chose) for every topic it writes and
  for its heartbeat; XPUB lets it see its subscribers arrive, which is how the graph knows it is
  wired before a source starts (no sleeps);
- one SUB socket connected to every publisher of every topic it reads; frames are multipart
  ``[topic, msgpack payload]``;
- a malformed or foreign message is counted, logged with topic and reason, and skipped;
- a ``header_only`` node (a relay) is handed the bytes of each message whose header alone was
  checked, and the first node downstream that decodes it checks the rest;
- a 1 Hz :class:`~messages.Heartbeat` on ``diagnostics`` with rates, latency percentiles
  (from the header's entry time), drops (sequence gaps per publisher) and error counts;
- in a container (several nodes in one process), a message for a neighbour is handed over as the
  object itself, like ROS 2's intra-process communication: no codec and no socket, and it is encoded
  only when someone outside the process subscribes; its arrays are made read-only, so one subscriber
  cannot change what another sees (the same as arrays decoded from bytes);
- SIGINT/SIGTERM end the loop; sockets close with LINGER 0, except that a source that finished
  flushes what it already sent (at most FLUSH_S), and a node with ``drain_on_stop`` (the recorder)
  handles what is already queued for it before it tears down: a last frame is not lost to a race
  with ZeroMQ's I/O thread.
"""
from __future__ import annotations

import collections
import copy
import gc
import logging
import os
import signal
import time
from typing import Any, ClassVar

import numpy as np
import zmq
from pydantic import BaseModel, ConfigDict

from messages import ALL_MESSAGES, DecodeError, Header, Heartbeat, Latency, Message, decode, encode
from messages.codec import MAX_MESSAGE_BYTES, decode_header
from messages.fastpath import array_fields, prepare
from nodes.spec import NodeSpec

HEARTBEAT_PERIOD_S = 1.0
FLUSH_S = 1.0   # a finished source's last frames still go out
DRAIN_S = 0.5   # a drain_on_stop node's queued frames still get handled
SIDE_POLL_S = 0.05  # a running node reads subscription notices and launcher commands this often
DIAGNOSTICS = "diagnostics"
SETUP_FAILED = 3  # exit code of a node whose setup raised: the launcher stops a graph that never started
# What a user's configuration causes (a profile, a file, a port): one line, no traceback. By name, so the runtime
# depends on no solving module.
EXPECTED_SETUP_ERRORS = (OSError,)
EXPECTED_SETUP_ERROR_NAMES = {"ProfileError", "RecordingError", "SubjectError", "BagError", "ConstraintsError",
                              "ValidationError", "ValueError"}
# Plain ints: combining pyzmq's enum flags costs microseconds per call on the hot path.
_NOBLOCK, _MORE, _POLLIN = int(zmq.NOBLOCK), int(zmq.NOBLOCK | zmq.SNDMORE), int(zmq.POLLIN)


class NoParams(BaseModel):
    model_config = ConfigDict(extra="forbid")


class Node:
    """Base class of every node kind. Subclasses declare their contract as class attributes."""

    kind: ClassVar[str] = ""
    Params: ClassVar[type[BaseModel]] = NoParams
    subscribes: ClassVar[dict[str, type[Message]]] = {}   # logical topic -> message type
    publishes: ClassVar[dict[str, type[Message]]] = {}
    is_source: ClassVar[bool] = False                     # sources wait for the launcher's "start"
    timer_period_s: ClassVar[float | None] = None         # call on_timer() this often (e.g. join timeouts)
    drain_on_stop: ClassVar[bool] = False                 # handle frames already queued when stopped
    # Forward bytes without reading them (a relay): the runtime checks only each message's header
    # (schema, version, sequence, as ROS 2's topic_tools relay reads none of its messages) and calls
    # on_raw with msg=None; whoever reads the message downstream checks the rest.
    header_only: ClassVar[bool] = False

    @classmethod
    def inputs(cls, params: BaseModel) -> dict[str, type[Message]]:
        """Topics this node reads with these params (default: the class's ``subscribes``)."""
        return cls.subscribes

    @classmethod
    def outputs(cls, params: BaseModel) -> dict[str, type[Message]]:
        """Topics this node writes with these params (default: the class's ``publishes``)."""
        return cls.publishes

    def __init__(self, params: BaseModel, ctx: "NodeContext"):
        self.params = params
        self.ctx = ctx
        self.log = ctx.log

    def setup(self) -> None:
        """Open files, build state. Called once before any message."""

    def on_message(self, topic: str, msg: Message) -> None:
        """Handle one decoded message of a logical topic."""

    def on_raw(self, wire_topic: str, payload: bytes, msg: Message | None) -> None:
        """Handle one message with its exact wire bytes (default: call on_message). ``msg`` is the
        decoded message, or None for a ``header_only`` node given bytes from a socket."""
        self.on_message(self.ctx._logical[wire_topic], msg)

    def tick(self) -> float | None:
        """Sources: produce output. Return seconds until the next call, or None when finished."""
        return None

    def on_timer(self) -> None:
        """Called every ``timer_period_s`` when the class sets one."""

    def teardown(self) -> None:
        """Close files. Called once on shutdown, also after an error."""


def inproc_endpoint(node_id: str) -> str:
    return f"inproc://{node_id}"


class _TopicStats:
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


class NodeContext:
    """What a node sees of the transport: publish, its id, its logger, the clock."""

    def __init__(self, spec: NodeSpec, node_cls: type[Node], zctx: zmq.Context | None = None,
                 params: BaseModel | None = None):
        self.spec = spec
        self.node_cls = node_cls
        params = params if params is not None else node_cls.Params.model_validate(spec.params)
        self.subscribes = node_cls.inputs(params)
        self.publishes = node_cls.outputs(params)
        self.log = logging.getLogger(f"mocap.{spec.id}")
        self._own_zctx = zctx is None
        self.zctx = zctx or zmq.Context()
        self.publisher_id = spec.id
        self.header_only = node_cls.header_only
        self._seq: dict[str, int] = collections.defaultdict(int)
        self._pub_stats: dict[str, _TopicStats] = collections.defaultdict(_TopicStats)
        self._sub_stats: dict[str, _TopicStats] = collections.defaultdict(_TopicStats)
        self._latency_ns: list[int] = []
        self.errors: collections.Counter[str] = collections.Counter()
        self.last_error = ""
        self._wire = {t: spec.wire_topic(t) for t in {**self.subscribes, **self.publishes}}
        self._written = [spec.wire_topic(t).encode() for t in self.publishes] + [DIAGNOSTICS.encode()]
        self._logical = {w: t for t, w in self._wire.items() if t in self.subscribes}
        self.pub: zmq.Socket | None = None
        self.sub: zmq.Socket | None = None
        self.sub_connected = False  # False when every input is handed over in-process
        self._subscriptions: collections.Counter[bytes] = collections.Counter()
        self._outside: dict[str, bool] = {}  # wire topic -> has a subscriber beyond the process (cache)
        self.local_readers: dict[str, list[NodeContext]] = {}  # wire topic -> container neighbours
        self.inbox: collections.deque[tuple[str, Message]] = collections.deque()  # handed over, not yet handled
        self.in_hand: Message | None = None  # the handed-over message being handled now (shared: not ours)
        self.received_ns = 0  # when the message being handled arrived (before decoding: a bag's receive time)
        self.default_up_axis = ""  # stamped where the source did not say it (a node with a profile sets it)
        for cls in ALL_MESSAGES:  # (a node typed `Message`, like the recorder, may get any of them)
            prepare(cls)  # the first frame through a node should cost what every other one does

    # -- sockets ---------------------------------------------------------------------------------
    def open(self) -> None:
        spec = self.spec
        self.authenticator = None
        if spec.curve_keys:
            from nodes import curve

            self.authenticator = curve.start_authenticator(self.zctx, spec.curve_keys)
        if spec.pub_endpoint:
            self.pub = self.zctx.socket(zmq.XPUB)
            if spec.curve_keys:
                curve.secure_publisher(self.pub, spec.curve_keys)
            self.pub.setsockopt(zmq.XPUB_VERBOSE, 1)
            self.pub.setsockopt(zmq.SNDHWM, spec.hwm)
            self.pub.setsockopt(zmq.LINGER, 0)
            self.pub.bind(spec.bind_endpoint or spec.pub_endpoint)
            if spec.inproc:  # nodes in the same container connect here: no I/O thread, no kernel
                self.pub.bind(inproc_endpoint(spec.id))
        self.sub = self.zctx.socket(zmq.SUB)
        if spec.curve_keys:
            curve.secure_subscriber(self.sub, spec.curve_keys)
        self.sub.setsockopt(zmq.RCVHWM, spec.hwm)
        self.sub.setsockopt(zmq.LINGER, 0)
        self.sub.setsockopt(zmq.MAXMSGSIZE, MAX_MESSAGE_BYTES)
        for logical in self.subscribes:
            wire = self._wire[logical]
            self.sub.setsockopt(zmq.SUBSCRIBE, wire.encode())
            for endpoint in spec.sub_endpoints.get(wire, []):
                self.sub.connect(endpoint)
                self.sub_connected = True

    def close(self, flush_s: float = 0.0) -> None:
        """Close the sockets; with ``flush_s``, first let the I/O thread send what was published."""
        if self.sub is not None:
            self.sub.close(linger=0)
        if self.pub is not None:
            self.pub.close(linger=int(flush_s * 1000))
        if getattr(self, "authenticator", None) is not None:
            self.authenticator.stop()
        if flush_s and self._own_zctx:
            self.zctx.term()  # returns once queued messages are out, or after the linger

    def drain(self, handle, limit_s: float) -> int:
        """Pass frames already queued on the SUB socket to ``handle`` (at most ``limit_s``)."""
        n, end = 0, time.monotonic() + limit_s
        while time.monotonic() < end:
            try:
                handle(self.recv_frames())
            except zmq.Again:
                if not self.sub.poll(20):  # nothing for 20 ms: what was in flight has arrived
                    break
                continue
            n += 1
        return n

    def recv_frames(self) -> list[bytes]:
        """One multipart message from the SUB socket, without blocking (zmq.Again when none), noting when
        it arrived. Frames tell whether more parts follow, which saves recv_multipart's RCVMORE query
        per part (~1 us each on the hot path)."""
        f = self.sub.recv(_NOBLOCK, copy=False)
        self.received_ns = time.time_ns()
        parts = [f.bytes]
        while f.more:
            f = self.sub.recv(_NOBLOCK, copy=False)
            parts.append(f.bytes)
        return parts

    def read_subscriptions(self) -> None:
        """Drain XPUB subscription notices (b'\\x01topic' / b'\\x00topic')."""
        while self.pub is not None:
            try:
                note = self.pub.recv(zmq.NOBLOCK)
            except zmq.Again:
                return
            kind, topic = note[:1], note[1:]
            if kind not in (b"\x01", b"\x00"):
                continue
            if not any(w.startswith(topic) for w in self._written):
                continue  # no message of ours would match it: not worth a counter (a peer may send thousands)
            self._subscriptions[topic] += 1 if kind == b"\x01" else -1
            self._outside.clear()

    def _has_outside(self, wire: str) -> bool:
        """Whether a subscription seen by the XPUB (a prefix, as ZeroMQ matches them) covers a topic."""
        got = self._outside.get(wire)
        if got is None:
            key = wire.encode()
            got = self._outside[wire] = any(n > 0 and key.startswith(p) for p, n in self._subscriptions.items())
        return got

    def has_subscribers(self, topic: str) -> bool:
        """Whether anyone subscribes to a logical topic now (skip work nobody will receive); the loop
        reads the XPUB's subscription notices whenever it has some."""
        wire = self.wire_topic(topic)
        return wire in self.local_readers or self._has_outside(wire)

    def subscribers_connected(self) -> bool:
        return all(self._subscriptions[t.encode()] >= n for t, n in self.spec.expected_subscribers.items())

    # -- publishing --------------------------------------------------------------------------------
    def wire_topic(self, logical: str) -> str:
        return self._wire.get(logical) or self.spec.wire_topic(logical)

    def publish(self, topic: str, msg: Message, source: Message | None = None) -> None:
        """Send ``msg`` on a logical topic. With ``source``, the frame number, capture time and
        graph-entry time are carried over from the message this one was computed from. A published
        message belongs to its readers: in a container it is shared, not copied, and its arrays become
        read-only, so give it arrays of its own (not views of a buffer the node keeps writing)."""
        if self.pub is None:
            return
        if msg is self.in_hand:  # a neighbour's message, republished: stamp a copy, others hold this one
            msg = copy.copy(msg)
            msg.__dict__["header"] = copy.copy(msg.header)
        # Written straight into the header's __dict__: pydantic's __setattr__ would cost ~10 us a message.
        h = msg.header.__dict__
        h["schema_name"], h["version"] = msg.SCHEMA, msg.VERSION
        if source is not None:
            sh = source.header
            h["frame"], h["capture_time_s"], h["entry_time_ns"] = sh.frame, sh.capture_time_s, sh.entry_time_ns
            h["up_axis"] = h["up_axis"] or sh.up_axis or self.default_up_axis
        elif h["entry_time_ns"] == 0:
            h["entry_time_ns"] = time.time_ns()
        wire = self.wire_topic(topic)
        seq = self._seq[wire] = self._seq[wire] + 1
        h["seq"], h["publisher"] = seq, self.publisher_id
        readers = self.local_readers.get(wire)
        if readers is None:
            self._send(wire, encode(msg))
            return
        _freeze_arrays(msg)
        for reader in readers:
            reader.hand_over(wire, msg)
        if self._has_outside(wire):
            self._send(wire, encode(msg))
        else:
            self._pub_stats[wire].count += 1

    def send_raw(self, wire_topic: str, payload: bytes) -> None:
        """Send bytes already encoded (a bag's, a heartbeat); neighbours in a container get them decoded."""
        for reader in self.local_readers.get(wire_topic, ()):
            try:
                reader.hand_over(wire_topic, _freeze_arrays(decode(payload, wire_topic)))
            except DecodeError as e:
                reader.count_error(f"decode_{e.kind}", str(e))
        self._send(wire_topic, payload)

    def _send(self, wire_topic: str, payload: bytes) -> None:
        try:  # two sends rather than send_multipart: a few microseconds less per message
            self.pub.send(wire_topic.encode(), _MORE)
            self.pub.send(payload, _NOBLOCK)
        except zmq.Again:  # HWM reached on every peer: keep-last semantics, the frame is dropped
            self.errors["send_dropped"] += 1
            return
        self._pub_stats[wire_topic].count += 1

    # -- receiving ---------------------------------------------------------------------------------
    def hand_over(self, wire: str, msg: Message) -> None:
        """A container neighbour's message, queued as the object itself (at most ``hwm``, as a socket)."""
        if len(self.inbox) < self.spec.hwm:
            self.inbox.append((wire, msg))  # else dropped: the sequence gap counts it, as over a socket

    def receive(self, frames: list[bytes]) -> tuple[str, Message] | None:
        """Decode one multipart frame into (logical topic, message); count and log failures."""
        if len(frames) != 2:
            self.count_error("bad_framing", f"expected [topic, payload], got {len(frames)} parts")
            return None
        wire = frames[0].decode("utf-8", "replace")
        logical = self._logical.get(wire)
        if logical is None:
            return None  # a longer topic that shares our prefix; not ours
        try:
            if self.header_only:
                msg, header = None, decode_header(frames[1], wire, self.subscribes[logical])
            else:
                msg = decode(frames[1], wire, self.subscribes[logical])
                header = msg.header
        except DecodeError as e:
            self.count_error(f"decode_{e.kind}", str(e))
            return None
        return (logical, msg) if self.account(wire, header) else None

    def account(self, wire: str, h: Header) -> bool:
        """Count a received message by its header (sequence gaps, restarts, latency); False for a
        sibling replica's."""
        if self.spec.replicas > 1 and h.frame % self.spec.replicas != self.spec.replica:
            return False  # a sibling replica's frame
        st = self._sub_stats[wire]
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
            self._latency_ns.append(time.time_ns() - h.entry_time_ns)
        return True

    def skipped(self, wire_topic: bytes) -> None:
        self._sub_stats[wire_topic.decode("utf-8", "replace")].drops += 1

    def count_error(self, reason: str, text: str, n: int = 1) -> None:
        """Something a node met and handled itself (a marker put wrong, a limb late): counted per reason in the
        heartbeat's errors, the text logged for the first few of each reason and then every 1000th, so a flood
        cannot fill the disk. The runtime counts its own (bad framing, undecodable messages) the same way."""
        before = self.errors[reason]
        self.errors[reason] += n
        self.last_error = text
        after = self.errors[reason]
        if before < 5 or after // 1000 > before // 1000:
            self.log.warning("%s (%s #%d)", text, reason, after)

    def handler_error(self, topic: str, exc: BaseException) -> None:
        self.count_error(f"handler_{type(exc).__name__}", f"handler for {topic!r} failed: {exc!r}")

    # -- heartbeat ---------------------------------------------------------------------------------
    def heartbeat(self, state: str, started_at: float) -> Heartbeat:
        now = time.monotonic()
        lat = np.asarray(self._latency_ns, dtype=np.float64) / 1e6
        self._latency_ns = []
        latency = Latency()
        if lat.size:
            p50, p95, p99 = percentiles(lat, (50, 95, 99))
            latency = Latency(p50_ms=p50, p95_ms=p95, p99_ms=p99, max_ms=float(lat.max()), samples=int(lat.size))
        rates = {t: s.rate(now) for t, s in {**self._sub_stats, **self._pub_stats}.items()}
        return Heartbeat(
            header=Heartbeat.make_header(entry_time_ns=time.time_ns()),
            node=self.spec.id, kind=self.spec.kind, pid=os.getpid(), state=state,
            uptime_s=now - started_at, rates_hz=rates,
            received={t: s.count for t, s in self._sub_stats.items()},
            published={t: s.count for t, s in self._pub_stats.items() if t != DIAGNOSTICS},
            drops={t: s.drops for t, s in self._sub_stats.items()},
            lost_frames={t: s.lost_frames for t, s in self._sub_stats.items() if s.lost_frames},
            errors=dict(self.errors), latency=latency, last_error=self.last_error[:500],
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


class _Stop(Exception):
    pass


class NodeLoop:
    """One node's share of a process's loop: its sockets, its source ticks, timer and heartbeat.

    A process usually runs one node; a container (``container:`` in the launch file) runs several in
    one loop, wired over ``inproc://`` sockets, which saves most of ZeroMQ's cross-process wake-ups."""

    def __init__(self, spec: NodeSpec, node_cls: type[Node], zctx: zmq.Context | None = None):
        if node_cls.header_only and node_cls.on_raw is Node.on_raw:
            raise TypeError(f"{node_cls.__name__} is header_only, so it must handle bytes in on_raw")
        self.spec, self.node_cls = spec, node_cls
        params = node_cls.Params.model_validate(spec.params)
        self.ctx = ctx = NodeContext(spec, node_cls, zctx, params)
        ctx.open()
        self.node = node_cls(params, ctx)
        self.control = None
        if spec.control_endpoint:
            self.control = ctx.zctx.socket(zmq.DEALER)
            self.control.setsockopt(zmq.LINGER, 0)
            self.control.connect(spec.control_endpoint)
        self.started_at = self.next_heartbeat = self.next_tick = time.monotonic()
        self.timer = node_cls.timer_period_s
        self.next_timer = self.started_at + (self.timer or 0)
        self.ready_sent = False
        self.set_up = False          # setup() returned: teardown() has something to tear down
        self.said_failed = False
        self.started = self.control is None  # without a launcher, run at once
        self.finished = False
        self.wants_bytes = node_cls.on_raw is not Node.on_raw  # a recorder (hand-offs get encoded for it)

    def setup_failed(self, e: Exception) -> None:
        """A node that cannot start says why in one line: to the launcher (which stops a graph that never
        started, rather than restarting the node in a loop) and in its log. A fault of ours keeps its traceback."""
        text = f"{type(e).__name__}: {e}"
        if isinstance(e, EXPECTED_SETUP_ERRORS) or type(e).__name__ in EXPECTED_SETUP_ERROR_NAMES:
            self.ctx.log.error("cannot start: %s", text)
        else:
            self.ctx.log.exception("cannot start: %s", text)
        if self.control is not None:
            self.control.send_multipart([b"failed", self.spec.id.encode(), text.encode(errors="replace")])
            self.said_failed = True

    def settled(self) -> bool:
        """Started and reported ready: from now on its side sockets need only an occasional look."""
        return self.started and (self.ready_sent or self.control is None)

    def sockets(self) -> list[zmq.Socket]:
        return [s for s in (self.ctx.sub, self.ctx.pub, self.control) if s is not None]

    def is_pure_source(self) -> bool:
        return not self.ctx.subscribes and self.ctx.pub is not None

    def wait_s(self, now: float) -> float:
        """How long the process may block in poll before this node has something to do."""
        if self.ctx.inbox:
            return 0.0
        if self.node_cls.is_source and self.started and not self.finished:
            wait = max(0.0, self.next_tick - now)
        else:
            wait = 0.1
        wait = min(wait, max(0.0, self.next_heartbeat - now), 0.1)
        if self.timer:
            wait = min(wait, max(0.0, self.next_timer - now))
        return wait

    def step(self, events: dict) -> bool:
        """Do what is due; False once a source has finished."""
        ctx, node, spec = self.ctx, self.node, self.spec
        now = time.monotonic()
        if not self.ready_sent and self.control is not None:
            ctx.read_subscriptions()
            if ctx.subscribers_connected():
                self.control.send_multipart([b"ready", spec.id.encode()])
                self.ready_sent = True
                self.started = self.started or not self.node_cls.is_source  # only sources wait for "start"
        if self.node_cls.is_source and self.started and now >= self.next_tick:
            try:
                delay = node.tick()
            except Exception as e:  # a source error ends the source, not silently
                ctx.handler_error("tick", e)
                raise
            if delay is None:
                self.finished = True
                ctx.log.info("source finished")
                return False
            self.next_tick = max(self.next_tick + delay, now - 0.05)  # keep cadence, never race to catch up
        # Read whether or not poll named the SUB socket: in a container, what an upstream node handed
        # over a moment ago in this same pass is in the inbox (or, for heartbeats, on inproc) already.
        if ctx.subscribes:
            self._read_sub(ctx.sub in events)
        if ctx.pub is not None and ctx.pub in events:
            ctx.read_subscriptions()
        if self.control is not None and self.control in events:
            try:
                while True:
                    if self.control.recv_multipart(zmq.NOBLOCK)[0] == b"start":
                        self.started = True
                        self.next_tick = time.monotonic()
            except zmq.Again:
                pass
        if self.timer and time.monotonic() >= self.next_timer:
            self.next_timer = time.monotonic() + self.timer
            try:
                node.on_timer()
            except Exception as e:
                ctx.handler_error("timer", e)
        if time.monotonic() >= self.next_heartbeat:
            state = "running" if self.started else "waiting"
            ctx.send_raw(DIAGNOSTICS, encode(_stamped(ctx, ctx.heartbeat(state, self.started_at))))
            self.next_heartbeat += HEARTBEAT_PERIOD_S
        return True

    def _read_inbox(self) -> None:
        """Handle what container neighbours handed over (all of it: they put it there this pass)."""
        ctx, node, inbox = self.ctx, self.node, self.ctx.inbox
        newest: dict[str, Message] = {}
        while inbox:
            wire, msg = inbox.popleft()
            if not ctx.account(wire, msg.header):
                continue
            if self.spec.keep_last:
                if wire in newest:
                    ctx._sub_stats[wire].drops += 1  # keep-last: an older frame nobody will see
                newest[wire] = msg
                continue
            _handle_local(ctx, node, wire, msg, self.wants_bytes)
        for wire, msg in newest.items():
            _handle_local(ctx, node, wire, msg, self.wants_bytes)

    def _read_sub(self, polled: bool) -> None:
        ctx, node, sub = self.ctx, self.node, self.ctx.sub
        if ctx.inbox:
            self._read_inbox()
        if not ctx.sub_connected:
            return
        if polled and not self.spec.keep_last:
            # Poll named the socket, so a message is there: handle it and go back to poll, which
            # returns at once if more wait. Asking EVENTS after every message costs 1.6 us of the
            # next message's latency, and a backlog is rare.
            _handle(ctx, node, ctx.recv_frames(), self.wants_bytes)
            return
        batch_end = time.monotonic() + 0.02
        newest: dict[bytes, list] = {}
        for _ in range(1000):  # bounded batch (count and time): heartbeats and ticks still run
            # Asking for EVENTS is far cheaper than the zmq.Again exception of an empty recv.
            if not sub.getsockopt(zmq.EVENTS) & _POLLIN or time.monotonic() > batch_end:
                break
            frames = ctx.recv_frames()
            if self.spec.keep_last and len(frames) == 2:
                if frames[0] in newest:
                    ctx.skipped(frames[0])  # keep-last: an older frame nobody will see
                newest[frames[0]] = frames
                continue
            _handle(ctx, node, frames, self.wants_bytes)
        for frames in newest.values():
            _handle(ctx, node, frames, self.wants_bytes)

    def finish(self, code: int) -> int:
        """Drain (if asked), tear down, say goodbye on diagnostics, close. Returns the exit code."""
        ctx = self.ctx
        if self.node_cls.drain_on_stop and code == 0:
            self._read_inbox()
            n = ctx.drain(lambda frames: _handle(ctx, self.node, frames, self.wants_bytes), DRAIN_S)
            if n:
                ctx.log.info("handled %d queued frames before stopping", n)
        try:
            if self.set_up:
                self.node.teardown()
        except Exception as e:
            ctx.log.exception("teardown failed: %s", e)
            code = 1
        if ctx.pub is not None:
            final = "finished" if self.finished else ("error" if code else "stopping")
            ctx.send_raw(DIAGNOSTICS, encode(_stamped(ctx, ctx.heartbeat(final, self.started_at))))
        if self.control is not None:
            self.control.close(linger=1000 if self.said_failed else 0)  # why it failed must reach the launcher
        ctx.close(flush_s=FLUSH_S if self.finished else 0.0)
        return code


def wire_hand_over(loops: list[NodeLoop]) -> None:
    """Connect a container's publishers to the neighbours that read their topics in-process."""
    readers: dict[str, list[NodeContext]] = collections.defaultdict(list)  # wire topic -> its readers
    for loop in loops:
        for wire in loop.ctx.spec.local_topics:
            readers[wire].append(loop.ctx)
    for loop in loops:
        loop.ctx.local_readers = {w: readers[w] for w in map(loop.ctx.wire_topic, loop.ctx.publishes)
                                  if w in readers}


def run_node(spec: NodeSpec, node_cls: type[Node], zctx: zmq.Context | None = None) -> int:
    """Run one node until SIGINT/SIGTERM, or until a source finishes. Returns the exit code."""
    return run_nodes([(spec, node_cls)], zctx)


def run_nodes(nodes: list[tuple[NodeSpec, type[Node]]], zctx: zmq.Context | None = None) -> int:
    """Run one node, or a container of several sharing one ZeroMQ context and one loop."""
    stopping = False

    def on_signal(signum, _frame):
        nonlocal stopping
        stopping = True

    if zctx is None and len(nodes) > 1:
        zctx = zmq.Context()  # inproc links work only within one context
    loops = [NodeLoop(spec, cls, zctx) for spec, cls in nodes]
    wire_hand_over(loops)
    poller = zmq.Poller()
    for loop in loops:
        for s in loop.sockets():
            poller.register(s, zmq.POLLIN)
    # Once the graph runs, the XPUB (subscription notices) and control sockets matter only now and
    # then: most polls watch the SUB sockets alone, which is cheaper on every message's path.
    data_poller = zmq.Poller()
    for loop in loops:
        if loop.ctx.sub_connected:
            data_poller.register(loop.ctx.sub, zmq.POLLIN)
    settled, next_side_poll = False, 0.0
    pure_source = len(loops) == 1 and loops[0].is_pure_source()
    code, current = 0, loops[0]
    try:
        for current in loops:
            try:
                current.node.setup()
            except KeyboardInterrupt:  # Ctrl-C while starting: the whole process group was asked to stop
                return 0
            except Exception as e:
                current.setup_failed(e)
                return SETUP_FAILED
            current.set_up = True
        # Until here a stop signal ends the process at once (a setup may load kernels for seconds, and has
        # nothing to flush); from here on it ends the loop, and teardown runs.
        signal.signal(signal.SIGINT, on_signal)
        signal.signal(signal.SIGTERM, on_signal)
        # What setup built (a bag's messages, kernels, tables) lives as long as the node: move it out
        # of the collector's sight, so a full collection cannot stall the loop for milliseconds.
        gc.collect()
        gc.freeze()
        running = True
        while running and not stopping:
            now = time.monotonic()
            wait_s = loops[0].wait_s(now) if len(loops) == 1 else min(loop.wait_s(now) for loop in loops)
            if wait_s < 0.001 and pure_source:
                time.sleep(wait_s)  # a pure source: sub-millisecond pacing without spinning a core
                wait_s = 0.0
            settled = settled or (bool(data_poller.sockets) and all(lp.settled() for lp in loops))
            # zmq polls in whole milliseconds; below one, poll without blocking.
            if settled and now < next_side_poll:
                events = dict(data_poller.poll(int(min(wait_s, next_side_poll - now) * 1000)))
            else:
                events = dict(poller.poll(int(wait_s * 1000)))
                next_side_poll = now + SIDE_POLL_S
            for current in loops:  # in launch-file order: upstream first, so a frame crosses in one pass
                running = current.step(events) and running
    except Exception as e:
        current.ctx.log.exception("node failed: %s", e)
        code = 1
    finally:
        for loop in loops:
            code = max(code, loop.finish(code))
    return code


def _handle_local(ctx: NodeContext, node: Node, wire: str, msg: Message, wants_bytes: bool) -> None:
    ctx.in_hand = msg
    ctx.received_ns = time.time_ns()
    try:
        _deliver(ctx, node, ctx._logical[wire], wire, msg, None, wants_bytes)
    finally:
        ctx.in_hand = None


def _handle(ctx: NodeContext, node: Node, frames: list[bytes], wants_bytes: bool) -> None:
    got = ctx.receive(frames)
    if got is not None:
        _deliver(ctx, node, got[0], frames[0].decode(), got[1], frames[1], wants_bytes)


def _deliver(ctx: NodeContext, node: Node, logical: str, wire: str, msg: Message | None, payload: bytes | None,
             wants_bytes: bool) -> None:
    """Call the node's handler (with the wire bytes, encoding a handed-over message, if it wants them)."""
    try:
        if wants_bytes:
            node.on_raw(wire, payload if payload is not None else encode(msg), msg)
        else:
            node.on_message(logical, msg)
    except Exception as e:
        ctx.handler_error(logical, e)


def _freeze_arrays(msg: Message) -> Message:
    """Make a handed-over message's arrays read-only, as arrays decoded from bytes are."""
    d = msg.__dict__
    for name in array_fields(type(msg)):
        d[name].flags.writeable = False
    return msg


def _stamped(ctx: NodeContext, hb: Heartbeat) -> Heartbeat:
    ctx._seq[DIAGNOSTICS] += 1
    hb.header.seq, hb.header.publisher = ctx._seq[DIAGNOSTICS], ctx.publisher_id
    return hb


def configure_logging(level: str = "INFO") -> None:
    logging.basicConfig(level=level, format="%(asctime)s %(levelname)s %(name)s: %(message)s")


def params_of(node_cls: type[Node], overrides: dict[str, Any]) -> BaseModel:
    return node_cls.Params.model_validate(overrides)

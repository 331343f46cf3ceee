"""A node's transport (NodeContext): its sockets, publishing, receiving and decoding, the hand-over between
neighbours in a container, and its statistics (nodes.node_stats)."""
from __future__ import annotations

import collections
import copy
import logging
import os
import time

import zmq
from pydantic import BaseModel

from messages import ALL_MESSAGES, DecodeError, Header, Heartbeat, Message, decode, encode
from messages.codec import MAX_MESSAGE_BYTES, decode_header
from messages.fastpath import array_fields, prepare
from nodes.node import Node
from nodes.node_stats import DIAGNOSTICS, NodeStats
from nodes.spec import NodeSpec

# Plain ints: combining pyzmq's enum flags costs microseconds per call on the hot path.
_NOBLOCK, _MORE = int(zmq.NOBLOCK), int(zmq.NOBLOCK | zmq.SNDMORE)


def inproc_endpoint(node_id: str) -> str:
    return f"inproc://{node_id}"


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
        self.stats = NodeStats(self.log)
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
        self.cpu_split = os.environ.get("MOCAP_CPU_SPLIT") == "1"  # count handlers' and publishing's CPU
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
        if self.cpu_split:
            t = time.thread_time()
            self._publish(topic, msg, source)
            self.stats.publishing_cpu_s += time.thread_time() - t
        else:
            self._publish(topic, msg, source)

    def _publish(self, topic: str, msg: Message, source: Message | None) -> None:
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
        freeze_arrays(msg)
        for reader in readers:
            reader.hand_over(wire, msg)
        if self._has_outside(wire):
            self._send(wire, encode(msg))
        else:
            self.stats.published[wire].count += 1

    def send_raw(self, wire_topic: str, payload: bytes) -> None:
        """Send bytes already encoded (a bag's, a heartbeat); neighbours in a container get them decoded."""
        for reader in self.local_readers.get(wire_topic, ()):
            try:
                reader.hand_over(wire_topic, freeze_arrays(decode(payload, wire_topic)))
            except DecodeError as e:
                reader.count_error(f"decode_{e.kind}", str(e))
        self._send(wire_topic, payload)

    def _send(self, wire_topic: str, payload: bytes) -> None:
        try:  # two sends rather than send_multipart: a few microseconds less per message
            self.pub.send(wire_topic.encode(), _MORE)
            self.pub.send(payload, _NOBLOCK)
        except zmq.Again:  # HWM reached on every peer: keep-last semantics, the frame is dropped
            self.stats.errors["send_dropped"] += 1
            return
        self.stats.published[wire_topic].count += 1

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
        self.stats.arrived(wire, h)
        return True

    def skipped(self, wire: str) -> None:
        """A message left unhandled (keep-last: an older frame nobody will see), counted as a drop."""
        self.stats.received[wire].drops += 1

    def logical_topic(self, wire: str) -> str:
        return self._logical[wire]

    def count_error(self, reason: str, text: str, n: int = 1) -> None:
        """Something a node met and handled itself (a marker put wrong, a limb late): counted per reason in the
        heartbeat's errors, the text logged for the first few of each reason. The runtime counts its own (bad
        framing, undecodable messages) the same way."""
        self.stats.count_error(reason, text, n)

    def handler_error(self, topic: str, exc: BaseException) -> None:
        self.count_error(f"handler_{type(exc).__name__}", f"handler for {topic!r} failed: {exc!r}")

    # -- heartbeat ---------------------------------------------------------------------------------
    def heartbeat(self, state: str, started_at: float) -> Heartbeat:
        return self.stats.heartbeat(self.spec.id, self.spec.kind, state, started_at)


def freeze_arrays(msg: Message) -> Message:
    """Make a handed-over message's arrays read-only, as arrays decoded from bytes are."""
    d = msg.__dict__
    for name in array_fields(type(msg)):
        d[name].flags.writeable = False
    return msg

"""The loop that runs one node, or a container of several, in a process: setup, polling, source ticks, timers,
heartbeats, the launcher's start and stop, and a clean shutdown (nodes.runtime says what it guarantees)."""
from __future__ import annotations

import collections
import gc
import logging
import math
import signal
import time

import zmq

from messages import Heartbeat, Message, encode
from mocap_core.warmup import warm_up
from nodes.node import Node
from nodes.node_stats import DIAGNOSTICS
from nodes.spec import NodeSpec
from nodes.transport import NodeContext

HEARTBEAT_PERIOD_S = 1.0
FLUSH_S = 1.0   # a finished source's last frames still go out
DRAIN_S = 0.5   # a drain_on_stop node's queued frames still get handled
SIDE_POLL_S = 0.05  # a running node reads subscription notices and launcher commands this often
SETUP_FAILED = 3  # exit code of a node whose setup raised: the launcher stops a graph that never started
# What a user's configuration causes (a profile, a file, a port): one line, no traceback. By name, so the runtime
# depends on no solving module.
EXPECTED_SETUP_ERRORS = (OSError,)
EXPECTED_SETUP_ERROR_NAMES = {"ProfileError", "RecordingError", "SubjectError", "BagError", "ConstraintsError",
                              "ValidationError", "ValueError"}
_POLLIN = int(zmq.POLLIN)


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

    def wait_ms(self, now: float) -> float:
        """How long (ms) the process may block in poll before this node has something to do. A timer or heartbeat
        is waited for to the next whole millisecond, as zmq polls: one due within a millisecond, rounded down,
        would have the loop poll without blocking, spinning a core, until it is due. A source's tick keeps its
        precision (a pure source sleeps the fraction)."""
        if self.ctx.inbox:
            return 0.0
        wait = min(self.next_heartbeat - now, 0.1)
        if self.timer:
            wait = min(wait, self.next_timer - now)
        wait = ceil_ms(wait)
        if self.node_cls.is_source and self.started and not self.finished:
            wait = min(wait, max(0.0, 1000 * (self.next_tick - now)))
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
            t = time.thread_time() if ctx.cpu_split else 0.0
            try:
                delay = node.tick()
            except Exception as e:  # a source error ends the source, not silently
                ctx.handler_error("tick", e)
                raise
            if ctx.cpu_split:
                ctx.stats.handlers_cpu_s += time.thread_time() - t
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
                    ctx.skipped(wire)  # keep-last: an older frame nobody will see
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
                    ctx.skipped(frames[0].decode("utf-8", "replace"))  # keep-last: an older frame nobody will see
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


def ceil_ms(seconds: float) -> int:
    """A wait in whole milliseconds, rounded up (none: 0)."""
    return max(0, math.ceil(seconds * 1000))


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
                warm_up(type(current.node).kernels(current.node.params), stamp=False)  # (the launcher stamps)
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
            wait_ms = loops[0].wait_ms(now) if len(loops) == 1 else min(loop.wait_ms(now) for loop in loops)
            if wait_ms < 1 and pure_source:
                time.sleep(wait_ms / 1000)  # a pure source: sub-millisecond pacing without spinning a core
                wait_ms = 0.0
            settled = settled or (bool(data_poller.sockets) and all(lp.settled() for lp in loops))
            # zmq polls in whole milliseconds: below one (a source's tick), poll without blocking.
            if settled and now < next_side_poll:
                events = dict(data_poller.poll(int(min(wait_ms, ceil_ms(next_side_poll - now)))))
            else:
                events = dict(poller.poll(int(wait_ms)))
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
        _deliver(ctx, node, ctx.logical_topic(wire), wire, msg, None, wants_bytes)
    finally:
        ctx.in_hand = None


def _handle(ctx: NodeContext, node: Node, frames: list[bytes], wants_bytes: bool) -> None:
    got = ctx.receive(frames)
    if got is not None:
        _deliver(ctx, node, got[0], frames[0].decode(), got[1], frames[1], wants_bytes)


def _deliver(ctx: NodeContext, node: Node, logical: str, wire: str, msg: Message | None, payload: bytes | None,
             wants_bytes: bool) -> None:
    """Call the node's handler (with the wire bytes, encoding a handed-over message, if it wants them)."""
    t = time.thread_time() if ctx.cpu_split else 0.0
    try:
        if wants_bytes:
            node.on_raw(wire, payload if payload is not None else encode(msg), msg)
        else:
            node.on_message(logical, msg)
    except Exception as e:
        ctx.handler_error(logical, e)
    if ctx.cpu_split:
        ctx.stats.handlers_cpu_s += time.thread_time() - t


def _stamped(ctx: NodeContext, hb: Heartbeat) -> Heartbeat:
    ctx._seq[DIAGNOSTICS] += 1
    hb.header.seq, hb.header.publisher = ctx._seq[DIAGNOSTICS], ctx.publisher_id
    return hb


def configure_logging(level: str = "INFO") -> None:
    logging.basicConfig(level=level, format="%(asctime)s %(levelname)s %(name)s: %(message)s")

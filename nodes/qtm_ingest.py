"""Stage 1 (live): labelled markers from Qualisys Track Manager, through the official ``qtm-rt`` client.

The client is asyncio; it runs in a thread of its own and hands frames to the node over a queue,
so the node's loop (heartbeats, publishing) never waits on the network. Labels and rate come from
the 3D and General parameters at every (re)connection; a label change publishes a new MarkerSet. Every frame's
header carries QTM's up axis (``AxisUpwards``; ``up_axis`` overrides a QTM that says it wrongly).
When QTM goes away the thread tries again every 0.25-0.5 s (``max_backoff_s``), so frames resume within a second
of QTM's return, and says so; a connection that QTM never answers is given up (and closed) after ``timeout_s``.
A watchdog reconnects when no frame came for ``stall_s`` and QTM did not say it stopped (``qtm_stall`` in the
heartbeat's errors); framing no QTM sends (sizes, component tables) closes the connection (``qtm_garbage``)
before qtm-rt's parser can spin on it (nodes/qtm_guard.py). Nothing from the network can stop the node.
"""
from __future__ import annotations

import asyncio
import queue
import threading
import time
import xml.etree.ElementTree as ET

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator

from messages import FLAG_MEASURED, FLAG_MISSING, MarkerFrame, MarkerSet
from mocap_core.world import DEFAULT_UP, normalize_up
from nodes.qtm_guard import GuardedReceiver
from nodes.actor_split import ActorSplit, actor_topics
from nodes.runtime import Node

UNITS_M = 0.001  # QTM streams millimetres
MIN_BACKOFF_S = 0.25
AWAY_LOG_S = 10.0


class Params(BaseModel):
    model_config = ConfigDict(extra="forbid")
    host: str = "127.0.0.1"
    port: int = Field(22223, ge=1, le=65535)
    version: str = "1.25"
    frames: str = Field("allframes", description="allframes, frequency:N or frequencydivisor:N")
    timeout_s: float = Field(5.0, gt=0)
    max_backoff_s: float = Field(0.5, gt=0, description="longest wait between connection attempts")
    stall_s: float = Field(1.0, ge=0, description="no frame for this long, and QTM did not say it stopped: "
                                                  "an error and a reconnect (0 = never)")
    up_axis: str | None = Field(None, description="the world's up axis (+z, -y, ...) over QTM's AxisUpwards")
    actors: list[str] = Field(default_factory=list, description="split the stream by the subject in front of "
                              "each label (actor1:LASI) onto mocap/<actor>/markers/raw; the launch file's actors: "
                              "sets it")

    @field_validator("up_axis")
    @classmethod
    def _up(cls, v):
        return None if v is None else normalize_up(v)


class QtmIngest(Node):
    kind = "qtm_ingest"
    Params = Params
    publishes = {"markers/raw": MarkerFrame, "markers/set": MarkerSet}
    is_source = True

    @classmethod
    def outputs(cls, params):
        return {**cls.publishes, **actor_topics(params.actors)}

    def setup(self) -> None:
        self.inbox: queue.Queue = queue.Queue(maxsize=10000)
        self.split = ActorSplit(self.ctx, self.params.actors, self.log)
        self.labels: list[str] = []
        self.up_axis = self.params.up_axis or DEFAULT_UP
        self.stopping = threading.Event()
        self.started_ns: int | None = None
        self.stale, self.stale_logged = 0, False
        self.thread = threading.Thread(target=self._client_thread, name="qtm-rt", daemon=True)
        self.thread.start()

    def tick(self) -> float | None:
        if self.started_ns is None:
            # The client streams from setup on, so that a missing QTM shows before the graph starts;
            # what came before the graph was ready is stale: it would enter as a burst seconds late.
            self.started_ns = time.time_ns()
        try:
            item = self.inbox.get(timeout=0.05)
        except queue.Empty:
            return 0.0
        while True:
            kind, payload = item
            if kind == "frame" and payload[3] < self.started_ns:
                self.stale += 1
            elif kind == "set":
                self.labels, rate, up = payload
                self.up_axis = self.params.up_axis or up
                self.split.publish("markers/set", MarkerSet(header=MarkerSet.make_header(up_axis=self.up_axis),
                                                            labels=self.labels, rate_hz=rate,
                                                            source=f"qtm://{self.params.host}"))
            elif kind == "frame":
                self._publish_frame(*payload)
            elif kind == "error":
                self.ctx.count_error(payload[0], payload[1])
            try:
                item = self.inbox.get_nowait()
            except queue.Empty:
                if self.stale and not self.stale_logged:
                    self.stale_logged = True
                    self.log.info("skipped %d frames received before the graph was ready", self.stale)
                return 0.0

    def _publish_frame(self, frame: int, timestamp_us: int, xyz_mm: np.ndarray, received_ns: int) -> None:
        if xyz_mm.shape[0] != len(self.labels):
            self.ctx.count_error("label_count", f"frame {frame}: {xyz_mm.shape[0]} markers for {len(self.labels)} labels")
            return
        pos = (xyz_mm * UNITS_M).astype(np.float32)
        flags = np.where(np.isnan(pos).any(axis=1), FLAG_MISSING, FLAG_MEASURED).astype(np.uint8)
        self.split.publish("markers/raw", MarkerFrame(
            header=MarkerFrame.make_header(frame, timestamp_us / 1e6, received_ns, self.up_axis), labels=self.labels,
            positions=pos, flags=flags))

    def teardown(self) -> None:
        self.stopping.set()
        self.thread.join(timeout=0.5)  # a daemon thread: never hold up the 2 s shutdown

    # -- the qtm-rt side, in its own thread ------------------------------------------------------------
    def _client_thread(self) -> None:
        asyncio.run(self._client_loop())

    async def _client_loop(self) -> None:
        import qtm_rt

        p = self.params
        backoff, away_since, said_away = MIN_BACKOFF_S, None, 0.0
        was_connected = False
        while not self.stopping.is_set():
            lost = asyncio.Event()
            loop = _GuardedLoop(asyncio.get_running_loop(), self._bad_stream)
            try:  # (qtm_rt waits for QTM's answer to its version command without a timeout of its own)
                conn = await asyncio.wait_for(
                    qtm_rt.connect(p.host, port=p.port, version=p.version, timeout=p.timeout_s, loop=loop,
                                   on_disconnect=lambda exc, lost=lost: lost.set(),  # (this session's)
                                   on_event=self._on_event), p.timeout_s)
            except asyncio.TimeoutError:
                conn = None
                for transport in loop.transports:  # (else the connection given up on stays open)
                    transport.close()
            if conn is None:
                now = time.monotonic()
                away_since = away_since or now
                if now - said_away >= AWAY_LOG_S:  # said at once, then every AWAY_LOG_S: retries are frequent
                    said_away = now
                    self.log.warning("QTM at %s:%d not reachable%s; retrying every %.1f s", p.host, p.port,
                                     f" for {now - away_since:.0f} s" if now > away_since else "", p.max_backoff_s)
                await self._sleep(backoff)
                backoff = min(backoff * 2, p.max_backoff_s)
                continue
            away_since, said_away = None, 0.0
            try:
                root = ET.fromstring(await conn.get_parameters(parameters=["general", "3d"]))
                labels = [e.text or "" for e in root.findall("The_3D/Label/Name")]
                rate = float(root.findtext("General/Frequency") or 0)
                up = _up_axis(root.findtext("The_3D/AxisUpwards"))
                if labels != self.labels or not was_connected:
                    self.log.info("QTM %s:%d: %d labels at %.0f Hz%s", p.host, p.port, len(labels), rate,
                                  " (labels changed)" if was_connected and labels != self.labels else "")
                self.inbox.put(("set", (labels, rate, up)))
                self.last_frame_s, self.said_no_3d = time.monotonic(), False  # (the watchdog counts from here)
                await conn.stream_frames(frames=p.frames, components=["3d"], on_packet=self._on_packet)
                was_connected, backoff = True, MIN_BACKOFF_S
                await self._watch(loop.receiver, lost)
            except Exception as e:  # a QTM that answers nonsense: count it, wait, try again
                self.inbox.put(("error", ("qtm_session", f"QTM session failed: {e!r}")))
                await self._sleep(backoff)
                backoff = min(backoff * 2, p.max_backoff_s)
            finally:
                try:
                    conn.disconnect()
                except Exception:
                    pass

    async def _watch(self, receiver, lost: asyncio.Event) -> None:
        """While streaming: until the connection is lost, or (the watchdog) no frame with 3D data came for
        ``stall_s`` and QTM did not say it stopped."""
        p = self.params
        while not lost.is_set() and not self.stopping.is_set():
            await asyncio.sleep(0.05)
            silent = time.monotonic() - self.last_frame_s
            if p.stall_s and not receiver.stopped and silent > p.stall_s:
                self.inbox.put(("error", ("qtm_stall", f"no frame from QTM at {p.host}:{p.port} for {silent:.1f} s; "
                                                       "reconnecting")))
                return
        if lost.is_set():
            self.log.warning("lost the connection to QTM at %s:%d; reconnecting", p.host, p.port)

    def _bad_stream(self, transport, why: str) -> None:
        """QTM's port sent what no QTM sends: counted, and the connection closed (the loop reconnects)."""
        self.inbox.put(("error", ("qtm_garbage", f"{why}; reconnecting")))
        transport.close()

    async def _sleep(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end and not self.stopping.is_set():
            await asyncio.sleep(0.05)

    def _on_packet(self, packet) -> None:
        received = time.time_ns()
        try:
            comp = packet.get_3d_markers()
            if comp is None:  # (2D only, or nothing: the watchdog reconnects if it goes on)
                if not self.said_no_3d:
                    self.said_no_3d = True
                    self.inbox.put_nowait(("error", ("qtm_no_3d", "QTM sends frames without 3D data: is its 3D "
                                                                  "tracking running?")))
                return
            self.last_frame_s = time.monotonic()
            _, markers = comp
            xyz = np.array([(m.x, m.y, m.z) for m in markers], dtype=np.float64).reshape(-1, 3)
            self.inbox.put_nowait(("frame", (packet.framenumber, packet.timestamp, xyz, received)))
        except queue.Full:
            self.dropped_full = getattr(self, "dropped_full", 0) + 1  # the node is not keeping up
        except Exception as e:
            try:
                self.inbox.put_nowait(("error", ("bad_packet", f"bad QTM packet: {e!r}")))
            except queue.Full:
                pass

    def _on_event(self, event) -> None:
        name = getattr(event, "name", str(event))
        self.log.info("QTM event: %s", name)


def _up_axis(text: str | None) -> str:
    """QTM's AxisUpwards ("+Z", "-Y", ...); QTM's default where it says nothing we understand."""
    try:
        return normalize_up(text or DEFAULT_UP)
    except ValueError:
        return DEFAULT_UP


class _GuardedLoop:
    """The running loop, keeping what ``qtm_rt.connect`` opens with it (a connect given up on leaves its connection
    open otherwise, and qtm-rt hands back nothing to close it with), and putting a GuardedReceiver in front of
    qtm-rt's parser before any byte arrives (nodes/qtm_guard.py)."""

    def __init__(self, loop: asyncio.AbstractEventLoop, on_bad):
        self._loop, self._on_bad, self.transports, self.receiver = loop, on_bad, [], None

    def __getattr__(self, name):
        return getattr(self._loop, name)

    async def create_connection(self, *args, **kwargs):
        transport, protocol = await self._loop.create_connection(*args, **kwargs)
        self.transports.append(transport)
        self.receiver = GuardedReceiver(protocol._handlers, lambda why: self._on_bad(transport, why))
        protocol._receiver = self.receiver  # (no data is handled before this coroutine step ends)
        return transport, protocol

"""`mocap qtm-sim FILE`: a QTM real-time server (protocol 1.25) that replays a recording.

It plays the part of Qualisys Track Manager running "RT from file": one measurement clock shared
by every client, frames paced in real time at the recording's rate (or ``--rate``), the official
``qtm-rt`` client's handshake and commands, NoMoreData and event 9 at the end (``--loop`` starts
again with event 8). A malformed command gets an Error packet; a client that does not speak the
protocol is disconnected; the server itself never stops for a client's sake.

Fault injection for tests: ``--drop-after N`` closes each client after N data frames,
``--stall-at N --stall-s S`` freezes the clock once at frame N, ``--no-3d-from N`` sends frames with no
3D data from frame N on, ``--hide LABEL:FIRST-LAST`` hides a marker for a range of frames (repeatable).
"""
from __future__ import annotations

import argparse
import asyncio
import logging
import signal
import socket
import time
from dataclasses import dataclass, field

import numpy as np

from mocap_core import qtm_protocol as qp
from mocap_core.recordings import Recording
from mocap_core.up_axis import recording_up_axis
from mocap_core.world import DEFAULT_UP, normalize_up
from nodes.bags import read_take

log = logging.getLogger("mocap.qtm_sim")
SLOW_CLIENT_BYTES = 8 * 1024 * 1024  # a client this far behind is dropped rather than slowing the others


@dataclass
class Faults:
    drop_after: int = 0
    stall_at: int = -1
    stall_s: float = 0.0
    no_3d_from: int = -1
    hide: list[tuple[str, int, int]] = field(default_factory=list)


@dataclass(eq=False)  # clients are kept in a set, by identity
class Client:
    writer: asyncio.StreamWriter
    name: str
    stream: qp.StreamRequest | None = None
    sent: int = 0
    next_send_s: float = 0.0


class QtmEmulator:
    def __init__(self, rec: Recording, rate_hz: float | None = None, loop: bool = False, up_axis: str = DEFAULT_UP,
                 faults: Faults | None = None):
        self.rec = rec
        self.rate = rate_hz or rec.rate_hz
        self.loop = loop
        self.up_axis = up_axis
        self.faults = faults or Faults()
        self.positions_mm = rec.positions.astype(np.float64) * 1000.0  # QTM streams millimetres
        for label, first, last in self.faults.hide:
            if label not in rec.labels:
                raise ValueError(f"--hide {label}: no such label (labels: {', '.join(rec.labels[:20])} ...)")
            self.positions_mm[first:last + 1, rec.labels.index(label)] = np.nan
        self.clients: set[Client] = set()
        self.index = 0              # next frame of the measurement
        self.running = False        # the measurement clock starts at the first stream or frame request
        self.finished = False
        self.started = asyncio.Event()
        self.stalled = False

    # -- the measurement clock --------------------------------------------------------------------------
    async def produce(self) -> None:
        await self.started.wait()
        t0 = time.monotonic()
        start_index = self.index
        while True:
            due = t0 + (self.index - start_index) / self.rate
            delay = due - time.monotonic()
            if delay > 0:
                await asyncio.sleep(delay)
            if self.index == self.faults.stall_at and not self.stalled:
                self.stalled = True
                log.warning("fault injection: stalling %.1f s at frame %d", self.faults.stall_s, self.index)
                await asyncio.sleep(self.faults.stall_s)
                t0 += self.faults.stall_s
            self.broadcast_frame(self.index)
            self.index += 1
            if self.index >= self.rec.n_frames:
                self.end_of_take()
                if not self.loop:
                    return
                self.index, start_index, t0 = 0, 0, time.monotonic()
                self.finished = False
                self.broadcast(qp.event_packet(qp.Event.RT_FROM_FILE_STARTED))
                log.info("looping: measurement restarted")

    def frame_bytes(self, index: int, components: tuple[str, ...]) -> bytes:
        if 0 <= self.faults.no_3d_from <= index:
            components = ()  # (a QTM whose 3D tracking stopped: frames with no component)
        return qp.data_packet(self.rec.first_frame + index, int(round(index / self.rec.rate_hz * 1e6)),
                              self.positions_mm[index], components)

    def broadcast_frame(self, index: int) -> None:
        t = index / self.rec.rate_hz
        cache: dict[tuple[str, ...], bytes] = {}
        for c in list(self.clients):
            s = c.stream
            if s is None or index % s.every_nth:
                continue
            if s.frequency_hz:
                if t + 1e-9 < c.next_send_s:
                    continue
                c.next_send_s = t + 1.0 / s.frequency_hz
            data = cache.get(s.components) or cache.setdefault(s.components, self.frame_bytes(index, s.components))
            self.send(c, data)
            c.sent += 1
            if self.faults.drop_after and c.sent >= self.faults.drop_after:
                log.warning("fault injection: dropping %s after %d frames", c.name, c.sent)
                self.drop(c)

    def end_of_take(self) -> None:
        self.finished = True
        log.info("end of take after %d frames", self.rec.n_frames)
        for c in list(self.clients):
            if c.stream is not None:
                self.send(c, qp.NO_MORE_DATA)
        self.broadcast(qp.event_packet(qp.Event.RT_FROM_FILE_STOPPED))

    def broadcast(self, data: bytes) -> None:
        for c in list(self.clients):
            self.send(c, data)

    def send(self, c: Client, data: bytes) -> None:
        if c.writer.is_closing():
            self.clients.discard(c)
            return
        if c.writer.transport.get_write_buffer_size() > SLOW_CLIENT_BYTES:
            log.warning("client %s is not reading; dropping it", c.name)
            self.drop(c)
            return
        c.writer.write(data)

    def drop(self, c: Client) -> None:
        self.clients.discard(c)
        c.writer.close()

    def start_measurement(self) -> None:
        if not self.running:
            self.running = True
            self.started.set()
            self.broadcast(qp.event_packet(qp.Event.RT_FROM_FILE_STARTED))

    # -- one client ---------------------------------------------------------------------------------------
    async def handle(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        peer = writer.get_extra_info("peername")
        c = Client(writer, f"{peer[0]}:{peer[1]}" if peer else "client")
        sock = writer.get_extra_info("socket")
        if sock is not None:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.clients.add(c)
        log.info("client %s connected (%d clients)", c.name, len(self.clients))
        writer.write(qp.text_packet(qp.PacketType.COMMAND, qp.WELCOME))  # before reading anything
        packets = qp.PacketReader()
        try:
            while not writer.is_closing():
                data = await reader.read(65536)
                if not data:
                    break
                for kind, payload in packets.feed(data):
                    self.on_packet(c, kind, payload)
        except qp.ProtocolError as e:
            log.warning("client %s sent garbage (%s): disconnecting it", c.name, e)
        except (ConnectionError, asyncio.IncompleteReadError):
            pass
        finally:
            self.clients.discard(c)
            writer.close()
            log.info("client %s disconnected (%d clients)", c.name, len(self.clients))

    def reply(self, c: Client, text: str, kind: qp.PacketType = qp.PacketType.COMMAND) -> None:
        self.send(c, qp.text_packet(kind, text))

    def on_packet(self, c: Client, kind: int, payload: bytes) -> None:
        if kind == qp.PacketType.XML:
            self.reply(c, "Setting parameters failed", qp.PacketType.ERROR)
            return
        text = payload.rstrip(b"\0").decode("ascii", "replace").strip()
        words = text.split()
        if not words:
            self.reply(c, "Parse Error", qp.PacketType.ERROR)
            return
        try:
            self.on_command(c, words[0].lower(), words[1:])
        except qp.CommandError as e:
            self.reply(c, str(e), qp.PacketType.ERROR)

    def on_command(self, c: Client, cmd: str, args: list[str]) -> None:
        if cmd == "version":
            if not args:
                self.reply(c, f"Version is {qp.PROTOCOL_VERSION}")
            elif _version_ok(args[0]):
                self.reply(c, f"Version set to {args[0]}")
            else:
                self.reply(c, "Version NOT supported", qp.PacketType.ERROR)
        elif cmd == "qtmversion":
            self.reply(c, qp.QTM_VERSION)
        elif cmd == "byteorder":
            self.reply(c, "Byte order is little endian")
        elif cmd in ("getstate", "getlastevent"):
            state = (qp.Event.RT_FROM_FILE_STOPPED if self.finished else
                     qp.Event.RT_FROM_FILE_STARTED if self.running else qp.Event.CONNECTED)
            self.send(c, qp.event_packet(state))
        elif cmd == "getparameters":
            xml = qp.parameters_xml(args, self.rec.labels, self.rec.rate_hz, self.up_axis.upper(),
                                    self.rec.n_frames / self.rec.rate_hz)
            self.reply(c, xml, qp.PacketType.XML)
        elif cmd == "getcurrentframe":
            comps = tuple(qp.validate_components([a.lower() for a in args]))
            self.start_measurement()
            index = min(self.index, self.rec.n_frames - 1)  # always exactly one Data packet [8.7]
            self.send(c, self.frame_bytes(index, comps))
        elif cmd == "streamframes":
            if args and args[0].lower() == "stop":
                c.stream = None  # no reply, and no more frames [2.2]
                return
            c.stream = qp.parse_stream_request(args)
            c.next_send_s = 0.0
            if self.finished and not self.loop:
                self.send(c, qp.NO_MORE_DATA)
            self.start_measurement()
        elif cmd == "takecontrol":
            self.reply(c, "You are now master")
        elif cmd == "releasecontrol":
            self.reply(c, "You are now a regular client")
        elif cmd in ("event", "setqtmevent"):
            self.reply(c, "Event set")
        elif cmd == "start":
            self.start_measurement()
            self.reply(c, "Starting RT from file" if args and args[0].lower() == "rtfromfile" else "Starting measurement")
        elif cmd == "stop":
            self.reply(c, "Stopping measurement")
        elif cmd == "new":
            self.reply(c, "Already connected")
        elif cmd == "close":
            self.reply(c, "No connection to close")
        else:
            raise qp.CommandError("Parse Error")


def _version_ok(text: str) -> bool:
    try:
        major, minor = (int(x) for x in text.split("."))
    except ValueError:
        return False
    return major == 1 and 1 <= minor <= 25


async def serve(emulator: QtmEmulator, host: str, port: int, ready_file: str | None = None) -> None:
    server = await asyncio.start_server(emulator.handle, host, port)
    bound = server.sockets[0].getsockname()[1]
    log.info("QTM RT emulator on %s:%d replaying %s (%d labels, %d frames at %.0f Hz)", host, bound,
             emulator.rec.source, len(emulator.rec.labels), emulator.rec.n_frames, emulator.rate)
    if ready_file:
        with open(ready_file, "w") as f:
            f.write(str(bound))
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    producer = asyncio.create_task(emulator.produce())
    async with server:
        await stop.wait()
    producer.cancel()
    for c in list(emulator.clients):
        c.writer.close()


def add_parser(sub) -> None:
    s = sub.add_parser("qtm-sim", help="QTM real-time server replaying a recording",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    s.add_argument("file", help="recording: .c3d, .trc or .mat (file.mat:take)")
    s.add_argument("--host", default="127.0.0.1", help="address to listen on (default loopback only)")
    s.add_argument("--port", type=int, default=qp.DEFAULT_PORT, help="TCP port (default 22223; 0 = any free port)")
    s.add_argument("--rate", type=float, help="replay rate in Hz (default: the recording's)")
    s.add_argument("--loop", action="store_true", help="start again at the end of the take")
    s.add_argument("--up-axis", type=_up_axis, metavar="AXIS",
                   help="the AxisUpwards to announce (+Z, -Y, ...; default: the recording's, from the file or "
                        "from the shipped profile its labels fit)")
    s.add_argument("--ready-file", help="write the bound port here once listening (for scripts and tests)")
    s.add_argument("--drop-after", type=int, default=0, metavar="N", help="fault: close each client after N frames")
    s.add_argument("--stall-at", type=int, default=-1, metavar="FRAME", help="fault: freeze the clock at this frame")
    s.add_argument("--stall-s", type=float, default=1.0, help="fault: how long the stall lasts")
    s.add_argument("--no-3d-from", type=int, default=-1, metavar="FRAME",
                   help="fault: frames from this one on carry no 3D data")
    s.add_argument("--hide", action="append", default=[], metavar="LABEL:FIRST-LAST",
                   help="fault: hide a marker for a frame range (repeatable)")
    s.set_defaults(func=run)


def run(args) -> int:
    hide = []
    for h in args.hide:
        try:
            label, rng = h.rsplit(":", 1)
            first, last = (int(x) for x in rng.split("-"))
        except ValueError:
            raise SystemExit(f"--hide {h!r}: expected LABEL:FIRST-LAST, e.g. --hide LELB:100-200") from None
        hide.append((label, first, last))
    rec = read_take(args.file)
    faults = Faults(args.drop_after, args.stall_at, args.stall_s, args.no_3d_from, hide)
    up = args.up_axis or recording_up_axis(rec, log) or DEFAULT_UP
    emulator = QtmEmulator(rec, args.rate, args.loop, up, faults)
    asyncio.run(serve(emulator, args.host, args.port, args.ready_file))
    return 0


def _up_axis(text: str) -> str:
    try:
        return normalize_up(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def start_emulator(take: str, *args: str, cwd: str | None = None):
    """Run `mocap qtm-sim TAKE ARGS` as a subprocess on a free port; returns (process, port) once it
    listens (for benchmarks and `mocap eval latency`). Stop it with SIGINT."""
    import subprocess
    import sys
    import tempfile
    import time
    from pathlib import Path

    ready = Path(tempfile.mkdtemp(prefix="mocap-qtm-")) / "port"
    proc = subprocess.Popen([sys.executable, "-m", "mocap_cli.main", "--log-level", "WARNING", "qtm-sim", str(take),
                             "--port", "0", "--ready-file", str(ready), *args], cwd=cwd)
    deadline = time.monotonic() + 30
    while not (ready.exists() and ready.read_text()):
        if proc.poll() is not None or time.monotonic() > deadline:
            raise RuntimeError(f"qtm-sim did not start (exit code {proc.poll()})")
        time.sleep(0.05)
    return proc, int(ready.read_text())

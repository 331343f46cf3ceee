"""The official qtm-rt client against our QTM emulator over real TCP, and the ingest node's recovery."""
import asyncio
import csv
import socket
import struct
import threading
import time
import xml.etree.ElementTree as ET

import numpy as np
import qtm_rt

from mocap_core.recordings import read_recording
from tests.conftest import data_file, emulator, free_port, launched, log_rows, wait_for

TAKE = "12_vicon_freeform_realgaps_nimble_nick_freeform_001.c3d"  # real gaps: NaN must come through


def test_qtm_rt_client_receives_the_take_exactly(tmp_path):
    rec = read_recording(data_file(TAKE))

    async def session(port):
        stopped = asyncio.Event()

        def on_event(ev):
            if ev == qtm_rt.QRTEvent.EventRTfromFileStopped:
                stopped.set()

        conn = await qtm_rt.connect("127.0.0.1", port=port, version="1.25", timeout=5, on_event=on_event)
        assert conn is not None
        assert (await conn.byte_order()) == b"Byte order is little endian"
        root = ET.fromstring(await conn.get_parameters(parameters=["general", "3d"]))
        labels = [e.text for e in root.findall("The_3D/Label/Name")]
        freq = float(root.findtext("General/Frequency"))
        frames = []
        assert await conn.stream_frames(components=["3d"], on_packet=frames.append) == b"Ok"
        await asyncio.wait_for(stopped.wait(), 30)
        try:
            await conn.get_current_frame(components=["6d"])  # valid for the SDK, not in this measurement
            error = None
        except qtm_rt.QRTCommandException as e:
            error = e.value
        conn.disconnect()
        return labels, freq, frames, error

    with emulator(tmp_path, "--rate", "1000") as (_, port):
        labels, freq, packets, error = asyncio.run(session(port))
    assert labels == rec.labels and freq == rec.rate_hz
    assert error == b"Component 6d is not available in this measurement"
    assert [p.framenumber for p in packets] == list(range(rec.n_frames))
    assert [p.timestamp for p in packets] == [round(i / rec.rate_hz * 1e6) for i in range(rec.n_frames)]
    got = np.array([[(m.x, m.y, m.z) for m in p.get_3d_markers()[1]] for p in packets])
    want = (rec.positions.astype(np.float64) * 1000).astype(np.float32)
    assert np.array_equal(np.isnan(got), np.isnan(want)) and np.isnan(want).any()
    np.testing.assert_allclose(got[~np.isnan(want)], want[~np.isnan(want)], rtol=1e-6)


def test_occluded_markers_are_all_ones_and_garbage_clients_are_dropped(tmp_path):
    with emulator(tmp_path, "--hide", "Nick01:LFHD:0-5000", "--rate", "500") as (proc, port):
        with socket.create_connection(("127.0.0.1", port)) as s:
            s.settimeout(5)
            welcome = s.recv(64)
            assert welcome == struct.pack("<II", 8 + 27, 1) + b"QTM RT Interface connected\0"
            cmd = b"getcurrentframe 3d\0"
            s.sendall(struct.pack("<II", 8 + len(cmd), 1) + cmd)
            head = b""
            while len(head) < 8:
                head += s.recv(8 - len(head))
            size, kind = struct.unpack("<II", head)
            while kind != 3:  # skip the event the measurement start broadcasts
                s.recv(size - 8)
                head = s.recv(8)
                size, kind = struct.unpack("<II", head)
            body = b""
            while len(body) < size - 8:
                body += s.recv(size - 8 - len(body))
            assert len(body) == 16 + 16 + 12 * 53
            # 16-byte frame header, 16-byte 3D component header, then 12 bytes per marker; LFHD is marker 1
            assert body[44:56] == b"\xff" * 12
            assert body[32:44] != b"\xff" * 12
        with socket.create_connection(("127.0.0.1", port)) as bad:
            bad.settimeout(5)
            bad.recv(64)
            bad.sendall(b"\xde\xad\xbe\xef" * 4)  # not the protocol
            assert bad.recv(64) == b""  # the server hangs up
        with socket.create_connection(("127.0.0.1", port)) as again:  # and still serves others
            again.settimeout(5)
            assert b"QTM RT Interface connected" in again.recv(64)
        assert proc.poll() is None


def _ingest_to_log(port: int, out, params: str = "") -> str:
    """A graph of the ingest node on ``port`` (retrying every 0.5 s at most; more ``params``) logging every
    frame to ``out``."""
    return f"""
nodes:
  - id: qtm
    kind: qtm_ingest
    params: {{port: {port}, max_backoff_s: 0.5{params}}}
  - id: log
    kind: frame_log
    params: {{path: {out}}}
    remaps: {{in: markers/raw}}
"""


def test_ingest_node_survives_qtm_restarts(tmp_path):
    port = free_port()
    out = tmp_path / "raw.csv"
    graph = _ingest_to_log(port, out)

    def count():
        return len(log_rows(out))

    with launched(tmp_path, graph) as g:
        with emulator(tmp_path, "--loop", port=port) as (sim, _):
            wait_for(lambda: count() > 50, 30, "frames from QTM")
            sim.kill()  # QTM vanishes without a goodbye
            sim.wait()
        n = count()
        wait_for(lambda: "lost the connection to QTM" in g.log(), 10, "the ingest to notice")
        with emulator(tmp_path, "--loop", port=port):
            wait_for(lambda: count() > n + 50, 30, "frames after QTM came back")
        assert g.proc.poll() is None and "restarted node" not in g.log()
        assert "not reachable; retrying" in g.log()


def test_ingest_node_gives_up_on_a_qtm_that_accepts_and_never_answers(tmp_path):
    """Something listens on QTM's port and says nothing (a QTM still starting, a wrong service): the client
    waits for the answer to its version command with no timeout of its own. The node's connect times out and
    closes the connection it gave up on, and once the real QTM is there it streams."""
    port = free_port()
    out = tmp_path / "raw.csv"
    graph = _ingest_to_log(port, out, ", timeout_s: 1.0")
    silent = socket.socket()
    silent.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    silent.bind(("127.0.0.1", port))
    silent.listen(8)
    with launched(tmp_path, graph) as g:
        try:
            silent.settimeout(30)
            held, _ = silent.accept()  # the node's client connects, and hears nothing
        finally:
            silent.close()
        held.settimeout(10)
        received = b""
        while chunk := held.recv(4096):  # its version command, then the close (a timeout here: left open)
            received += chunk
        assert b"version 1.25" in received, received
        with held, emulator(tmp_path, "--loop", port=port):
            wait_for(lambda: len(log_rows(out)) > 50, 30, "frames once QTM answers")
        assert g.proc.poll() is None and "not reachable; retrying" in g.log(), g.log()[-2000:]


def test_ingest_skips_frames_from_before_the_graph_was_ready(tmp_path):
    """QTM streams while a slow node still starts: those frames are stale and must not enter the graph as a
    burst seconds late (every logged frame is fresh)."""
    out = tmp_path / "raw.csv"
    with emulator(tmp_path, "--loop") as (sim, port):
        graph = f"""
nodes:
  - id: qtm
    kind: qtm_ingest
    params: {{port: {port}}}
  - id: slow
    kind: tests.fixtures_nodes.slow_sink:SlowSink
    params: {{delay_s: 0.0, setup_s: 3.0}}
  - id: log
    kind: frame_log
    params: {{path: {out}}}
    remaps: {{in: markers/raw}}
"""
        with launched(tmp_path, graph) as g:
            wait_for(lambda: out.exists() and sum(1 for _ in open(out)) > 200, 30, "frames from QTM")
            wait_for(lambda: "received before the graph was ready" in g.log(), 10, "the skipped frames to be logged")
    with open(out) as f:
        lat_ms = [float(r["latency_us"]) / 1000 for r in csv.DictReader(f)]
    assert max(lat_ms) < 500, max(lat_ms)  # without the skip the first frames are ~3 s old


GARBAGE = {  # what a babbling peer on QTM's port sent, each of which made qtm-rt spin at 100 % CPU
    "eight zero bytes": b"\x00" * 8,
    "a size-0 command": struct.pack("<II", 0, 1) + b"x" * 32,
    "a huge size field": struct.pack("<II", 0xFFFFFFF0, 3) + b"\x00" * 64,
    "2^32-1 components": struct.pack("<IIqII", 8 + 16 + 8, 3, 0, 1, 0xFFFFFFFF) + struct.pack("<II", 0, 1),
}


def test_qtm_rt_parser_is_guarded_against_framing_no_qtm_sends():
    from qtm_rt.packet import QRTPacketType

    from nodes.qtm_guard import GuardedReceiver

    for name, data in GARBAGE.items():
        said = []
        rx = GuardedReceiver({t: (lambda d: None) for t in QRTPacketType}, said.append)
        rx.data_received(data)   # returns at once: it spun forever or buffered without end in qtm-rt's own
        if name == "a huge size field":
            assert said == ["QTM sent a packet size of 4294967280 bytes"]
        else:
            assert said and said[0].startswith("QTM sent"), (name, said)


def _garbage_qtm(port: int, payload: bytes, accepted: list):
    """A peer on QTM's port: the welcome, then garbage, to every client that connects."""
    server = socket.socket()
    server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    server.bind(("127.0.0.1", port))
    server.listen(8)
    server.settimeout(0.2)
    welcome = b"QTM RT Interface connected\x00"
    stop = threading.Event()

    def serve():
        while not stop.is_set():
            try:
                conn, _ = server.accept()
            except OSError:
                continue
            accepted.append(conn)
            conn.sendall(struct.pack("<II", 8 + len(welcome), 1) + welcome + payload)
        server.close()

    threading.Thread(target=serve, daemon=True).start()
    return stop


def test_a_babbling_qtm_is_an_error_and_a_reconnect_not_a_spin(tmp_path):
    import psutil

    port = free_port()
    out = tmp_path / "raw.csv"
    accepted: list = []
    stop = _garbage_qtm(port, GARBAGE["eight zero bytes"], accepted)
    try:
        with launched(tmp_path, _ingest_to_log(port, out)) as g:
            wait_for(lambda: len(accepted) >= 3, 30, "the ingest to reconnect after the garbage")
            beat = wait_for(lambda: g.heartbeats().get("qtm"), 20, "the ingest's heartbeat")
            assert beat.errors.get("qtm_garbage", 0) >= 1, beat
            cpu = psutil.Process(g.node_pids()["qtm"]).cpu_percent(interval=2.0)
            assert cpu < 50, f"the ingest spins: {cpu:.0f} % CPU"
            assert g.proc.poll() is None
    finally:
        stop.set()
        for conn in accepted:
            conn.close()


def test_a_stalled_qtm_is_an_error_and_frames_resume(tmp_path):
    """QTM stops sending mid-stream without a word (its clock frozen 3 s): the watchdog counts it in the heartbeat
    and reconnects; frames come again."""
    port = free_port()
    out = tmp_path / "raw.csv"
    with launched(tmp_path, _ingest_to_log(port, out)) as g:
        with emulator(tmp_path, "--loop", "--stall-at", "300", "--stall-s", "3", port=port):
            wait_for(lambda: "no frame from QTM" in g.log(), 30, "the watchdog")
            n = len(log_rows(out))
            wait_for(lambda: len(log_rows(out)) > n + 100, 30, "frames after the stall")
            beat = g.heartbeats()["qtm"]
            assert beat.errors.get("qtm_stall", 0) >= 1, beat
            # a reconnect a second at most, not a storm (an old connection's close once ended each new session)
            reconnects = g.log().count("lost the connection to QTM") + beat.errors.get("qtm_stall", 0)
            assert reconnects <= 6, (reconnects, beat)


def test_frames_without_3d_data_are_an_error_and_a_reconnect_a_second(tmp_path):
    """QTM streams frames with no 3D component (its 3D tracking stopped): said in the heartbeat, and the watchdog
    reconnects once a second, not in a storm (before: no frame, no error, state running)."""
    port = free_port()
    out = tmp_path / "raw.csv"
    with launched(tmp_path, _ingest_to_log(port, out)) as g:
        with emulator(tmp_path, "--loop", "--no-3d-from", "100", port=port):
            wait_for(lambda: len(log_rows(out)) >= 50, 30, "frames from QTM")
            beat = wait_for(lambda: (b := g.heartbeats().get("qtm")) and b.errors.get("qtm_no_3d") and b, 10,
                            "the missing 3D data in the heartbeat")
            stalls = beat.errors.get("qtm_stall", 0)
            time.sleep(3.0)
            beat = g.heartbeats()["qtm"]
            # once a second (a storm made about a hundred a second); heartbeats a second old at either end
            assert 1 <= beat.errors.get("qtm_stall", 0) - stalls <= 8, beat
            assert g.proc.poll() is None


def test_frames_resume_within_a_second_of_qtm_coming_back(tmp_path):
    port = free_port()
    out = tmp_path / "raw.csv"
    with launched(tmp_path, _ingest_to_log(port, out)) as g:
        with emulator(tmp_path, "--loop", port=port) as (sim, _):
            wait_for(lambda: len(log_rows(out)) > 50, 30, "frames from QTM")
            sim.kill()
            sim.wait()
        time.sleep(5)   # away long enough for any backoff to have grown
        n = len(log_rows(out))
        with emulator(tmp_path, "--loop", port=port):
            back = time.monotonic()   # the emulator listens from here
            wait_for(lambda: len(log_rows(out)) > n, 10, "frames after QTM came back")
            assert time.monotonic() - back < 1.0
        assert g.proc.poll() is None

"""The official qtm-rt client against our QTM emulator over real TCP, and the ingest node's recovery."""
import asyncio
import csv
import os
import signal
import socket
import struct
import subprocess
import sys
import xml.etree.ElementTree as ET

import numpy as np
import qtm_rt

from mocap_core.recordings import read_recording
from tests.conftest import REPO, data_file, emulator, free_port, launched, log_rows, wait_for

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

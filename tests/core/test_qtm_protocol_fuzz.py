"""Fuzzing the QTM emulator's packet reader and command parser: only the documented errors, ever."""
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from mocap_core import qtm_protocol as qp
from mocap_core.recordings import Recording
from mocap_cli.qtm_sim import Client, QtmEmulator


class FakeTransport:
    def get_write_buffer_size(self):
        return 0


class FakeWriter:
    def __init__(self):
        self.data = bytearray()
        self.transport = FakeTransport()
        self.closed = False

    def write(self, b):
        self.data += b

    def is_closing(self):
        return self.closed

    def close(self):
        self.closed = True


def emulator():
    rec = Recording(["A", "B"], np.zeros((5, 2, 3), np.float32), 100.0, "test")
    return QtmEmulator(rec)


def packets(data: bytes):
    out, buf = [], bytes(data)
    while len(buf) >= 8:
        size, kind = qp.HEADER.unpack_from(buf)
        out.append((kind, buf[8:size]))
        buf = buf[size:]
    return out


@settings(max_examples=400, deadline=None)
@given(st.binary(max_size=200))
def test_packet_reader_raises_only_protocol_errors(data):
    try:
        qp.PacketReader().feed(data)
    except qp.ProtocolError:
        pass


@settings(max_examples=400, deadline=None)
@given(st.lists(st.sampled_from(["version", "getparameters", "streamframes", "getcurrentframe", "takecontrol",
                                 "3d", "all", "frequency:0", "frequencydivisor:-1", "udp:1", "stop", "6d", "1.25",
                                 "x", "general", "allframes", "frequency:abc"]), max_size=5),
       st.text(max_size=20))
def test_any_command_gets_a_well_formed_reply_or_none(words, junk):
    emu = emulator()
    c = Client(FakeWriter(), "fuzz")
    emu.on_packet(c, qp.PacketType.COMMAND, (" ".join(words) + " " + junk).encode("utf-8", "replace") + b"\0")
    for kind, payload in packets(c.writer.data):
        assert kind in (qp.PacketType.ERROR, qp.PacketType.COMMAND, qp.PacketType.XML, qp.PacketType.DATA,
                        qp.PacketType.EVENT, qp.PacketType.NO_MORE_DATA)
        if kind in (qp.PacketType.ERROR, qp.PacketType.COMMAND, qp.PacketType.XML):
            assert payload.endswith(b"\0")


def test_unknown_command_is_a_parse_error():
    emu = emulator()
    c = Client(FakeWriter(), "t")
    emu.on_packet(c, qp.PacketType.COMMAND, b"launchrockets now\0")
    assert packets(c.writer.data) == [(qp.PacketType.ERROR, b"Parse Error\0")]

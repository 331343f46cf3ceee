"""The QTM real-time protocol (version 1.25, little-endian), byte by byte, with no sockets.

Everything the emulator (`mocap qtm-sim`) needs to frame packets, parse commands and build
replies and data packets. Sources: ../shared/reference/qtm_rt_protocol.md (sections in brackets).
"""
from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import IntEnum
from xml.sax.saxutils import escape

import numpy as np

PROTOCOL_VERSION = "1.25"
DEFAULT_PORT = 22223
WELCOME = "QTM RT Interface connected"      # no trailing period: qtm-rt compares it exactly [2.1]
QTM_VERSION = "QTM Version is 2024.2 (build 0, mocap-graph emulator)"
HEADER = struct.Struct("<II")               # size (including the header), type [1.3]
DATA_HEADER = struct.Struct("<qII")         # timestamp us, frame number, component count [4.1]
COMPONENT_3D = struct.Struct("<IIIhh")      # size, type, marker count, drop rate, out-of-sync rate [4.3]
MAX_COMMAND_BYTES = 64 * 1024               # a client sending more is not speaking the protocol
OCCLUDED = b"\xff\xff\xff\xff" * 3          # an occluded marker's x, y, z: all bits set [4.3]
COMPONENTS = {"2d", "2dlin", "3d", "3dres", "3dnolabels", "3dnolabelsres", "analog", "analogsingle", "force",
              "forcesingle", "6d", "6dres", "6deuler", "6deulerres", "gazevector", "eyetracker", "image",
              "timecode", "skeleton", "skeleton:global"}


class PacketType(IntEnum):
    ERROR = 0
    COMMAND = 1
    XML = 2
    DATA = 3
    NO_MORE_DATA = 4
    EVENT = 6


class Event(IntEnum):
    CONNECTED = 1
    CONNECTION_CLOSED = 2
    CAPTURE_STARTED = 3
    CAPTURE_STOPPED = 4
    RT_FROM_FILE_STARTED = 8
    RT_FROM_FILE_STOPPED = 9


class ProtocolError(Exception):
    """A client sent something that is not the QTM RT protocol (the server drops it)."""


def packet(kind: PacketType, payload: bytes = b"") -> bytes:
    return HEADER.pack(HEADER.size + len(payload), int(kind)) + payload


def text_packet(kind: PacketType, text: str) -> bytes:
    return packet(kind, text.encode("ascii", "replace") + b"\0")  # strings are always NUL-terminated [1.3]


def event_packet(event: Event) -> bytes:
    return packet(PacketType.EVENT, bytes([int(event)]))


NO_MORE_DATA = packet(PacketType.NO_MORE_DATA)


class PacketReader:
    """Reassembles packets from a byte stream (split and merged reads both happen) [1.3]."""

    def __init__(self):
        self.buffer = bytearray()

    def feed(self, data: bytes) -> list[tuple[int, bytes]]:
        self.buffer += data
        out = []
        while len(self.buffer) >= HEADER.size:
            size, kind = HEADER.unpack_from(self.buffer)
            if size < HEADER.size or size > MAX_COMMAND_BYTES:
                raise ProtocolError(f"packet size {size} is out of range")
            if kind not in (PacketType.COMMAND, PacketType.XML):
                raise ProtocolError(f"a client may send command or XML packets, not type {kind}")
            if len(self.buffer) < size:
                break
            out.append((kind, bytes(self.buffer[HEADER.size:size])))
            del self.buffer[:size]
        return out


@dataclass
class StreamRequest:
    every_nth: int = 1          # AllFrames = 1, FrequencyDivisor:n = n
    frequency_hz: float = 0.0   # Frequency:n (0 = not used)
    components: tuple[str, ...] = ("3d",)


class CommandError(Exception):
    """A well-framed command the server answers with an Error packet (the client stays connected)."""


def parse_stream_request(args: list[str]) -> StreamRequest:
    """``StreamFrames (AllFrames | Frequency:n | FrequencyDivisor:n) [UDP...] components`` [2.3]."""
    if not args:
        raise CommandError("Parse Error")
    rate, comps = args[0].lower(), [a.lower() for a in args[1:]]
    req = StreamRequest()
    try:
        if rate == "allframes":
            pass
        elif rate.startswith("frequencydivisor:"):
            req.every_nth = int(rate.split(":", 1)[1])
            if req.every_nth < 1:
                raise ValueError
        elif rate.startswith("frequency:"):
            req.frequency_hz = float(rate.split(":", 1)[1])
            if req.frequency_hz <= 0:
                raise ValueError
        else:
            raise CommandError("Parse Error")
    except ValueError:
        raise CommandError("Parse Error") from None
    if comps and comps[0].startswith("udp"):
        raise CommandError("UDP streaming is not supported by this emulator; stream over TCP")
    return StreamRequest(req.every_nth, req.frequency_hz, tuple(validate_components(comps)))


def validate_components(comps: list[str]) -> list[str]:
    if not comps:
        raise CommandError("Parse Error")
    for c in comps:
        if c not in COMPONENTS:
            raise CommandError("Parse Error")
    unsupported = [c for c in comps if c not in ("3d", "3dres")]
    if unsupported:
        raise CommandError(f"Component {unsupported[0]} is not available in this measurement")
    return comps


def data_packet(frame: int, timestamp_us: int, positions_mm: np.ndarray, components: tuple[str, ...]) -> bytes:
    """One Data packet with 3D and/or 3DRes components; NaN markers go out as all-ones bytes [4.3]."""
    pos = np.asarray(positions_mm, dtype="<f4")
    n = pos.shape[0]
    occluded = np.isnan(pos).any(axis=1)
    parts = []
    for comp in components:
        if comp == "3d":
            body = bytearray(pos.tobytes())
            stride, kind = 12, 1
        else:  # 3dres: x, y, z, residual (0 for seen markers)
            res = np.zeros((n, 4), "<f4")
            res[:, :3] = pos
            body = bytearray(res.tobytes())
            stride, kind = 16, 9
        for i in np.flatnonzero(occluded):
            body[i * stride: i * stride + 12] = OCCLUDED
        parts.append(COMPONENT_3D.pack(COMPONENT_3D.size + len(body), kind, n, 0, 0) + bytes(body))
    payload = DATA_HEADER.pack(timestamp_us, frame, len(parts)) + b"".join(parts)
    return packet(PacketType.DATA, payload)


def parameters_xml(which: list[str], labels: list[str], rate_hz: float, up_axis: str = "+Z",
                   capture_time_s: float = 0.0) -> str:
    """``GetParameters`` reply: General and/or The_3D inside the versioned root [3]."""
    which = [w.lower() for w in which] or ["all"]
    known = {"all", "general", "3d", "6d", "analog", "force", "gazevector", "eyetracker", "image", "skeleton",
             "skeleton:global", "calibration"}
    if any(w not in known for w in which):
        raise CommandError("Parse Error")
    parts = [f"<QTM_Parameters_Ver_{PROTOCOL_VERSION}>"]
    if "all" in which or "general" in which:
        parts.append(f"<General><Frequency>{rate_hz:g}</Frequency><Capture_Time>{capture_time_s:.6f}</Capture_Time>"
                     "<Start_On_External_Trigger>false</Start_On_External_Trigger></General>")
    if "all" in which or "3d" in which:
        label_xml = "".join(f"<Label><Name>{escape(name)}</Name><RGBColor>{_colour(i)}</RGBColor>"
                            "<Trajectory_Type>Measured</Trajectory_Type></Label>" for i, name in enumerate(labels))
        parts.append(f"<The_3D><AxisUpwards>{up_axis}</AxisUpwards><CalibrationTime></CalibrationTime>"
                     f"<Labels>{len(labels)}</Labels>{label_xml}<Bones></Bones></The_3D>")
    if any(w not in ("all", "general", "3d") for w in which) and "all" not in which:
        raise CommandError("Parameters not available")
    parts.append(f"</QTM_Parameters_Ver_{PROTOCOL_VERSION}>")
    return "".join(parts)


def _colour(i: int) -> int:
    r, g, b = (37 * i) % 256, (91 * i + 64) % 256, (53 * i + 128) % 256
    return r | (g << 8) | (b << 16)  # decimal RGB, as real QTM writes it [3.2]

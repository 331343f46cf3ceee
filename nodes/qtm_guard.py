"""A guard in front of qtm-rt's packet parser, and what the ingest's watchdog reads.

qtm-rt's receiver trusts every size field: a packet whose size is below the 8-byte header (8 zero bytes, a size-0
command) loops forever on the same bytes, a data packet with a component of size 0 and a count of 2^32-1 loops
four billion times, and a size of 0xFFFFFFF0 buffers everything QTM sends after it. Each of these stalls the
client at 100 % CPU with no error. ``GuardedReceiver`` checks the framing first: packet size, type, and a data
packet's component table; anything else is handed to qtm-rt unchanged. On a bad packet it calls ``on_bad`` (the
ingest closes the connection and reconnects) and drops what it buffered.

It also notes whether QTM said the stream ended (NoMoreData, or the events that stop it), so a watchdog can tell a
stall from a QTM that stopped on purpose.
"""
from __future__ import annotations

import struct
from typing import Callable

from qtm_rt.packet import QRTPacketType, RTComponentData, RTDataQRTPacket, RTheader
from qtm_rt.receiver import Receiver

MAX_PACKET = 16 << 20       # bytes: a 3D frame of 1,000 markers is 16 KB, the largest parameters XML a few MB
MAX_COMPONENTS = 64         # QTM defines fewer than 32 component types
STOP_EVENTS = {2, 9, 12}    # ConnectionClosed, RTfromFileStopped, QTMShuttingDown
_TYPES = {t.value for t in QRTPacketType}


class BadPacket(Exception):
    pass


def check_data_packet(body: bytes) -> None:
    """A data packet's body: its component table must tile the body."""
    if len(body) < RTDataQRTPacket.size:
        raise BadPacket(f"a data packet of {len(body)} bytes, below its {RTDataQRTPacket.size}-byte header")
    _, _, count = RTDataQRTPacket.unpack_from(body, 0)
    if count > MAX_COMPONENTS:
        raise BadPacket(f"a data packet claiming {count} components")
    position = RTDataQRTPacket.size
    for _ in range(count):
        if position + RTComponentData.size > len(body):
            raise BadPacket("a data packet whose components run past its end")
        size, _ = RTComponentData.unpack_from(body, position)
        if size < RTComponentData.size or position + size > len(body):
            raise BadPacket(f"a component of {size} bytes at byte {position} of a {len(body)}-byte data packet")
        position += size


class GuardedReceiver(Receiver):
    def __init__(self, handlers, on_bad: Callable[[str], None]):
        super().__init__(handlers)
        self.on_bad = on_bad
        self.stopped = False       # QTM said the stream ended: silence is expected, not a stall
        self.failed = False

    def data_received(self, data):
        if self.failed:
            return
        buffer = self._received_data + data
        try:
            while len(buffer) >= RTheader.size:
                size, type_ = RTheader.unpack_from(buffer, 0)
                if size < RTheader.size or size > MAX_PACKET:
                    raise BadPacket(f"a packet size of {size} bytes")
                if type_ not in _TYPES:
                    raise BadPacket(f"a packet of unknown type {type_}")
                if len(buffer) < size:
                    break
                body = buffer[RTheader.size:size]
                if type_ == QRTPacketType.PacketData.value:
                    check_data_packet(body)
                    self.stopped = False
                elif type_ == QRTPacketType.PacketNoMoreData.value:
                    self.stopped = True
                elif type_ == QRTPacketType.PacketEvent.value and body[:1] and body[0] in STOP_EVENTS:
                    self.stopped = True
                try:
                    self._parse_received(body, type_)
                except (struct.error, ValueError, IndexError) as e:  # a body qtm-rt cannot unpack
                    raise BadPacket(f"a packet of type {type_} that does not parse ({e})") from None
                buffer = buffer[size:]
        except BadPacket as e:
            self.failed = True
            self._received_data = b""
            self.on_bad(f"QTM sent {e}")
            return
        self._received_data = buffer

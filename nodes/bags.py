"""Topic bags in MCAP: each message's exact wire bytes, its receive time (log time) and the time it entered the
graph (publish time), both wall clock.

Channels use ``message_encoding: msgpack`` with the message's JSON Schema (``schema encoding:
jsonschema``), so any MCAP tool can list and inspect them; ``mocap bag export --json`` rewrites a
bag with JSON encoding (arrays as lists of numbers), ``--foxglove`` in Foxglove's own schemas for its 3D panel
(nodes/foxglove_scene.py). Chunks are small (64 KiB), so a recorder killed
with SIGKILL loses at most its last chunk: :func:`read_bag` reads such a file up to the damage.

A recorder never truncates a file that exists: it writes the next *piece* of the take beside it
(``take.mcap``, then ``take.1.mcap``, ``take.2.mcap`` ...; :func:`free_piece`), so a recorder that the
launcher restarts keeps everything recorded before. Reading a bag reads its pieces in order, as one.
"""
from __future__ import annotations

import json
import logging
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import numpy as np
from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader, make_reader
from zstandard import ZstdError
from mcap.writer import CompressionType, Writer

from messages import BY_SCHEMA, MarkerFrame, decode
from messages.arrays import WIRE_JSON_SCHEMA
from messages.codec import json_schemas, peek_schema
from mocap_core.recordings import Recording, RecordingError, read_recording

CHUNK_BYTES = 64 * 1024
log = logging.getLogger("mocap.bags")
LIBRARY = "mocap-graph"


class BagError(Exception):
    pass


@dataclass
class BagMessage:
    topic: str
    schema: str
    data: bytes           # the exact wire payload
    log_time_ns: int      # when the recorder received it
    publish_time_ns: int  # the frame's capture time (the recorder) or entry time (bag record); else as log_time


def piece(path: Path, k: int) -> Path:
    """The take's k-th piece: the path itself for 0, ``stem.k.suffix`` after."""
    return path if k == 0 else path.with_name(f"{path.stem}.{k}{path.suffix}")


def free_piece(path: str | Path) -> Path:
    """The first piece of ``path`` that does not exist yet (an empty file counts as free)."""
    path, k = Path(path), 0
    while piece(path, k).exists() and piece(path, k).stat().st_size > 0:
        k += 1
    return piece(path, k)


def pieces(path: str | Path) -> list[Path]:
    """The take's pieces that exist, in order (the path first)."""
    path, out = Path(path), []
    while piece(path, len(out)).exists():
        out.append(piece(path, len(out)))
    return out


class BagWriter:
    def __init__(self, path: str | Path, metadata: dict[str, str] | None = None):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.file = open(self.path, "wb")
        self.writer = Writer(self.file, chunk_size=CHUNK_BYTES, compression=CompressionType.ZSTD)
        self.writer.start(profile="", library=LIBRARY)
        self.schemas: dict[str, int] = {}
        self.channels: dict[tuple[str, str], int] = {}
        self.sequence: dict[int, int] = {}
        self.count = 0
        self.json_schemas = json_schemas()
        if metadata:
            self.writer.add_metadata("run", {k: str(v) for k, v in metadata.items()})

    def _channel(self, topic: str, schema: str) -> int:
        key = (topic, schema)
        if key not in self.channels:
            if schema not in self.schemas:
                body = json.dumps(self.json_schemas.get(schema, {"type": "object"})).encode()
                self.schemas[schema] = self.writer.register_schema(schema, "jsonschema", body)
            self.channels[key] = self.writer.register_channel(topic, "msgpack", self.schemas[schema])
        return self.channels[key]

    def write(self, topic: str, payload: bytes, log_time_ns: int, publish_time_ns: float | None = None) -> None:
        """``publish_time_ns``: the frame's capture time, say; None: its entry time; one MCAP cannot hold (negative,
        not finite): the log time."""
        head = peek_schema(payload)
        schema = head[0] if head else "unknown"
        if publish_time_ns is None:
            publish_time_ns = log_time_ns
            if head is not None and schema in BY_SCHEMA:
                try:
                    publish_time_ns = decode(payload, topic).header.entry_time_ns or log_time_ns
                except Exception:
                    pass
        publish_time_ns = int(publish_time_ns) if 0 <= publish_time_ns < 2 ** 64 else log_time_ns  # (unsigned)
        cid = self._channel(topic, schema)
        seq = self.sequence.get(cid, 0) + 1
        self.sequence[cid] = seq
        self.writer.add_message(cid, log_time=log_time_ns, data=payload, publish_time=publish_time_ns, sequence=seq)
        self.count += 1

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        self.writer.add_metadata(name, {k: str(v) for k, v in data.items()})

    def close(self) -> None:
        self.writer.finish()
        self.file.close()


def _open(path: Path):
    if not path.exists():
        raise BagError(f"{path}: bag not found")
    with open(path, "rb") as f:
        magic = f.read(8)
    if magic != b"\x89MCAP0\r\n":
        raise BagError(f"{path}: not an MCAP file")
    return open(path, "rb")


def read_bag(path: str | Path, topics: list[str] | None = None) -> Iterator[BagMessage]:
    """Messages in file order, the take's pieces one after the other. A piece cut short (recorder killed) is read
    up to the damage."""
    path = Path(path)
    for part in pieces(path) or [path]:
        yield from _read_piece(part, topics)


def read_take(path: str | Path, take: str | None = None) -> Recording:
    """A recording of any kind a command or a source reads: a topic bag's markers, or what
    mocap_core.recordings.read_recording reads (C3D, TRC, MAT, ``synthetic:``)."""
    if str(path).lower().endswith(".mcap"):
        if not Path(path).exists():
            raise RecordingError(f"{path}: file not found")
        return read_bag_markers(Path(path))
    return read_recording(path, take)


def read_bag_markers(path: Path, topic: str = "markers/raw") -> Recording:
    """The marker frames of a topic bag (so a bag can feed `mocap solve` and `mocap qtm-sim`)."""
    try:
        frames = [decode(m.data, m.topic, MarkerFrame) for m in read_bag(path, [topic])]
    except BagError as e:
        raise RecordingError(str(e)) from None
    if not frames:
        raise RecordingError(f"{path}: no {topic} messages in the bag")
    labels = frames[0].labels
    if any(f.labels != labels for f in frames):
        raise RecordingError(f"{path}: the marker set changes within the bag; split it first")
    times = np.array([f.header.capture_time_s for f in frames])
    rate = 1.0 / float(np.median(np.diff(times))) if len(times) > 1 else 100.0
    pos = np.stack([f.positions for f in frames]).astype(np.float32)
    meta = {"up_axis": frames[0].header.up_axis} if frames[0].header.up_axis else {}
    return Recording(list(labels), pos, round(rate, 3), str(path), int(frames[0].header.frame), meta)


def _read_piece(path: Path, topics: list[str] | None) -> Iterator[BagMessage]:
    f = _open(path)
    try:
        reader = NonSeekingReader(f, validate_crcs=True)
        count = 0
        try:
            for schema, channel, message in reader.iter_messages(topics=topics, log_time_order=False):
                count += 1
                yield BagMessage(channel.topic, schema.name if schema else "unknown", message.data,
                                 message.log_time, message.publish_time)
        except (McapError, EOFError, ValueError, OSError, struct.error, ZstdError, RuntimeError, MemoryError) as e:
            # a recorder killed mid-write leaves a cut chunk and no footer: keep what came before
            log.warning("%s: damaged after %d messages (%s: %s); the rest is unreadable", path, count,
                        type(e).__name__, e)
    finally:
        f.close()


def bag_metadata(path: str | Path) -> dict[str, dict[str, str]]:
    path = Path(path)
    f = _open(path)
    try:
        reader = make_reader(f)
        return {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    except Exception:
        return {}
    finally:
        f.close()


def bag_info(path: str | Path) -> dict:
    """Topics, counts, rates, duration and schemas (read by streaming, so damaged bags work too)."""
    stats: dict[str, dict] = {}
    first = last = None
    for m in read_bag(path):
        s = stats.setdefault(m.topic, {"schema": m.schema, "count": 0, "first_ns": m.log_time_ns, "last_ns": 0})
        s["count"] += 1
        s["last_ns"] = m.log_time_ns
        first = m.log_time_ns if first is None else min(first, m.log_time_ns)
        last = m.log_time_ns if last is None else max(last, m.log_time_ns)
    for s in stats.values():
        span = (s["last_ns"] - s["first_ns"]) / 1e9
        s["rate_hz"] = (s["count"] - 1) / span if span > 0 else 0.0
    duration = (last - first) / 1e9 if first is not None else 0.0
    return {"path": str(path), "pieces": [str(p) for p in pieces(path)], "duration_s": duration,
            "messages": sum(s["count"] for s in stats.values()), "topics": stats, "metadata": bag_metadata(path)}


def to_json(value):
    """A decoded message -> JSON-able data; arrays as (nested) lists of numbers, NaN as null."""
    import numpy as np
    from pydantic import BaseModel

    if isinstance(value, np.ndarray):
        return to_json(value.tolist())
    if isinstance(value, BaseModel):
        return {(f.alias or n): to_json(getattr(value, n)) for n, f in type(value).model_fields.items()}
    if isinstance(value, dict):
        return {k: to_json(v) for k, v in value.items()}
    if isinstance(value, list):
        return [to_json(v) for v in value]
    if isinstance(value, float) and value != value:
        return None
    return value


JSON_ARRAY_SCHEMA = {"type": "array", "description": "numpy array as (nested) lists of numbers; null where NaN"}


def _with_json_arrays(schema):
    """A message's JSON Schema with each wire array (raw bytes, dtype, shape) as the lists ``to_json`` writes."""
    if isinstance(schema, dict) and schema.get("properties") == WIRE_JSON_SCHEMA["properties"]:
        return {**JSON_ARRAY_SCHEMA, **({"title": schema["title"]} if "title" in schema else {})}
    if isinstance(schema, dict):
        return {k: _with_json_arrays(v) for k, v in schema.items()}
    if isinstance(schema, list):
        return [_with_json_arrays(v) for v in schema]
    return schema


def export_json(src: str | Path, dst: str | Path) -> int:
    """Rewrite a bag with JSON message encoding (Foxglove and Lichtblick read JSON, not msgpack)."""
    out = open(dst, "wb")
    w = Writer(out, chunk_size=1024 * 1024, compression=CompressionType.ZSTD)
    w.start(profile="", library=LIBRARY)
    schemas, channels, n = {}, {}, 0
    all_schemas = json_schemas()
    for name, meta in bag_metadata(src).items():
        w.add_metadata(name, meta)
    for m in read_bag(src):
        try:
            msg = decode(m.data, m.topic)
        except Exception:
            continue  # a foreign payload has no JSON form
        if m.schema not in schemas:
            schema = _with_json_arrays(all_schemas.get(m.schema, {}))
            schemas[m.schema] = w.register_schema(m.schema, "jsonschema", json.dumps(schema).encode())
        if m.topic not in channels:
            channels[m.topic] = w.register_channel(m.topic, "json", schemas[m.schema])
        w.add_message(channels[m.topic], log_time=m.log_time_ns, publish_time=m.publish_time_ns,
                      data=json.dumps(to_json(msg)).encode())
        n += 1
    w.finish()
    out.close()
    return n

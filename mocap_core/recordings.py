"""Readers for marker recordings: C3D (ezc3d), TRC and MoCap Toolbox MAT files.

Every reader returns a :class:`Recording`: positions as frames x labels x 3 float32 in metres,
NaN where a marker is occluded (all-zero points and negative C3D residuals count as occluded),
the labels, and the capture rate. A truncated or corrupt file raises :class:`RecordingError`.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mocap_core.world import MAX_COORDINATE_M

UNIT_SCALE = {"mm": 0.001, "cm": 0.01, "m": 1.0, "dm": 0.1, "in": 0.0254}


class RecordingError(Exception):
    pass


@dataclass
class Recording:
    labels: list[str]
    positions: np.ndarray          # (frames, markers, 3) float32 metres, NaN = occluded
    rate_hz: float
    source: str = ""
    first_frame: int = 0
    meta: dict = field(default_factory=dict)   # "up_axis" where the file says it (mocap_core.world)

    @property
    def n_frames(self) -> int:
        return self.positions.shape[0]

    def times(self) -> np.ndarray:
        return np.arange(self.n_frames) / self.rate_hz

    def slice(self, start: int, stop: int | None = None) -> "Recording":
        return Recording(self.labels, self.positions[start:stop], self.rate_hz, self.source,
                         self.first_frame + start, self.meta)

    def actor(self, name: str) -> "Recording":
        """One subject's markers (labels "name:LABEL") of a take of several."""
        from mocap_core.profiles import actor_of

        cols = [i for i, x in enumerate(self.labels) if actor_of(x) == name]
        return Recording([self.labels[i] for i in cols], self.positions[:, cols], self.rate_hz,
                         f"{self.source} ({name})", self.first_frame, self.meta)


def _finish(labels, xyz_units: np.ndarray, units: str, rate: float, source: str, first_frame=0, meta=None):
    scale = UNIT_SCALE.get(units.strip().lower())
    if scale is None:
        raise RecordingError(f"{source}: unknown length unit {units!r} (known: {', '.join(UNIT_SCALE)})")
    pos = np.asarray(xyz_units, dtype=np.float64) * scale
    if pos.ndim != 3 or pos.shape[0] == 0:
        raise RecordingError(f"{source}: no frames")
    pos[np.all(pos == 0.0, axis=2)] = np.nan
    pos[~(np.abs(pos) <= MAX_COORDINATE_M).all(axis=2)] = np.nan  # infinite, or past any capture volume: occluded
    if not rate or not np.isfinite(rate) or rate <= 0:
        raise RecordingError(f"{source}: bad capture rate {rate!r}")
    if len(set(labels)) != len(labels):
        dup = sorted({x for x in labels if labels.count(x) > 1})
        raise RecordingError(f"{source}: duplicate marker labels {dup}")
    return Recording(list(labels), pos.astype(np.float32), float(rate), source, first_frame, meta or {})


C3D_TIMEOUT_S = 20.0  # and 1 s per MB: a C3D is read at over 10 MB/s


def read_c3d(path: Path) -> Recording:
    """ezc3d reads it in a forked child: some corrupt files crash ezc3d (a segfault would take the caller with it)
    or make it loop; the child's death or a timeout becomes a RecordingError naming the file. (os.fork, not
    multiprocessing: it works in daemonic processes too, a Dask worker's say.)"""
    import faulthandler
    import os
    import pickle
    import select
    import signal

    timeout = C3D_TIMEOUT_S + path.stat().st_size / 1e6
    read_end, write_end = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: read, send the result (or the error) back, and leave without cleaning up
        os.close(read_end)
        faulthandler.disable()  # a crash here is the parent's to report, without a dump of the caller's stack
        try:
            payload = ("ok", _read_c3d(path))
        except RecordingError as e:
            payload = ("error", str(e))
        except Exception as e:  # anything else of ezc3d's on a bad file
            payload = ("error", f"{path}: not a readable C3D file ({type(e).__name__}: {e})")
        with os.fdopen(write_end, "wb") as out:
            out.write(pickle.dumps(payload, protocol=pickle.HIGHEST_PROTOCOL))
        os._exit(0)
    os.close(write_end)
    chunks, deadline = [], time.monotonic() + timeout
    try:
        while True:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([read_end], [], [], left)[0]:
                os.kill(pid, signal.SIGKILL)
                raise RecordingError(f"{path}: reading the C3D file did not finish in {timeout:.0f} s (corrupt file?)")
            chunk = os.read(read_end, 1 << 20)
            if not chunk:
                break
            chunks.append(chunk)
    finally:
        os.close(read_end)
        _, status = os.waitpid(pid, 0)
    if not chunks:
        raise RecordingError(f"{path}: the C3D reader crashed on this file ({_how(status)}): it is corrupt")
    kind, value = pickle.loads(b"".join(chunks))
    if kind == "error":
        raise RecordingError(value)
    return value


def _how(status: int) -> str:
    import os

    return f"signal {os.WTERMSIG(status)}" if os.WIFSIGNALED(status) else f"exit {os.WEXITSTATUS(status)}"


def _read_c3d(path: Path) -> Recording:
    import ezc3d

    try:
        c = ezc3d.c3d(str(path))
    except Exception as e:  # ezc3d raises RuntimeError/IOError variants on bad files
        raise RecordingError(f"{path}: not a readable C3D file ({e})") from None
    try:
        point = c["parameters"]["POINT"]
        labels = [s.strip() for s in point["LABELS"]["value"]]
        for extra in ("LABELS2", "LABELS3"):
            if extra in point:
                labels += [s.strip() for s in point[extra]["value"]]
        units = point["UNITS"]["value"][0] if "UNITS" in point else "mm"
        rate = float(point["RATE"]["value"][0])
        pts = np.asarray(c["data"]["points"])          # (4, markers, frames)
        residual = np.asarray(c["data"]["meta_points"]["residuals"])  # (1, markers, frames)
    except (KeyError, IndexError, ValueError, TypeError) as e:
        raise RecordingError(f"{path}: C3D file lacks the POINT parameters ({e})") from None
    labels = labels[: pts.shape[1]]
    xyz = np.transpose(pts[:3], (2, 1, 0)).astype(np.float64)
    xyz[np.transpose(residual[0]) < 0] = np.nan
    if xyz.shape[0] == 0:
        raise RecordingError(f"{path}: C3D file has no frames")
    first = int(c["header"]["points"]["first_frame"])
    expected = _c3d_header_frames(path)
    if expected and xyz.shape[0] < expected:
        raise RecordingError(f"{path}: C3D header promises {expected} frames but the file holds "
                             f"{xyz.shape[0]} (truncated file?)")
    return _finish(labels, xyz, units, rate, str(path), first)


def write_c3d(rec: Recording, path: str | Path) -> None:
    """``rec`` as a C3D file (metres; an occluded marker has residual -1, as C3D says)."""
    import ezc3d

    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [rec.rate_hz]
    c["parameters"]["POINT"]["LABELS"]["value"] = list(rec.labels)
    c["parameters"]["POINT"]["UNITS"]["value"] = ["m"]
    pts = np.ones((4, len(rec.labels), rec.n_frames))
    xyz = np.transpose(rec.positions, (2, 1, 0))
    seen = np.isfinite(xyz).all(axis=0)
    pts[:3] = np.where(seen, xyz, 0.0)
    c["data"]["points"] = pts
    c["data"]["meta_points"]["residuals"] = np.where(seen, 0.0, -1.0)[None]
    c.write(str(path))


def crowd(rec: Recording, actors: list[str], spacing_m: float = 3.0) -> Recording:
    """A take of several actors, each ``rec`` moved ``spacing_m`` further along x and named ``actor:LABEL``, as
    QTM and Vicon stream several labelled subjects."""
    from mocap_core.profiles import strip_prefix

    names = [strip_prefix(label) for label in rec.labels]
    shift = np.zeros(3, np.float32)
    parts = []
    for i, _ in enumerate(actors):
        shift[0] = i * spacing_m
        parts.append(rec.positions + shift)
    return Recording([f"{a}:{n}" for a in actors for n in names], np.concatenate(parts, axis=1), rec.rate_hz,
                     f"{rec.source} x{len(actors)}", rec.first_frame, rec.meta)


def _c3d_header_frames(path: Path) -> int | None:
    """Frame count from the raw C3D header (ezc3d silently shortens a truncated file)."""
    import struct

    with open(path, "rb") as f:
        head = f.read(512)
        param_block = head[0]
        f.seek(512 * (param_block - 1) + 3)
        processor = f.read(1)
    if len(head) < 512:
        return None
    endian = ">" if processor == b"\x56" else "<"  # 86 = MIPS big-endian; 84/85 little-endian-ish
    first, last = struct.unpack(endian + "HH", head[6:10])
    return last - first + 1 if last >= first > 0 else None


def read_trc(path: Path) -> Recording:
    try:
        lines = path.read_text(errors="replace").splitlines()
    except OSError as e:
        raise RecordingError(f"{path}: cannot read ({e})") from None
    if len(lines) < 6 or not lines[0].startswith("PathFileType"):
        raise RecordingError(f"{path}: not a TRC file (no PathFileType header)")
    keys, values = lines[1].split("\t"), lines[2].split("\t")
    header = dict(zip((k.strip() for k in keys), (v.strip() for v in values)))
    try:
        rate = float(header.get("DataRate") or header["CameraRate"])
        n_markers = int(header["NumMarkers"])
        n_frames = int(header["NumFrames"])
    except (KeyError, ValueError) as e:
        raise RecordingError(f"{path}: TRC header lacks DataRate/NumMarkers/NumFrames ({e})") from None
    names = [s.strip() for s in lines[3].split("\t")[2:] if s.strip()]
    if len(names) != n_markers:
        raise RecordingError(f"{path}: header says {n_markers} markers but names {len(names)}")
    rows = []
    for lineno, line in enumerate(lines[5:], start=6):
        if not line.strip():
            continue
        cells = line.split("\t")
        try:
            vals = [float(c) if c.strip() else np.nan for c in cells[2: 2 + 3 * n_markers]]
        except ValueError as e:
            raise RecordingError(f"{path} line {lineno}: not a number ({e})") from None
        if len(vals) < 3 * n_markers:
            raise RecordingError(f"{path} line {lineno}: {len(vals)} values, expected {3 * n_markers} "
                                 "(truncated file?)")
        rows.append(vals)
    if len(rows) != n_frames:
        raise RecordingError(f"{path}: header says {n_frames} frames but the file has {len(rows)} (truncated?)")
    xyz = np.array(rows, dtype=np.float64).reshape(len(rows), n_markers, 3)
    return _finish(names, xyz, header.get("Units", "mm"), rate, str(path))


def read_mat(path: Path, take: str | None = None) -> Recording:
    """MoCap Toolbox .mat: one struct per take (``take`` picks one; default the first)."""
    from scipy.io import loadmat

    try:
        mat = loadmat(str(path), squeeze_me=True, struct_as_record=False)
    except Exception as e:
        raise RecordingError(f"{path}: not a readable MAT file ({e})") from None
    takes = {k: v for k, v in mat.items() if not k.startswith("__") and hasattr(v, "markerName")}
    if not takes:
        raise RecordingError(f"{path}: no MoCap Toolbox take (struct with markerName) in the file")
    name = take or sorted(takes)[0]
    if name not in takes:
        raise RecordingError(f"{path}: no take {name!r} (takes: {', '.join(sorted(takes))})")
    t = takes[name]
    try:
        labels = [str(x) for x in np.atleast_1d(t.markerName)]
        frames = int(t.nFrames)
        if frames <= 0:
            raise ValueError(f"nFrames is {frames}")
        data = np.asarray(t.data, dtype=np.float64).reshape(frames, len(labels), 3)
        rate = float(t.freq)
    except (AttributeError, TypeError, ValueError, OverflowError) as e:
        raise RecordingError(f"{path}: take {name!r} is malformed ({e}); a MoCap Toolbox take has nFrames, freq, "
                             "markerName and data (nFrames x 3 markers)") from None
    return _finish(labels, data, "mm", rate, f"{path}:{name}", meta={"take": name})


def read_recording(path: str | Path, take: str | None = None) -> Recording:
    """Read a C3D, TRC or MAT file (``file.mat:take`` picks a take of a MAT file)."""
    text = str(path)
    if text.startswith("synthetic:"):
        from mocap_core.synthetic import from_spec

        try:
            return from_spec(text)
        except ValueError as e:
            raise RecordingError(str(e)) from None
    if take is None and ".mat:" in text:
        text, take = text.rsplit(":", 1)
    path = Path(text)
    if not path.exists():
        raise RecordingError(f"{path}: file not found")
    suffix = path.suffix.lower()
    if suffix == ".c3d":
        return read_c3d(path)
    if suffix == ".trc":
        return read_trc(path)
    if suffix == ".mat":
        return read_mat(path, take)
    if suffix == ".mcap":  # (the graph's topic bags: nodes.bags.read_take reads them and these)
        raise RecordingError(f"{path}: an MCAP bag is read by nodes.bags.read_take, not here")
    raise RecordingError(f"{path}: unknown recording format {suffix!r} (C3D, TRC, MAT or an MCAP bag)")

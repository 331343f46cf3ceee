"""The joints CSV (docs/design.md): ``frame,time`` then ``<joint>.x,.y,.z,.status`` for every joint.

Positions in metres in the input's world frame; status is located, estimated, held or missing;
a missing joint has empty x, y, z.
"""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from mocap_core.skeleton import JOINTS, STATUS_NAMES

STATUS_CODES = {name: code for code, name in STATUS_NAMES.items()}


def header() -> list[str]:
    cols = ["frame", "time"]
    for j in JOINTS:
        cols += [f"{j}.x", f"{j}.y", f"{j}.z", f"{j}.status"]
    return cols


class JointsCsvWriter:
    """Streams rows, so a long take never has to sit in memory twice."""

    def __init__(self, path: str | Path):
        self.file = open(path, "w", newline="")
        self.writer = csv.writer(self.file)
        self.writer.writerow(header())

    def write_frames(self, frames: np.ndarray, times: np.ndarray, positions: np.ndarray, status: np.ndarray) -> None:
        """Frames (F,) numbered and timed (F,), their joints' positions (F, J, 3) and status (F, J)."""
        missing = ((status == 0) | np.isnan(positions).any(axis=2)).tolist()
        names = [[STATUS_NAMES[s] for s in row] for row in status.tolist()]
        rows = []
        for n, t, p, m, s in zip(frames.tolist(), times.tolist(), positions.tolist(), missing, names):
            row = [n, "%.6f" % t]
            for (x, y, z), lost, name in zip(p, m, s):
                row += ["", "", "", "missing"] if lost else ["%.6f" % x, "%.6f" % y, "%.6f" % z, name]
            rows.append(row)
        self.writer.writerows(rows)

    def close(self) -> None:
        self.file.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def read_joints_csv(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """-> frames (F,), times (F,), positions (F, J, 3) with NaN for missing, status (F, J)."""
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    if not rows or rows[0] != header():
        raise ValueError(f"{path}: not a joints CSV of this skeleton model")
    body = rows[1:]
    frames = np.array([int(r[0]) for r in body])
    times = np.array([float(r[1]) for r in body])
    pos = np.full((len(body), len(JOINTS), 3), np.nan)
    status = np.zeros((len(body), len(JOINTS)), np.uint8)
    for i, r in enumerate(body):
        for j in range(len(JOINTS)):
            x, y, z, s = r[2 + 4 * j: 6 + 4 * j]
            status[i, j] = STATUS_CODES[s]
            if x:
                pos[i, j] = float(x), float(y), float(z)
    return frames, times, pos, status

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

    def write(self, frame: int, time_s: float, positions: np.ndarray, status: np.ndarray) -> None:
        row = [frame, f"{time_s:.6f}"]
        for p, s in zip(positions, status):
            if s == 0 or np.isnan(p).any():
                row += ["", "", "", "missing"]
            else:
                row += [f"{p[0]:.6f}", f"{p[1]:.6f}", f"{p[2]:.6f}", STATUS_NAMES[int(s)]]
        self.writer.writerow(row)

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

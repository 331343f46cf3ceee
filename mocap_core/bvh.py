"""BVH writer: right-handed, Y up, metres; the joint tree of the skeleton model.

Channels: the root has ``Xposition Yposition Zposition Zrotation Xrotation Yrotation``; every other
joint has the same six, its position channels carrying its measured offset from its parent each
frame (OFFSET holds the take's median). With them, forward kinematics gives back the solved joint
positions exactly, even where two joints are not rigidly linked (the sternum-clavicle point moves
on the chest, for example). Rotations are each bone's frame relative to its parent's (Euler ZXY,
degrees: R = Rz Rx Ry). End sites (head_top, hand_*, toe_*) are ``End Site`` blocks.
A joint missing in a frame keeps its last pose.

The file is written as the frames come, a second's worth at a time: the motion rows are appended and the
header (the OFFSETs so far and the frame count, in fields of fixed width) rewritten in place, so the file on
disk is a whole BVH after every flush and a crash loses at most the last second.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from mocap_core.rig import to_canonical
from mocap_core.skeleton import END_SITES, JOINTS, PARENT, children

CHANNELS = "Xposition Yposition Zposition Zrotation Xrotation Yrotation"


class BvhWriter:
    def __init__(self, path: str | Path, rate_hz: float, up_axis: str = "z", flush_s: float = 1.0):
        self.path = Path(path)
        self.rate_hz = rate_hz
        self.a = to_canonical(up_axis)
        self.rows: list[str] = []      # not yet on disk
        self.frames = 0                # rows on disk and pending
        self.flush_rows = max(1, int(round(flush_s * rate_hz)))
        self.offsets: list[np.ndarray] = []
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.file = open(self.path, "w+")
        self._write_header()
        n = len(JOINTS)
        self.last_local = np.zeros((n, 3))
        self.last_rot = np.tile(np.eye(3), (n, 1, 1))
        self.last_root = np.zeros(3)

    def add(self, positions: np.ndarray, frames: np.ndarray) -> None:
        """One frame of the skeleton model (source world): positions (J, 3), bone frames (J, 3, 3)."""
        p = positions @ self.a.T
        r = self.a @ frames
        ok_p = np.isfinite(p).all(axis=1)
        ok_r = np.isfinite(r).all(axis=(1, 2))
        rot = np.where(ok_r[:, None, None], r, self.last_rot)
        self.last_rot = rot
        local = self.last_local.copy()
        for j, name in enumerate(JOINTS):
            parent = PARENT[name]
            if parent is None:
                if ok_p[j]:
                    self.last_root = p[j]
                continue
            pj = JOINTS.index(parent)
            if ok_p[j] and ok_p[pj]:
                local[j] = rot[pj].T @ (p[j] - p[pj])
        self.last_local = local
        self.offsets.append(local)
        values = list(self.last_root)
        euler_of = {}
        for j, name in enumerate(JOINTS):
            parent = PARENT[name]
            rel = rot[j] if parent is None else rot[JOINTS.index(parent)].T @ rot[j]
            euler_of[name] = Rotation.from_matrix(rel).as_euler("ZXY", degrees=True)
        for name in self._order():
            j = JOINTS.index(name)
            pos = self.last_root if PARENT[name] is None else local[j]
            values += list(pos) + list(euler_of[name])
        self.rows.append(" ".join(f"{v:.6f}" for v in values[3:]))
        self.frames += 1
        if len(self.rows) >= self.flush_rows:
            self.flush()

    def flush(self) -> None:
        """The pending rows onto the end of the file, then the header with the OFFSETs and count so far."""
        self.file.seek(0, 2)
        self.file.write("".join(row + "\n" for row in self.rows))
        self.rows = []
        self._write_header()
        self.file.flush()

    def _order(self) -> list[str]:
        """Joints with channels, in the order the hierarchy lists them (depth first)."""
        out = []

        def walk(name):
            if name in END_SITES:
                return
            out.append(name)
            for c in children(name):
                walk(c)

        walk(JOINTS[0])
        return out

    def close(self) -> None:
        self.flush()
        self.file.close()

    def _write_header(self) -> None:
        """HIERARCHY and MOTION's two lines at the file's start, always the same length (fixed-width fields)."""
        median = np.median(np.array(self.offsets), axis=0) if self.offsets else np.zeros((len(JOINTS), 3))
        lines = ["HIERARCHY"]

        def offset(pad, name):
            return f"{pad}  OFFSET " + " ".join(f"{v:13.6f}" for v in median[JOINTS.index(name)])

        def block(name, depth):
            pad = "  " * depth
            if name in END_SITES:
                lines.extend([f"{pad}End Site", f"{pad}{{", offset(pad, name), f"{pad}}}"])
                return
            head = "ROOT" if PARENT[name] is None else "JOINT"
            lines.extend([f"{pad}{head} {name}", f"{pad}{{", offset(pad, name), f"{pad}  CHANNELS 6 {CHANNELS}"])
            for c in children(name):
                block(c, depth + 1)
            lines.append(f"{pad}}}")

        block(JOINTS[0], 0)
        lines += ["MOTION", f"Frames: {self.frames:<12d}", f"Frame Time: {1.0 / self.rate_hz:.8f}"]
        self.file.seek(0)
        self.file.write("\n".join(lines) + "\n")

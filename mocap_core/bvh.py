"""BVH writer: a rig that animation tools import as it is. Right-handed, Y up, metres; the joint tree of the
skeleton model, named for a common rig if asked (``NAMINGS``: Mixamo/HumanIK, Unreal's mannequin).

The rest pose (every channel zero) is a T-pose facing +Z: arms along the lateral axis, legs down. Each
OFFSET is the subject's own bone, the take's median of the child joint's place in its parent's bone frame,
turned into the T-pose; a bone never seen takes the skeleton model's T-pose bone. Only the root moves (six
channels, ``Xposition Yposition Zposition Zrotation Xrotation Yrotation``); every other joint has the three
rotations, so bones keep their lengths. A joint's rotation is its bone frame relative to its T-pose frame
(as the rig's, mocap_core/rig.py), local to its parent's, in Euler ZXY degrees (R = Rz Rx Ry). Forward
kinematics places each joint where the solve put it, to within how far that bone's length wandered. A joint
missing in a frame keeps its last local rotation (a joint never seen keeps its parent's). End sites
(head_top, hand_*, toe_*) are ``End Site`` blocks.

The file is written as the frames come, a second's worth at a time: the motion rows are appended and the
header (the OFFSETs so far and the frame count, in fields of fixed width) rewritten in place, so the file on
disk is a whole BVH after every flush and a crash loses at most the last second.
"""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from mocap_core.rig import rest_frames, t_pose_positions
from mocap_core.skeleton import END_SITES, JOINTS, PARENT_INDEX, children
from mocap_core.world import to_canonical

ROOT_CHANNELS = "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation"
JOINT_CHANNELS = "CHANNELS 3 Zrotation Xrotation Yrotation"
FACE_PLUS_Z = np.diag([-1.0, 1.0, -1.0])  # the rig's T-pose faces -Z; BVH rigs (Mixamo's, CMU's) face +Z
MAX_SAMPLES = 20000  # frames whose bones make the median OFFSETs (minutes of a take: plenty for a median)

_COMMON = {"pelvis": "Hips", "spine0": "Spine", "spine1": "Spine1", "spine3": "Spine2", "neck": "Neck",
           "head": "Head", "head_top": "HeadTop_End"}
_SIDED = {"clavicle": "Shoulder", "shoulder": "Arm", "elbow": "ForeArm", "wrist": "Hand", "hand": "HandMiddle1",
          "hip": "UpLeg", "knee": "Leg", "ankle": "Foot", "foot": "ToeBase", "toe": "Toe_End"}
_UNREAL = {"pelvis": "pelvis", "spine0": "spine_01", "spine1": "spine_02", "spine3": "spine_03", "neck": "neck_01",
           "head": "head", "head_top": "head_end"}
_UNREAL_SIDED = {"clavicle": "clavicle", "shoulder": "upperarm", "elbow": "lowerarm", "wrist": "hand",
                 "hand": "middle_01", "hip": "thigh", "knee": "calf", "ankle": "foot", "foot": "ball", "toe": "toe_end"}


def _named(common: dict, sided: dict, fmt) -> dict[str, str]:
    out = dict(common)
    for joint in JOINTS:
        if joint not in common:
            stem, side = joint.rsplit("_", 1)
            out[joint] = fmt(sided[stem], side)
    return out


NAMINGS: dict[str, dict[str, str]] = {
    "mocap": {j: j for j in JOINTS},
    "mixamo": _named(_COMMON, _SIDED, lambda s, side: ("Left" if side == "l" else "Right") + s),
    "unreal": _named(_UNREAL, _UNREAL_SIDED, lambda s, side: f"{s}_{side}"),
}
NAMINGS["humanik"] = NAMINGS["mixamo"]  # Mixamo's skeleton is HumanIK's


def _depth_first() -> list[int]:
    out = []

    def walk(name):
        out.append(JOINTS.index(name))
        for c in children(name):
            walk(c)

    walk(JOINTS[0])
    return out


ORDER = _depth_first()                                        # the hierarchy's order
MOVING = [j for j in ORDER if JOINTS[j] not in END_SITES]     # joints with channels, in the same order
_PARENT = np.where(PARENT_INDEX >= 0, PARENT_INDEX, 0)


class BvhWriter:
    def __init__(self, path: str | Path, rate_hz: float, up_axis: str = "z", flush_s: float = 1.0,
                 names: str = "mocap"):
        if names not in NAMINGS:
            raise ValueError(f"BVH names {names!r}: expected one of {', '.join(NAMINGS)}")
        self.path = Path(path)
        self.rate_hz = rate_hz
        self.names = NAMINGS[names]
        self.a = to_canonical(up_axis)
        self.rest = FACE_PLUS_Z @ rest_frames()        # T-pose bone frames, canonical, facing +Z
        t_pos = t_pose_positions() @ FACE_PLUS_Z.T
        # the model's bone in its parent's frame, for bones the take never shows
        self.model_local = np.einsum("jki,jk->ji", self.rest[_PARENT], t_pos - t_pos[_PARENT])
        self.samples: list[np.ndarray] = []            # (F, J, 3) each joint's place in its parent's frame
        self.n_samples = 0
        self.final_offsets: np.ndarray | None = None   # the OFFSETs once MAX_SAMPLES frames have made them
        self.rows: list[str] = []                      # not yet on disk
        self.frames = 0                                # rows on disk and pending
        self.flush_rows = max(1, int(round(flush_s * rate_hz)))
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.file = open(self.path, "w+")
        self._write_header()
        n = len(JOINTS)
        self.last_local = np.tile(np.eye(3), (n, 1, 1))   # each joint's rotation in its parent's (rig) frame
        self.last_root = np.zeros(3)

    def add(self, positions: np.ndarray, frames: np.ndarray) -> None:
        """One frame of the skeleton model (source world): positions (J, 3), bone frames (J, 3, 3)."""
        self.add_frames(positions[None], frames[None])

    def add_frames(self, positions: np.ndarray, frames: np.ndarray) -> None:
        """Frames of the skeleton model (source world): positions (F, J, 3), bone frames (F, J, 3, 3)."""
        p = positions @ self.a.T
        f = self.a @ frames
        ok_p = np.isfinite(p).all(axis=2)
        ok_f = np.isfinite(f).all(axis=(2, 3))
        room = max(0, MAX_SAMPLES - self.n_samples)
        if room:
            local = np.einsum("fjki,fjk->fji", f[:room, _PARENT], p[:room] - p[:room, _PARENT])
            local[~(ok_p & ok_p[:, _PARENT] & ok_f[:, _PARENT])[:room]] = np.nan
            self.samples.append(local)
            self.n_samples += len(local)
        world = f @ np.transpose(self.rest, (0, 2, 1))    # rotation from the T-pose, as the rig's
        rel = np.einsum("fjki,fjkl->fjil", world[:, _PARENT], world)
        rel[:, 0] = world[:, 0]
        ok = ok_f & ok_f[:, _PARENT]
        ok[:, 0] = ok_f[:, 0]
        local_moving = np.empty((len(p), len(MOVING), 3, 3))
        roots = np.empty((len(p), 3))
        for k in range(len(p)):  # (each frame keeps the last known rotation of a joint it lacks)
            self.last_local = np.where(ok[k, :, None, None], rel[k], self.last_local)
            if ok_p[k, 0]:
                self.last_root = p[k, 0]
            local_moving[k], roots[k] = self.last_local[MOVING], self.last_root
        with warnings.catch_warnings():  # at gimbal lock scipy picks one of the equal answers, and says so
            warnings.simplefilter("ignore", UserWarning)
            euler = Rotation.from_matrix(local_moving.reshape(-1, 3, 3)).as_euler("ZXY", degrees=True)
        values = np.concatenate([roots, euler.reshape(len(p), -1)], axis=1)
        row = " ".join(["%.6f"] * values.shape[1])
        self.rows.extend(row % tuple(v) for v in values.tolist())
        self.frames += len(p)
        if len(self.rows) >= self.flush_rows:
            self.flush()

    def flush(self) -> None:
        """The pending rows onto the end of the file, then the header with the OFFSETs and count so far."""
        self.file.seek(0, 2)
        self.file.write("".join(row + "\n" for row in self.rows))
        self.rows = []
        self._write_header()
        self.file.flush()

    def close(self) -> None:
        self.flush()
        self.file.close()

    def offsets(self) -> np.ndarray:
        """Each joint's OFFSET (J, 3): its median place in its parent's frame, turned into the T-pose."""
        if self.final_offsets is not None:
            return self.final_offsets
        local = self.model_local.copy()
        if self.samples:
            stack = np.concatenate(self.samples)
            seen = np.isfinite(stack[..., 0]).any(axis=0)
            if seen.any():
                local[seen] = np.nanmedian(stack[:, seen], axis=0)
        out = np.einsum("jik,jk->ji", self.rest[_PARENT], local)
        out[0] = 0.0
        if self.n_samples >= MAX_SAMPLES:  # no frame is sampled after these: every later header has the same
            self.final_offsets = out
        return out

    def _write_header(self) -> None:
        """HIERARCHY and MOTION's two lines at the file's start, always the same length (fixed-width fields)."""
        offsets = self.offsets()
        lines = ["HIERARCHY"]

        def offset(pad, j):
            return f"{pad}  OFFSET " + " ".join(f"{v:13.6f}" for v in offsets[j])

        def block(name, depth):
            pad, j = "  " * depth, JOINTS.index(name)
            if name in END_SITES:
                lines.extend([f"{pad}End Site", f"{pad}{{", offset(pad, j), f"{pad}}}"])
                return
            head = "ROOT" if depth == 0 else "JOINT"
            lines.extend([f"{pad}{head} {self.names[name]}", f"{pad}{{", offset(pad, j),
                          f"{pad}  {ROOT_CHANNELS if depth == 0 else JOINT_CHANNELS}"])
            for c in children(name):
                block(c, depth + 1)
            lines.append(f"{pad}}}")

        block(JOINTS[0], 0)
        lines += ["MOTION", f"Frames: {self.frames:<12d}", f"Frame Time: {1.0 / self.rate_hz:.8f}"]
        self.file.seek(0)
        self.file.write("\n".join(lines) + "\n")

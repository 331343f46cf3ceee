"""Skeleton arrays <-> SkeletonFrame messages (bone frames travel as quaternions)."""
from __future__ import annotations

import numpy as np

from messages import SkeletonFrame
from mocap_core.ik.kernels import frames_to_quats, quats_to_frames


def to_message(positions: np.ndarray, frames: np.ndarray, status: np.ndarray) -> SkeletonFrame:
    return SkeletonFrame(header=SkeletonFrame.make_header(), positions=positions.astype(np.float32),
                         orientations=frames_to_quats(np.ascontiguousarray(frames, np.float64)).astype(np.float32),
                         status=status.astype(np.uint8))


def from_message(msg: SkeletonFrame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """-> positions (J, 3) float64, frames (J, 3, 3), status (J,) (writable copies)."""
    return (msg.positions.astype(np.float64), quats_to_frames(msg.orientations.astype(np.float64)),
            msg.status.copy())

"""Skeleton arrays <-> SkeletonFrame (and LimbSolution) messages: the same layout (messages.schemas), float32 on
the wire."""
from __future__ import annotations

import numpy as np

from messages import LimbSolution, SkeletonFrame


def to_message(positions: np.ndarray, frames: np.ndarray, status: np.ndarray) -> SkeletonFrame:
    return SkeletonFrame(header=SkeletonFrame.make_header(), positions=positions.astype(np.float32),
                         rotations=frames.astype(np.float32), status=status.astype(np.uint8))


def from_message(msg: SkeletonFrame | LimbSolution) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """-> positions (J, 3) float64, frames (J, 3, 3), status (J,) (writable copies), of a skeleton or a limb."""
    return msg.positions.astype(np.float64), msg.rotations.astype(np.float64), msg.status.copy()

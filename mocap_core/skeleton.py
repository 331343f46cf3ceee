"""The skeleton model: joint names, the joint tree, limbs and joint status codes (thesis 3.2).

Joints are listed in pre-order (parents before children); this is the "model order" of every
array, CSV and message. Each joint is named after the proximal end of its bone, as in the thesis:
``elbow_l`` is the elbow centre and also the forearm that starts there.

Bone axes (facts 2.1, our convention for every bone): local +y runs along the bone toward its
child, local +z points to the subject's front (for the foot: up), x = y cross z completes a
right-handed frame (so x is the subject's left on the spine and the subject's right on the limbs).
End sites (``head_top``, ``hand_*`` at the second metacarpal head, ``toe_*``) close their chains;
they carry their parent's orientation.
"""
from __future__ import annotations

from enum import IntEnum

import numpy as np

_TREE: list[tuple[str, str | None]] = [
    ("pelvis", None),
    ("spine0", "pelvis"),
    ("spine1", "spine0"),
    ("spine3", "spine1"),
    ("neck", "spine3"),
    ("head", "neck"),
    ("head_top", "head"),
]
for _s in ("l", "r"):
    _TREE += [
        (f"clavicle_{_s}", "spine3"),
        (f"shoulder_{_s}", f"clavicle_{_s}"),
        (f"elbow_{_s}", f"shoulder_{_s}"),
        (f"wrist_{_s}", f"elbow_{_s}"),
        (f"hand_{_s}", f"wrist_{_s}"),
    ]
for _s in ("l", "r"):
    _TREE += [
        (f"hip_{_s}", "pelvis"),
        (f"knee_{_s}", f"hip_{_s}"),
        (f"ankle_{_s}", f"knee_{_s}"),
        (f"foot_{_s}", f"ankle_{_s}"),
        (f"toe_{_s}", f"foot_{_s}"),
    ]

JOINTS: tuple[str, ...] = tuple(name for name, _ in _TREE)
PARENT: dict[str, str | None] = dict(_TREE)
INDEX: dict[str, int] = {name: i for i, name in enumerate(JOINTS)}
PARENT_INDEX = np.array([-1 if p is None else INDEX[p] for _, p in _TREE], dtype=np.int64)
END_SITES = frozenset({"head_top", "hand_l", "hand_r", "toe_l", "toe_r"})
N_JOINTS = len(JOINTS)

# The IK stages of the graph, each with the chain of joints it fills: the torso first, then the four limbs in
# parallel (docs/design.md). A chain's root hangs from a joint the stage before placed (the pelvis, the sternum, the hips).
LIMBS: dict[str, tuple[str, ...]] = {
    "torso": ("spine0", "spine1", "spine3", "neck", "head", "head_top"),
    "left_arm": ("clavicle_l", "shoulder_l", "elbow_l", "wrist_l", "hand_l"),
    "right_arm": ("clavicle_r", "shoulder_r", "elbow_r", "wrist_r", "hand_r"),
    "left_leg": ("hip_l", "knee_l", "ankle_l", "foot_l", "toe_l"),
    "right_leg": ("hip_r", "knee_r", "ankle_r", "foot_r", "toe_r"),
}


def children(joint: str) -> list[str]:
    return [name for name, parent in _TREE if parent == joint]


class Status(IntEnum):
    """Per-joint status in every skeleton message and the joints CSV."""

    MISSING = 0
    LOCATED = 1    # computed from markers this frame
    ESTIMATED = 2  # filled by IK this frame
    HELD = 3       # last known pose reused (a late limb, or no reference yet)


STATUS_NAMES = {s.value: s.name.lower() for s in Status}
# The same, as plain ints: numba kernels read them as compile-time constants.
MISSING, LOCATED, ESTIMATED, HELD = (int(s) for s in Status)

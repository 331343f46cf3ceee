"""Retargeting onto a character rig: rotations, not positions, relative to the rig's rest pose.

The default rig is a Unity Humanoid (HumanBodyBones names) in T-pose, where every bone's world
rotation is the identity. For each rig bone we take the bone frame of the joint it maps to and
the frame the same joint has when the subject stands in a T-pose (computed once by localizing a
synthetic T-pose, so the two always follow the same conventions):

    rig world rotation = frame now · frame in T-pose^T        (both in a right-handed Y-up frame)
    rig local rotation = parent's rig world rotation^T · rig world rotation

Coordinates: the source's right-handed world is first turned so +Y is up ("canonical", what BVH
uses); Unity is left-handed Y-up with the subject facing +Z, which is the canonical frame with Z
negated (the subject faces -Z there): p_unity = (x, y, -z), R_unity = F R F with F = diag(1, 1, -1),
i.e. q_unity = (-qx, -qy, qz, qw) (UniVRM's ReverseZ).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from mocap_core.profiles import LANDMARK_INDEX, LANDMARKS
from mocap_core.skeleton import INDEX, PARENT
from mocap_core.world import to_canonical

# (Unity HumanBodyBones name, our joint, parent rig bone)
UNITY_HUMANOID: tuple[tuple[str, str, str | None], ...] = (
    ("Hips", "pelvis", None),
    ("Spine", "spine0", "Hips"),
    ("Chest", "spine1", "Spine"),
    ("UpperChest", "spine3", "Chest"),
    ("Neck", "neck", "UpperChest"),
    ("Head", "head", "Neck"),
    ("LeftShoulder", "clavicle_l", "UpperChest"),
    ("LeftUpperArm", "shoulder_l", "LeftShoulder"),
    ("LeftLowerArm", "elbow_l", "LeftUpperArm"),
    ("LeftHand", "wrist_l", "LeftLowerArm"),
    ("RightShoulder", "clavicle_r", "UpperChest"),
    ("RightUpperArm", "shoulder_r", "RightShoulder"),
    ("RightLowerArm", "elbow_r", "RightUpperArm"),
    ("RightHand", "wrist_r", "RightLowerArm"),
    ("LeftUpperLeg", "hip_l", "Hips"),
    ("LeftLowerLeg", "knee_l", "LeftUpperLeg"),
    ("LeftFoot", "ankle_l", "LeftLowerLeg"),
    ("LeftToes", "foot_l", "LeftFoot"),
    ("RightUpperLeg", "hip_r", "Hips"),
    ("RightLowerLeg", "knee_r", "RightUpperLeg"),
    ("RightFoot", "ankle_r", "RightLowerLeg"),
    ("RightToes", "foot_r", "RightFoot"),
)
BONES = tuple(b for b, _, _ in UNITY_HUMANOID)
BONE_JOINT = np.array([INDEX[j] for _, j, _ in UNITY_HUMANOID])
BONE_PARENT = np.array([-1 if p is None else BONES.index(p) for _, _, p in UNITY_HUMANOID])
FLIP_Z = np.diag([1.0, 1.0, -1.0])


def t_pose_landmarks() -> np.ndarray:
    """Landmarks of a subject in T-pose, canonical frame: +Y up, facing -Z, right hand at +X,
    palms forward (so the elbows' medial epicondyles point down and the thumbs up)."""
    lm = np.full((len(LANDMARKS), 3), np.nan)

    def put(name, p):
        lm[LANDMARK_INDEX[name]] = p

    fwd, up = np.array([0, 0, -1.0]), np.array([0, 1.0, 0])
    put("SACR", [0, 1.0, 0.10])
    put("L_IAS", [-0.12, 1.0, -0.05])
    put("R_IAS", [0.12, 1.0, -0.05])
    put("TV12", [0, 1.25, 0.11])
    put("TV2", [0, 1.5, 0.09])
    put("SME", [0, 1.45, -0.08])
    put("SGL", [0, 1.65, -0.09])
    put("L_HEAD", [-0.08, 1.65, 0])
    put("R_HEAD", [0.08, 1.65, 0])
    for side, s in (("L", -1.0), ("R", 1.0)):
        out = np.array([s, 0, 0])  # lateral
        elbow, wrist = np.array([0.48 * s, 1.40, 0.02]), np.array([0.73 * s, 1.40, 0.02])
        put(f"{side}_SAE", [0.19 * s, 1.45, 0.02])
        put(f"{side}_HLE", elbow + 0.042 * up)
        put(f"{side}_HME", elbow - 0.042 * up)
        put(f"{side}_RSP", wrist + 0.02 * up)
        put(f"{side}_USP", wrist - 0.02 * up)
        put(f"{side}_HM2", wrist + 0.08 * out + 0.01 * fwd)
        knee, ankle = np.array([0.09 * s, 0.5, 0.0]), np.array([0.09 * s, 0.08, 0.02])
        put(f"{side}_FLE", knee + 0.057 * out)
        put(f"{side}_FME", knee - 0.057 * out)
        put(f"{side}_TTC", knee + 0.05 * fwd - 0.06 * up)
        put(f"{side}_FAL", ankle + 0.042 * out)
        put(f"{side}_TAM", ankle - 0.042 * out)
        put(f"{side}_FCC", ankle - 0.07 * fwd - 0.05 * up)
        put(f"{side}_FM2", ankle + 0.15 * fwd - 0.06 * up)
    return lm


@lru_cache(maxsize=1)
def _t_pose():
    from mocap_core.localization import Localizer

    return Localizer().localize(t_pose_landmarks())


def rest_frames() -> np.ndarray:
    """Bone frames (J, 3, 3) of the T-pose, canonical frame."""
    return _t_pose().frames[0]


def t_pose_positions() -> np.ndarray:
    """Joint positions (J, 3) of the T-pose, canonical frame."""
    return _t_pose().positions[0]


@lru_cache(maxsize=1)
def default_rig_offsets() -> np.ndarray:
    """The default character's bones (B, 3), Unity frame: each bone's offset from its parent rig bone in
    the T-pose (where every world rotation is the identity, so local offsets are world differences). A
    1.75 m humanoid: the proportions a receiver's character keeps when positions come from the rig."""
    p = FLIP_Z @ t_pose_positions()[BONE_JOINT].T
    out = (p - p[:, _PARENT_OF]).T
    out[~_HAS_PARENT] = 0.0
    return out


def rig_world_rotations(frames_src: np.ndarray, up_axis: str) -> np.ndarray:
    """Bone frames (J, 3, 3) in the source world -> rig bones' world rotations (B, 3, 3), Unity frame."""
    a = to_canonical(up_axis)
    rest = rest_frames()[BONE_JOINT]
    canon = a @ frames_src[BONE_JOINT]
    q = canon @ np.transpose(rest, (0, 2, 1))
    return FLIP_Z @ q @ FLIP_Z


_HAS_PARENT = BONE_PARENT >= 0
_PARENT_OF = np.where(_HAS_PARENT, BONE_PARENT, 0)


def rig_local_rotations(world: np.ndarray) -> np.ndarray:
    local = np.einsum("bji,bjk->bik", world[_PARENT_OF], world)  # parent^T @ bone, all bones at once
    local[~_HAS_PARENT] = world[~_HAS_PARENT]
    return local


def to_unity_position(p_src: np.ndarray, up_axis: str) -> np.ndarray:
    return (FLIP_Z @ to_canonical(up_axis) @ np.asarray(p_src, float).T).T


def rest_offsets(positions: np.ndarray, frames: np.ndarray, up_axis: str) -> np.ndarray:
    """The rig's rest pose for this subject, Unity frame: each bone's offset from its parent rig bone
    (B, 3), from the subject's measured bones (median over the frames given). Applying the rig's
    world rotations to these offsets gives back the joint positions (forward kinematics)."""
    offsets = np.zeros((len(BONES), 3))
    rest = rest_frames()
    for b, p in enumerate(BONE_PARENT):
        if p < 0:
            continue
        j, pj = BONE_JOINT[b], BONE_JOINT[p]
        local = np.einsum("fji,fj->fi", frames[:, pj], positions[:, j] - positions[:, pj])  # in the parent's frame
        local = np.nanmedian(local, axis=0)
        offsets[b] = FLIP_Z @ (rest[pj] @ local)  # the same offset with the parent in its T-pose frame
    return offsets


def local_positions(positions_src: np.ndarray, world: np.ndarray, up_axis: str) -> np.ndarray:
    """Each rig bone's offset from its parent this frame, in the parent's rig frame (B, 3)."""
    p = to_unity_position(positions_src[BONE_JOINT], up_axis)
    out = np.einsum("bji,bj->bi", world[_PARENT_OF], p - p[_PARENT_OF])
    out[~_HAS_PARENT] = 0.0
    return out


def forward_kinematics(root_unity: np.ndarray, world: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Rig bone positions (B, 3), Unity frame, from the root position, world rotations and offsets."""
    pos = np.zeros((len(BONES), 3))
    pos[0] = root_unity
    for b, p in enumerate(BONE_PARENT):
        if p >= 0:
            pos[b] = pos[p] + world[p] @ offsets[b]
    return pos


__all__ = ["BONES", "UNITY_HUMANOID", "PARENT", "forward_kinematics", "local_positions", "rest_offsets",
           "rig_local_rotations", "rig_world_rotations", "to_unity_position"]

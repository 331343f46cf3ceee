"""Functional joint centres: where a joint is, from how the segments on either side of it move, with no landmark.

A joint's centre is fixed in the parent segment, and every marker on the child segment keeps its distance from it.
Seen from the parent (each child marker's track in the parent's frame), a ball joint's child markers move on spheres
about the centre, a hinge's on circles about its axis. The linear least-squares fit of Gamage & Lasenby (2002), with
each marker's own radius eliminated by centring its track:

    2 (x_k(t) - mean_k x) . c = |x_k(t)|^2 - mean_k |x|^2        for every child marker k and frame t

SCoRE and SARA (Ehrig et al. 2006, 2007) solve the symmetric form, which needs a full pose of the child segment too
(three markers on the thigh); the marker sets here seldom have them, so the centre is fitted from the parent's side,
which needs one child marker. The design's singular values say how far the child's markers moved about the centre in
each direction (the rms excursion): a ball joint needs all three, a hinge two (its axis is the third, which the
motion cannot see, so a hinge's centre is put on its axis where it passes nearest the parent's own joint: the femur's
and humerus's long axes meet the knee's and elbow's hinge near square). Too little motion and the joint is refused
with a message that says how much it moved.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mocap_core.geometry import rigid_fit
from mocap_core.skeleton import INDEX, PARENT_INDEX

# How far off a functional centre may be, by the fit's own residuals, before it is refused.
TOLERANCE_M = 0.02


class NoCentre(ValueError):
    pass


@dataclass
class Centre:
    place: np.ndarray        # (3,) the centre in the parent's frame (metres)
    axis: np.ndarray | None  # (3,) a hinge's axis in the parent's frame; None for a ball joint
    excursion_m: np.ndarray  # (3,) the child markers' rms excursion about the centre, largest first
    uncertainty_m: np.ndarray  # how far off the centre may be along each direction fitted (2 for a hinge)

    def why_not(self, what: str, tolerance_m: float = TOLERANCE_M) -> str:
        """Why the centre is not to be trusted ("" when it is)."""
        if self.uncertainty_m.max() <= tolerance_m:
            return ""
        return (f"{what}: the child segment's markers moved {_mm(self.excursion_m)} mm rms about it, too little for "
                f"their wobble: it could be {self.uncertainty_m.max() * 1000:.0f} mm off (at most "
                f"{tolerance_m * 1000:.0f}); move the joint through more of its range (a range-of-motion trial)")


def cluster_poses(points: np.ndarray, min_points: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Each frame's pose (R (F, 3, 3), t (F, 3); NaN where fewer than ``min_points`` are seen) of a segment carrying
    ``points`` (F, K, 3): the rigid fit of its mean shape to the points seen (Soderkvist & Wedin). The mean shape is
    the points in the pose of the frame that sees most of them, averaged over every frame after a first alignment."""
    F = len(points)
    seen = np.isfinite(points).all(axis=2)
    R, t = np.full((F, 3, 3), np.nan), np.full((F, 3), np.nan)
    if seen.shape[1] < min_points or seen.sum(axis=1).max() < min_points:
        return R, t
    shape = points[int(np.argmax(seen.sum(axis=1)))].copy()
    for _ in range(2):
        usable = seen & np.isfinite(shape).all(axis=1)
        for f in np.flatnonzero(usable.sum(axis=1) >= min_points):
            k = usable[f]
            R[f], t[f] = rigid_fit(shape[k], points[f, k], np.ones(int(k.sum())))
        local = np.einsum("fba,fkb->fka", R, points - t[:, None])   # every point in the pose's frame
        with np.errstate(invalid="ignore"):
            shape = np.nanmean(local, axis=0) if np.isfinite(local).any() else shape
    return R, t


def in_frame(R: np.ndarray, t: np.ndarray, points: np.ndarray) -> np.ndarray:
    """World points (F, K, 3) in the frames (R, t) of each frame: R^T (p - t)."""
    return np.einsum("fba,fkb->fka", R, points - t[:, None])


def centre_of_rotation(local: np.ndarray, hinge: bool = False, near: np.ndarray | None = None,
                       what: str = "the joint") -> Centre:
    """The centre of rotation of child markers ``local`` (F, K, 3), seen in the parent's frame (NaN where not seen).
    ``hinge``: the centre on the axis nearest ``near`` (the parent's own joint centre; the markers' mean without).
    Raises NoCentre when no child marker is seen long enough; ``Centre.why_not`` says whether the motion
    placed it well enough."""
    rows, rhs = [], []
    for k in range(local.shape[1]):
        x = local[:, k][np.isfinite(local[:, k]).all(axis=1)]
        if len(x) < 10:
            continue
        sq = np.einsum("fa,fa->f", x, x)
        rows.append(x - x.mean(axis=0))
        rhs.append((sq - sq.mean()) / 2)
    if not rows:
        raise NoCentre(f"{what}: no marker of the child segment is seen in 10 frames with the parent's")
    A, b = np.concatenate(rows), np.concatenate(rhs)
    _, s, vt = np.linalg.svd(A, full_matrices=False)
    excursion = s / np.sqrt(len(A))
    dims = 2 if hinge else 3          # a hinge's axis (the last direction) is not fitted
    plane = vt[:dims]
    c = plane.T @ ((plane @ A.T @ b) / s[:dims] ** 2)
    # How far the centre may be off in each direction fitted: the fit's residual (a marker's distance from the centre
    # wobbling with the skin, times that distance; over many frames alike, so no averaging down) over the markers'
    # excursion in that direction (Centre.uncertainty_m).
    wobble = float(np.sqrt(np.mean((A @ c - b) ** 2)))
    axis = None
    if hinge:  # the axis is the direction the markers did not move in; the centre goes on it nearest ``near``
        axis = vt[2]
        if near is None:
            near = np.nanmean(local.reshape(-1, 3), axis=0)
        c = c + axis * float(axis @ (near - c))
    return Centre(c, axis, excursion, wobble / excursion[:dims])


def _mm(v: np.ndarray) -> str:
    return "/".join(f"{x * 1000:.0f}" for x in v)


# The joints a calibration looks for from motion: (parent bone, child bone, a hinge?). The shoulder's centre moves
# with the shoulder blade, so it has no fixed place on a bone to find.
FUNCTIONAL = {"hip": ("pelvis", "hip", False), "knee": ("hip", "knee", True), "elbow": ("shoulder", "elbow", True)}


@dataclass
class Found:
    joint: str
    positions: np.ndarray | None   # (F, 3) the centre in every frame (NaN where the parent is not seen)
    centre: Centre | None
    why: str = ""                  # why it is not to be trusted ("": it is)
    axes: np.ndarray | None = None  # (F, 3) a hinge's axis in every frame (NaN where the parent is not seen)

    def apart_m(self, located: np.ndarray, joint_index: dict[str, int]) -> float:
        """The mean distance (m) from where the landmarks put the joint (``located`` (F, J, 3)); NaN where they never
        do."""
        apart = np.linalg.norm(self.positions - located[:, joint_index[self.joint]], axis=1)
        return float(np.nanmean(apart)) if np.isfinite(apart).any() else float("nan")


def functional_centres(markers: np.ndarray, marker_bone: np.ndarray, joint_index: dict[str, int],
                       located: np.ndarray | None = None) -> list[Found]:
    """The hips', knees' and elbows' centres from the take's motion (F, M, 3), each marker on the bone
    ``marker_bone`` (a joint index, -1: none) names; each with why it is not to be trusted, if it is not. The parent
    bone's own joint (the hip for a knee) counts as one of its points: found from motion here, else where the
    landmarks put it (``located`` (F, J, 3), NaN where not); a hinge's centre goes on its axis nearest that joint
    (nearest the parent's markers without one)."""
    found: dict[str, np.ndarray] = {}
    out = []
    for side in "lr":
        for joint, (parent, child, hinge) in FUNCTIONAL.items():
            name = f"{joint}_{side}"
            parent_bone = parent if parent == "pelvis" else f"{parent}_{side}"
            parent_markers = markers[:, marker_bone == joint_index[parent_bone]]
            above = found.get(parent_bone)
            if above is None and located is not None and parent != "pelvis":
                above = located[:, joint_index[parent_bone]]
                above = above if np.isfinite(above).all(axis=1).any() else None
            if above is not None:
                parent_markers = np.concatenate([above[:, None], parent_markers], axis=1)
            R, t = cluster_poses(parent_markers)
            child_markers = markers[:, marker_bone == joint_index[f"{child}_{side}"]]
            if not np.isfinite(R).any():
                have = parent_markers.shape[1] - (above is not None)
                out.append(Found(name, None, None, f"{name}: its parent bone {parent_bone} carries {have} marker(s)"
                                 f"{' besides its joint' if above is not None else ''}, and a pose needs 3"))
                continue
            near = np.nanmean(in_frame(R, t, parent_markers[:, :1] if above is not None else parent_markers)
                              .reshape(-1, 3), axis=0) if hinge else None
            try:
                c = centre_of_rotation(in_frame(R, t, child_markers), hinge, near, what=name)
            except NoCentre as e:
                out.append(Found(name, None, None, str(e)))
                continue
            positions = np.einsum("fab,b->fa", R, c.place) + t
            axes = np.einsum("fab,b->fa", R, c.axis) if hinge else None
            why = c.why_not(name)
            if not why:
                found[f"{child}_{side}"] = positions
            out.append(Found(name, positions, c, why, axes))
    return out


# The bone whose frame says which way is the body's left (its x axis), for the frame of each joint found from motion.
LEFT_FROM = {"hip": "pelvis", "knee": "pelvis", "elbow": "spine3"}
CHILDREN = [np.flatnonzero(PARENT_INDEX == j) for j in range(len(PARENT_INDEX))]


def locate_from_motion(markers: np.ndarray, marker_bone: np.ndarray, positions: np.ndarray,
                       frames: np.ndarray) -> tuple[str, ...]:
    """Put the hips, knees and elbows that no landmark locates in any frame where the take's motion finds them
    (``functional_centres``), in place: the joint's position in every frame, and the frames of the bones on either
    side of a hinge where they had none (y along the bone, x along the hinge's axis towards the body's right, as the
    landmarks' frames have it): the parent's, and the joint's own where its child is located (a wrist, an ankle).
    ``positions`` (F, J, 3) and ``frames`` (F, J, 3, 3): what the landmarks located, NaN where not. Returns the
    joints it put."""
    placed = []
    for f in functional_centres(markers, marker_bone, INDEX, positions):
        j = INDEX[f.joint]
        if f.why or np.isfinite(positions[:, j]).any():
            continue
        positions[:, j] = f.positions
        placed.append(f.joint)
        if f.axes is None:
            continue
        right = -frames[:, INDEX[LEFT_FROM[f.joint.rsplit("_", 1)[0]]], :, 0]
        axis = f.axes * np.sign(np.einsum("fa,fa->f", f.axes, right))[:, None]
        for bone, end in [(PARENT_INDEX[j], j), *((j, c) for c in CHILDREN[j])]:
            y = _unit(positions[:, end] - positions[:, bone])
            x = _unit(axis - np.einsum("fa,fa->f", axis, y)[:, None] * y)
            unknown = ~np.isfinite(frames[:, bone]).all(axis=(1, 2))
            frames[unknown, bone] = np.stack([x, y, np.cross(x, y)], axis=2)[unknown]
    return tuple(sorted(placed, key=INDEX.get))


def _unit(v: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore", divide="ignore"):
        return v / np.linalg.norm(v, axis=-1, keepdims=True)

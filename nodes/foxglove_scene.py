"""The skeleton as Foxglove's 3D panel draws it, in foxglove-sdk's schemas (shared by the foxglove_output node and
`mocap bag export --foxglove`):

- ``/skeleton`` (``foxglove.SceneUpdate``): one entity, a sphere per joint coloured by status (located white,
  estimated red, held orange, as the viewer) and the bones as a line list;
- ``/markers`` (``foxglove.SceneUpdate``): the labelled markers, small grey spheres;
- ``/tf`` (``foxglove.FrameTransforms``): every joint's bone frame as a child of ``world`` (Foxglove's
  transform tree: the 3D panel can follow any joint).

Foxglove's world is Z up, so the source's world is turned by its up axis (the header's) first.
"""
from __future__ import annotations

import numpy as np
from foxglove.messages import (
    Color, FrameTransform, FrameTransforms, LinePrimitive, LinePrimitiveLineType, Point3, Pose, Quaternion,
    SceneEntity, SceneUpdate, SpherePrimitive, Timestamp, Vector3,
)
from scipy.spatial.transform import Rotation

from mocap_core.skeleton import JOINTS, PARENT_INDEX, Status
from mocap_core.world import DEFAULT_UP, to_canonical

WORLD = "world"
TOPICS = ("/skeleton", "/markers", "/tf")
COLOURS = {Status.LOCATED: Color(r=0.9, g=0.91, b=0.94, a=1.0), Status.ESTIMATED: Color(r=1.0, g=0.23, b=0.23, a=1.0),
           Status.HELD: Color(r=1.0, g=0.65, b=0.15, a=1.0)}
BONE_COLOUR = Color(r=0.55, g=0.75, b=1.0, a=1.0)
MARKER_COLOUR = Color(r=0.6, g=0.6, b=0.6, a=1.0)
_BONES = [(int(p), j) for j, p in enumerate(PARENT_INDEX) if p >= 0]
_IDENTITY = Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)


def to_z_up(up_axis: str) -> np.ndarray:
    """Rotation from the source's world to Foxglove's (right-handed, Z up)."""
    return to_canonical("+z").T @ to_canonical(up_axis or DEFAULT_UP)


def stamp(t_ns: int) -> Timestamp:
    return Timestamp(sec=int(t_ns // 1_000_000_000), nsec=int(t_ns % 1_000_000_000))


def _point(p) -> Point3:
    return Point3(x=float(p[0]), y=float(p[1]), z=float(p[2]))


def _sphere(p, size: float, colour: Color) -> SpherePrimitive:
    return SpherePrimitive(pose=Pose(position=Vector3(x=float(p[0]), y=float(p[1]), z=float(p[2])),
                                     orientation=_IDENTITY),
                           size=Vector3(x=size, y=size, z=size), color=colour)


def skeleton_scene(positions: np.ndarray, status: np.ndarray, up_axis: str, t_ns: int,
                   actor: str = "") -> SceneUpdate:
    """One frame's joints and bones (positions (J, 3) in the source's world; NaN where missing); an actor's
    skeleton is an entity of its own, named for them."""
    p = positions @ to_z_up(up_axis).T
    seen = np.isfinite(p).all(axis=1) & (status != Status.MISSING)
    spheres = [_sphere(p[j], 0.04, COLOURS.get(Status(int(status[j])), COLOURS[Status.LOCATED]))
               for j in np.flatnonzero(seen)]
    points = [_point(p[k]) for parent, j in _BONES if seen[parent] and seen[j] for k in (parent, j)]
    lines = [LinePrimitive(type=LinePrimitiveLineType.LineList, pose=Pose(position=Vector3(x=0.0, y=0.0, z=0.0),
                                                                           orientation=_IDENTITY),
                           thickness=0.015, scale_invariant=False, points=points, color=BONE_COLOUR)]
    entity = SceneEntity(timestamp=stamp(t_ns), frame_id=WORLD, id=actor or "skeleton", spheres=spheres, lines=lines)
    return SceneUpdate(entities=[entity])


def marker_scene(positions: np.ndarray, up_axis: str, t_ns: int) -> SceneUpdate:
    p = positions @ to_z_up(up_axis).T
    spheres = [_sphere(q, 0.015, MARKER_COLOUR) for q in p if np.isfinite(q).all()]
    return SceneUpdate(entities=[SceneEntity(timestamp=stamp(t_ns), frame_id=WORLD, id="markers", spheres=spheres)])


def joint_transforms(positions: np.ndarray, frames: np.ndarray, up_axis: str, t_ns: int,
                     actor: str = "") -> FrameTransforms:
    """Each located joint's bone frame as a child of ``world`` (an actor's named ``<actor>/<joint>``)."""
    a = to_z_up(up_axis)
    p = positions @ a.T
    r = a @ frames
    ok = np.isfinite(p).all(axis=1) & np.isfinite(r).all(axis=(1, 2))
    q = np.zeros((len(JOINTS), 4))
    if ok.any():
        q[ok] = Rotation.from_matrix(r[ok]).as_quat()  # (x, y, z, w)
    ts = stamp(t_ns)
    names = [f"{actor}/{j}" for j in JOINTS] if actor else JOINTS
    return FrameTransforms(transforms=[
        FrameTransform(timestamp=ts, parent_frame_id=WORLD, child_frame_id=names[j],
                       translation=Vector3(x=float(p[j, 0]), y=float(p[j, 1]), z=float(p[j, 2])),
                       rotation=Quaternion(x=float(q[j, 0]), y=float(q[j, 1]), z=float(q[j, 2]), w=float(q[j, 3])))
        for j in np.flatnonzero(ok)])


class Channels:
    """The three topics in one foxglove-sdk context (a live server's, or an MCAP writer's)."""

    def __init__(self, context):
        from foxglove.channels import FrameTransformsChannel, SceneUpdateChannel

        self.skeleton = SceneUpdateChannel("/skeleton", context=context)
        self.markers = SceneUpdateChannel("/markers", context=context)
        self.tf = FrameTransformsChannel("/tf", context=context)

    def log(self, msg, t_ns: int, actor: str = "") -> int:
        """A SkeletonFrame (to /skeleton and /tf; ``actor``'s, in a stream of several) or a MarkerFrame (to
        /markers), stamped ``t_ns``; how many messages went out."""
        from messages import SkeletonFrame
        from nodes.skeleton_codec import from_message

        up = msg.header.up_axis
        if isinstance(msg, SkeletonFrame):
            positions, frames, status = from_message(msg)
            self.skeleton.log(skeleton_scene(positions, status, up, t_ns, actor), log_time=t_ns)
            self.tf.log(joint_transforms(positions, frames, up, t_ns, actor), log_time=t_ns)
            return 2
        self.markers.log(marker_scene(msg.positions.astype(float), up, t_ns), log_time=t_ns)
        return 1


def export_foxglove(src, dst) -> int:
    """A bag's skeleton/solved and markers/raw in these schemas, to a new MCAP for the Foxglove app. Log and
    publish times are each frame's graph-entry time (wall clock), so the timeline reads as the session did."""
    import foxglove

    from messages import decode
    from nodes.bags import read_bag

    context = foxglove.Context()
    writer = foxglove.open_mcap(dst, allow_overwrite=True, context=context)
    channels = Channels(context)
    n = 0
    try:
        for m in read_bag(src, ["skeleton/solved", "markers/raw"]):
            msg = decode(m.data, m.topic)
            n += channels.log(msg, msg.header.entry_time_ns or m.log_time_ns)
    finally:
        writer.close()
    return n

"""Node kinds by name. A launch file names a kind from this table, or any ``package.module:Class``
(that is how a studio swaps in its own solver node without touching this repository)."""
from __future__ import annotations

import importlib

from nodes.runtime import Node

KINDS: dict[str, str] = {
    "synthetic_source": "nodes.synthetic_source:SyntheticSource",
    "relay": "nodes.relay:Relay",
    "raw_relay": "nodes.relay:RawRelay",
    "frame_log": "nodes.frame_log:FrameLog",
    "file_source": "nodes.file_source:FileSource",
    "qtm_ingest": "nodes.qtm_ingest:QtmIngest",
    "bag_player": "nodes.bag_player:BagPlayer",
    "recorder": "nodes.recorder:Recorder",
    "hip_interpolation": "nodes.hip_interpolation:HipInterpolation",
    "joint_localization": "nodes.joint_localization:JointLocalization",
    "ik_gapfill": "nodes.ik_gapfill:IkGapfill",
    "skeleton_fit": "nodes.skeleton_fit:SkeletonFit",
    "retarget": "nodes.retarget:Retarget",
    "vmc_output": "nodes.vmc_output:VmcOutput",
    "bvh_writer": "nodes.bvh_writer:BvhWriterNode",
    "viewer": "nodes.viewer:Viewer",
    "foxglove_output": "nodes.foxglove_output:FoxgloveOutput",
}


class UnknownKind(Exception):
    pass


def load_kind(kind: str) -> type[Node]:
    target = KINDS.get(kind, kind)
    if ":" not in target:
        raise UnknownKind(f"unknown node kind {kind!r}; known kinds: {', '.join(sorted(KINDS))} "
                          "(or give package.module:Class)")
    module_name, _, class_name = target.partition(":")
    try:
        cls = getattr(importlib.import_module(module_name), class_name)
    except (ImportError, AttributeError) as e:
        raise UnknownKind(f"node kind {kind!r}: cannot load {target} ({e})") from None
    if not (isinstance(cls, type) and issubclass(cls, Node)):
        raise UnknownKind(f"node kind {kind!r}: {target} is not a nodes.runtime.Node")
    return cls

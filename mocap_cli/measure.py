"""Shared by `mocap eval latency` and the benchmarks: the live graph fed by the QTM emulator with a
frame log at its end, and the figures read back from that log."""
from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from mocap_cli.graph_registry import registry_path
from mocap_cli.launch_file import LaunchFile, NodeEntry, load_launch_file

REPO = Path(__file__).resolve().parents[1]


# Where the solving nodes run (node id -> container; absent: a process of its own). "one" is
# launch/studio_composed.yaml's layout (lowest latency); "two" splits the work over two processes, so
# both cores of a 2-core machine take part (highest throughput).
LAYOUTS: dict[str, dict[str, str]] = {
    "processes": {},
    "one": {n: "core" for n in ("hips", "localize", "torso", "left_arm", "right_arm", "left_leg", "right_leg",
                                "retarget")},
    "two": {**{n: "front" for n in ("hips", "localize", "torso", "left_arm", "right_arm")},
            **{n: "back" for n in ("left_leg", "right_leg", "retarget")}},
}


def live_graph(port: int, profile: str, log_path: str | Path, name: str,
               layout: str = "processes", subject: str | None = None) -> LaunchFile:
    """launch/qtm_studio.yaml pointed at the emulator, without the viewer, VMC and Foxglove, logging skeleton/solved,
    with the solving nodes in the processes ``layout`` names (see LAYOUTS). With a ``subject`` file, the
    rigid-skeleton fit (one skeleton_fit node, in the container of the others) solves instead."""
    lf = load_launch_file(REPO / "launch" / "qtm_studio.yaml", [
        f"qtm.port={port}", f"hips.profile={profile}", f"localize.profile={profile}"])
    lf.nodes = [n for n in lf.nodes if n.kind not in ("viewer", "vmc_output", "foxglove_output")]
    if subject:
        at = next(i for i, n in enumerate(lf.nodes) if n.id == "hips")
        lf.nodes = [n for n in lf.nodes if n.kind not in ("hip_interpolation", "joint_localization", "ik_gapfill")]
        lf.nodes.insert(at, NodeEntry(id="fit", kind="skeleton_fit", params={"profile": profile, "subject": subject}))
        next(n for n in lf.nodes if n.id == "retarget").params["input"] = "whole"
    for n in lf.nodes:
        n.container = LAYOUTS[layout].get("hips" if n.id == "fit" else n.id)
    lf.nodes.append(NodeEntry(id="log", kind="frame_log", params={"path": str(log_path)},
                              remaps={"in": "skeleton/solved"}))
    lf.name = name
    return lf


def frame_log_figures(path: str | Path) -> tuple[np.ndarray, int]:
    """A frame_log CSV -> (latency per message in ms, sequence gaps = messages dropped on the way)."""
    with open(path) as f:
        rows = list(csv.DictReader(f))
    latency_ms = np.array([float(r["latency_us"]) for r in rows]) / 1000
    seq = np.array([int(r["seq"]) for r in rows])
    return latency_ms, int((np.diff(seq) - 1).clip(min=0).sum()) if len(seq) > 1 else 0


def capture_frames_missing(path: str | Path) -> int:
    """Capture frames that never reached the log, lost anywhere on the way (sequence gaps only see the
    last hop): the gaps in the frame numbers, ignoring a looping source's wrap-around."""
    with open(path) as f:
        frames = np.array([int(r["frame"]) for r in csv.DictReader(f)])
    steps = np.diff(frames)
    return int((steps[steps > 0] - 1).sum()) if len(frames) > 1 else 0


def usage(graph: str) -> dict[str, tuple[float, float, float]]:
    """Per process (a node, a container of nodes, and the forkserver they were forked from): (RSS in MB, PSS in MB,
    CPU seconds used so far). PSS splits each shared page among the processes that share it: its sum is what the
    graph holds."""
    import psutil

    data = json.loads(registry_path(graph).read_text())
    procs = {}
    for n in data["nodes"]:
        try:
            procs.setdefault(n["process"], psutil.Process(n["pid"]))
        except (psutil.Error, TypeError):
            procs[n["process"]] = None
    parent = next((p.parent() for p in procs.values() if p is not None), None)
    if parent is not None and parent.pid != data["launcher_pid"]:
        procs["forkserver"] = parent
    out = {}
    for name, p in procs.items():
        try:
            cpu, memory = p.cpu_times(), p.memory_full_info()
            out[name] = (memory.rss / 2**20, memory.pss / 2**20, cpu.user + cpu.system)
        except (psutil.Error, AttributeError):
            out[name] = (float("nan"), float("nan"), float("nan"))
    return out

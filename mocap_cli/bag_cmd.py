"""`mocap bag record | play | info | export | from-recording`: MCAP topic bags (like rosbag2)."""
from __future__ import annotations

import json
import logging
import signal

import time
from pathlib import Path

import numpy as np
import zmq

from messages import FLAG_MEASURED, FLAG_MISSING, MarkerFrame, MarkerSet, encode
from mocap_cli.graph_registry import find_graph, publishers_of
from mocap_cli.launch_file import LaunchError, NodeEntry, load_launch_file
from nodes.bags import BagWriter, bag_info, export_json, free_piece, read_take

log = logging.getLogger("mocap.bag")
SOURCE_KINDS = {"file_source", "qtm_ingest", "synthetic_source", "bag_player"}


def add_parser(sub) -> None:
    s = sub.add_parser("bag", help="record, play and inspect MCAP topic bags")
    bsub = s.add_subparsers(dest="action", required=True)

    r = bsub.add_parser("record", help="record topics of a running graph")
    r.add_argument("topics", nargs="*", help="topics to record")
    r.add_argument("--all", action="store_true", help="record every topic (diagnostics included)")
    r.add_argument("-o", "--output", required=True, help="output .mcap")
    r.add_argument("--graph", help="graph name, when several are running")
    r.add_argument("--duration", type=float, help="stop after this many seconds")
    r.set_defaults(func=cmd_record)

    p = bsub.add_parser("play", help="replay a bag, into a graph from a launch file",
                        description="Replays a bag. With --launch, the graph's source node(s) are replaced by the "
                                    "player, so the bag feeds the whole graph; without, the player runs alone "
                                    "(inspect it with `mocap topic echo`).")
    p.add_argument("file")
    p.add_argument("--launch", help="graph to feed (its file_source/qtm_ingest nodes are replaced)")
    p.add_argument("--set", action="append", metavar="NODE.PARAM=VALUE", help="override a node param of the graph")
    p.add_argument("--rate", type=float, default=1.0, help="speed factor (default 1)")
    p.add_argument("--loop", action="store_true")
    p.add_argument("--topics", nargs="+", help="play only these topics")
    p.add_argument("--start-offset", type=float, default=0.0, metavar="S", help="skip the first S seconds")
    p.add_argument("--lockstep", metavar="TOPIC", nargs="?", const="skeleton/solved",
                   help="send the next frame only after the graph published the last on TOPIC "
                        "(default skeleton/solved)")
    p.add_argument("--restamp", action="store_true", help="give messages a fresh graph-entry time")
    p.add_argument("--spin-ms", type=float, default=1.0, metavar="MS",
                   help="busy-wait the last MS before each timed message for accurate spacing (default 1; 0 = "
                        "sleep only, which leaves more CPU to the graph)")
    p.add_argument("--record", metavar="OUT.mcap", help="also record the graph's output topics (see --record-topics)")
    p.add_argument("--record-topics", nargs="+", default=["skeleton/solved"])
    p.set_defaults(func=cmd_play)

    i = bsub.add_parser("info", help="topics, counts, rates, duration, schemas")
    i.add_argument("file")
    i.add_argument("--json", action="store_true")
    i.set_defaults(func=cmd_info)

    e = bsub.add_parser("export", help="rewrite a bag for Foxglove: its 3D scene (--foxglove) or JSON (--json)")
    e.add_argument("file")
    out = e.add_mutually_exclusive_group(required=True)
    out.add_argument("--foxglove", metavar="OUT.mcap", help="skeleton and markers in Foxglove's schemas, for its "
                     "3D panel (SceneUpdate, FrameTransforms)")
    out.add_argument("--json", metavar="OUT.mcap", help="every message as JSON, arrays as lists of numbers")
    e.set_defaults(func=cmd_export)

    f = bsub.add_parser("from-recording", help="make a markers/raw bag from a C3D/TRC/MAT recording")
    f.add_argument("file")
    f.add_argument("-o", "--output", required=True)
    f.add_argument("--frames", type=int, default=0, help="only the first N frames (0 = all)")
    f.add_argument("--start", type=int, default=0, help="first frame index")
    f.set_defaults(func=cmd_from_recording)


def cmd_record(args) -> int:
    graph = find_graph(args.graph)
    topics = sorted({t for n in graph["nodes"] for t in n["publishes"]}) if args.all else args.topics
    if not topics:
        raise LaunchError("name the topics to record, or pass --all")
    zctx = zmq.Context.instance()
    sock = zctx.socket(zmq.SUB)
    sock.setsockopt(zmq.RCVHWM, 100000)
    for t in topics:
        endpoints = publishers_of(graph, t)
        if not endpoints:
            raise LaunchError(f"no node of graph {graph['name']!r} publishes {t!r}")
        sock.setsockopt(zmq.SUBSCRIBE, t.encode())
        for e in endpoints:
            sock.connect(e)
    launch = Path(graph.get("launch_file") or "")
    bag = BagWriter(free_piece(args.output), {"graph": graph["name"], "topics": ",".join(topics),
                                              "launch_file": launch.read_text() if launch.is_file() else ""})
    stop = False

    def on_signal(*_):
        nonlocal stop
        stop = True

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    wanted = set(topics)
    t_end = time.monotonic() + args.duration if args.duration else None
    log.info("recording %s from graph %s into %s", ", ".join(topics), graph["name"], bag.path)
    try:
        while not stop and (t_end is None or time.monotonic() < t_end):
            if sock.poll(100):
                while True:
                    try:
                        wire, payload = sock.recv_multipart(zmq.NOBLOCK)[:2]
                    except zmq.Again:
                        break
                    topic = wire.decode(errors="replace")
                    if topic in wanted:
                        bag.write(topic, payload, time.time_ns())
    finally:
        bag.close()
        sock.close(linger=0)
    log.info("wrote %d messages to %s", bag.count, bag.path)
    return 0


def cmd_play(args) -> int:
    from mocap_cli.launcher import Launcher

    info = bag_info(args.file)  # fails clearly on a missing, corrupt or foreign file
    player = {"path": str(Path(args.file).resolve()), "rate": args.rate, "loop": args.loop, "topics": args.topics,
              "start_offset_s": args.start_offset, "lockstep_topic": args.lockstep, "restamp": args.restamp,
              "spin_ms": args.spin_ms}
    if args.launch:
        lf = load_launch_file(args.launch, args.set or [])
        sources = [n for n in lf.nodes if n.kind in SOURCE_KINDS]
        if not sources:
            raise LaunchError(f"{args.launch} has no source node ({', '.join(sorted(SOURCE_KINDS))}) to replace")
        lf.nodes = [n for n in lf.nodes if n not in sources]
        lf.nodes.insert(0, NodeEntry(id="bag", kind="bag_player", params=player, respawn=False))
    else:
        from mocap_cli.launch_file import LaunchFile

        lf = LaunchFile(name="bag", nodes=[NodeEntry(id="bag", kind="bag_player", params=player, respawn=False)])
    if args.record:
        lf.nodes.append(NodeEntry(id="bag_recorder", kind="recorder",
                                  params={"path": args.record, "topics": args.record_topics,
                                          "launch_file": args.launch or ""}))
    log.info("playing %s (%d messages, %.1f s)", args.file, info["messages"], info["duration_s"])
    return Launcher(lf, args.launch or "").run(until_done=not args.loop, drain_s=1.0)


def cmd_info(args) -> int:
    info = bag_info(args.file)
    if args.json:
        print(json.dumps(info, indent=2))
        return 0
    print(f"bag:       {info['path']}\nduration:  {info['duration_s']:.3f} s\nmessages:  {info['messages']}")
    if len(info["pieces"]) > 1:
        print(f"pieces:    {len(info['pieces'])} ({', '.join(Path(p).name for p in info['pieces'])}), read as one")
    for name, meta in info["metadata"].items():
        print(f"metadata {name}: " + ", ".join(f"{k}={(v[:60] + '...') if len(v) > 60 else v}" for k, v in meta.items()
                                                if v))
    print(f"{'topic':<28} {'schema':<22} {'count':>7} {'rate Hz':>9}")
    for topic, s in sorted(info["topics"].items()):
        print(f"{topic:<28} {s['schema']:<22} {s['count']:>7} {s['rate_hz']:>9.1f}")
    return 0


def cmd_export(args) -> int:
    if args.foxglove:
        from nodes.foxglove_scene import export_foxglove

        n = export_foxglove(args.file, args.foxglove)
        print(f"wrote {n} Foxglove messages to {args.foxglove} (open it in Foxglove; a 3D panel shows /skeleton)")
        return 0
    n = export_json(args.file, args.json)
    print(f"wrote {n} JSON messages to {args.json}")
    return 0


def cmd_from_recording(args) -> int:
    rec = read_take(args.file)
    stop = rec.n_frames if not args.frames else min(rec.n_frames, args.start + args.frames)
    bag = BagWriter(args.output, {"source": rec.source, "rate_hz": rec.rate_hz, "labels": ",".join(rec.labels)})
    t0 = time.time_ns()
    s = MarkerSet(header=MarkerSet.make_header(0, 0.0, t0), labels=rec.labels, rate_hz=rec.rate_hz, source=rec.source)
    s.header.publisher = "from-recording"
    bag.write("markers/set", encode(s), t0, 0)
    for seq, i in enumerate(range(args.start, stop), start=1):
        t = i / rec.rate_hz
        pos = rec.positions[i]
        flags = np.where(np.isnan(pos).any(axis=1), FLAG_MISSING, FLAG_MEASURED).astype(np.uint8)
        m = MarkerFrame(header=MarkerFrame.make_header(rec.first_frame + i, t, t0 + int(t * 1e9)), labels=rec.labels,
                        positions=pos, flags=flags)
        m.header.seq, m.header.publisher = seq, "from-recording"
        bag.write("markers/raw", encode(m), t0 + int((t - args.start / rec.rate_hz) * 1e9) + 1, int(t * 1e9))
    bag.close()
    print(f"wrote {stop - args.start} frames of {rec.source} to {args.output}")
    return 0




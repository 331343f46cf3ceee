"""`mocap`: one entry point for the graph, its tools and the offline commands."""
from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

from mocap_core.fit.subject import SubjectError
from mocap_core.ik.constraints import ConstraintsError
from mocap_core.ik.solvers import UnknownSolver
from mocap_core.profiles import ProfileError
from mocap_core.recordings import RecordingError
from mocap_cli.graph_registry import NoGraph, RegistryError, find_graph, running_graphs
from nodes.bags import BagError
from mocap_cli.launch_file import LaunchError, add_realtime_flag, load_launch_file
from nodes.runtime import configure_logging


def cmd_launch(args) -> int:
    from mocap_cli.launcher import Launcher, dump_plan

    lf = load_launch_file(args.file, args.set or [])
    if args.plan:
        print(dump_plan(lf))
        return 0
    if args.realtime is not None:
        lf.realtime = args.realtime
    if args.name:
        lf.name = args.name
    elif args.host:
        lf.name = f"{lf.name}-{args.host}"  # this machine's share of the graph
    if any(g["name"] == lf.name for g in running_graphs()):
        raise LaunchError(f"a graph named {lf.name!r} is already running; stop it or pass --name")
    return Launcher(lf, args.file, host=args.host).run(duration_s=args.duration, until_done=args.until_done)


def cmd_topic(args) -> int:
    from mocap_cli import topic_tools

    graph = find_graph(args.graph)
    if args.action == "list":
        topic_tools.topic_list(graph)
    elif args.action == "echo":
        return topic_tools.topic_echo(graph, args.topic, args.once, args.timeout)
    elif args.action == "hz":
        topic_tools.topic_hz(graph, args.topic, args.window, args.duration)
    return 0


def cmd_node(args) -> int:
    from mocap_cli import topic_tools

    topic_tools.node_list(find_graph(args.graph), args.seconds)
    return 0


def cmd_keys(args) -> int:
    from nodes.curve import generate

    d = generate(args.directory)
    print(f"wrote CURVE keys to {d}: server.key(_secret), client.key(_secret), authorized/client.key; "
          f"use them with `transport: {{kind: tcp, curve_keys: {d}}}`")
    return 0


def cmd_schema(args) -> int:
    from messages import json_schemas

    schemas = json_schemas()
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        for name, schema in schemas.items():
            (out / f"{name}.schema.json").write_text(json.dumps(schema, indent=2))
        print(f"wrote {len(schemas)} schemas to {out}")
    else:
        print(json.dumps(schemas, indent=2))
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="mocap", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--log-level", default="INFO", help="DEBUG, INFO, WARNING (default INFO)")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    s = sub.add_parser("launch", help="run a node graph from a launch file",
                       description="Start every node of a launch file as its own process; Ctrl-C stops them all.")
    s.add_argument("file", help="launch file (YAML), e.g. launch/studio.yaml")
    s.add_argument("--set", action="append", metavar="NODE.PARAM=VALUE",
                   help="override a node param (repeatable), e.g. --set left_arm.solver=fabrik; a launch-file key of "
                        "the node (container, replicas, host, ...) where its kind has no param of that name")
    s.add_argument("--name", help="graph name (default: the launch file's name)")
    s.add_argument("--duration", type=float, help="stop after this many seconds")
    s.add_argument("--until-done", action="store_true", help="stop when every source has finished")
    s.add_argument("--plan", action="store_true", help="print each process's spec (endpoints, wiring) and exit")
    s.add_argument("--host", help="run the nodes of this machine (a name in the file's hosts:); without it, the "
                                  "nodes with no host:")
    add_realtime_flag(s)
    s.set_defaults(func=cmd_launch)

    s = sub.add_parser("topic", help="inspect topics of a running graph")
    s.add_argument("--graph", help="graph name, when several are running")
    tsub = s.add_subparsers(dest="action", required=True)
    tsub.add_parser("list", help="topics with their publishers and subscribers")
    e = tsub.add_parser("echo", help="print decoded messages of a topic")
    e.add_argument("topic")
    e.add_argument("--once", action="store_true", help="print one message and exit")
    e.add_argument("--timeout", type=float, help="give up after this many seconds")
    h = tsub.add_parser("hz", help="measure a topic's rate")
    h.add_argument("topic")
    h.add_argument("--window", type=float, default=1.0, help="seconds per report (default 1)")
    h.add_argument("--duration", type=float, help="stop after this many seconds")
    s.set_defaults(func=cmd_topic)

    s = sub.add_parser("node", help="nodes of a running graph, from their heartbeats")
    s.add_argument("action", choices=["list"])
    s.add_argument("--graph", help="graph name, when several are running")
    s.add_argument("--seconds", type=float, default=1.5, help="how long to listen for heartbeats")
    s.set_defaults(func=cmd_node)

    s = sub.add_parser("keys", help="make CURVE keys for authenticated, encrypted tcp links")
    s.add_argument("action", choices=["generate"])
    s.add_argument("directory")
    s.set_defaults(func=cmd_keys)

    s = sub.add_parser("schema", help="export the JSON Schema of every message")
    s.add_argument("--out", help="directory to write <schema>.schema.json files (default: print)")
    s.set_defaults(func=cmd_schema)

    from mocap_cli import commands  # the offline commands register themselves here
    commands.register(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    configure_logging(args.log_level)
    try:
        return args.func(args) or 0
    except (LaunchError, NoGraph, RecordingError, ProfileError, ConstraintsError, UnknownSolver, BagError,
            SubjectError, RegistryError) as e:
        logging.getLogger("mocap").error("%s", e)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())

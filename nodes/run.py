"""Process entry point of one node: ``python -m nodes.run '<NodeSpec JSON>'`` (the launcher's call), or of a
container of several: ``python -m nodes.run '[<NodeSpec JSON>, ...]'``."""
from __future__ import annotations

import ctypes
import json
import logging
import os
import signal
import sys

from nodes.priority import use_realtime
from nodes.registry import load_kind
from nodes.runtime import configure_logging, run_nodes
from nodes.spec import NodeSpec


def _die_with_parent() -> None:
    """Linux: get SIGTERM if the parent dies (the launcher, or its forkserver, which ends with it), even by SIGKILL,
    so no node is left behind."""
    try:
        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
        if os.getppid() == 1:
            sys.exit(0)
    except OSError:
        pass


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 1:
        print("usage: python -m nodes.run '<NodeSpec JSON>' | '[<NodeSpec JSON>, ...]'  (normally started by "
              "`mocap launch`)", file=sys.stderr)
        return 2
    _die_with_parent()
    nodes = [(spec, load_kind(spec.kind)) for spec in parse_specs(argv[0])]
    configure_logging(os.environ.get("MOCAP_LOG_LEVEL", "INFO"))
    if any(spec.realtime for spec, _ in nodes):  # before any thread starts (zmq's I/O thread inherits it)
        why = use_realtime()
        if why:  # (a launcher says it once for its whole graph)
            launched = nodes[0][0].control_endpoint is not None
            logging.getLogger(f"mocap.{nodes[0][0].id}").log(
                logging.DEBUG if launched else logging.WARNING,
                "realtime: runs at normal priority (%s); allow real-time scheduling with an rtprio limit or "
                "CAP_SYS_NICE (docs/graph.md)", why)
    profile_dir = os.environ.get("MOCAP_PROFILE_DIR")
    if profile_dir:  # developers: one cProfile file per node, read with `python -m pstats FILE`
        import cProfile

        profiler = cProfile.Profile()
        try:
            return profiler.runcall(run_nodes, nodes)
        finally:
            os.makedirs(profile_dir, exist_ok=True)
            name = "+".join(spec.id for spec, _ in nodes).replace("#", "_")
            profiler.dump_stats(os.path.join(profile_dir, f"{name}.prof"))
    return run_nodes(nodes)


def parse_specs(text: str) -> list[NodeSpec]:
    """One spec (a JSON object) or a container's (a JSON list)."""
    if text.lstrip().startswith("["):
        return [NodeSpec.model_validate(d) for d in json.loads(text)]
    return [NodeSpec.model_validate_json(text)]


def finish(code: int) -> None:
    """End the process with ``code``, skipping the interpreter's finalization: with numba and LLVM loaded it can take
    seconds on a busy machine, and the launcher gives a node 1.5 s after SIGTERM. Files and sockets are closed."""
    logging.shutdown()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


if __name__ == "__main__":
    finish(main())

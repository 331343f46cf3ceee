"""Process entry point of one node: ``python -m nodes.run '<NodeSpec JSON>'`` (the launcher's call), or of a
container of several: ``python -m nodes.run '[<NodeSpec JSON>, ...]'``."""
from __future__ import annotations

import ctypes
import json
import logging
import os
import signal
import sys

from nodes.registry import load_kind
from nodes.runtime import configure_logging, run_nodes
from nodes.spec import NodeSpec


def _die_with_parent() -> None:
    """Linux: get SIGTERM if the launcher dies, even by SIGKILL, so no node is left behind."""
    try:
        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
        if os.getppid() == 1:
            sys.exit(0)
    except OSError:
        pass


def _tell_launcher_warm(control_endpoint: str) -> None:
    """The launcher holds the sources back until the spare is warm: its loading competes for the CPU."""
    import zmq

    ctx = zmq.Context.instance()
    sock = ctx.socket(zmq.DEALER)
    sock.setsockopt(zmq.LINGER, 1000)
    sock.connect(control_endpoint)
    sock.send(b"warm")
    sock.close()


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    standby = bool(argv) and argv[0] == "--standby"
    if not (len(argv) == 1 or (standby and len(argv) <= 3)):
        print("usage: python -m nodes.run '<NodeSpec JSON>' | '[<NodeSpec JSON>, ...]' | --standby [CONTROL_ENDPOINT "
              "[KERNEL,...]]  (normally started by `mocap launch`)", file=sys.stderr)
        return 2
    _die_with_parent()
    if standby:
        # A spare process for fast restarts: imports and loads the graph's kernels now, then waits for the spec
        # of the node it has to replace on stdin (the launcher's; python start-up alone takes ~1.5 s).
        from mocap_core.warmup import PARTS, warm_up

        warm_up(PARTS if len(argv) < 3 else tuple(k for k in argv[2].split(",") if k), stamp=False)
        if len(argv) >= 2:
            _tell_launcher_warm(argv[1])
        try:
            line = sys.stdin.readline()
        except KeyboardInterrupt:  # Ctrl-C reaches the whole process group; a spare holds nothing
            return 0
        if not line.strip():
            return 0
        argv = [line]
    nodes = [(spec, load_kind(spec.kind)) for spec in parse_specs(argv[0])]
    configure_logging(os.environ.get("MOCAP_LOG_LEVEL", "INFO"))
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


if __name__ == "__main__":
    code = main()
    # Skip interpreter finalization: with numba and LLVM loaded it can take seconds on a busy machine,
    # and the launcher gives a node 1.5 s after SIGTERM. Files and sockets are closed by now.
    logging.shutdown()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)

"""Node processes forked from one warm parent, so a graph pays its imports and kernel loading once.

Every node still runs in a process of its own; what they share is how they start. The launcher asks
multiprocessing's forkserver for each process: a parent that imported the graph's node kinds and loaded its numba
kernels once, then forks a child per node (or container). The child starts in milliseconds with all of that
loaded, and the memory it holds (numba, LLVM's code, numpy, pydantic) stays shared with the parent and its
siblings until written: a graph holds it once, not once per process. A restart is a fork, not a new Python.

``preload`` (before the first ``start``) says what the parent loads. The parent lives as long as the process that
started it; a node gets SIGTERM if its parent dies (nodes.run), and the parent ends when the launcher does.
"""
from __future__ import annotations

import multiprocessing
import multiprocessing.forkserver
import os

_CONTEXT = multiprocessing.get_context("forkserver")
_ENV = "MOCAP_FORKSERVER_PRELOAD"   # kinds;kernels, read by the parent as it starts


def preload(kinds: list[str], kernels: tuple[str, ...]) -> None:
    """What the parent loads: these node kinds' modules and these kernel parts (mocap_core.warmup). Only the
    first call before the parent starts counts; a later graph's extra kernels are loaded by its nodes."""
    os.environ[_ENV] = ",".join(kinds) + ";" + ",".join(kernels)
    _CONTEXT.set_forkserver_preload(["nodes.forkserver_preload"])


def start(spec_json: str) -> multiprocessing.Process:
    """A running node process for ``python -m nodes.run``'s argument; it runs in this process's environment and
    working directory as they are now (the parent's are those of when it started)."""
    process = _CONTEXT.Process(target=_run, args=(spec_json, dict(os.environ), os.getcwd()), name="mocap-node")
    process.start()
    return process


def _run(spec_json: str, env: dict[str, str], cwd: str) -> None:
    # A child inherits the pipe whose closing tells the parent that the launcher is gone (so that it could start
    # processes of its own): held here, it would keep the parent, and so this node, alive after the launcher.
    server = multiprocessing.forkserver._forkserver
    if server._forkserver_alive_fd is not None:
        os.close(server._forkserver_alive_fd)
        server._forkserver_alive_fd = None
    os.environ.clear()
    os.environ.update(env)
    os.chdir(cwd)
    from nodes.run import finish, main

    finish(main([spec_json]))


def preloaded_parts() -> tuple[list[str], tuple[str, ...]]:
    """(kinds, kernel parts) the parent was asked to load."""
    kinds, _, kernels = os.environ.get(_ENV, ";").partition(";")
    return [k for k in kinds.split(",") if k], tuple(k for k in kernels.split(",") if k)

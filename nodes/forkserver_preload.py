"""Imported once by the forkserver's parent process (nodes.forkserver): the graph's node kinds and numba kernels,
loaded before any node forks. A failure here only costs the sharing: each node then loads what it needs itself."""
from __future__ import annotations

import gc
import logging

from nodes.forkserver import preloaded_parts


def _load() -> None:
    kinds, kernels = preloaded_parts()
    try:
        from mocap_core.warmup import warm_up
        from nodes.registry import load_kind

        for kind in kinds:
            load_kind(kind)
        warm_up(kernels, stamp=False)
    except Exception as e:  # (a node that needs it will say what is wrong in its own log)
        logging.getLogger("mocap.forkserver").warning("preloading the graph's nodes failed: %s", e)
    # What is loaded now lives as long as every node: out of the collector's sight, so no collection in a node
    # writes to (and so un-shares) the pages it sits on.
    gc.collect()
    gc.freeze()


_load()

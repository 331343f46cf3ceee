"""Real-time scheduling for a graph's node processes (the launch file's ``realtime: true``).

Under Linux's normal scheduler a node woken by a frame may wait behind any busy process for a few milliseconds, so on
a loaded machine a limb comes late and retarget holds it. Under SCHED_RR a woken node runs at once, ahead of every
normal process. Priority 10 is low among real-time ones: the kernel's interrupt threads (50) and audio servers
(about 20-90) still come first, and the kernel leaves normal processes 5 % of each second however busy the graph is.
"""
from __future__ import annotations

import os

REALTIME_PRIORITY = 10


def use_realtime() -> str:
    """Put this process (and the threads it starts from now on) under SCHED_RR; "" when done, else why not."""
    try:
        os.sched_setscheduler(0, os.SCHED_RR, os.sched_param(REALTIME_PRIORITY))
    except OSError as e:  # (PermissionError without the privilege)
        return f"{type(e).__name__}: {e.strerror or e}"
    return ""


def is_realtime(pid: int) -> bool:
    """Whether a process runs under a real-time policy (False if it is gone)."""
    try:
        return os.sched_getscheduler(pid) in (os.SCHED_RR, os.SCHED_FIFO)
    except OSError:
        return False

"""Joining the torso and the four limb solutions of each frame (the retarget stage's first job).

Limb solutions arrive from parallel processes in any order. A frame is released as soon as it is
complete. A late limb never blocks the stream: a frame is also released when a newer frame is
complete or when it has waited ``max_wait_s``; a limb that has not arrived then is taken from its
last solution, moved with its root, and marked held. Solutions that arrive after their frame left
are counted as late and dropped.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mocap_core.skeleton import INDEX, Status
from mocap_core.skeleton import LIMBS as STAGES

LIMBS = tuple(limb for limb in STAGES if limb != "torso")  # what joins the torso
RESTART_JUMP = 10  # frames
# Limbs are solved from their frame's torso, so limbs here without it mean the torso is still queued (a stage reads
# its inputs in turn, and after a stall a backlog of limbs can come first), not lost: they wait for it until a later
# frame's torso shows it was lost on the way, or for this long.
TORSO_LOST_S = 1.0
LIMB_INDEX = {limb: np.array([INDEX[j] for j in STAGES[limb]]) for limb in LIMBS}


@dataclass
class _Pending:
    arrived_s: float
    torso: tuple | None = None                 # (positions, frames, status, header-ish source)
    limbs: dict = field(default_factory=dict)  # limb -> (positions, frames, status)


@dataclass
class Joined:
    frame: int
    positions: np.ndarray
    frames: np.ndarray
    status: np.ndarray
    held_limbs: list[str]
    source: object  # the torso message, for header propagation


class FrameJoiner:
    def __init__(self, max_wait_s: float = 0.02):
        self.max_wait_s = max_wait_s
        self.pending: dict[int, _Pending] = {}
        self.last: dict[str, tuple] = {}   # limb -> last (positions, frames, status)
        self.released_up_to = -1 << 62
        self.torso_up_to = -1 << 62   # the newest frame whose torso came
        self.late = 0

    def _restarted(self, frame: int) -> bool:
        """Torso frame numbers that jump back (a looping take, a QTM restart) start a new stream. Only the torso's
        say so: they come in order, where limbs may lag many frames behind on a busy machine."""
        if frame < self.torso_up_to - RESTART_JUMP:
            self.pending.clear()
            self.released_up_to = self.torso_up_to = -1 << 62
            return True
        return False

    def add_torso(self, frame: int, now_s: float, positions, frames, status, source) -> list[Joined]:
        self._restarted(frame)
        if frame <= self.released_up_to:
            self.late += 1
            return []
        self.pending.setdefault(frame, _Pending(now_s)).torso = (positions, frames, status, source)
        self.torso_up_to = max(self.torso_up_to, frame)
        return self.release(now_s)

    def add_limb(self, frame: int, now_s: float, limb: str, positions, frames, status) -> list[Joined]:
        if frame <= self.released_up_to:
            self.late += 1
            return []
        self.pending.setdefault(frame, _Pending(now_s)).limbs[limb] = (positions, frames, status)
        return self.release(now_s)

    def release(self, now_s: float) -> list[Joined]:
        out = []
        complete = [f for f, p in self.pending.items() if p.torso is not None and len(p.limbs) == len(LIMBS)]
        newest_complete = max(complete, default=None)
        for f in sorted(self.pending):
            p = self.pending[f]
            done = p.torso is not None and len(p.limbs) == len(LIMBS)
            overdue = now_s - p.arrived_s >= self.max_wait_s
            superseded = newest_complete is not None and f < newest_complete
            if not (done or ((overdue or superseded) and p.torso is not None)):
                if p.torso is None and (self.torso_up_to > f or now_s - p.arrived_s >= TORSO_LOST_S):
                    del self.pending[f]  # its torso was lost: nothing to join the limbs to
                    if f < self.torso_up_to:  # (limbs beyond every torso: a stream's before it started again)
                        self.released_up_to = max(self.released_up_to, f)
                    continue
                break  # keep frames in order
            out.append(self._join(f, p))
            del self.pending[f]
            self.released_up_to = f
        return out

    def _join(self, frame: int, p: _Pending) -> Joined:
        positions, frames, status, source = (np.array(a, copy=True) if i < 3 else a for i, a in enumerate(p.torso))
        held = []
        for limb in LIMBS:
            idx = LIMB_INDEX[limb]
            got = p.limbs.get(limb)
            if got is not None:
                positions[idx], frames[idx], status[idx] = got
                self.last[limb] = got
            elif limb in self.last:
                lp, lf, ls = self.last[limb]
                positions[idx] = lp - lp[0] + positions[idx[0]]  # moved with the limb's root
                frames[idx] = lf
                status[idx] = np.where(ls == Status.MISSING, Status.MISSING, Status.HELD)
                held.append(limb)
            else:
                held.append(limb)  # never seen: the torso message's localized joints stand
        return Joined(frame, positions, frames, status, held, source)

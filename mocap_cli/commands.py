"""Offline commands (solve, eval, qtm-sim, bag, demo) register their sub-parsers here."""
from __future__ import annotations


def register(sub) -> None:
    pass

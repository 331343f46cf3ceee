"""One solver interface, the solvers picked by name (adding one: its module in mocap_core/ik and its line in
solvers_kernels.SOLVERS).

A solver moves a chain (positions ``P`` (n+1, 3) with a fixed root, bone frames ``R`` (n, 3, 3))
so that its end effector reaches ``target``, honouring the chain's limits when asked.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from mocap_core.ik import solvers_kernels as k


class SolverParams(NamedTuple):
    """How a solver runs: a tuple, as the numba kernels take it."""
    max_iterations: int = 140        # CCD's cap in the thesis's code (facts 9.2)
    stop_distance_m: float = 0.01    # IK threshold of the thesis's code
    constraints: bool = True
    escape_step_deg: float = 10.0    # deadlock escape: rotate the chain +-10, +-20 ... degrees
    escape_max_deg: float = 120.0

    def typed(self) -> "SolverParams":
        """Each field of its declared type, the types the kernels are compiled for (an int given for a float would
        compile them again, on a live node's first frame)."""
        return SolverParams(int(self.max_iterations), float(self.stop_distance_m), bool(self.constraints),
                            float(self.escape_step_deg), float(self.escape_max_deg))


class ChainLimits(NamedTuple):
    """A chain's joint limits (thesis 3.5.4), bone by bone: a tuple, as the numba kernels take it."""
    ref0: np.ndarray       # (3, 3) frame of the chain root's parent
    pp: np.ndarray         # (n, 3, 3)
    cones: np.ndarray      # (n, 4) radians
    has_cone: np.ndarray   # (n,)
    twists: np.ndarray     # (n, 2) radians
    has_twist: np.ndarray  # (n,)


@dataclass
class SolveResult:
    iterations: int
    residual_m: float


@dataclass(frozen=True)
class Solver:
    """A solver: its name and its place in solvers_kernels.SOLVERS. The limb fill's kernel runs it by that place
    on every run of lost joints (the shared driver, solvers_kernels.solve, calling the module's step); ``solve``
    runs it on one chain from Python."""

    name: str
    kernel_id: int

    def solve(self, P: np.ndarray, R: np.ndarray, target: np.ndarray, limits: ChainLimits,
              params: SolverParams) -> SolveResult:
        it, res = k.solve(self.kernel_id, P, R, np.asarray(target, np.float64), limits, params.typed())
        return SolveResult(int(it), float(res))


SOLVERS: dict[str, Solver] = {name: Solver(name, i) for i, name in enumerate(k.NAMES)}


class UnknownSolver(Exception):
    pass


def get_solver(name: str) -> Solver:
    try:
        return SOLVERS[name]
    except KeyError:
        raise UnknownSolver(f"unknown solver {name!r} (solvers: {', '.join(SOLVERS)})") from None

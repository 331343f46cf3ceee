"""The IK solvers (thesis 3.5: a module each, registered below) and the driver loop they share.

Each solver's ``step`` runs one iteration on a chain in place. :func:`solve` runs the loop that all share: stop
within ``stop_m`` of the target, the iteration cap, constraints after every step (when on), and the deadlock escape
when the end effector stops getting closer.
"""
from __future__ import annotations

import warnings

import numpy as np
from numba import literal_unroll, njit
from numba.core.errors import NumbaExperimentalFeatureWarning

from mocap_core.ik import ccd, dls, fabrik, jacobian_transpose
from mocap_core.ik.kernels import constrain_chain, escape_rotation, rotate_subchain, rotation_between, vnorm

# The solvers, by module: each has its step(P, R, target, limits, constrained), one iteration on a chain in place.
# Adding one is its module and its line here (here, not elsewhere: numba's cache of this file's kernels only
# knows this file).
SOLVERS = (ccd, fabrik, jacobian_transpose, dls)
NAMES = tuple(m.__name__.rsplit(".", 1)[1] for m in SOLVERS)
STEPS = tuple(m.step for m in SOLVERS)
CCD = NAMES.index("ccd")  # what a stalled, limited solve finishes with (see solve)
# numba types the steps as first-class functions to unroll over them, and says that feature is new
warnings.filterwarnings("ignore", "First-class function type", NumbaExperimentalFeatureWarning)
# An iteration that brings the end effector less than 1% closer than the best since the last escape
# counts as a stall: STALL_ITERATIONS in a row
# trigger the deadlock escape (crawling along a joint limit costs time and gains nothing visible).
MIN_PROGRESS = 0.01
STALL_ITERATIONS = 4
# An escape counts as fruitful when it brings the best distance down by this fraction; crawling
# closer a millimetre per escape is how a constrained chain used to spend milliseconds on a frame.
ESCAPE_GAIN = 0.1


@njit(cache=True)
def _step(solver, P, R, target, limits, constrained):
    """One iteration of the solver at ``solver`` in SOLVERS."""
    i = 0
    for step in literal_unroll(STEPS):
        if i == solver:
            step(P, R, target, limits, constrained)
        i += 1


@njit(cache=True)
def solve(solver, P, R, target, limits, params, escape_patience=2):
    """Run a solver on the chain in place, within ``limits`` (ChainLimits) when ``params`` (SolverParams) say so;
    returns (iterations, residual distance in metres).

    An unreachable target (farther than the chain is long) gets the chain stretched straight at
    it, as in the thesis's code, then limited. When the distance stops shrinking the deadlock
    escape turns the whole chain and the solver goes on; the best pose seen is kept. After
    ``escape_patience`` escapes in a row that gain less than ESCAPE_GAIN the target is taken as
    out of reach within the limits, and the best pose is returned."""
    constrained, max_iter, stop_m = params.constraints, params.max_iterations, params.stop_distance_m
    n = R.shape[0]
    if vnorm(target - P[0]) >= _chain_length(P):
        return 0, _stretch_at(P, R, target, limits, constrained)
    best = vnorm(P[n] - target)
    bestP, bestR = P.copy(), R.copy()
    # iterations since the best distance since the last escape (``local``) shrank by MIN_PROGRESS, and since the
    # best distance of the whole solve did
    since_gain, since_best, local = 0, 0, best
    attempt = np.int64(0)  # int64 from the start: a literal would compile each kernel it reaches twice
    fruitless, best_at_escape, it = 0, best, 0
    window_best = best      # a limited non-CCD solver that does not halve its distance in a window crawls
    while it < max_iter and best > stop_m:
        _step(solver, P, R, target, limits, constrained)
        it += 1
        dist = vnorm(P[n] - target)
        # Progress is judged against the best distance since the last escape, not the last step's:
        # a chain that oscillates against its limits (down 5 %, up 5 %, ...) is as stuck as one
        # that does not move, and used to crawl through all its iterations (1-4 ms a frame).
        since_gain, local = (0, dist) if dist < local * (1.0 - MIN_PROGRESS) else (since_gain + 1, local)
        since_best = 0 if dist < best * (1.0 - MIN_PROGRESS) else since_best + 1
        if dist < best:
            best = dist
            bestP[:] = P
            bestR[:] = R
        crawling = False
        if solver != CCD and constrained and it % (2 * STALL_ITERATIONS) == 0:
            crawling = best > 0.5 * window_best
            window_best = best
        # stuck, or an escape that has not beaten the best pose within a few iterations
        if (since_gain >= STALL_ITERATIONS or since_best >= 2 * STALL_ITERATIONS or crawling) and best > stop_m:
            since_gain, since_best = 0, 0
            P[:] = bestP
            R[:] = bestR
            if solver != CCD and constrained:
                # FABRIK's deadlock under limits (thesis 5): its passes ignore the limits that the
                # backward pass then enforces, and the two undo each other; the Jacobian methods
                # step the same way and get projected back. CCD sweeps, which turn each joint within
                # its limits, finish the solve from the best pose found.
                solver = CCD
                local = best
                continue
            fruitless = fruitless + 1 if best > best_at_escape * (1.0 - ESCAPE_GAIN) else 0
            best_at_escape = best
            if fruitless > escape_patience or not _escape(P, R, limits, params, attempt):
                break
            attempt += 1
            local = vnorm(P[n] - target)  # progress is judged afresh from the turned pose
    P[:] = bestP
    R[:] = bestR
    return it, best


@njit(cache=True, inline="always")
def _chain_length(P):
    total = 0.0
    for i in range(P.shape[0] - 1):
        total += vnorm(P[i + 1] - P[i])
    return total


@njit(cache=True, inline="always")
def _stretch_at(P, R, target, limits, constrained):
    """An unreachable target: the chain stretched straight at it, as in the thesis's code, then limited; returns
    the distance left."""
    n = R.shape[0]
    for i in range(n):
        rotate_subchain(P, R, i, rotation_between(P[i + 1] - P[i], target - P[i]))
    if constrained:
        constrain_chain(P, R, limits)
    return vnorm(P[n] - target)


@njit(cache=True, inline="always")
def _escape(P, R, limits, params, attempt):
    """The deadlock escape's ``attempt``-th turn of the whole chain, limited when the solve is; False when the
    turns are used up."""
    if not escape_rotation(P, R, limits.ref0, attempt, params.escape_step_deg, params.escape_max_deg):
        return False
    if params.constraints:
        constrain_chain(P, R, limits)
    return True

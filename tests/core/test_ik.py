"""IK solvers and limits: known answers and properties (hypothesis)."""
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mocap_core.geometry import frame_yx
from mocap_core.ik import kernels
from mocap_core.ik.constraints import ConstraintsError, load_constraints
from mocap_core.ik.solvers import SOLVERS, ChainLimits, SolverParams, get_solver, UnknownSolver
from mocap_core.skeleton import INDEX

SOLVER_NAMES = sorted(SOLVERS)
FREE = SolverParams(constraints=False, max_iterations=500, stop_distance_m=1e-3)


def straight_chain(lengths, direction=(0, 0, -1.0)):
    """A chain hanging along ``direction`` from the origin; frames with y along the bones, z = +x."""
    d = np.asarray(direction, float)
    d /= np.linalg.norm(d)
    P = np.vstack([np.zeros(3), np.cumsum(np.outer(lengths, d), axis=0)])
    R = np.tile(frame_yx(d, np.array([0, 1.0, 0]) if abs(d[1]) < 0.9 else np.array([1.0, 0, 0])), (len(lengths), 1, 1))
    return P, R


def no_limits(n, ref0=np.eye(3)):
    return ChainLimits(np.asarray(ref0, float), np.tile(np.eye(3), (n, 1, 1)), np.zeros((n, 4)), np.zeros(n, bool),
                       np.zeros((n, 2)), np.zeros(n, bool))


def lengths_of(P):
    return np.linalg.norm(np.diff(P, axis=0), axis=1)


@pytest.mark.parametrize("name", SOLVER_NAMES)
def test_planar_two_bone_reaches_the_analytic_elbow(name):
    # upper arm 0.3, forearm 0.25 in the x-z plane; target at distance 0.4 from the root
    P, R = straight_chain([0.3, 0.25])
    # a slight bend towards +x picks the branch
    P[1] = 0.3 * np.array([np.sin(0.05), 0, -np.cos(0.05)])
    P[2] = P[1] + 0.25 * np.array([np.sin(0.1), 0, -np.cos(0.1)])
    target = np.array([0.4, 0.0, 0.0]) * [np.cos(-0.6), 0, 1] + [0, 0, -0.4 * np.sin(0.6)]
    res = get_solver(name).solve(P, R, target, no_limits(2), FREE)
    assert res.residual_m <= 1e-3
    np.testing.assert_allclose(lengths_of(P), [0.3, 0.25], atol=1e-9)
    # the elbow is on one of the two circles' intersections: |elbow| = 0.3 and |target - elbow| = 0.25
    assert abs(np.linalg.norm(P[1]) - 0.3) < 1e-9 and abs(np.linalg.norm(target - P[1]) - 0.25) < 2e-3
    assert abs(P[1][1]) < 1e-6  # stays in the plane of the problem


@pytest.mark.parametrize("name", SOLVER_NAMES)
def test_target_on_a_straight_chain_is_already_solved(name):
    P, R = straight_chain([0.2, 0.2, 0.2])
    before = P.copy()
    res = get_solver(name).solve(P, R, before[-1].copy(), no_limits(3), FREE)
    assert res.iterations == 0 or res.residual_m < 1e-3
    np.testing.assert_allclose(P, before, atol=1e-3)


@pytest.mark.parametrize("name", SOLVER_NAMES)
def test_target_behind_the_root_is_reached_without_limits(name):
    P, R = straight_chain([0.3, 0.25, 0.1])
    target = np.array([0.0, 0.05, 0.35])  # up, behind where the chain hangs
    res = get_solver(name).solve(P, R, target, no_limits(3), FREE)
    assert res.residual_m <= 1e-3, res
    np.testing.assert_allclose(lengths_of(P), [0.3, 0.25, 0.1], atol=1e-9)


@pytest.mark.parametrize("name", SOLVER_NAMES)
def test_unreachable_target_stretches_the_chain_towards_it(name):
    P, R = straight_chain([0.3, 0.25])
    target = np.array([1.0, 1.0, 0.0])
    res = get_solver(name).solve(P, R, target, no_limits(2), FREE)
    direction = target / np.linalg.norm(target)
    np.testing.assert_allclose(P[1], 0.3 * direction, atol=1e-9)
    np.testing.assert_allclose(P[2], 0.55 * direction, atol=1e-9)
    assert res.residual_m == pytest.approx(np.linalg.norm(target) - 0.55)


def test_unknown_solver_is_named():
    with pytest.raises(UnknownSolver, match="solvers: ccd, fabrik"):
        get_solver("newton")


# -- limits -------------------------------------------------------------------------------------------
def test_nearest_point_on_ellipse_matches_brute_force():
    rng = np.random.default_rng(1)
    for _ in range(200):
        a, b = rng.uniform(0.1, 3, 2)
        y = rng.uniform(0, 4, 2)
        x0, x1 = kernels.nearest_on_ellipse(a, b, y[0], y[1])
        assert (x0 / a) ** 2 + (x1 / b) ** 2 == pytest.approx(1.0, abs=1e-6)
        t = np.linspace(0, np.pi / 2, 20001)
        brute = np.min(np.hypot(a * np.cos(t) - y[0], b * np.sin(t) - y[1]))
        assert np.hypot(x0 - y[0], x1 - y[1]) <= brute + 1e-6


def angle_from_axis(d):
    return math.degrees(math.acos(np.clip(d[1], -1, 1)))


def test_cone_handles_angles_over_90_and_behind_the_parent():
    hinge = np.radians([10, 175, 10, 5])  # the elbow: +z flexion up to 175 degrees
    inside, _ = kernels.cone_project(np.array([0, np.cos(np.radians(150)), np.sin(np.radians(150))]), hinge)
    assert inside  # bent 150 degrees forward: allowed, although "behind" the parent's axis
    inside, legal = kernels.cone_project(np.array([0, np.cos(np.radians(30)), -np.sin(np.radians(30))]), hinge)
    assert not inside and angle_from_axis(legal) == pytest.approx(5, abs=1e-6) and legal[2] < 0
    reversed_cone = np.radians([120, 120, 120, 120])  # all over 90: only straight behind is illegal
    inside, legal = kernels.cone_project(np.array([0.0, -1.0, 0.0]), reversed_cone)
    assert not inside and angle_from_axis(legal) == pytest.approx(120, abs=1e-6)


def ref_local(P, R, i, ref0, pp):
    ref = kernels.ref_frame(R, ref0, pp, i)
    d = P[i + 1] - P[i]
    return ref.T @ (d / np.linalg.norm(d)), ref


def inside_cone(local, cone_rad, tol_deg=0.5):
    theta = math.acos(np.clip(local[1], -1, 1))
    h = math.hypot(local[0], local[2])
    if h < 1e-9:
        return theta < math.radians(tol_deg)
    a = cone_rad[0] if local[0] >= 0 else cone_rad[2]
    b = cone_rad[1] if local[2] >= 0 else cone_rad[3]
    u, v = theta * local[0] / h, theta * local[2] / h
    grow = math.radians(tol_deg)
    return (u / (a + grow)) ** 2 + (v / (b + grow)) ** 2 <= 1.0


def arm_chain_limits(c, side="l"):
    bones = [INDEX[f"shoulder_{side}"], INDEX[f"elbow_{side}"], INDEX[f"wrist_{side}"]]
    return bones, ChainLimits(np.eye(3), c.pp[bones], c.cones[bones], c.has_cone[bones], c.twists[bones],
                              c.has_twist[bones])


CONSTRAINTS = load_constraints()


@settings(max_examples=40, deadline=None)
@given(st.sampled_from(SOLVER_NAMES),
       st.tuples(st.floats(-0.7, 0.7), st.floats(-0.7, 0.7), st.floats(-0.7, 0.7)))
def test_after_any_solve_limits_hold_and_lengths_are_kept(name, target):
    # an arm hanging down from a clavicle frame whose y points to the subject's left (+y here)
    lengths = [0.28, 0.25, 0.08]
    P, R = straight_chain(lengths)
    ref0 = frame_yx(np.array([0, 1.0, 0]), np.array([0, 0, -1.0]))  # clavicle: y left, x down, z forward
    bones, limits = arm_chain_limits(CONSTRAINTS)
    limits = limits._replace(ref0=np.ascontiguousarray(ref0))
    kernels.constrain_chain(P, R, limits)
    get_solver(name).solve(P, R, np.array(target), limits, SolverParams(max_iterations=60))
    np.testing.assert_allclose(lengths_of(P), lengths, atol=1e-9)
    for i in range(3):
        local, ref = ref_local(P, R, i, limits.ref0, limits.pp)
        assert inside_cone(local, limits.cones[i]), (name, i, local)
        alpha = kernels.twist_angle(R[i], ref)
        lo, hi = limits.twists[i]
        assert lo - 1e-6 <= alpha <= hi + 1e-6, (name, i, math.degrees(alpha))


@settings(max_examples=40, deadline=None)
@given(st.sampled_from(SOLVER_NAMES), st.floats(-0.4, 0.4), st.floats(-0.8, -0.2))
def test_knees_never_bend_forwards_with_constraints(name, x, z):
    lengths = [0.42, 0.40]
    P, R = straight_chain(lengths)
    R[:] = frame_yx(np.array([0, 0, -1.0]), np.array([0, -1.0, 0]))  # thigh/shank: y down, x right, z forward(+x)
    pelvis = frame_yx(np.array([0, 0, 1.0]), np.array([0, 1.0, 0]))  # y up, x left, z forward (+x)
    bones = [INDEX["hip_l"], INDEX["knee_l"]]
    c = CONSTRAINTS
    limits = ChainLimits(np.ascontiguousarray(pelvis), c.pp[bones], c.cones[bones], c.has_cone[bones],
                         c.twists[bones], c.has_twist[bones])
    get_solver(name).solve(P, R, np.array([x, 0.0, z]), limits, SolverParams(max_iterations=60))
    thigh, shank = P[1] - P[0], P[2] - P[1]
    forward = R[0][:, 2]  # the thigh's anterior axis
    bend = np.cross(thigh, shank) @ R[0][:, 0]  # rotation of the shank about the thigh's x (right) axis
    shank_forward = shank @ forward / np.linalg.norm(shank)
    assert shank_forward <= math.sin(math.radians(0.5 + 0.5)) + 1e-6, (name, shank_forward, bend)


def test_constraints_file_errors(tmp_path):
    bad = tmp_path / "c.yaml"
    bad.write_text("joints:\n  elbow_x: {cone: [1, 2, 3, 4]}\n")
    with pytest.raises(ConstraintsError, match="unknown joint 'elbow_x'"):
        load_constraints(bad)
    bad.write_text("joints:\n  elbow_l: {cone: [1, 2, 3]}\n")
    with pytest.raises(ConstraintsError, match="elbow_l"):
        load_constraints(bad)
    bad.write_text("joints:\n  elbow_l: {twist: [40, -40]}\n")
    with pytest.raises(ConstraintsError, match="min <= max"):
        load_constraints(bad)
    bad.write_text("joints:\n  hip_l: {parent_pointer: ['spin:90']}\n")
    with pytest.raises(ConstraintsError, match="rotx:DEG"):
        load_constraints(bad)


def test_left_side_mirrors_the_right():
    c = CONSTRAINTS
    for joint in ("clavicle", "shoulder", "hip", "ankle"):
        l, r = c.cones[INDEX[f"{joint}_l"]], c.cones[INDEX[f"{joint}_r"]]
        np.testing.assert_allclose(l[[0, 1, 2, 3]], r[[2, 1, 0, 3]])
    for joint in ("shoulder", "hip", "knee", "elbow"):
        np.testing.assert_allclose(c.twists[INDEX[f"{joint}_l"]], -c.twists[INDEX[f"{joint}_r"]][::-1])

"""Hip-marker interpolation: one unit test per case (thesis 3.4.8, facts section 4)."""
import numpy as np

from mocap_core.geometry import rotation_between
from mocap_core.hip_interpolation import HipInterpolator

TRIANGLE = np.array([[-0.10, 0.0, 1.0], [0.05, 0.12, 1.0], [0.05, -0.12, 1.0]])  # SACR, L_IAS, R_IAS
NAN = np.full(3, np.nan)


def primed(max_step_m=10.0):
    h = HipInterpolator(max_step_m=max_step_m)
    out, interp = h.fill(TRIANGLE)
    assert not interp.any()
    return h


def rotz(deg):
    return rotation_between(np.array([1.0, 0, 0]), np.array([np.cos(np.radians(deg)), np.sin(np.radians(deg)), 0]))


def test_all_three_seen_pass_through_and_become_last_known():
    h = HipInterpolator()
    moved = TRIANGLE + [0.01, 0, 0]
    out, interp = h.fill(moved)
    np.testing.assert_array_equal(out, moved)
    np.testing.assert_array_equal(h.last_known, moved)
    assert not interp.any()


def test_one_missing_follows_the_rotation_of_the_two_seen():
    r = rotz(30)
    moved = TRIANGLE @ r.T + [0.2, 0.1, 0.0]   # the pelvis turned 30 degrees about vertical and moved
    for missing in range(3):
        frame = moved.copy()
        frame[missing] = NAN
        out, interp = primed().fill(frame)
        np.testing.assert_allclose(out[missing], moved[missing], atol=1e-9)
        assert interp[missing] and interp.sum() == 1


def test_two_missing_translate_with_the_one_seen():
    h = primed()
    moved = TRIANGLE + [0.05, -0.02, 0.01]
    frame = moved.copy()
    frame[[1, 2]] = NAN
    out, interp = h.fill(frame)
    np.testing.assert_allclose(out, moved, atol=1e-12)
    assert interp.tolist() == [False, True, True]


def test_all_missing_keep_the_previous_frame():
    h = primed()
    out, interp = h.fill(np.full((3, 3), np.nan))
    np.testing.assert_array_equal(out, TRIANGLE)
    assert interp.all()


def test_prediction_is_rate_limited_to_max_step_per_frame():
    h = primed(max_step_m=0.02)
    frame = TRIANGLE + [0.5, 0, 0]
    frame[[1, 2]] = NAN
    out, _ = h.fill(frame)
    np.testing.assert_allclose(np.linalg.norm(out[1:] - TRIANGLE[1:], axis=1), [0.02, 0.02])
    np.testing.assert_array_equal(out[0], frame[0])  # a seen marker is never clamped


def test_nothing_predicted_before_the_first_complete_triangle():
    h = HipInterpolator()
    frame = TRIANGLE.copy()
    frame[0] = NAN
    out, interp = h.fill(frame)
    assert np.isnan(out[0]).all() and not interp.any()


def test_last_known_updates_only_on_complete_frames():
    h = primed()
    frame = TRIANGLE + 1.0
    frame[2] = NAN
    h.fill(frame)
    np.testing.assert_array_equal(h.last_known, TRIANGLE)


# -- beyond the thesis: every hip marker lost, the triangle carried by the trunk and knee markers ---------
ANCHORS = np.array([[-0.12, 0.0, 1.45], [-0.10, 0.0, 1.75], [0.12, 0.0, 1.50], [0.05, 0.0, 1.85],
                    [0.0, 0.18, 1.60], [0.0, -0.18, 1.60], [0.02, 0.10, 0.55], [0.02, -0.10, 0.55]])


def test_all_lost_fit_follows_a_rigid_move_of_the_body_exactly():
    h = HipInterpolator(max_step_m=10.0, when_lost="fit")
    h.fill(TRIANGLE, ANCHORS)
    rot, shift = rotz(30), np.array([0.3, -0.2, 0.05])
    out, interp = h.fill(np.full((3, 3), np.nan), ANCHORS @ rot.T + shift)
    np.testing.assert_allclose(out, TRIANGLE @ rot.T + shift, atol=1e-9)
    assert interp.all()


def test_all_lost_fit_with_some_anchors_missing_and_the_knees_weighing_less():
    h = HipInterpolator(max_step_m=10.0, when_lost="fit")
    h.fill(TRIANGLE, ANCHORS)
    now = ANCHORS + [0.2, 0.0, 0.0]
    now[[1, 3]] = np.nan            # two trunk markers lost too
    now[6] += [0.3, 0.0, 0.0]       # a knee swung forward: it must pull the pelvis only a little
    out, _ = h.fill(np.full((3, 3), np.nan), now)
    off = np.linalg.norm(out - (TRIANGLE + [0.2, 0, 0]), axis=1).max()
    assert off < 0.3 / 3, off       # under a third of the knee's swing (a trunk-only fit would be exact)


def test_all_lost_fit_falls_back_to_holding_without_enough_anchors():
    h = HipInterpolator(max_step_m=10.0, when_lost="fit")
    h.fill(TRIANGLE, ANCHORS)
    few = np.full_like(ANCHORS, np.nan)
    few[:2] = ANCHORS[:2] + 0.3     # two points fix no rotation
    out, _ = h.fill(np.full((3, 3), np.nan), few)
    np.testing.assert_array_equal(out, TRIANGLE)
    missing = HipInterpolator(when_lost="missing")
    missing.fill(TRIANGLE, ANCHORS)
    assert np.isnan(missing.fill(np.full((3, 3), np.nan), ANCHORS)[0]).all()

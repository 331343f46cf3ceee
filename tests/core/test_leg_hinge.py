"""The leg hinge: lost knee and ankle landmarks from the hip and one marker on the shank."""
import numpy as np
import pytest

from mocap_core.fill_options import HipOptions
from mocap_core.fill_units import MarkerSet
from mocap_core.landmark_fills import LandmarkFills, fill_take
from mocap_core.leg_hinge import COURSE_S, LegHinge
from mocap_core.localization import hip_centres
from mocap_core.profiles import LANDMARK_INDEX, LANDMARKS
from mocap_core.segment_rebuild import SegmentRebuilder

from tests.conftest import data_file

KNEE_ANKLE = ("R_FLE", "R_FME", "R_FAL", "R_TAM")


def _turn_about_up(angle):
    """A turn about the vertical (y: the pelvis frame's up here)."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _kicking_leg(frames):
    """Landmarks and the right shank marker of an actor who turns on the spot and walks on while the right
    leg kicks (hip flexion 0-80 deg) and the knee bends (0-90 deg), all about the knee's axis (x). Every
    distance the hinge uses is rigid."""
    lm = np.full((frames, len(LANDMARKS), 3), np.nan)
    marker = np.zeros((frames, 1, 3))
    for f in range(frames):
        t = f / 100
        turn, origin = _turn_about_up(0.8 * np.sin(0.7 * t)), np.array([0.3 * t, 1.0, 0.1 * t])
        hip_flexion, knee_flexion = np.radians(40 - 40 * np.cos(2.1 * t)), np.radians(45 - 45 * np.cos(3.3 * t))
        local = {"L_IAS": [0.12, 0, 0], "R_IAS": [-0.12, 0, 0], "SACR": [0, 0.0, -0.15]}
        for name, p in local.items():
            lm[f, LANDMARK_INDEX[name]] = origin + turn @ np.array(p)
        _, _, hip = hip_centres(lm[f])
        thigh = turn @ np.array([0, -np.cos(hip_flexion), np.sin(hip_flexion)])
        a = hip_flexion - knee_flexion
        shank, ahead = turn @ np.array([0, -np.cos(a), np.sin(a)]), turn @ np.array([0, np.sin(a), np.cos(a)])
        lateral = turn @ np.array([-1.0, 0, 0])
        knee = hip + 0.40 * thigh
        lm[f, LANDMARK_INDEX["R_FLE"]], lm[f, LANDMARK_INDEX["R_FME"]] = knee + 0.05 * lateral, knee - 0.05 * lateral
        ankle = knee + 0.42 * shank
        lm[f, LANDMARK_INDEX["R_FAL"]] = ankle + 0.035 * lateral
        lm[f, LANDMARK_INDEX["R_TAM"]] = ankle - 0.035 * lateral
        marker[f, 0] = knee + 0.2 * shank + 0.04 * lateral + 0.03 * ahead
    return lm, marker


def test_a_kicking_leg_is_followed_from_its_shank_marker_alone():
    """Knee and ankle landmarks lost for 1.5 s of a kick while the actor turns and walks on: exact (0.5 mm)
    wherever the knee is bent 15 deg or more, and 45 mm off at worst where it is nearly straight (the bend
    is then ambiguous: the marker's distance from the hip hardly changes with it), where holding them
    leaves them 0.2-0.75 m off."""
    lm, marker = _kicking_leg(300)
    hidden = lm.copy()
    for name in KNEE_ANKLE:
        hidden[150:, LANDMARK_INDEX[name]] = np.nan
    hinge = LegHinge(["R_shank"])
    out = hidden.copy()
    for f in range(300):
        filled = hinge.fill(out[f], marker[f])
        assert filled.sum() == (4 if f >= 150 else 0)
    bent = 45 - 45 * np.cos(3.3 * np.arange(150, 300) / 100) >= 15
    assert 0.3 < bent.mean() < 0.9
    for name in KNEE_ANKLE:
        k = LANDMARK_INDEX[name]
        error = np.linalg.norm(out[150:, k] - lm[150:, k], axis=1)
        held = np.linalg.norm(lm[149, k] - lm[150:, k], axis=1)
        assert error[bent].max() < 0.0005 and error.max() < 0.045 and error.mean() < 0.01, name
        assert held.max() > 0.2 and held.mean() > 0.1, name


def test_no_shank_marker_nothing_filled_and_a_wrong_count_is_an_error():
    lm, marker = _kicking_leg(120)
    for name in KNEE_ANKLE:
        lm[100:, LANDMARK_INDEX[name]] = np.nan
    assert not LegHinge([]).active and not LegHinge(["R_forearm"]).active
    hinge = LegHinge(["R_shank"])
    assert not hinge.fill(lm[0].copy(), None).any()  # no tracking markers given: nothing to go on
    for f in range(100):
        hinge.fill(lm[f], marker[f])
    assert hinge.fill(lm[100], marker[100]).sum() == 4
    with pytest.raises(ValueError, match="expected 1 tracking markers"):
        hinge.fill(lm[101], np.zeros((2, 3)))


@pytest.mark.parametrize("rate_hz", [None, 240.0])
def test_a_lost_shank_marker_goes_on_at_its_last_step_for_a_few_frames(rate_hz):
    """Knee, ankle and the shank marker lost together: for COURSE_S (in frames at the take's rate, from its times;
    120 Hz without them) the leg is put as by a marker going on at its last step (the same points as a second
    hinge given that marker), then not."""
    lm, marker = _kicking_leg(120)
    for name in KNEE_ANKLE:
        lm[100:, LANDMARK_INDEX[name]] = np.nan
    hinge, told = LegHinge(["R_shank"]), LegHinge(["R_shank"])

    def at(f):
        return np.nan if rate_hz is None else f / rate_hz
    for f in range(100):
        hinge.fill(lm[f], marker[f], time_s=at(f))
        told.fill(lm[f].copy(), marker[f], time_s=at(f))
    step, gone = marker[99] - marker[98], np.full((1, 3), np.nan)
    course_frames = round(COURSE_S * (rate_hz or 120.0))
    for k in range(1, course_frames + 1):
        frame, expected = lm[99 + k].copy(), lm[99 + k].copy()
        assert hinge.fill(frame, gone, time_s=at(99 + k)).sum() == 4
        told.fill(expected, marker[99] + k * step, time_s=at(99 + k))
        assert np.allclose(frame, expected, equal_nan=True)
    frame = lm[100 + course_frames].copy()
    assert not hinge.fill(frame, gone, time_s=at(100 + course_frames)).any()
    assert np.isnan(frame[LANDMARK_INDEX["R_FLE"]]).all()


def test_with_the_shank_marker_lost_the_ankle_puts_the_knee():
    """Knee markers and the shank marker lost together for 1.5 s of the kick, the malleoli seen (or rebuilt
    from the foot): after the marker's course the ankle is the shank's point. Its distance from the hip
    fixes the bend and its direction the thigh's turn: the epicondyles are exact (0.5 mm) wherever the
    knee is bent 15 deg or more, and nowhere worse than with the marker itself (45 mm)."""
    lm, marker = _kicking_leg(300)
    fle, fme = LANDMARK_INDEX["R_FLE"], LANDMARK_INDEX["R_FME"]
    hidden, gone = lm.copy(), marker.copy()
    hidden[150:, [fle, fme]] = np.nan
    gone[150:] = np.nan
    hinge = LegHinge(["R_shank"])
    out = hidden.copy()
    for f in range(300):
        assert hinge.fill(out[f], gone[f]).sum() == (2 if f >= 150 else 0)
    after = 150 + round(COURSE_S * 120) + 1  # (no times: 120 Hz; on its course the marker is a guess, 8 mm off)
    error = np.linalg.norm(out[after:, [fle, fme]] - lm[after:, [fle, fme]], axis=2).max(axis=1)
    bent = 45 - 45 * np.cos(3.3 * np.arange(after, 300) / 100) >= 15
    assert 0.3 < bent.mean() < 0.9
    assert error[bent].max() < 0.0005 and error.max() < 0.045 and error.mean() < 0.01, (error.max(), error.mean())


def _turned_about(points, pivot, end, angle):
    """``points`` turned by ``angle`` about the line from ``pivot`` to ``end``."""
    u = (end - pivot) / np.linalg.norm(end - pivot)
    k = np.array([[0, -u[2], u[1]], [u[2], 0, -u[0]], [-u[1], u[0], 0]])
    turn = np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k
    return pivot + (points - pivot) @ turn.T


@pytest.mark.parametrize("wrong_deg", [-25, 12, 40])
def test_a_knee_rebuilt_from_the_marker_and_the_ankle_alone_gets_its_roll_from_the_hip(wrong_deg):
    """The rebuild's shaft pair (shank marker and lateral malleolus, the medial one lost) leaves the knee's
    roll about their line as its reference had it. Given a roll off by ``wrong_deg``, the hinge turns the
    epicondyles back to where their distances from the hip centre hold: exactly (0.5 mm) without the price
    that holds the roll near the rebuild's, and nearer than given with it. A seen knee, or one the rebuild
    had three partners for, is left as it is."""
    lm, marker = _kicking_leg(300)
    fle, fme, fal, tam = (LANDMARK_INDEX[n] for n in KNEE_ANKLE)
    hinge, priced = LegHinge(["R_shank"], roll_price=0.0), LegHinge(["R_shank"])
    for f in range(100):
        assert not hinge.fill(lm[f].copy(), marker[f], filled=np.zeros(len(LANDMARKS), bool)).any()
        priced.fill(lm[f].copy(), marker[f], filled=np.zeros(len(LANDMARKS), bool))
    rebuilt = np.zeros(len(LANDMARKS), bool)
    rebuilt[[fle, fme]] = True
    error, given, error_priced = [], [], []
    for f in range(100, 300):
        frame = lm[f].copy()
        frame[tam] = np.nan
        frame[[fle, fme]] = _turned_about(lm[f, [fle, fme]], marker[f, 0], lm[f, fal], np.radians(wrong_deg))
        before, settled = frame.copy(), frame.copy()
        assert not hinge.fill(frame, marker[f], filled=rebuilt).any()  # (rebuilt points are not counted again)
        priced.fill(settled, marker[f], filled=rebuilt)
        error_priced.append(np.linalg.norm(settled[[fle, fme]] - lm[f, [fle, fme]], axis=1).max())
        error.append(np.linalg.norm(frame[[fle, fme]] - lm[f, [fle, fme]], axis=1).max())
        given.append(np.linalg.norm(before[[fle, fme]] - lm[f, [fle, fme]], axis=1).max())
        assert np.array_equal(np.delete(frame, [fle, fme], axis=0), np.delete(before, [fle, fme], axis=0),
                              equal_nan=True)
    error, given, error_priced = np.array(error), np.array(given), np.array(error_priced)
    assert error.max() < 0.0005 and (error_priced < given).all(), (error.max(), (error_priced / given).max())
    # three partners (both malleoli and the marker) fix the roll themselves; a seen knee is measured
    frame = lm[150].copy()
    frame[[fle, fme]] += 0.03
    for mask in (rebuilt, np.zeros(len(LANDMARKS), bool)):
        moved = frame.copy()
        hinge.fill(moved, marker[150], filled=mask)
        assert np.array_equal(moved[[fle, fme]], frame[[fle, fme]])


def test_a_leg_never_seen_whole_is_not_filled():
    """No frame with the knee's epicondyles and the marker seen together: no shape to fill by."""
    lm, marker = _kicking_leg(50)
    lm[:, LANDMARK_INDEX["R_FME"]] = np.nan
    hinge = LegHinge(["R_shank"])
    assert not any(hinge.fill(lm[f], marker[f]).any() for f in range(50))


def test_the_vicon_kick_knee_and_ankle_from_the_shank_marker():
    """The Vicon free-form take, right knee and ankle markers removed from 1 s to the end, on top of its own
    gaps (heel and metatarsals gone for the last second, in a kick): at the landmark stage the rebuild with
    the hinge puts the knee and ankle joints in more frames than the rebuild alone, within 50 / 40 mm on
    average (43 / 31 measured), and in the kick's last second, where the rebuild alone has no knee at all."""
    from mocap_core.hip_interpolation import HipInterpolator
    from mocap_core.localization import Localizer
    from mocap_core.pipeline import SkeletonPipeline
    from mocap_core.profiles import load_profile
    from mocap_core.recordings import read_recording
    from mocap_core.skeleton import INDEX

    rec = read_recording(data_file("12_vicon_freeform_realgaps_nimble_nick_freeform_001.c3d"))
    profile = load_profile("vicon53")
    pipe = SkeletonPipeline(profile, rec.labels, fill_gaps=False)
    lm, tracking = pipe.landmark_map.apply(rec.positions), pipe.landmark_map.tracking(rec.positions)
    reference = pipe.solve_landmarks(pipe.landmarks(rec.positions)).positions
    hidden = lm.copy()
    for name in ("R_FLE", "R_FME", "R_TTC", "R_FAL", "R_TAM"):
        hidden[120:, LANDMARK_INDEX[name]] = np.nan
    hidden, _ = HipInterpolator().fill_landmarks(hidden)
    present = [LANDMARKS[i] for i in np.flatnonzero(np.isfinite(lm).all(axis=2).any(axis=0))]
    errors = {}
    for hinge in (True, False):
        fills = LandmarkFills(HipOptions(rebuild=True), MarkerSet(pipe.landmark_map.tracking_of, present))
        assert [type(fill) for fill in fills.fills] == [SegmentRebuilder, LegHinge]
        if not hinge:
            fills.fills.pop()
        out, filled = fill_take(fills.fill, hidden, tracking=tracking)
        pos = Localizer(profile.body).localize(out, filled).positions
        errors[hinge] = {j: np.linalg.norm(pos[120:, INDEX[j]] - reference[120:, INDEX[j]], axis=1)
                         for j in ("knee_r", "ankle_r")}
    for j in ("knee_r", "ankle_r"):
        with_hinge, without = errors[True][j], errors[False][j]
        assert np.isfinite(with_hinge).sum() > np.isfinite(without).sum() + 50, j
        assert np.nanmean(with_hinge) < {"knee_r": 0.05, "ankle_r": 0.04}[j] and np.nanmax(with_hinge) < 0.3, j
    # the kick's last second, where the rebuild alone has no knee at all
    kick = slice(960 - 120, None)
    assert np.isnan(errors[False]["knee_r"][kick]).mean() > 0.5 > np.isnan(errors[True]["knee_r"][kick]).mean()

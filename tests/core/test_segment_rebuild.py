"""Lost forearm and foot landmarks rebuilt from the markers of their segment still seen."""
import numpy as np
import pytest

from mocap_core.experiments import Gap, GapTake, gap_run
from mocap_core.fill_options import STUDIO as STUDIO_RIGID, HipOptions
from mocap_core.geometry import rigid_fit
from mocap_core.landmark_fills import fill_take
from mocap_core.localization import Localizer
from mocap_core.pipeline import SkeletonPipeline
from mocap_core.profiles import LANDMARK_INDEX, LANDMARKS, load_profile
from mocap_core.recordings import read_recording
from mocap_core.segment_rebuild import SegmentRebuilder
from mocap_core.skeleton import INDEX, Status
from tests.conftest import data_file

# The studio's fills, measured against the localization of the complete take: without the rigid chain, which moves
# located joints onto the subject's bones (tests/core/test_rigid_chain.py).
STUDIO = STUDIO_RIGID.model_copy(update={"rigid": False})

FOREARM = [LANDMARK_INDEX[n] for n in ("L_HLE", "L_HME", "L_UOA", "L_RSP", "L_USP")]


def rotation(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def test_a_lost_marker_follows_its_segments_rigid_motion_known_answer():
    rng = np.random.default_rng(3)
    first = rng.normal(scale=0.1, size=(len(LANDMARKS), 3))
    rebuilder = SegmentRebuilder()
    assert not rebuilder.fill(first.copy()).any()  # nothing lost, nothing rebuilt
    rot, shift = rotation([1, 2, 0.5], 0.7), np.array([0.3, -0.1, 1.2])
    moved = first @ rot.T + shift
    lost = moved.copy()
    lost[LANDMARK_INDEX["L_HLE"]] = lost[LANDMARK_INDEX["L_HME"]] = np.nan
    rebuilt = rebuilder.fill(lost)
    assert set(np.flatnonzero(rebuilt)) == {LANDMARK_INDEX["L_HLE"], LANDMARK_INDEX["L_HME"]}
    np.testing.assert_allclose(lost[FOREARM], moved[FOREARM], atol=1e-9)
    np.testing.assert_array_equal(lost[~rebuilt], moved[~rebuilt])  # the seen ones are left alone


def test_the_rigid_fit_leans_on_the_partners_nearest_the_lost_marker_known_answer():
    """Skin moves far partners more (a forearm twists along its length), so each partner weighs by the inverse
    square of its distance from the lost marker. Known answer: numpy's weighted Kabsch (geometry.rigid_fit) with
    those weights. A forearm twisted 20 degrees at the wrist, less towards the elbow (olecranon, a forearm
    marker, the styloids): the rebuilt elbow marker is under 0.8x as far off as an unweighted fit's (6.3 against
    8.8 mm)."""
    rng = np.random.default_rng(8)
    first = rng.normal(scale=0.1, size=(len(LANDMARKS), 3))
    hle, hme, uoa, rsp, usp = FOREARM
    first[[hle, hme, uoa, rsp, usp]] = [[0, 0, 0], [0.06, 0, 0], [0.02, -0.03, 0.01], [0, -0.25, 0.03],
                                        [0.05, -0.25, -0.02]]
    wand = np.array([[0.03, -0.12, 0.03]])
    rebuilder = SegmentRebuilder(("L_forearm",))
    rebuilder.fill(first.copy(), wand.copy())
    twisted, twisted_wand = first.copy(), wand.copy()
    axis = np.array([0.03, 0, 0])  # the forearm's long axis runs along -y through it
    for points, k in ((twisted, uoa), (twisted, rsp), (twisted, usp), (twisted_wand, 0)):
        points[k] = axis + rotation([0, 1, 0], np.radians(20) * -points[k][1] / 0.25) @ (points[k] - axis)
    turn, shift = rotation([0.3, 1, -0.2], 0.8), np.array([0.4, 0.1, 1.0])
    moved, moved_wand = twisted @ turn.T + shift, twisted_wand @ turn.T + shift
    lost = moved.copy()
    lost[[hle, hme]] = np.nan
    rebuilder.fill(lost, moved_wand)
    before = np.vstack([first[[uoa, rsp, usp]], wand])
    after = np.vstack([moved[[uoa, rsp, usp]], moved_wand])
    rot, t = rigid_fit(before, after, 1 / np.linalg.norm(before - first[hle], axis=1) ** 2)
    np.testing.assert_allclose(lost[hle], rot @ first[hle] + t, atol=1e-9)
    rot, t = rigid_fit(before, after, np.ones(4))
    unweighted = np.linalg.norm(rot @ first[hle] + t - moved[hle])
    assert np.linalg.norm(lost[hle] - moved[hle]) < 0.8 * unweighted, (np.linalg.norm(lost[hle] - moved[hle]),
                                                                        unweighted)


def _slid_forearm():
    """A forearm (elbow markers, olecranon, styloids, two forearm markers) seen, then turned and moved, its ulnar
    styloid marker slid 30 mm up the forearm on the skin: the styloids' spacing, which bone fixes, changes."""
    rng = np.random.default_rng(11)
    first = rng.normal(scale=0.1, size=(len(LANDMARKS), 3))
    hle, hme, uoa, rsp, usp = FOREARM
    first[[hle, hme, uoa, rsp, usp]] = [[0, 0, 0], [0.06, 0, 0], [0.02, -0.03, 0.01], [0, -0.25, 0.03],
                                        [0.05, -0.25, -0.02]]
    wand = np.array([[0.03, -0.12, 0.03], [0.01, -0.18, -0.02]])
    turn, shift = rotation([0.3, 1, -0.2], 0.8), np.array([0.4, 0.1, 1.0])
    moved, moved_wand = first @ turn.T + shift, wand @ turn.T + shift
    moved[usp] += turn @ [0.0, 0.03, 0.0]  # towards the elbow
    return first, wand, moved, moved_wand


def test_a_styloid_that_slid_is_left_out_of_the_fit_known_answer():
    """The styloids sit on the ends of radius and ulna, a spacing bone fixes: when it changes by over 5 mm, the
    one whose distances to the other partners changed more (the ulnar one here, 30 mm up the forearm) is left out.
    Known answer: the radial styloid and the forearm's two markers alone carry the elbow (and the olecranon, lost
    too) exactly. With the slid marker in the fit the elbow is over 5 mm off. (The Vicon take's inner wrist
    marker: its left elbow's landmarks 55 / 175 -> 30 / 28 mm.)"""
    first, wand, moved, moved_wand = _slid_forearm()
    hle, hme, uoa, rsp, usp = FOREARM
    rebuilder = SegmentRebuilder(("L_forearm", "L_forearm"))
    rebuilder.fill(first.copy(), wand.copy())
    lost = moved.copy()
    lost[[hle, hme, uoa]] = np.nan
    assert rebuilder.fill(lost, moved_wand.copy())[hle]
    np.testing.assert_allclose(lost[[hle, hme, uoa]], moved[[hle, hme, uoa]], atol=1e-9)
    before = np.vstack([first[[rsp, usp]], wand])
    after = np.vstack([moved[[rsp, usp]], moved_wand])
    rot, t = rigid_fit(before, after, 1 / np.linalg.norm(before - first[hle], axis=1) ** 2)
    assert np.linalg.norm(rot @ first[hle] + t - moved[hle]) > 0.005  # what the slid marker would have done


def test_a_slid_styloid_stays_out_while_its_pair_is_lost():
    """The frame after, the radial styloid is lost and the olecranon seen again: the pair's spacing cannot be
    measured, and the last verdict stands. The ulnar styloid, still seen, is left out as if it were lost, and the
    olecranon and the forearm's markers carry the elbow exactly."""
    first, wand, moved, moved_wand = _slid_forearm()
    hle, hme, uoa, rsp, usp = FOREARM
    results = []
    for hide_usp in (False, True):
        rebuilder = SegmentRebuilder(("L_forearm", "L_forearm"))
        rebuilder.fill(first.copy(), wand.copy())
        lost = moved.copy()
        lost[[hle, hme, uoa]] = np.nan
        rebuilder.fill(lost, moved_wand.copy())
        lost = moved.copy()
        lost[[hle, hme, rsp]] = np.nan
        if hide_usp:
            lost[usp] = np.nan
        assert rebuilder.fill(lost, moved_wand.copy())[hle]
        results.append(lost[[hle, hme]])
    np.testing.assert_array_equal(results[0], results[1])
    np.testing.assert_allclose(results[0], moved[[hle, hme]], atol=1e-9)


def test_two_partners_are_not_enough_and_a_lost_wrist_is_not_rebuilt():
    rng = np.random.default_rng(4)
    first = rng.normal(scale=0.1, size=(len(LANDMARKS), 3))
    rebuilder = SegmentRebuilder()
    rebuilder.fill(first.copy())
    lost = first.copy()
    lost[[LANDMARK_INDEX[n] for n in ("L_HLE", "L_HME", "L_UOA")]] = np.nan  # the styloids alone are seen
    assert not rebuilder.fill(lost).any() and np.isnan(lost[LANDMARK_INDEX["L_HLE"]]).all()
    lost = first.copy()
    lost[[LANDMARK_INDEX["L_RSP"], LANDMARK_INDEX["L_USP"]]] = np.nan  # both styloids: the IK stage's job
    assert not rebuilder.fill(lost).any()


def test_tracking_markers_join_their_bone_known_answer():
    """Only the two styloids and one forearm tracking marker are seen: with the tracking marker the elbow
    is rebuilt exactly; without it two partners are not enough. The shank rebuilds the knee from the
    malleoli and its own tracking marker."""
    rng = np.random.default_rng(6)
    first = rng.normal(scale=0.1, size=(len(LANDMARKS), 3))
    tracking_of = ("L_forearm", "L_shank", "R_foot")
    tracks = rng.normal(scale=0.1, size=(3, 3))
    rebuilder = SegmentRebuilder(tracking_of)
    rebuilder.fill(first.copy(), tracks.copy())
    rot, shift = rotation([0.2, -1, 0.4], 1.1), np.array([-0.5, 0.2, 0.9])
    moved, moved_tracks = first @ rot.T + shift, tracks @ rot.T + shift
    lost = moved.copy()
    gone = [LANDMARK_INDEX[n] for n in ("L_HLE", "L_HME", "L_UOA", "L_FLE", "L_FME", "L_TTC")]
    lost[gone] = np.nan
    rebuilt = rebuilder.fill(lost, moved_tracks.copy())
    assert set(np.flatnonzero(rebuilt)) == set(gone)
    np.testing.assert_allclose(lost[gone], moved[gone], atol=1e-9)
    plain = SegmentRebuilder()
    plain.fill(first.copy())
    lost = moved.copy()
    lost[gone] = np.nan
    assert not plain.fill(lost).any()
    with pytest.raises(ValueError, match="3 tracking markers"):
        rebuilder.fill(moved.copy())


def test_a_shaft_marker_and_a_landmark_carry_the_bone_known_answer():
    """A shank seen only at its ankle marker and one shank tracking marker: two partners along the bone.
    A swing (about an axis across their line) carries the knee marker exactly; a roll about their line
    is not seen, so the knee is off by its chord: 2 r sin(roll / 2), r its distance from the line."""
    ankle, wand, knee = np.array([0.0, 0.0, 0.1]), np.array([0.01, 0.02, 0.3]), np.array([0.05, 0.0, 0.5])
    first = np.full((len(LANDMARKS), 3), np.nan)
    first[LANDMARK_INDEX["L_FAL"]], first[LANDMARK_INDEX["L_FLE"]] = ankle, knee
    rebuilder = SegmentRebuilder(("L_shank",))
    rebuilder.fill(first.copy(), wand[None].copy())
    line = (wand - ankle) / np.linalg.norm(wand - ankle)
    across = np.cross(line, [1.0, 0.0, 0.0])
    off = (knee - ankle) - ((knee - ankle) @ line) * line  # the knee from the partners' line
    for roll in (0.0, 0.4):
        turn = rotation(across, 0.9) @ rotation(line, roll)  # roll about the line first, then swing
        shift = np.array([0.2, -0.3, 0.05])
        moved = (first - ankle) @ turn.T + ankle + shift
        moved_wand = (wand - ankle) @ turn.T + ankle + shift
        lost = moved.copy()
        lost[LANDMARK_INDEX["L_FLE"]] = np.nan
        rebuilt = rebuilder.fill(lost, moved_wand[None].copy())
        assert rebuilt[LANDMARK_INDEX["L_FLE"]]
        error = np.linalg.norm(lost[LANDMARK_INDEX["L_FLE"]] - moved[LANDMARK_INDEX["L_FLE"]])
        assert error == pytest.approx(2 * np.linalg.norm(off) * np.sin(roll / 2), abs=1e-9)
    # two landmarks (the malleoli) run across the bone: not enough
    both = first.copy()
    both[LANDMARK_INDEX["L_TAM"]] = [-0.06, 0.0, 0.1]
    plain = SegmentRebuilder()
    plain.fill(both.copy())
    lost = both.copy()
    lost[LANDMARK_INDEX["L_FLE"]] = np.nan
    assert not plain.fill(lost).any()


def _rolling_forearm(bone: str):
    """A forearm (or, for the same points, a shank) seen whole once, then rolled 2 degrees a frame about the
    line from its outer wrist marker to its shaft marker, up to 120, with everything else lost: the elbow's
    epicondyles (the knee's on the shank), the other styloid. The bone above's marker turns with it.
    Returns each frame's largest error of the two members the bone above refines."""
    members = {"forearm": ("L_HLE", "L_HME", "L_RSP", "L_USP", "L_UOA"),
               "shank": ("L_FLE", "L_FME", "L_FAL", "L_TAM", "L_TTC")}[bone]
    above = {"forearm": "L_upper_arm", "shank": "L_thigh"}[bone]
    places = ([0.04, 0.0, 0.3], [-0.04, 0.0, 0.3], [0.03, 0.0, 0.0], [-0.03, 0.0, 0.0], [0.0, -0.02, 0.32])
    first = np.full((len(LANDMARKS), 3), np.nan)
    for name, place in zip(members, places):
        first[LANDMARK_INDEX[name]] = place
    pivot, shaft = first[LANDMARK_INDEX[members[2]]], np.array([0.01, 0.02, 0.15])
    line = (shaft - pivot) / np.linalg.norm(shaft - pivot)
    # the bone above's marker 8 cm from that line, square to the epicondyles' axis (so that its distances to
    # them change with the roll, as on an arm)
    across = np.cross(line, first[LANDMARK_INDEX[members[0]]] - first[LANDMARK_INDEX[members[1]]])
    tracks = np.array([shaft, pivot + 0.45 * line + 0.08 * across / np.linalg.norm(across)])
    rebuilder = SegmentRebuilder((f"L_{bone}", above))
    rebuilder.fill(first.copy(), tracks.copy())
    errors = []
    for frame in range(1, 61):
        turn = rotation(line, np.radians(2.0 * frame))
        moved, moved_tracks = (first - pivot) @ turn.T + pivot, (tracks - pivot) @ turn.T + pivot
        lost = moved.copy()
        lost[[LANDMARK_INDEX[n] for n in (members[0], members[1], members[3], members[4])]] = np.nan
        rebuilder.fill(lost, moved_tracks.copy())
        errors.append(max(np.linalg.norm(lost[LANDMARK_INDEX[n]] - moved[LANDMARK_INDEX[n]]) for n in members[:2]))
    return np.array(errors)


def test_a_forearm_rolled_past_its_reference_keeps_its_elbow_with_the_upper_arm_known_answer():
    """Two partners along the forearm (the outer wrist marker and the forearm's): the roll about their line is
    the pronation, and it goes on while they are all that is seen. The upper arm's marker fixes that roll up to
    a mirror image, and the epicondyles' side in the frame before picks the image: they follow 120 degrees
    within 10 mm (ROLL_PRICE, which holds a roll the distances hardly fix, holds it a little behind one that
    goes on). The Vicon take's right elbow, lost with its inner wrist marker in a fast swing: 138 -> 53 mm at
    most. A shank hardly rolls: it keeps its reference's roll, off by the chord here."""
    forearm, shank = _rolling_forearm("forearm"), _rolling_forearm("shank")
    assert forearm.max() < 0.01, forearm.max()
    chord = 2 * 0.05 * np.sin(np.radians(120.0) / 2)  # (the epicondyles are about 5 cm from the line)
    assert shank[-1] > 0.5 * chord and shank[-1] > 10 * forearm[-1], (shank[-1], chord, forearm[-1])


def test_a_reference_is_not_replaced_by_one_with_fewer_partners_known_answer():
    """The foot: ankle, malleolus, heel, toe (the mean of two metatarsal tracking markers). The heel is
    lost in the frame before the ankle is; the reference of the frame before that, with the heel, is
    kept. Then the ankle and the malleolus are lost and the foot moves: heel and metatarsals carry the
    ankle exactly (the metatarsals and the toe alone are on one line)."""
    rng = np.random.default_rng(8)
    first = np.full((len(LANDMARKS), 3), np.nan)
    for name in ("L_FAL", "L_TAM", "L_FCC"):
        first[LANDMARK_INDEX[name]] = rng.normal(scale=0.1, size=3)
    metatarsals = rng.normal(scale=0.1, size=(2, 3))
    first[LANDMARK_INDEX["L_FM2"]] = metatarsals.mean(axis=0)
    rebuilder = SegmentRebuilder(("L_foot", "L_foot"))
    rebuilder.fill(first.copy(), metatarsals.copy())
    heel_lost = first.copy()
    heel_lost[LANDMARK_INDEX["L_FCC"]] = np.nan
    assert rebuilder.fill(heel_lost, metatarsals.copy())[LANDMARK_INDEX["L_FCC"]]  # from the first frame
    rot, shift = rotation([0.3, 1, -0.2], 0.8), np.array([0.1, 0.4, -0.2])
    moved, moved_metatarsals = first @ rot.T + shift, metatarsals @ rot.T + shift
    lost = moved.copy()
    lost[[LANDMARK_INDEX["L_FAL"], LANDMARK_INDEX["L_TAM"]]] = np.nan
    rebuilt = rebuilder.fill(lost, moved_metatarsals.copy())
    assert rebuilt[LANDMARK_INDEX["L_FAL"]]
    np.testing.assert_allclose(lost[LANDMARK_INDEX["L_FAL"]], moved[LANDMARK_INDEX["L_FAL"]], atol=1e-9)


def test_epicondyles_keep_their_learned_distances_to_the_upper_arm():
    """A rigid motion of the whole arm is still reproduced exactly with the upper arm's distances on; when
    the humerus slips 8 mm against the forearm's markers, the upper arm's three tracking markers, which
    moved with it, pull the rebuilt epicondyle towards where it is (bone lengths are constant)."""
    rng = np.random.default_rng(8)
    first = rng.normal(scale=0.1, size=(len(LANDMARKS), 3))
    upper = rng.normal(scale=0.1, size=(3, 3))
    hle, hme = LANDMARK_INDEX["L_HLE"], LANDMARK_INDEX["L_HME"]

    def rebuilt_after(frame, tracks, tracking_of=("L_upper_arm",) * 3):
        rebuilder = SegmentRebuilder(tracking_of)
        rebuilder.fill(first.copy(), upper.copy()[:len(tracking_of)])  # distances learned: all seen
        lost = frame.copy()
        lost[[hle, hme]] = np.nan
        assert rebuilder.fill(lost, tracks[:len(tracking_of)].copy())[hle]
        return lost[hle]

    rot, shift = rotation([1, -0.3, 0.6], 0.5), np.array([0.1, 0.4, -0.2])
    np.testing.assert_allclose(rebuilt_after(first @ rot.T + shift, upper @ rot.T + shift),
                               (first @ rot.T + shift)[hle], atol=1e-6)
    slip = np.array([0.008, 0.0, 0.0])
    off = np.linalg.norm(rebuilt_after(first, upper + slip) - (first[hle] + slip))
    rigid_off = np.linalg.norm(rebuilt_after(first, upper + slip, ()) - (first[hle] + slip))
    assert rigid_off == pytest.approx(0.008) and off < 0.9 * rigid_off, (off, rigid_off)


def _slide_along():
    """The forearm of _slid_forearm, seen at 0 s, then turned and moved, its ulnar styloid marker slid 28 mm up the
    forearm about the radial one, the styloids' spacing kept exactly: the slid frame and its forearm markers, the
    frame as it would be unslid, and a rebuilder that has seen the first frame at ``start_s``."""
    first, wand, _, _ = _slid_forearm()
    hle, hme, uoa, rsp, usp = FOREARM
    turn, shift = rotation([0.3, 1, -0.2], 0.8), np.array([0.4, 0.1, 1.0])
    slid = first.copy()
    offset = np.array([0.05, 0.03, -0.05])
    slid[usp] = first[rsp] + offset * np.linalg.norm(first[usp] - first[rsp]) / np.linalg.norm(offset)
    return slid @ turn.T + shift, wand @ turn.T + shift, first @ turn.T + shift, first, wand


def _sliding_rebuilder(first, wand, start_s):
    rebuilder = SegmentRebuilder(("L_forearm", "L_forearm"))
    rebuilder.fill(first.copy(), wand.copy(), start_s)
    return rebuilder


def _elbow_off(rebuilder, frame, wand, time_s, truth):
    """How far the lateral epicondyle, lost with the other elbow markers in ``frame``, is rebuilt from ``truth``."""
    hle, hme, uoa, rsp, usp = FOREARM
    lost = frame.copy()
    lost[[hle, hme, uoa]] = np.nan
    assert rebuilder.fill(lost, wand.copy(), time_s)[hle]
    return np.linalg.norm(lost[hle] - truth[hle])


def test_a_styloid_slid_with_the_spacing_kept_is_left_out_after_a_quarter_second_known_answer():
    """The styloids' spacing holds, but the ulnar one's distances to the forearm's two markers have changed by
    28 mm, the radial one's not at all (the Vicon take's inner wrist marker at 8.7 s). For the first 0.25 s that
    is taken as skin swinging in a strike and the marker stays in the fit, which puts the elbow over 5 mm off;
    from then on it is left out, and the radial styloid and the forearm's markers carry the elbow exactly.
    Without the frames' times it is never left out."""
    moved, moved_wand, truth, first, wand = _slide_along()
    for timed in (True, False):
        rebuilder = _sliding_rebuilder(first, wand, 0.0 if timed else np.nan)
        errors = np.array([_elbow_off(rebuilder, moved, moved_wand, f / 100 if timed else np.nan, truth)
                           for f in range(1, 41)])
        assert (errors[:24] > 0.005).all(), errors  # 0.01-0.24 s: in the fit
        if timed:
            np.testing.assert_allclose(errors[25:], 0.0, atol=1e-9)  # 0.26 s on: left out
        else:
            assert (errors > 0.005).all(), errors


def test_a_slide_is_timed_again_when_the_clock_goes_back():
    """A stream restarted (a bag played again) brings its clock back: a slide timed before it is timed again from
    there, so it is left out 0.25 s after the restart, not at once."""
    moved, moved_wand, truth, first, wand = _slide_along()
    rebuilder = _sliding_rebuilder(first, wand, 10.0)
    errors = [_elbow_off(rebuilder, moved, moved_wand, t, truth) for t in [10.1, 10.2, 10.3, 10.4, 0.0, 0.1, 0.2, 0.3]]
    assert errors[0] > 0.005 and errors[3] < 1e-9, errors  # in at 10.1 s, out from 10.35 s
    assert errors[4] > 0.005 and errors[6] > 0.005 and errors[7] < 1e-9, errors  # timed again from 0 s


def test_a_styloid_swung_against_the_forearm_for_less_than_a_quarter_second_stays_in():
    """The same slide for 0.2 s, then back, then again: each run of it is shorter than SLID_ALONG_S, so the
    marker is never left out (a strike's skin swing on the karate take's wrist bar)."""
    moved, moved_wand, back, first, wand = _slide_along()
    rebuilder = _sliding_rebuilder(first, wand, 0.0)
    for f in range(1, 61):
        swung = (f // 20) % 2 == 0  # 0.01-0.19 s and 0.40-0.59 s swung, 0.20-0.39 s back
        off = _elbow_off(rebuilder, moved if swung else back, moved_wand, f / 100, back)
        if swung:
            assert off > 0.005, f  # the slid marker still pulls the fit
        else:
            assert off < 1e-9, f


def test_a_lone_styloid_is_rebuilt_from_the_other_and_the_forearm_known_answer():
    """One styloid lost, the other seen: the wrist joint (their mean) would be lost with it. A forearm turned and
    moved, its ulnar styloid lost: rebuilt exactly from the radial one, the elbow's markers, the olecranon and the
    forearm's marker. Both lost: neither is (the wrist is left to the IK stage). With under three partners besides
    the other styloid (karate's set: one elbow marker, one forearm marker; here the elbow's lateral marker alone,
    no forearm marker): not rebuilt either."""
    first, wand, _, _ = _slid_forearm()
    hle, hme, uoa, rsp, usp = FOREARM
    turn, shift = rotation([0.3, 1, -0.2], 0.8), np.array([0.4, 0.1, 1.0])
    moved, moved_wand = first @ turn.T + shift, wand @ turn.T + shift
    for lost_names, rebuilt_names, tracked in (([usp], [usp], True), ([rsp], [rsp], True), ([rsp, usp], [], True),
                                                ([usp, hme, uoa], [], False), ([usp], [usp], False)):
        rebuilder = SegmentRebuilder(("L_forearm",) if tracked else ())
        rebuilder.fill(first.copy(), wand[:1].copy() if tracked else None)
        lost = moved.copy()
        lost[lost_names] = np.nan
        mask = rebuilder.fill(lost, moved_wand[:1].copy() if tracked else None)
        assert set(np.flatnonzero(mask)) & set(lost_names) == set(rebuilt_names), (lost_names, np.flatnonzero(mask))
        if rebuilt_names:
            np.testing.assert_allclose(lost[rebuilt_names], moved[rebuilt_names], atol=1e-9)


def test_sprint_wrist_with_one_styloid_hidden_is_kept_by_the_rebuild():
    """The sprint's left ulnar styloid hidden from 1 s to the end: the wrist joint, lost with it, comes back from
    the rebuilt styloid within 4 / 12 mm of the reference (mean / max; the IK stage's fill was 19 / 67)."""
    rec, prof = read_recording(data_file("03_sprint_start_BTK_SprintMotion.trc")), load_profile("btk_sprint")
    pipe = SkeletonPipeline(prof, rec.labels, fill_gaps=False)
    lm = pipe.landmark_map.apply(rec.positions)
    reference = Localizer(prof.body).localize(lm, None).positions[:, INDEX["wrist_l"]]
    start = int(rec.rate_hz)
    hidden = lm.copy()
    hidden[start:, LANDMARK_INDEX["L_USP"]] = np.nan
    filled, mask = fill_take(SegmentRebuilder(pipe.landmark_map.tracking_of).fill, hidden,
                             tracking=pipe.landmark_map.tracking(rec.positions), time_s=np.arange(len(lm)) / rec.rate_hz)
    assert mask[start:, LANDMARK_INDEX["L_USP"]].all()
    loc = Localizer(prof.body).localize(filled, mask)
    error = np.linalg.norm(loc.positions[start:, INDEX["wrist_l"]] - reference[start:], axis=-1)
    assert error.mean() < 0.006 and error.max() < 0.02, (error.mean(), error.max())
    bare = Localizer(prof.body).localize(hidden, None)
    assert (bare.status[start:, INDEX["wrist_l"]] == Status.MISSING).all()


def test_the_tracking_markers_distances_hold_when_the_styloids_slide():
    """The styloids' skin slides 12 mm against the forearm; the forearm's wand and the upper arm's marker
    stay where the bones have them. The second pass keeps the rebuilt epicondyle at its learned
    distances to those two (the first pass alone leaves one 3.2 mm off)."""
    rng = np.random.default_rng(9)
    first = rng.normal(scale=0.1, size=(len(LANDMARKS), 3))
    tracks = rng.normal(scale=0.1, size=(2, 3))
    hle, hme, rsp, usp = (LANDMARK_INDEX[n] for n in ("L_HLE", "L_HME", "L_RSP", "L_USP"))
    rebuilder = SegmentRebuilder(("L_forearm", "L_upper_arm"))
    rebuilder.fill(first.copy(), tracks.copy())
    rot, shift = rotation([0.3, 1, -0.2], 0.7), np.array([0.2, -0.1, 0.3])
    moved, moved_tracks = first @ rot.T + shift, tracks @ rot.T + shift
    lost = moved.copy()
    lost[[hle, hme]] = np.nan
    lost[rsp] += [0.012, 0, 0]
    lost[usp] += [0, -0.01, 0.005]
    assert rebuilder.fill(lost, moved_tracks.copy())[hle]
    for k in range(2):
        learned = np.linalg.norm(first[hle] - tracks[k])
        assert abs(np.linalg.norm(lost[hle] - moved_tracks[k]) - learned) < 0.0015, k
    assert np.linalg.norm(lost[hle] - moved[hle]) < 0.008


@pytest.mark.parametrize("lost_names, slid, tracking_of, held, free", [
    # the malleoli: the foot flexes (heel and one metatarsal slide against the ankle); the shank's wand holds
    (("L_FAL", "L_TAM"), ("L_FCC", "L_FM2"), ("L_foot", "L_foot", "L_shank"), (2,), (0, 1)),
    # the knee's epicondyles: the malleoli's skin slides; the thigh's marker holds, the shank's own does not
    (("L_FLE", "L_FME", "L_TTC"), ("L_FAL", "L_TAM"), ("L_shank", "L_shank", "L_thigh"), (2,), (0, 1)),
])
def test_the_bone_above_holds_a_joints_landmarks(lost_names, slid, tracking_of, held, free):
    """The malleoli belong to the shank as well as the foot, the knee's epicondyles to the thigh as well as the
    shank: their learned distances to the bone above's tracking marker are kept within 2 mm when the own
    bone's partners slide by 10-12 mm, and the bone's own tracking markers do not hold them firmly (the
    foot flexes: the Vicon take's malleolus keeps its distance to the metatarsals only within 10-13 mm SD)."""
    rng = np.random.default_rng(11)
    first = rng.normal(scale=0.1, size=(len(LANDMARKS), 3))
    tracks = rng.normal(scale=0.1, size=(len(tracking_of), 3))
    lost_idx = [LANDMARK_INDEX[n] for n in lost_names]
    rebuilder = SegmentRebuilder(tracking_of)
    rebuilder.fill(first.copy(), tracks.copy())
    rot, shift = rotation([0.3, 1, -0.2], 0.7), np.array([0.2, -0.1, 0.3])
    moved, moved_tracks = first @ rot.T + shift, tracks @ rot.T + shift
    lost = moved.copy()
    lost[lost_idx] = np.nan
    lost[LANDMARK_INDEX[slid[0]]] += [0.012, 0, 0]
    lost[LANDMARK_INDEX[slid[1]]] += [0, -0.01, 0.005]
    moved_tracks[free[0]] += [0, 0.03, 0.01]  # an own-bone tracking marker slides as well
    assert rebuilder.fill(lost, moved_tracks.copy())[lost_idx[0]]
    point = lost[lost_idx[0]]
    for k in held:
        learned = np.linalg.norm(first[lost_idx[0]] - tracks[k])
        assert abs(np.linalg.norm(point - moved_tracks[k]) - learned) < 0.002, k
    assert np.linalg.norm(point - moved[lost_idx[0]]) < 0.012


def test_a_rigid_leg_is_rebuilt_exactly_with_the_bones_above():
    """A rigid motion of the whole leg (foot, shank and thigh markers all moved alike) is reproduced exactly
    with the shank's and thigh's distances on."""
    rng = np.random.default_rng(12)
    first = rng.normal(scale=0.1, size=(len(LANDMARKS), 3))
    tracking_of = ("L_foot", "L_foot", "L_shank", "L_thigh")
    tracks = rng.normal(scale=0.1, size=(len(tracking_of), 3))
    rebuilder = SegmentRebuilder(tracking_of)
    rebuilder.fill(first.copy(), tracks.copy())
    rot, shift = rotation([1, -0.3, 0.6], 0.5), np.array([0.1, 0.4, -0.2])
    moved, moved_tracks = first @ rot.T + shift, tracks @ rot.T + shift
    names = ("L_FAL", "L_TAM", "L_FLE", "L_FME")
    lost = moved.copy()
    lost[[LANDMARK_INDEX[n] for n in names]] = np.nan
    rebuilt = rebuilder.fill(lost, moved_tracks.copy())
    for n in names:
        assert rebuilt[LANDMARK_INDEX[n]], n
        np.testing.assert_allclose(lost[LANDMARK_INDEX[n]], moved[LANDMARK_INDEX[n]], atol=1e-6)


def test_partners_on_one_line_rebuild_nothing():
    """Heel and malleoli lost: the toe landmark is the midpoint of the two metatarsal tracking markers,
    so the three partners lie on one line and the foot's rotation about it is unknown."""
    rng = np.random.default_rng(9)
    first = rng.normal(scale=0.1, size=(len(LANDMARKS), 3))
    metatarsals = rng.normal(scale=0.05, size=(2, 3))
    first[LANDMARK_INDEX["L_FM2"]] = metatarsals.mean(axis=0)
    rebuilder = SegmentRebuilder(("L_foot", "L_foot"))
    rebuilder.fill(first.copy(), metatarsals.copy())
    lost = first.copy()
    lost[[LANDMARK_INDEX[n] for n in ("L_FAL", "L_TAM", "L_FCC")]] = np.nan
    assert not rebuilder.fill(lost, metatarsals.copy()).any()
    lost = first.copy()
    lost[[LANDMARK_INDEX[n] for n in ("L_FAL", "L_TAM")]] = np.nan  # with the heel: off the line
    assert rebuilder.fill(lost, metatarsals.copy())[LANDMARK_INDEX["L_FAL"]]


@pytest.mark.parametrize("angle", [0.4, -1.1])
def test_partners_on_one_line_are_rolled_by_the_bone_above_known_answer(angle):
    """Heel lost, the metatarsals and the toe between them on one line: the shank's two markers fix the foot's
    roll about it, so the malleoli come back after a turn about that line of 23 or 63 degrees, on top of a swing
    of the whole foot: within a tenth of the turn's chord, by which the line's least turn alone leaves them off
    (ROLL_PRICE holds the roll towards the reference's: 3 mm of 83 at 23 degrees, 17 of 218 at 63). Each member
    is rolled on its own: the medial malleolus, nearer the line here, is less firmly held and only nearer than the
    chord. (One marker's distance leaves two rolls, mirror images; the one nearer the reference's is taken.)"""
    rng = np.random.default_rng(13)
    first = rng.normal(scale=0.1, size=(len(LANDMARKS), 3))
    tracks = rng.normal(scale=0.08, size=(4, 3))  # two metatarsals and the shank's two markers
    first[LANDMARK_INDEX["L_FM2"]] = tracks[:2].mean(axis=0)
    rebuilder = SegmentRebuilder(("L_foot", "L_foot", "L_shank", "L_shank"))
    rebuilder.fill(first.copy(), tracks.copy())  # distances learned: all seen
    line = tracks[1] - tracks[0]
    roll = rotation(line, angle)
    rot, shift = rotation([0.2, 1, 0.4], 0.6), np.array([0.3, 0.1, -0.2])
    moved = (first - tracks[0]) @ roll.T + tracks[0]
    moved_tracks = (tracks - tracks[0]) @ roll.T + tracks[0]
    moved, moved_tracks = moved @ rot.T + shift, moved_tracks @ rot.T + shift
    names = ("L_FAL", "L_TAM", "L_FCC")
    lost = moved.copy()
    lost[[LANDMARK_INDEX[n] for n in names]] = np.nan
    # (the shank's markers turned with the foot: the distances they keep are the ones learned)
    rebuilt = rebuilder.fill(lost, moved_tracks.copy())
    unit = line / np.linalg.norm(line)
    for n in ("L_FAL", "L_TAM"):
        assert rebuilt[LANDMARK_INDEX[n]], n
        offset = first[LANDMARK_INDEX[n]] - tracks[0]
        chord = 2 * np.linalg.norm(offset - (offset @ unit) * unit) * abs(np.sin(angle / 2))
        off = np.linalg.norm(lost[LANDMARK_INDEX[n]] - moved[LANDMARK_INDEX[n]])
        assert off < (0.1 if n == "L_FAL" else 0.5) * chord, (n, off, chord)
    assert not rebuilt[LANDMARK_INDEX["L_FCC"]]  # the heel is no member the bone above refines


def test_nothing_is_rebuilt_before_the_segment_was_seen():
    lm = np.random.default_rng(5).normal(size=(len(LANDMARKS), 3))
    lm[LANDMARK_INDEX["L_FCC"]] = np.nan
    assert not SegmentRebuilder().fill(lm).any()


def test_joints_from_rebuilt_landmarks_are_estimated_not_located():
    take = read_recording(data_file("02_qualisys_walking_ezc3d_Qualisys.c3d"))
    lm = load_profile("qualisys_sports").resolve(take.labels).apply(take.positions[:40])
    lm[20:, LANDMARK_INDEX["L_FCC"]] = np.nan
    filled, rebuilt = fill_take(SegmentRebuilder().fill, lm)
    assert rebuilt[20:, LANDMARK_INDEX["L_FCC"]].all() and not rebuilt[:20].any()
    loc = Localizer().localize(filled, rebuilt)
    assert (loc.status[20:, INDEX["foot_l"]] == Status.ESTIMATED).all()
    assert (loc.status[:20, INDEX["foot_l"]] == Status.LOCATED).all()
    assert (loc.status[20:, INDEX["knee_l"]] == Status.LOCATED).all()


def _gap(take, profile, joints, start_s, stop_s=None, part=None, rebuilds=(False, True)):
    """Runs of `joints` hidden from start_s to stop_s (the end), the fills as in the studio, by rebuild on / off."""
    rec, prof = read_recording(data_file(take), part), load_profile(profile)
    pipe = SkeletonPipeline(prof, rec.labels, fill_gaps=False)
    lm = pipe.landmark_map.apply(rec.positions)
    reference = pipe.solve_landmarks(pipe.landmarks(rec.positions)).positions
    start = int(start_s * rec.rate_hz)
    stop = rec.n_frames if stop_s is None else int(stop_s * rec.rate_hz)
    take = GapTake(lm, reference, prof, rec.rate_hz, pipe.landmark_map.tracking(rec.positions),
                   pipe.landmark_map.tracking_of)
    return {rebuild: gap_run(take, Gap(joints, start, stop), hips=HipOptions(rebuild=rebuild), fills=STUDIO)
            for rebuild in rebuilds}


def test_sprint_elbow_rebuilt_from_the_olecranon_and_styloids():
    """The elbow target (20 / 60 mm): the elbow's epicondyle markers hidden from 1 s to the end of
    the sprint. The olecranon and both styloids carry them, the upper arm's two markers keep their
    distances; the swivel alone (the shoulder from the acromion moves a lot) is several times as far."""
    runs = _gap("03_sprint_start_BTK_SprintMotion.trc", "btk_sprint", ["elbow_l"], 1.0)
    with_, without = runs[True].stats(), runs[False].stats()
    assert with_["mean"] < 0.02 and with_["max"] < 0.06, with_
    assert with_["mean"] < 0.6 * without["mean"] and with_["max"] < 0.5 * without["max"], (with_, without)
    # the olecranon hidden too: the two styloids run across the forearm and leave its roll about their line
    # free; the upper arm's markers fix it (53 -> 27 mm)
    strict = _gap("03_sprint_start_BTK_SprintMotion.trc", "btk_sprint", ["elbow_l", "L_UOA"], 1.0)
    assert strict[True].stats()["mean"] < 0.6 * strict[False].stats()["mean"], (strict[True].stats(),
                                                                                strict[False].stats())


def test_walk_heel_rebuilt_from_malleoli_and_toe():
    runs = _gap("02_qualisys_walking_ezc3d_Qualisys.c3d", "qualisys_sports", ["foot_l"], 0.5, 1.5)
    assert runs[True].stats()["mean"] < 0.01 and runs[True].stats()["max"] < 0.02, runs[True].stats()
    assert runs[False].stats()["mean"] > 0.02  # carried with the shank, it was 30 mm off


def test_walk_knee_and_ankle_rebuilt_from_the_shank_and_foot_tracking_markers():
    """The knee+ankle target (30 mm): the malleoli come back from heel and metatarsals, then the
    knee's markers from the malleoli, the fibula head and the shank's wand."""
    runs = _gap("02_qualisys_walking_ezc3d_Qualisys.c3d", "qualisys_sports", ["knee_l", "ankle_l"], 0.5, 2.0)
    knee, ankle = runs[True].stats(0), runs[True].stats(1)
    assert knee["mean"] < 0.02 and knee["max"] < 0.05 and ankle["mean"] < 0.01, (knee, ankle)
    assert runs[False].stats(0)["mean"] > 0.02  # the swivel alone: 33 mm; with limb memory and learned lengths 23


def test_walk_elbow_rebuilt_with_the_forearm_wand():
    """The Qualisys set has no olecranon marker: the forearm's wand is the third partner."""
    runs = _gap("02_qualisys_walking_ezc3d_Qualisys.c3d", "qualisys_sports", ["elbow_l"], 0.3)
    assert runs[True].stats()["mean"] < 0.01 and runs[True].stats()["max"] < 0.02, runs[True].stats()
    assert runs[False].stats()["mean"] > 1.5 * runs[True].stats()["mean"]  # the swivel alone: 7 mm


def test_karate_knee_carried_by_its_ankle_and_shank_markers():
    """CMU's shank has the ankle marker and one shank marker (LSHN) besides the knee's: two partners
    along the bone. The knee hidden from 1 s to 20 s: the swivel alone was 66 / 409 mm off."""
    runs = _gap("08_cmu_135_02_karate_kata.c3d", "cmu41", ["knee_l"], 1.0, 20.0)
    with_, without = runs[True].stats(), runs[False].stats()
    assert with_["mean"] < 0.03 and with_["max"] < 0.1, with_
    assert with_["mean"] < 0.5 * without["mean"], (with_, without)


def test_karate_elbow_rebuilt_from_the_forearm_and_upper_arm_markers():
    """CMU's set has a lateral elbow marker only; its forearm (LFRM) and upper arm (LUPA) markers are
    tracking markers of the profile. The swivel alone was 169 / 454 mm off (with the limb memory and
    learned lengths 56 / 256)."""
    runs = _gap("08_cmu_135_02_karate_kata.c3d", "cmu41", ["elbow_l"], 1.0, 20.0)
    with_, without = runs[True].stats(), runs[False].stats()
    assert with_["mean"] < 0.03 and with_["max"] < 0.1, with_
    assert with_["mean"] < 0.4 * without["mean"], (with_, without)


def test_karate_elbows_meet_the_elbow_target_with_the_forearm_rolled_by_the_upper_arm():
    """The elbow target (20 / 60 mm), both karate elbows hidden from 1 s to 20 s, the fills as in the studio.
    The wrist bar turns with pronation, the epicondyle does not: the rigid fit's roll, taken from the bar, is
    corrected by the upper arm's marker where that marker's distance fixes it (ROLL_FIRM_FROM). Before: left
    18.9 / 63.2 mm, right 22.0 / 71.2 (the right arm's held poses 24-32 mm off, its strikes over 60)."""
    for side, max_m in (("l", 0.060), ("r", 0.065)):
        run = _gap("08_cmu_135_02_karate_kata.c3d", "cmu41", [f"elbow_{side}"], 1.0, 20.0, rebuilds=(True,))[True]
        assert run.stats()["mean"] <= 0.020 and run.stats()["max"] <= max_m, (side, run.stats())


def test_vicon_elbow_rebuilt_without_its_sliding_wrist_marker():
    """The Vicon take's left inner wrist marker slides 30-50 mm up the forearm after 1.5 s (its spacing from the
    outer one, which bone fixes, changes by 7-9 mm). The elbow hidden from 1 s to the end: with that marker left
    out of the fit, the rebuild is 30 mm off on average (115 while it was kept in, worse than the swivel alone,
    105). From 8.7 s the spacing is back within 4 mm; the marker is still left out there, as slid along with the
    spacing kept (SLID_ALONG_M): the elbow from 8.7 s on is 16 / 43 mm off, where taking it back in left it
    64 / 128."""
    runs = _gap("12_vicon_freeform_realgaps_nimble_nick_freeform_001.c3d", "vicon53", ["elbow_l"], 1.0)
    with_, without = runs[True].stats(), runs[False].stats()
    assert with_["mean"] < 0.045, with_
    last = runs[True].error_m[runs[True].frames >= 8.7 * 120, 0]
    assert np.nanmean(last) < 0.025 and np.nanmax(last) < 0.06, (np.nanmean(last), np.nanmax(last))
    assert with_["mean"] < 0.5 * without["mean"], (with_, without)


def test_a_lost_acromion_is_carried_with_the_trunk():
    """The left acromion hidden from 1 s to the end of a dance (dance1: the other acromion, both spine markers and
    the sternum seen). Carried with the trunk it keeps the shoulder joint within 20 mm on average, where without
    the rebuild the chest falls back to other markers and the arm's IK puts the shoulder."""
    runs = _gap("13_qualisys_dance_walk_mocaptoolbox_mcdemodata.mat", "dance28", ["shoulder_l"], 1.0, part="dance1")
    with_, without = runs[True].stats(), runs[False].stats()
    assert with_["mean"] < 0.02 and with_["max"] < 0.06, with_
    assert with_["mean"] < 0.3 * without["mean"], (with_, without)

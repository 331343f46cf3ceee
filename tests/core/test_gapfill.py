"""Gap filling on a real take: hide markers that are really there and compare with the truth."""
import numpy as np
import pytest

from mocap_core.fill_options import FillOptions
from mocap_core.gapfill import GapFiller, LimbFiller
from mocap_core.hip_interpolation import HipInterpolator
from mocap_core.localization import Localizer
from mocap_core.pipeline import SkeletonPipeline
from mocap_core.profiles import LANDMARK_INDEX, load_profile
from mocap_core.recordings import read_recording
from mocap_core.skeleton import INDEX, Status
from mocap_core.ik.solvers import SOLVERS
from tests.conftest import data_file


@pytest.fixture(scope="module")
def walk():
    rec = read_recording(data_file("02_qualisys_walking_ezc3d_Qualisys.c3d"))
    prof = load_profile("qualisys_sports")
    lm, _ = HipInterpolator().fill_landmarks(prof.resolve(rec.labels).apply(rec.positions))
    return lm, prof


def localized(lm, prof):
    loc = Localizer(prof.body).localize(lm)
    return loc.positions, loc.frames, loc.status


def filled(lm, prof, filler):
    """Localize the landmarks and fill every frame's gaps with ``filler`` (a GapFiller or LimbFiller)."""
    pos, frames, status = localized(lm, prof)
    for f in range(len(pos)):
        filler.fill(pos[f], frames[f], status[f])
    return pos, frames, status


@pytest.mark.parametrize("solver", sorted(SOLVERS))
def test_hidden_elbow_is_estimated_near_the_truth(walk, solver):
    lm, prof = walk
    truth, _, _ = localized(lm, prof)
    hidden = lm.copy()
    hidden[100:, [LANDMARK_INDEX["L_HLE"], LANDMARK_INDEX["L_HME"]]] = np.nan
    pos, frames, status = filled(hidden, prof, GapFiller(solver))
    e = INDEX["elbow_l"]
    assert (status[:100, e] == Status.LOCATED).all() and (status[100:, e] == Status.ESTIMATED).all()
    err = np.linalg.norm(pos[100:, e] - truth[100:, e], axis=1)
    assert err.mean() < 0.06, f"{solver}: mean elbow error {err.mean() * 1000:.0f} mm"
    # bone lengths come from the last complete frame and are kept
    upper = np.linalg.norm(pos[100:, e] - pos[100:, INDEX["shoulder_l"]], axis=1)
    assert upper.std() < 0.01
    # the wrist (the target) keeps its measured position
    np.testing.assert_array_equal(pos[100:, INDEX["wrist_l"]], truth[100:, INDEX["wrist_l"]])


def test_missing_end_effector_is_held_relative_to_its_parent(walk):
    lm, prof = walk
    hidden = lm.copy()
    hidden[150:, LANDMARK_INDEX["R_HM2"]] = np.nan
    pos, frames, status = filled(hidden, prof, LimbFiller("right_arm"))
    h, w = INDEX["hand_r"], INDEX["wrist_r"]
    assert (status[150:, h] == Status.HELD).all()
    # the hand keeps its offset in the frame of the wrist's parent chain: constant distance to the wrist
    d = np.linalg.norm(pos[150:, h] - pos[150:, w], axis=1)
    assert d.std() < 1e-6


def test_nothing_is_invented_before_the_limb_was_seen_whole(walk):
    lm, prof = walk
    hidden = lm.copy()
    hidden[:50, LANDMARK_INDEX["L_FLE"]] = np.nan
    hidden[:50, LANDMARK_INDEX["L_FME"]] = np.nan
    hidden[:50, LANDMARK_INDEX["L_TTC"]] = np.nan
    pos, frames, status = filled(hidden, prof, LimbFiller("left_leg"))
    assert (status[:50, INDEX["knee_l"]] == Status.MISSING).all()
    assert (status[50:, INDEX["knee_l"]] == Status.LOCATED).all()


def test_reacquisition_blend_bounds_the_per_frame_move(walk):
    """Beyond the thesis: markers that come back are blended in at most reacquire_step_m per frame."""
    lm, prof = walk
    hidden = lm.copy()
    hidden[100:200, [LANDMARK_INDEX["L_FLE"], LANDMARK_INDEX["L_FME"], LANDMARK_INDEX["L_TTC"]]] = np.nan
    moves = {}
    for step in (0.0, 0.005):
        pos, frames, status = filled(hidden, prof, LimbFiller("left_leg", "ccd",
                                                                options=FillOptions(reacquire_step_m=step)))
        k = INDEX["knee_l"]
        moves[step] = np.linalg.norm(np.diff(pos[195:215, k], axis=0), axis=1).max()
        truth, _, _ = localized(lm, prof)
        # the blend ends: later frames are the measurement again
        np.testing.assert_allclose(pos[300:, k], truth[300:, k], atol=1e-9)
    normal = np.percentile(np.linalg.norm(np.diff(localized(lm, prof)[0][:, INDEX["knee_l"]], axis=0), axis=1), 95)
    assert moves[0.005] <= normal + 0.005 + 1e-9
    assert moves[0.0] > moves[0.005]


def test_swivel_option_beats_the_thesis_method_on_a_walk(walk):
    """Beyond the thesis: a lone missing elbow from its bone lengths and the carried swivel angle."""
    lm, prof = walk
    truth, _, _ = localized(lm, prof)
    hidden = lm.copy()
    hidden[60:, [LANDMARK_INDEX["L_HLE"], LANDMARK_INDEX["L_HME"]]] = np.nan
    err = {}
    for swivel in (False, True):
        pos, frames, status = filled(hidden, prof, GapFiller("ccd", options=FillOptions(swivel=swivel)))
        e = INDEX["elbow_l"]
        assert (status[60:, e] == Status.ESTIMATED).all()
        err[swivel] = np.linalg.norm(pos[60:, e] - truth[60:, e], axis=1)
        # bone lengths kept exactly by the circle construction
        if swivel:
            upper = np.linalg.norm(pos[60:, e] - pos[60:, INDEX["shoulder_l"]], axis=1)
            assert upper.std() < 1e-6
    assert err[True].mean() < 0.025 and err[True].max() < 0.06, (err[True].mean(), err[True].max())
    assert err[True].mean() < err[False].mean()


def test_lost_pelvis_follows_the_body_on_a_walk():
    """Beyond the thesis: every hip marker hidden for 1.5 s of walking. Holding them (the thesis) leaves
    the pelvis behind as the subject walks on; fitting them to the trunk and knees keeps it close."""
    rec = read_recording(data_file("02_qualisys_walking_ezc3d_Qualisys.c3d"))
    prof = load_profile("qualisys_sports")
    raw = prof.resolve(rec.labels).apply(rec.positions)
    truth = Localizer(prof.body).localize(HipInterpolator().fill_landmarks(raw)[0]).positions
    hips = [LANDMARK_INDEX[n] for n in ("SACR", "L_IAS", "R_IAS")]
    hidden = raw.copy()
    hidden[50:200, hips] = np.nan
    err = {}
    for when_lost in ("hold", "fit"):
        lm, flags = HipInterpolator(when_lost=when_lost).fill_landmarks(hidden)
        assert flags[50:200].all()
        pos = Localizer(prof.body).localize(lm).positions
        seg = [INDEX[j] for j in ("pelvis", "hip_l", "hip_r")]
        err[when_lost] = np.linalg.norm(pos[50:200][:, seg] - truth[50:200][:, seg], axis=-1)
    assert err["hold"].mean() > 0.3                     # the subject walked on without it
    assert err["fit"].mean() < 0.03 and err["fit"].max() < 0.06, (err["fit"].mean(), err["fit"].max())


def test_knee_and_ankle_lost_together_beyond_the_thesis(walk):
    """Beyond the thesis: the lost ankle moves with the still-tracked foot (segment_carry), the knee is then
    a lone joint on its swivel circle; against the thesis's IK chain from hip to foot."""
    lm, prof = walk
    truth, _, _ = localized(lm, prof)
    hidden = lm.copy()
    hidden[60:200, [LANDMARK_INDEX[n] for n in ("L_FLE", "L_FME", "L_TTC", "L_FAL", "L_TAM")]] = np.nan
    err = {}
    for beyond in (False, True):
        pos, frames, status = filled(hidden, prof, GapFiller("ccd", options=FillOptions(swivel=beyond,
                                                                                        segment_carry=beyond)))
        k, a = INDEX["knee_l"], INDEX["ankle_l"]
        assert (status[60:200, [k, a]] == Status.ESTIMATED).all()
        err[beyond] = np.linalg.norm(pos[60:200][:, [k, a]] - truth[60:200][:, [k, a]], axis=-1).mean(axis=0)
        if beyond:  # the thigh keeps its length; the foot stays rigid
            thigh = np.linalg.norm(pos[60:200, k] - pos[60:200, INDEX["hip_l"]], axis=1)
            foot = np.linalg.norm(pos[60:200, a] - pos[60:200, INDEX["foot_l"]], axis=1)
            assert thigh.std() < 1e-6 and foot.std() < 1e-6
    assert err[True][0] < 0.05 and err[True][1] < 0.02, err
    assert (err[True] < err[False] / 3).all(), err


def test_swivel_angle_from_the_next_joints_frame_known_answer():
    """The point on the swivel circle where the bone to the target, seen in the target joint's frame, is
    its usual direction: found from a prior 17 degrees off, on either side; with no weights the prior
    stays."""
    from mocap_core.analytic_fill import on_circle_fitting

    axis, centre_to_target, radius = np.array([0, 0, -1.0]), np.array([0, 0, -0.2]), 0.1
    c, s_ = np.cos(0.4), np.sin(0.4)
    ref = np.array([[c, -s_, 0], [s_, c, 0], [0, 0, 1.0]])  # the target joint's frame, turned about z
    weight = np.full(3, 400.0)
    for truth in np.radians([20, 75, 140, -60, 179]):
        elbow = radius * np.array([np.cos(truth), np.sin(truth), 0])
        bone = centre_to_target - elbow
        usual = ref.T @ (bone / np.linalg.norm(bone))
        for off in (0.3, -0.3):
            prior = np.array([np.cos(truth + off), np.sin(truth + off), 0])
            u = on_circle_fitting(prior, axis, radius, centre_to_target, (ref, usual, weight), (np.zeros(3), 0.0))
            assert abs(np.linalg.norm(u) - 1) < 1e-9 and abs(u @ axis) < 1e-9
            np.testing.assert_allclose(u, elbow / radius, atol=0.01)  # within 0.6 degrees: turning costs a little
    prior = np.array([1.0, 0, 0])
    np.testing.assert_allclose(on_circle_fitting(prior, axis, radius, centre_to_target, (ref, usual, np.zeros(3)),
                                                 (np.zeros(3), 0.0)),
                               prior)


def test_lost_hand_moves_with_the_forearm(walk):
    """Beyond the thesis: a lost end effector keeps its last pose relative to the last tracked bone before it
    (the forearm), where Algorithm 1 keeps it relative to the limb's parent (the chest)."""
    lm, prof = walk
    truth, _, _ = localized(lm, prof)
    hidden = lm.copy()
    hidden[60:250, LANDMARK_INDEX["L_HM2"]] = np.nan
    err = {}
    for carry in (False, True):
        pos, frames, status = filled(hidden, prof, GapFiller("ccd", options=FillOptions(segment_carry=carry)))
        h = INDEX["hand_l"]
        assert (status[60:250, h] == Status.HELD).all() and np.isfinite(frames[60:250, INDEX["wrist_l"]]).all()
        err[carry] = np.linalg.norm(pos[60:250, h] - truth[60:250, h], axis=1)
    assert err[True].mean() < 0.02 and err[True].mean() < err[False].mean() / 2, (err[True].mean(), err[False].mean())


def _turn_deg(rotation) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(rotation) - 1) / 2, -1, 1))))


def test_a_lost_joints_frame_turns_with_its_bones_plane_only_where_they_bend_known_answer():
    """shape_turn: two bones well bent turn with their plane (a hinge's roll); straight, by the least rotation
    of the second bone. Nearly straight (2 degrees), the plane is noise: 1 mm aside at the joint turned it about
    the second bone by 90 degrees, and a joint lost out of its neighbours' reach (on their line) had an arbitrary
    frame (the Vicon take's left shoulder, 130-175 degrees a frame). Between, the roll is taken in part."""
    from mocap_core.analytic_fill import STRAIGHT_SIN, shape_turn
    from mocap_core.ik.kernels import axis_angle, rotation_between

    first, second = np.array([0.0, 0.0, -0.3]), np.array([0.0, 0.1, -0.25])  # bent about 22 degrees
    spin = axis_angle(np.array([0.3, 0.2, 0.9]) / np.linalg.norm([0.3, 0.2, 0.9]), 0.7)
    np.testing.assert_allclose(shape_turn(first, second, spin @ first, spin @ second), spin, atol=1e-9)
    straight = np.array([0.0, 0.0, -0.25])
    tipped = np.array([0.0, 0.01, -0.25])
    np.testing.assert_allclose(shape_turn(first, straight, first, tipped), rotation_between(straight, tipped),
                               atol=1e-12)
    # nearly straight, the joint 1 mm to one side, then to the other: a small turn, not the plane's half turn
    aside = np.array([0.001, 0.0, 0.0])
    before = shape_turn(first + aside, straight - aside, first - aside, straight + aside)
    assert _turn_deg(before) < 1.0
    assert STRAIGHT_SIN > np.sin(np.radians(2))
    # bent 11 degrees to one side, then to the other (the joint crossed its neighbours' line): its plane is the
    # same plane, so no roll, only the second bone's least turn (not a half turn's share: 105 degrees)
    side, other = np.array([0.0, 0.02, -0.1]), np.array([0.0, -0.02, -0.1])
    crossed = shape_turn(first, side, first, other)
    assert _turn_deg(crossed) == pytest.approx(_turn_deg(rotation_between(side, other)), abs=1e-6)


def test_a_lost_shoulders_frame_does_not_flip_where_its_acromion_flickers():
    """The Vicon take's left acromion marker flickers at frames 199-203. With its landmark lost (the partial means,
    which keep it, off here), the chest falls back to other markers and the clavicle's root jumps 53-63 mm a
    frame; the lone shoulder, out of reach of its clavicle and elbow, was put on their line, and its frame turned
    130-175 degrees a frame (an arbitrary plane), and the elbow, wrist and hand frames with it (127-137). Now the
    shoulder's frame turns under 30 degrees a frame there and the arm's under 50 (what is left is the
    clavicle's own jump)."""
    from mocap_core.experiments import _turns_deg

    rec = read_recording(data_file("12_vicon_freeform_realgaps_nimble_nick_freeform_001.c3d"))
    pipe = SkeletonPipeline(load_profile("vicon53"), rec.labels, options="studio", rate_hz=rec.rate_hz)
    pipe.partial = None
    chunk = next(pipe.run(rec.positions[:240], chunk=240))
    assert chunk.status[199, INDEX["shoulder_l"]] == Status.ESTIMATED
    turns = {joint: np.nanmax(_turns_deg(chunk.frames[197:207, INDEX[joint]]))
             for joint in ("shoulder_l", "elbow_l", "wrist_l", "hand_l")}
    assert turns["shoulder_l"] < 30 and max(turns.values()) < 50, turns

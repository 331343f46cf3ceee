"""The body model: a lone lost elbow from a regression on the rest of the located body."""
import numpy as np

from mocap_core.body_model import MAX_SPEED_M_S, MAX_WEIGHT, MIN_SAMPLES, BodyModel
from mocap_core.end_model import EndModel
from mocap_core.experiments import Gap, GapTake, gap_run
from mocap_core.fill_options import STUDIO, FillOptions, HipOptions
from mocap_core.gapfill import LimbFiller
from mocap_core.hip_interpolation import HipInterpolator
from mocap_core.localization import Localizer
from mocap_core.pipeline import SkeletonPipeline
from mocap_core.profiles import LANDMARK_INDEX, load_profile
from mocap_core.recordings import read_recording
from mocap_core.skeleton import INDEX, JOINTS, N_JOINTS, Status
from tests.conftest import data_file
from tests.core.test_learned_lengths import dance_left_elbow_hidden

MIRROR = np.array([-1.0, 1.0, 1.0])
# the left elbow from the left shoulder (chest frame = world, x to the subject's left) is this linear
# function of where the head is from that shoulder; the right elbow is its mirror image
GAIN = np.array([[0.5, 0.2, 0.0], [0.0, -0.4, 0.3], [0.1, 0.0, 0.6]])
OFFSET = np.array([0.05, 0.0, -0.25])
APART_S = 1.0  # the random poses stand a second apart, so the model point's speed cap does not bind


def body(rng, left_elbow_seen=True, scale=1.0):
    """A random skeleton (every joint jittered about a mirror-symmetric base), both elbows placed by the
    known linear rule."""
    base = np.zeros((N_JOINTS, 3))
    for j, name in enumerate(JOINTS):
        side = -1.0 if name.endswith("_r") else 1.0
        base[j] = [side * (0.05 + 0.01 * (j % 7)), 0.02 * (j % 5), 0.6 - 0.05 * j]
    pos = base + scale * rng.normal(0.0, 0.05, base.shape)
    for side, sign in (("l", np.ones(3)), ("r", MIRROR)):
        shoulder = pos[INDEX[f"shoulder_{side}"]]
        head = (pos[INDEX["head"]] - shoulder) * sign
        pos[INDEX[f"elbow_{side}"]] = shoulder + (GAIN @ head + OFFSET) * sign
    frames = np.tile(np.eye(3), (N_JOINTS, 1, 1))
    status = np.full(N_JOINTS, int(Status.LOCATED))
    truth = pos[INDEX["elbow_l"]].copy()
    if not left_elbow_seen:
        pos[INDEX["elbow_l"]] = np.nan
        status[INDEX["elbow_l"]] = Status.MISSING
    return pos, frames, status, truth


def left_arm_model():
    chain = np.array([INDEX[j] for j in ("clavicle_l", "shoulder_l", "elbow_l", "wrist_l", "hand_l")])
    other = np.array([INDEX[j] for j in ("clavicle_r", "shoulder_r", "elbow_r", "wrist_r", "hand_r")])
    return BodyModel(chain, other, 2, INDEX["spine3"])


def test_the_other_arms_mirrored_poses_teach_the_rule_known_answer():
    """The left elbow is never seen: the model learns the rule from the right arm alone, mirrored, and
    puts the left elbow where the rule does."""
    rng = np.random.default_rng(0)
    model = left_arm_model()
    errors, weights = np.full(1500, np.nan), np.zeros(1500)
    for f in range(1500):
        pos, frames, status, truth = body(rng, left_elbow_seen=False)
        model.learn(pos, frames, status)
        point, weights[f] = model.predict(pos, frames, status, APART_S)
        if f < MIN_SAMPLES - 1:
            assert np.isnan(point).all() and weights[f] == 0.0  # not trusted before MIN_SAMPLES poses
        else:
            errors[f] = np.linalg.norm(point - truth)
    assert model.n[0] == 1500  # one (mirrored) pose a frame: the missing left elbow teaches nothing
    # the rule is linear and exact, so only the ridge's shrinkage over 81 features is left, and it fades
    # as the poses add up (the rule's own spread is 60 mm)
    assert np.nanmean(errors[200:300]) < 0.015 and np.mean(errors[-300:]) < 0.002 and np.max(errors[-300:]) < 0.005, \
        [round(np.nanmean(errors[a:a + 100]) * 1000, 1) for a in range(100, 1500, 200)]
    # and it is trusted more as it learns, never past MAX_WEIGHT
    assert weights[-300:].mean() > weights[200:300].mean() > 0 and weights.max() <= MAX_WEIGHT


def test_a_pose_unlike_any_learned_is_trusted_less():
    rng = np.random.default_rng(1)
    model = left_arm_model()
    for _ in range(300):
        model.learn(*body(rng)[:3])
    _, usual = model.predict(*body(rng, left_elbow_seen=False)[:3], APART_S)
    _, unusual = model.predict(*body(rng, left_elbow_seen=False, scale=8.0)[:3], APART_S)
    assert unusual < 0.5 * usual, (usual, unusual)


def test_an_unlocated_joint_takes_the_mean_and_a_filled_one_teaches_nothing():
    rng = np.random.default_rng(2)
    model = left_arm_model()
    for _ in range(100):
        model.learn(*body(rng)[:3])
    pos, frames, status, _ = body(rng, left_elbow_seen=False)
    status[INDEX["knee_r"]] = Status.ESTIMATED  # another limb's filled joint
    point, weight = model.predict(pos, frames, status, APART_S)
    assert np.isfinite(point).all() and weight > 0
    learned = model.n[0]
    pos, frames, status, _ = body(rng)
    status[INDEX["knee_r"]] = Status.ESTIMATED
    model.learn(pos, frames, status)
    assert model.n[0] == learned


def test_the_models_point_moves_no_faster_than_its_cap():
    """A pose unlike the last one (the linear model swings on a fast move) moves the point at most
    MAX_SPEED_M_S; once the joint is seen again, the next gap starts afresh."""
    rng = np.random.default_rng(4)
    model = left_arm_model()
    for _ in range(300):
        model.learn(*body(rng)[:3])
    frame_s = 1 / 200  # a QTM rate
    pos, frames, status, _ = body(rng, left_elbow_seen=False)
    first, _ = model.predict(pos, frames, status, frame_s)
    pos2, frames2, status2, _ = body(rng, left_elbow_seen=False)
    pos2[INDEX["shoulder_l"]] = pos[INDEX["shoulder_l"]]  # the same root: the point's move is the model's
    second, _ = model.predict(pos2, frames2, status2, frame_s)
    model.predict(*body(rng)[:3], frame_s)  # seen again: the next gap starts afresh
    free, _ = model.predict(pos2, frames2, status2, frame_s)  # where the model alone puts it
    limit = MAX_SPEED_M_S * frame_s
    assert np.linalg.norm(free - first) > 3 * limit  # a swing the cap must hold back
    np.testing.assert_allclose(second, first + (free - first) * limit / np.linalg.norm(free - first), atol=1e-12)


def test_a_nan_flood_teaches_nothing_and_predicts_nothing():
    rng = np.random.default_rng(3)
    model = left_arm_model()
    for _ in range(100):
        model.learn(*body(rng)[:3])
    learned = model.n[0]
    pos, frames, status, _ = body(rng)
    pos[INDEX["elbow_l"]] = np.nan  # "located" without a position: the right arm's pose alone is learned
    model.learn(pos, frames, status)
    assert model.n[0] == learned + 1 and np.isfinite(model.sxx).all() and np.isfinite(model.sxy).all()
    sums = model.sxx.copy()
    pos[:] = np.nan                 # everything
    model.learn(pos, frames, status)
    assert model.n[0] == learned + 1 and np.array_equal(model.sxx, sums)
    status[INDEX["elbow_l"]] = Status.MISSING
    point, weight = model.predict(pos, frames, status, APART_S)
    assert np.isnan(point).all() and weight == 0.0
    frames[:] = np.nan              # no parent frame either
    assert model.predict(pos, frames, status, APART_S)[1] == 0.0


def test_the_body_model_on_a_dancers_arm():
    """dance2 of the 28-marker set, the left elbow hidden from 1 s to the end, the studio's swivel, segment
    carry, limb memory and learned lengths on: the worst of the dance set's arms (36 mm mean). The body
    model takes it under 31 mm, and the elbow stays on its circle."""
    truth, loc, start = dance_left_elbow_hidden("dance2")
    mean, upper = {}, {}
    for on in (False, True):
        pos, frames, status = loc.positions.copy(), loc.frames.copy(), loc.status.copy()
        filler = LimbFiller("left_arm", options=FillOptions(swivel=True, segment_carry=True, limb_memory=True,
                                                               body_model=on))
        for f in range(len(pos)):
            filler.fill(pos[f], frames[f], status[f])
        assert (status[start:, INDEX["elbow_l"]] == Status.ESTIMATED).all()
        elbow = pos[start:, INDEX["elbow_l"]]
        mean[on] = np.linalg.norm(elbow - truth[start:, INDEX["elbow_l"]], axis=1).mean()
        upper[on] = np.linalg.norm(elbow - pos[start:, INDEX["shoulder_l"]], axis=1)
    assert mean[True] < 0.031 and mean[True] < 0.87 * mean[False], {k: round(v * 1000, 1) for k, v in mean.items()}
    assert np.ptp(upper[True]) < 1e-6  # the learned upper arm, every frame


# -- the end model: a limb lost from its first joint down --------------------------------------------------------
def arm_lost_body(rng, left_arm_seen=True):
    """A random skeleton as body() has it, both wrists placed from their shoulder by the same linear rule (the
    right one mirrored); with the left arm not seen, its elbow, wrist and hand are all missing."""
    pos, frames, status, _ = body(rng)
    for side, sign in (("l", np.ones(3)), ("r", MIRROR)):
        shoulder = pos[INDEX[f"shoulder_{side}"]]
        head = (pos[INDEX["head"]] - shoulder) * sign
        pos[INDEX[f"wrist_{side}"]] = shoulder + (GAIN.T @ head + 2 * OFFSET) * sign
    truth = pos[INDEX["wrist_l"]].copy()
    if not left_arm_seen:
        for name in ("elbow_l", "wrist_l", "hand_l"):
            pos[INDEX[name]] = np.nan
            status[INDEX[name]] = Status.MISSING
    return pos, frames, status, truth


def test_the_end_model_puts_a_lost_arms_wrist_by_the_other_arms_rule_known_answer():
    """The whole left arm is never seen: the end model learns the wrist's rule from the right arm, mirrored,
    and puts the left wrist where the rule does. Nothing of either arm below the shoulder is a feature (the
    other arm's wrist would be the answer itself, mirrored), and a lone lost elbow does not ask it."""
    rng = np.random.default_rng(5)
    chain = np.array([INDEX[j] for j in ("clavicle_l", "shoulder_l", "elbow_l", "wrist_l", "hand_l")])
    other = np.array([INDEX[j] for j in ("clavicle_r", "shoulder_r", "elbow_r", "wrist_r", "hand_r")])
    model = BodyModel(chain, other, 3, INDEX["spine3"], root=1)
    assert not {INDEX[j] for j in ("elbow_l", "wrist_l", "elbow_r", "wrist_r")} & set(model.features.tolist())
    errors = []
    for f in range(1500):
        pos, frames, status, truth = arm_lost_body(rng, left_arm_seen=False)
        model.learn(pos, frames, status)
        point, _ = model.predict(pos, frames, status, APART_S)
        if f >= 1200:
            errors.append(np.linalg.norm(point - truth))
    # exact but for the ridge's shrinkage, which fades as the poses add up (the rule's own spread is 60 mm)
    assert np.mean(errors) < 0.002 and np.max(errors) < 0.006, (np.mean(errors), np.max(errors))
    pos, frames, status, _ = body(rng, left_elbow_seen=False)  # the elbow alone: the middle joint's model's case
    assert np.isnan(model.predict(pos, frames, status, APART_S)[0]).all()


def walk2_left_arm_lost():
    """walk2 of the 28-marker set, the left arm's markers (elbow, both wrist styloids, hand) hidden 1 s in every
    2 s from 1 s: (the reference, the localized take with them hidden, the hidden frames)."""
    rec = read_recording(data_file("13_qualisys_dance_walk_mocaptoolbox_mcdemodata.mat"), "walk2")
    prof = load_profile("dance28")
    lm, _ = HipInterpolator().fill_landmarks(prof.resolve(rec.labels).apply(rec.positions))
    truth = Localizer(prof.body).localize(lm).positions
    hidden = np.zeros(len(lm), bool)
    second = int(rec.rate_hz)
    for a in range(second, len(lm), 2 * second):
        hidden[a:a + second] = True
    lost = lm.copy()
    for name in ("L_HLE", "L_RSP", "L_USP", "L_HM2"):
        lost[hidden, LANDMARK_INDEX[name]] = np.nan
    return truth, Localizer(prof.body).localize(lost), hidden


def test_the_end_model_on_a_walkers_lost_arm():
    """walk2, the whole left arm hidden 1 s in every 2 s, the studio's options: held as it was (with the shoulder
    girdle, segment carry's), the walker's swinging wrist was 182 mm off on average, the elbow 79; put where the
    end model has it once the gap has lasted 0.2 s, the rest of the arm aiming at it, 88 and 42 mm. The wrist
    is then estimated and the hand, beyond it, held; before that the arm is held."""
    truth, loc, hidden = walk2_left_arm_lost()
    mean = {}
    for on in (False, True):
        pos, frames, status = loc.positions.copy(), loc.frames.copy(), loc.status.copy()
        filler = LimbFiller("left_arm", options=STUDIO.model_copy(update={"end_model": on}))
        for f in range(len(pos)):
            filler.fill(pos[f], frames[f], status[f], f / 60.0)
        mean[on] = {j: np.linalg.norm(pos[hidden, INDEX[j]] - truth[hidden, INDEX[j]], axis=1).mean()
                    for j in ("elbow_l", "wrist_l")}
        if on:  # once the gap has lasted END_WAIT_S (0.2 s, 12 frames)
            late = hidden & ((np.arange(len(pos)) - 60) % 120 >= 12)
            assert (status[late, INDEX["wrist_l"]] == Status.ESTIMATED).all()
            assert (status[late, INDEX["hand_l"]] == Status.HELD).all()
            early = hidden & ((np.arange(len(pos)) - 60) % 120 < 11)
            assert (status[early, INDEX["wrist_l"]] == Status.HELD).all()
    show = {on: {j: round(e * 1000, 1) for j, e in m.items()} for on, m in mean.items()}
    assert mean[True]["wrist_l"] < 0.5 * mean[False]["wrist_l"], show
    assert mean[True]["elbow_l"] < 0.6 * mean[False]["elbow_l"], show


def test_a_leg_whose_hinge_drops_out_is_held_not_handed_to_the_end_model():
    """The Vicon take, right knee and ankle hidden from 1 s (rebuilt, with the shank's wand, by the leg hinge).
    In the hip-height kick every foot marker is lost too, and for 4 frames (1011-1014) the hinge has nothing
    to put the leg by: the whole leg is missing there. It was last put by the hinge, not by its markers, so
    the end model leaves it held: handed to the model and back, 25 frames came out 100-150 mm worse."""
    rec = read_recording(data_file("12_vicon_freeform_realgaps_nimble_nick_freeform_001.c3d"))
    prof = load_profile("vicon53")
    pipe = SkeletonPipeline(prof, rec.labels, fill_gaps=False)
    lm = pipe.landmark_map.apply(rec.positions)
    reference = pipe.solve_landmarks(pipe.landmarks(rec.positions)).positions
    take = GapTake(lm, reference, prof, rec.rate_hz, pipe.landmark_map.tracking(rec.positions),
                   pipe.landmark_map.tracking_of)
    runs = {on: gap_run(take, Gap(["knee_r", "ankle_r"], int(rec.rate_hz), rec.n_frames), hips=HipOptions(rebuild=True),
                        fills=STUDIO.model_copy(update={"end_model": on})) for on in (False, True)}
    np.testing.assert_allclose(runs[True].error_m, runs[False].error_m, atol=1e-9)


def test_a_nan_flood_leaves_the_end_model_working():
    """Twenty frames of a malformed source mid-take (every joint "located" at NaN, then every joint missing):
    the end model learns nothing from them, its sums stay finite, and the left arm lost afterwards is still put
    where it predicts."""
    truth, loc, hidden = walk2_left_arm_lost()
    pos, frames, status = loc.positions.copy(), loc.frames.copy(), loc.status.copy()
    flood = slice(130, 150)  # in a second that shows the arm whole
    assert not hidden[flood].any()
    pos[flood] = np.nan
    status[130:140] = Status.LOCATED
    status[140:150] = Status.MISSING
    filler = LimbFiller("left_arm", options=STUDIO.model_copy(update={"end_model": True}))
    learned = []
    for f in range(len(pos)):
        filler.fill(pos[f], frames[f], status[f], f / 60.0)
        learned.append(filler.get(EndModel).model.n[0])
    assert learned[149] == learned[129] and np.isfinite(filler.get(EndModel).model.sxx).all()
    late = hidden & (np.arange(len(pos)) > 200) & ((np.arange(len(pos)) - 60) % 120 >= 12)
    assert (status[late, INDEX["wrist_l"]] == Status.ESTIMATED).all() and np.isfinite(pos[hidden]).all()


def test_the_end_model_waits_as_long_with_qtm_stamps_as_with_exact_ones():
    """QTM stamps frames to the microsecond, so at 120 Hz the steps are 8333 and 8334 us, not 1/120 s: the end model's
    wait must end on the same frame either way (it ended a frame apart: 6.5 mm off for 30 frames of a live solve)."""
    rec = read_recording(data_file("08_cmu_135_02_karate_kata.c3d")).slice(337, 1440)
    markers = rec.positions.astype(np.float64)
    markers[900 - 337:1020 - 337] = np.nan   # the actor walks out for a second

    def solve(stamp):
        pipe = SkeletonPipeline(load_profile("cmu41"), rec.labels, options="studio", rate_hz=rec.rate_hz)
        fill = pipe.filler.fill
        pipe.filler.fill = lambda p, fr, st, t, *markers: fill(p, fr, st, stamp(t), *markers)
        return np.concatenate([c.positions for c in pipe.run(markers)])

    exact = solve(lambda t: t)
    qtm = solve(lambda t: round((337 + round(t * rec.rate_hz)) / rec.rate_hz * 1e6) / 1e6)
    assert np.nanmax(np.abs(qtm - exact)) < 1e-4

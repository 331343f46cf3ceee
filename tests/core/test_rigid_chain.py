"""The IK stage's rigid chain: every limb output with the subject's bones, on known chains and real takes."""
import numpy as np
import pytest

from mocap_core.fill_options import FillOptions
from mocap_core.fit.calibration import LiveBones, calibrate_bones
from mocap_core.fit.subject import load_subject
from mocap_core.gapfill import LimbFiller
from mocap_core.pipeline import SkeletonPipeline
from mocap_core.profiles import load_profile
from mocap_core.recordings import read_recording
from mocap_core.skeleton import INDEX, JOINTS, N_JOINTS, PARENT_INDEX, Status
from mocap_core.rigid_chain import RigidChain
from tests.conftest import data_file


def _leg_frame(knee_bend: float, stretch: float = 1.0):
    """A whole skeleton with the pelvis at the origin and a left leg bent at the knee; its shank and foot bones
    ``stretch`` times their length (a located joint off the rigid leg)."""
    pos, frames = np.full((N_JOINTS, 3), np.nan), np.full((N_JOINTS, 3, 3), np.nan)
    status = np.zeros(N_JOINTS, np.uint8)
    pos[INDEX["pelvis"]], frames[INDEX["pelvis"]] = [0, 0, 1.0], np.eye(3)
    hip = np.array([0.1, 0, 0.9])
    knee = hip + 0.4 * np.array([0, np.sin(knee_bend), -np.cos(knee_bend)])
    ankle = knee + 0.4 * stretch * np.array([0, 0, -1.0])
    foot = ankle + 0.05 * stretch * np.array([0, 1.0, 0])
    toe = foot + 0.1 * np.array([0, 1.0, 0])
    points = (hip, knee, ankle, foot, toe)
    for k, (name, p) in enumerate(zip(("hip_l", "knee_l", "ankle_l", "foot_l", "toe_l"), points)):
        pos[INDEX[name]], status[INDEX[name]] = p, Status.LOCATED
        along = points[min(k + 1, 4)] - points[min(k, 3)]  # a bone frame's y along the bone it starts, x sideways
        y = along / np.linalg.norm(along)
        frames[INDEX[name]] = np.column_stack([[1.0, 0, 0], y, np.cross([1.0, 0, 0], y)])
    status[INDEX["pelvis"]] = Status.LOCATED
    return pos, frames, status


def _lengths(pos, names):
    return np.array([np.linalg.norm(pos[INDEX[n]] - pos[PARENT_INDEX[INDEX[n]]]) for n in names])


LEG = ("hip_l", "knee_l", "ankle_l", "foot_l", "toe_l")


def test_a_rigid_leg_is_output_as_it_was_placed():
    filler = LimbFiller("left_leg", options=FillOptions(rigid=True))
    for bend in np.linspace(0, 1.2, 60):  # learns the bones while every joint is located
        pos, frames, status = _leg_frame(bend)
        placed = pos.copy()
        filler.fill(pos, frames, status)
        assert np.allclose(pos[[INDEX[n] for n in LEG]], placed[[INDEX[n] for n in LEG]], atol=1e-9)


def test_a_stretched_frame_keeps_the_bones_calibrated_from_the_stream():
    filler = LimbFiller("left_leg", options=FillOptions(rigid=True))
    for bend in np.tile(np.linspace(0, 1.2, 60), 4):  # 2.4 s at 100 Hz: every bone re-taken twice
        filler.fill(*_leg_frame(bend))
    pos, frames, status = _leg_frame(0.6, stretch=1.3)  # ankle and foot 30 % too far, as one bad frame
    filler.fill(pos, frames, status)
    assert np.allclose(_lengths(pos, LEG[1:]), [0.4, 0.4, 0.05, 0.1], atol=1e-9)  # (medians: the bad frame is out)
    # the bone frames point along the bones they start
    for a, b in zip(LEG[1:3], LEG[2:4]):
        bone = pos[INDEX[b]] - pos[INDEX[a]]
        assert np.allclose(frames[INDEX[a]][:, 1], bone / np.linalg.norm(bone), atol=1e-9)
    # the located toe pulls the foot towards it: the chain's end lands between the rigid guesses
    assert np.linalg.norm(pos[INDEX["toe_l"]] - _leg_frame(0.6, stretch=1.3)[0][INDEX["toe_l"]]) < 0.1


def test_a_subject_sets_the_bones_from_the_first_frame():
    pos, frames, status = _leg_frame(0.3)
    subject_pos = np.stack([_leg_frame(0.3, stretch=1.1)[0]] * 40)
    subject_frames = np.tile(np.eye(3), (40, N_JOINTS, 1, 1))
    subject = calibrate_bones(subject_pos, subject_frames, "test")
    filler = LimbFiller("left_leg", options=FillOptions(rigid=True))
    filler.use(subject)
    filler.fill(pos, frames, status)
    assert np.allclose(_lengths(pos, LEG[1:]), [0.4, 0.44, 0.055, 0.1], atol=1e-6)


def _worst_case(rec, prof, start):
    """The thesis's worst case: from ``start`` only the pelvis, head, hand and toe markers."""
    kept = {m for lm in ("SACR", "L_IAS", "R_IAS", "L_IPS", "R_IPS", "SGL", "L_HEAD", "R_HEAD", "L_HM2", "R_HM2",
                         "L_FM2", "R_FM2") if lm in prof.landmarks for m in prof.markers_of(lm)}
    markers = rec.positions.astype(np.float64)
    for i, label in enumerate(prof.columns(rec.labels)):
        if label not in kept:
            markers[start:, i] = np.nan
    return markers


def test_the_torso_and_limbs_are_rigid_in_the_worst_case_of_a_real_take():
    """The thesis's worst case on a real take (only the pelvis, head, hand and toe markers from 1 s): every bone at
    one length in every frame, and no joint the complete take locates left missing."""
    rec = read_recording(data_file("02_qualisys_walking_ezc3d_Qualisys.c3d"))
    prof = load_profile("qualisys_sports")
    markers = _worst_case(rec, prof, int(rec.rate_hz))
    pipe = SkeletonPipeline(prof, rec.labels, options="studio", rate_hz=rec.rate_hz)
    chunks = list(pipe.run(markers))
    pos = np.concatenate([c.positions for c in chunks])
    status = np.concatenate([c.status for c in chunks])
    lengths = np.linalg.norm(pos[:, 1:] - pos[:, PARENT_INDEX[1:]], axis=-1)
    typical = np.nanmedian(lengths, axis=0)
    bones = typical > 0.01
    assert np.isfinite(lengths[:, bones]).all()
    assert np.abs(lengths[:, bones] / typical[bones] - 1).max() < 0.01
    complete = SkeletonPipeline(prof, rec.labels, fill_gaps=False)
    located = np.concatenate([c.status for c in complete.run(rec.positions)]) == Status.LOCATED
    ever = located.any(axis=0)
    assert (status[:, ever] != Status.MISSING).all(), [JOINTS[j] for j in np.flatnonzero(ever)
                                                       if (status[:, j] == Status.MISSING).any()]


def test_a_subject_round_trip_gives_the_same_solve(tmp_path):
    rec = read_recording(data_file("02_qualisys_walking_ezc3d_Qualisys.c3d"))
    prof = load_profile("qualisys_sports")
    pipe = SkeletonPipeline(prof, rec.labels, options="studio", rate_hz=rec.rate_hz)
    subject = pipe.calibrate(rec.positions)
    subject.labels, subject.marker_bone = ["SACR"], np.array([-1])  # a file names one label at least
    subject.marker_offsets, subject.spread_m = np.zeros((1, 3)), np.full(1, np.nan)
    subject.save(tmp_path / "actor.yaml")
    again = load_subject(tmp_path / "actor.yaml")
    assert np.allclose(again.lengths(), subject.lengths(), atol=1e-5)
    first = np.concatenate([c.positions for c in pipe.run(rec.positions)])
    second = SkeletonPipeline(prof, rec.labels, options="studio", rate_hz=rec.rate_hz)
    second.use(again)
    out = np.concatenate([c.positions for c in second.run(rec.positions)])
    assert np.nanmax(np.abs(out - first)) < 1e-3  # the file keeps offsets to 0.01 mm
    lengths = np.linalg.norm(out[:, 1:] - out[:, PARENT_INDEX[1:]], axis=-1)
    known = again.known[1:] & (again.lengths()[1:] > 0.01)
    assert np.allclose(np.nanmedian(lengths, axis=0)[known], again.lengths()[1:][known], atol=1e-4)


@pytest.mark.parametrize("limb", ["torso", "left_arm", "left_leg"])
def test_the_rigid_chain_is_a_registered_fill(limb):
    filler = LimbFiller(limb, options=FillOptions(rigid=True))
    assert isinstance(filler.rigid, RigidChain)
    assert LimbFiller(limb).rigid is None


def test_live_bones_keep_frames_spread_over_the_whole_stream():
    """Past its capacity the buffer lets every other frame go: what is kept stays evenly spread from the first frame
    to the last, so the medians are the whole stream's, not its beginning's."""
    live = LiveBones(np.array([INDEX["knee_l"]]), most=10)
    for bend in np.linspace(0, 1.0, 80):  # the knee's place in the hip's frame (held still) turns with the bend
        pos, frames, status = _leg_frame(bend)
        frames[INDEX["hip_l"]] = np.eye(3)
        live.add((pos, frames, status))
    kept = live.local[:live.kept, 0]
    assert live.stride == 8 and live.kept == 10
    seen = np.array([_leg_frame(b)[0][INDEX["knee_l"]] - [0.1, 0, 0.9] for b in np.linspace(0, 1.0, 80)])
    assert np.allclose(kept, seen[::8])


def test_a_stream_calibrates_the_bones_a_take_calibrates():
    """Live (the graph's nodes, mocap solve with calibrate false): after 20 s of a real take every bone is within 2 %
    of the bones calibrated from the complete take, and no frame lost a joint while it calibrated."""
    rec = read_recording(data_file("13_qualisys_dance_walk_mocaptoolbox_mcdemodata.mat"), "dance1")
    prof = load_profile("dance28")
    pipe = SkeletonPipeline(prof, rec.labels, options="studio", rate_hz=rec.rate_hz)
    take = pipe.calibrate(rec.positions)
    first = rec.positions[:int(20 * rec.rate_hz)]
    status = np.concatenate([c.status for c in pipe.run(first, calibrate=False)])
    located = np.concatenate([c.status for c in SkeletonPipeline(prof, rec.labels, fill_gaps=False).run(first)])
    assert not ((located == Status.LOCATED) & (status == Status.MISSING)).any()
    for limb in pipe.filler.limbs.values():
        for j, offset in zip(limb.joints, limb.rigid.offsets):
            if take.known[j] and take.lengths()[j] > 0.01:
                length = np.linalg.norm(offset)
                assert abs(length / take.lengths()[j] - 1) < 0.02, (JOINTS[j], length, take.lengths()[j])


@pytest.mark.parametrize("take,variant", [(t, v) for t in ("vicon", "karate", "walk1") for v in ("no_tracking",
                                                                                                   "no_hands")])
def test_a_stripped_marker_set_keeps_every_joint_and_every_bone(take, variant):
    """A profile without its ``tracking:`` list, or a take without its hand markers: every joint the localization
    locates in some frame is output in every frame (the subject places what nothing else did), every bone rigid."""
    files = {"vicon": ("12_vicon_freeform_realgaps_nimble_nick_freeform_001.c3d", None, "vicon53"),
             "karate": ("08_cmu_135_02_karate_kata.c3d", None, "cmu41"),
             "walk1": ("13_qualisys_dance_walk_mocaptoolbox_mcdemodata.mat", "walk1", "dance28")}
    file, name, profile = files[take]
    rec = read_recording(data_file(file), name)
    rec = rec.slice(0, min(rec.n_frames, int(10 * rec.rate_hz)))
    prof = load_profile(profile)
    markers = rec.positions.copy()
    if variant == "no_tracking":
        prof = prof.model_copy(update={"tracking": {}})
    else:
        col = list(prof.columns(rec.labels))
        hands = [col.index(x) for lm in prof.landmarks if "_HM" in lm for x in prof.markers_of(lm) if x in col]
        assert hands
        markers[:, hands] = np.nan
    chunks = list(SkeletonPipeline(prof, rec.labels, rate_hz=rec.rate_hz).run(markers))
    pos, status = np.concatenate([c.positions for c in chunks]), np.concatenate([c.status for c in chunks])
    located = np.concatenate([c.status for c in SkeletonPipeline(prof, rec.labels, fill_gaps=False).run(markers)])
    ever = (located == Status.LOCATED).any(axis=0)
    assert (status[:, ever] != Status.MISSING).all(), [JOINTS[j] for j in np.flatnonzero(ever)
                                                       if (status[:, j] == Status.MISSING).any()]
    lengths = np.linalg.norm(pos[:, 1:] - pos[:, PARENT_INDEX[1:]], axis=-1)[:, ever[1:]]
    typical = np.median(lengths, axis=0)
    assert np.abs(lengths - typical).max() < 1e-6


def test_one_marker_a_wrist_and_no_head_markers_still_give_every_bone_turned():
    """A set with one marker at each wrist and none on the head (many running sets): the wrists stand at their marker,
    the forearms roll with the elbows' axes, the head follows the neck (the thesis's default skeleton, scaled); every
    joint in every frame with a finite bone frame."""
    rec = read_recording(data_file("12_vicon_freeform_realgaps_nimble_nick_freeform_001.c3d"))
    rec = rec.slice(0, int(5 * rec.rate_hz))
    shipped = load_profile("vicon53")
    landmarks = {k: v for k, v in shipped.landmarks.items() if not (k.endswith("_USP") or "HEAD" in k or k == "SGL")}
    prof = type(shipped).model_validate({**shipped.model_dump(), "landmarks": landmarks})
    assert prof.landmarks["L_USP"] == prof.landmarks["L_RSP"]  # the styloid the set lacks stands at the other
    chunks = list(SkeletonPipeline(prof, rec.labels, rate_hz=rec.rate_hz).run(rec.positions))
    pos, frames = np.concatenate([c.positions for c in chunks]), np.concatenate([c.frames for c in chunks])
    status = np.concatenate([c.status for c in chunks])
    assert (status != Status.MISSING).all(), [JOINTS[j] for j in range(N_JOINTS) if (status[:, j] == 0).any()]
    assert np.isfinite(pos).all() and np.isfinite(frames).all()
    head = np.linalg.norm(pos[:, INDEX["head"]] - pos[:, INDEX["neck"]], axis=-1)
    assert 0.1 < head.min() and head.max() < 0.2
    assert (status[:, INDEX["wrist_l"]] == Status.LOCATED).mean() > 0.9


def test_a_subject_with_markers_fits_each_limb_to_the_markers_riding_it():
    """With a subject that places markers on its bones (``mocap calibrate``), each limb is the subject's chain fitted
    to the markers riding it: in the thesis's worst case the hand and toe markers turn the arms and legs, and the
    hidden elbows and knees come far closer to the complete take's solve than with the subject's bones alone;
    every bone at its length."""
    from dataclasses import replace

    from mocap_core.fit.calibration import calibrate

    rec = read_recording(data_file("02_qualisys_walking_ezc3d_Qualisys.c3d"))
    prof = load_profile("qualisys_sports")
    subject = calibrate(rec.positions, rec.labels, prof, rec.rate_hz)
    bones_only = replace(subject, labels=[], marker_bone=np.zeros(0, np.int64), marker_offsets=np.zeros((0, 3)),
                         spread_m=np.zeros(0))
    start = int(rec.rate_hz)
    hidden = _worst_case(rec, prof, start)
    measured = [INDEX[j] for j in ("elbow_l", "elbow_r", "knee_l", "knee_r")]
    errors = {}
    for name, s in (("markers", subject), ("bones", bones_only)):
        solved = []
        for markers in (rec.positions.astype(np.float64), hidden):
            pipe = SkeletonPipeline(prof, rec.labels, rate_hz=rec.rate_hz)
            pipe.use(s)
            solved.append(np.concatenate([c.positions for c in pipe.run(markers)]))
        complete, worst = solved
        errors[name] = np.linalg.norm(worst[start:, measured] - complete[start:, measured], axis=-1).mean()
        lengths = np.linalg.norm(worst[:, 1:] - worst[:, PARENT_INDEX[1:]], axis=-1)
        known = subject.known[1:] & (subject.lengths()[1:] > 0.01)
        assert np.abs(lengths[:, known] / subject.lengths()[1:][known] - 1).max() < 1e-6
    assert errors["markers"] < 0.6 * errors["bones"], errors

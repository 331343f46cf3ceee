"""The IK stage's rigid chain: every limb output with the subject's bones, on known chains and real takes."""
import numpy as np
import pytest

from mocap_core.fill_options import FillOptions
from mocap_core.fit.calibration import calibrate_bones
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
    for name, p in zip(("hip_l", "knee_l", "ankle_l", "foot_l", "toe_l"), (hip, knee, ankle, foot, toe)):
        pos[INDEX[name]], status[INDEX[name]] = p, Status.LOCATED
        frames[INDEX[name]] = np.eye(3)
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


def test_a_stretched_frame_keeps_the_learned_bones():
    filler = LimbFiller("left_leg", options=FillOptions(rigid=True))
    for bend in np.linspace(0, 1.2, 60):
        filler.fill(*_leg_frame(bend))
    pos, frames, status = _leg_frame(0.6, stretch=1.3)  # ankle and foot 30 % too far, as one bad frame
    filler.fill(pos, frames, status)
    learned = filler.lengths[:-1, 0] / filler.lengths[:-1, 1]  # (this frame's counted in: 0.4 x 60 + 0.52, / 61)
    assert np.allclose(_lengths(pos, LEG[1:]), learned, atol=1e-9)
    assert np.allclose(learned, [0.4, 0.4 + 0.12 / 61, 0.05 + 0.015 / 61, 0.1])
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


def test_the_torso_and_limbs_are_rigid_in_the_worst_case_of_a_real_take():
    """The thesis's worst case on a real take (only the pelvis, head, hand and toe markers from 1 s): every bone at
    one length in every frame, and no joint the complete take locates left missing."""
    rec = read_recording(data_file("02_qualisys_walking_ezc3d_Qualisys.c3d"))
    prof = load_profile("qualisys_sports")
    kept = {m for lm in ("SACR", "L_IAS", "R_IAS", "L_IPS", "R_IPS", "SGL", "L_HEAD", "R_HEAD", "L_HM2", "R_HM2",
                         "L_FM2", "R_FM2") if lm in prof.landmarks for m in prof.markers_of(lm)}
    markers = rec.positions.copy()
    start = int(rec.rate_hz)
    for i, label in enumerate(prof.columns(rec.labels)):
        if label not in kept:
            markers[start:, i] = np.nan
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

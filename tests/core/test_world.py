"""The world's up axis (mocap_core/world.py) and the profile the labels fit (profiles.detect_profile)."""
import numpy as np
import pytest

from mocap_core.profiles import ProfileError, detect_profile, profile_for
from mocap_core.recordings import read_recording
from mocap_core.world import UP_AXES, normalize_up, to_canonical
from tests.conftest import data_file


@pytest.mark.parametrize("up", UP_AXES)
def test_to_canonical_turns_the_up_axis_to_plus_y_by_a_proper_rotation(up):
    a = to_canonical(up)
    np.testing.assert_allclose(a @ a.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(a) == pytest.approx(1.0)
    v = np.zeros(3)
    v["xyz".index(up[1])] = 1.0 if up[0] == "+" else -1.0
    np.testing.assert_allclose(a @ v, [0, 1, 0], atol=1e-12)


def test_up_axis_spellings():
    assert normalize_up("Z") == "+z" and normalize_up("+Y") == "+y" and normalize_up("-x") == "-x"
    with pytest.raises(ValueError, match="expected one of"):
        normalize_up("up")


@pytest.mark.parametrize("take, profile, up", [
    ("02_qualisys_walking_ezc3d_Qualisys.c3d", "qualisys_sports", "+z"),
    ("03_sprint_start_BTK_SprintMotion.trc", "btk_sprint", "+z"),
    ("08_cmu_135_02_karate_kata.c3d", "cmu41", "+z"),
    ("12_vicon_freeform_realgaps_nimble_nick_freeform_001.c3d", "vicon53", "+y"),
    ("13_qualisys_dance_walk_mocaptoolbox_mcdemodata.mat", "dance28", "+z"),
])
def test_the_shipped_profile_is_found_from_the_labels(take, profile, up):
    p = detect_profile(read_recording(data_file(take)).labels)
    assert p is not None and p.name == profile and p.up_axis == up


def test_no_fitting_profile_says_what_to_do():
    with pytest.raises(ProfileError, match="no shipped profile fits these labels .*Your own marker set"):
        profile_for("auto", ["A", "B", "C"])

"""`mocap eval options`: each studio option left out in turn."""
import pytest

from mocap_core.fill_options import FillOptions
from mocap_core.leave_one_out import LEFT_OUT, cases, score, without
from mocap_core.presets import PRESETS
from mocap_core.profiles import load_profile
from mocap_core.recordings import read_recording
from tests.conftest import data_file


def test_each_option_left_out_alone_and_the_swivel_with_what_steers_it():
    studio = PRESETS["studio"]
    for option, (stage, value) in LEFT_OUT.items():
        got = without(option)
        assert getattr(getattr(got, stage), option) == value
        other = "ik" if stage == "hips" else "hips"
        assert getattr(got, other) == getattr(studio, other)
    assert without("swivel").ik == studio.ik.model_copy(update={"swivel": False, "limb_memory": False,
                                                               "body_model": False})
    with pytest.raises(ValueError, match="steers the swivel"):
        FillOptions(limb_memory=True)


def test_the_end_model_carries_a_lost_arm_and_the_pose_memory_lost_knees_on_the_walk():
    rec = read_recording(data_file("02_qualisys_walking_ezc3d_Qualisys.c3d"))
    rec = rec.slice(0, int(6 * rec.rate_hz))
    profile = load_profile("qualisys_sports")
    names = [c.name for c in cases(profile, rec)]
    assert names == ["worst", "elbow_l", "short_elbow_l", "arm_l", "elbow_r", "short_elbow_r", "arm_r",
                     "knee_ankle_l", "knee_ankle_r", "pelvis"]
    got = score(rec, profile, ["studio", "end_model", "when_lost"])
    # an arm lost 1 s in every 2 s, held as it was without the end model; the pelvis held still without its fit
    assert got["end_model"]["arm_l"] > got["studio"]["arm_l"] + 20, got
    assert got["when_lost"]["pelvis"] > got["studio"]["pelvis"] + 100, got
    assert got["studio"]["pelvis"] < 40, got

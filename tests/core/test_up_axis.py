"""The up axis from a take's own frames: wherever a take is turned, its feet's floor and its head say which way is up."""
import logging

import numpy as np
import pytest

from mocap_core.profiles import load_profile
from mocap_core.recordings import read_recording
from mocap_core.up_axis import take_up_axis, up_from_landmarks
from mocap_core.world import UP_AXES, to_canonical
from tests.conftest import data_file

TAKES = [("03_sprint_start_BTK_SprintMotion.trc", "btk_sprint", "+z"),   # a crouched start: the head leans forward
         ("08_cmu_135_02_karate_kata.c3d", "cmu41", "+z"),
         ("12_vicon_freeform_realgaps_nimble_nick_freeform_001.c3d", "vicon53", "+y")]


@pytest.mark.parametrize("file,profile,up", TAKES)
def test_every_turn_of_a_take_is_found_upright(file, profile, up):
    rec, prof = read_recording(data_file(file)), load_profile(profile)
    lm = prof.resolve(rec.labels).apply(rec.positions)
    assert up_from_landmarks(lm) == up
    canonical = lm @ to_canonical(up).T  # (+y up)
    for target in UP_AXES:
        turned = canonical @ to_canonical(target)  # (target up)
        assert up_from_landmarks(turned) == target, target


def test_a_profile_that_says_the_wrong_axis_is_overruled_and_said(caplog):
    rec = read_recording(data_file("08_cmu_135_02_karate_kata.c3d"))
    turned = rec.positions @ to_canonical("+z").T  # now +y up, and the file does not say so
    rec = type(rec)(rec.labels, turned.astype(np.float32), rec.rate_hz, rec.source, rec.first_frame, {})
    with caplog.at_level("WARNING", logger="test.up"):
        assert take_up_axis(rec, load_profile("cmu41"), logging.getLogger("test.up")) == "+y"
    assert "says +z is up" in caplog.text
    rec.meta["up_axis"] = "+z"  # a file that says it: kept, and the disagreement said
    caplog.clear()
    with caplog.at_level("WARNING", logger="test.up"):
        assert take_up_axis(rec, load_profile("cmu41"), logging.getLogger("test.up")) == "+z"
    assert "along +y" in caplog.text


@pytest.mark.parametrize("stated,said", [("+z", True), ("+y", False), ("", False)])
def test_a_live_stream_that_states_the_wrong_axis_is_said_once(stated, said):
    from mocap_core.up_axis import StreamUpCheck

    rec, prof = read_recording(data_file(TAKES[2][0])), load_profile("vicon53")  # +y up
    lm = prof.resolve(rec.labels).apply(rec.positions)
    check = StreamUpCheck()
    sentences = [s for f in range(rec.n_frames) if (s := check.add(lm[f], stated, f / rec.rate_hz))]
    assert len(sentences) == (1 if said else 0), sentences
    if said:
        assert "says +z is up" in sentences[0] and "along +y" in sentences[0] and "up_axis" in sentences[0]

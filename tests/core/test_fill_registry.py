"""A fill is a class, its test and a registry line: the README's example, registered, is an option, a flag and a
fill that runs."""
import argparse
import re
from pathlib import Path

import numpy as np
import pytest

from mocap_cli.option_flags import add_option_flags, options_of
from mocap_core.fill_options import FillOptions, HipOptions, hip_options, limb_options
from mocap_core.fill_units import LandmarkFill, MarkerSet, switch
from mocap_core.fills import LANDMARK_FILLS, LIMB_FILLS
from mocap_core.gapfill import LimbFiller
from mocap_core.landmark_fills import LandmarkFills
from mocap_core.profiles import LANDMARK_INDEX, LANDMARKS
from mocap_core.skeleton import ESTIMATED, HELD, INDEX, LOCATED, MISSING, N_JOINTS

README = (Path(__file__).resolve().parents[2] / "README.md").read_text()


def readme_fill():
    """The fill the README shows, as it is written there."""
    code = next(block for block in re.findall(r"```python\n(.*?)```", README, re.S) if "(LimbFill)" in block)
    scope = {"LimbFill": __import__("mocap_core.fill_units", fromlist=["LimbFill"]).LimbFill, "switch": switch,
             "MISSING": MISSING, "HELD": HELD}
    exec(code, scope)
    return scope["HoldLast"]


def arm_frames(elbow_lost_from: int, frames: int = 5):
    """The left arm whole, then its elbow lost; the rest of the body located."""
    out = []
    for f in range(frames):
        pos = np.zeros((N_JOINTS, 3)) + np.arange(N_JOINTS)[:, None] * [0.0, 0.0, 0.05]
        pos[[INDEX[j] for j in ("clavicle_l", "shoulder_l", "elbow_l", "wrist_l", "hand_l")]] = \
            [[0.1, 0, 1.4], [0.2, 0, 1.4], [0.2, 0.05, 1.1], [0.2, 0.2, 0.9], [0.2, 0.25, 0.85]]
        status = np.full(N_JOINTS, LOCATED, np.uint8)
        if f >= elbow_lost_from:
            pos[INDEX["elbow_l"]], status[INDEX["elbow_l"]] = np.nan, MISSING
        out.append((pos, np.tile(np.eye(3), (N_JOINTS, 1, 1)), status))
    return out


def test_the_readme_fill_registered_is_an_option_and_a_flag_and_runs_in_its_place():
    options_model = limb_options((*LIMB_FILLS, readme_fill()))
    assert "hold_last" in options_model.model_fields and "hold_last" not in FillOptions.model_fields
    parser = argparse.ArgumentParser()
    add_option_flags(parser, options_model)
    options = options_of(options_model, parser.parse_args(["--hold-last"]))
    assert options.hold_last and not options.swivel
    held, plain = LimbFiller("left_arm", options=options), LimbFiller("left_arm")
    for (pos, frames, status), (pos2, frames2, status2) in zip(arm_frames(3), arm_frames(3)):
        before = pos[INDEX["elbow_l"]].copy()
        held.fill(pos, frames, status)
        plain.fill(pos2, frames2, status2)
    np.testing.assert_array_equal(pos[INDEX["elbow_l"]], [0.2, 0.05, 1.1])  # where the last whole output had it
    assert status[INDEX["elbow_l"]] == HELD and np.isnan(before).all()
    assert status2[INDEX["elbow_l"]] == ESTIMATED  # without it, Algorithm 1's


class DropLeftElbow(LandmarkFill):
    """A landmark fill that drops the left lateral epicondyle (for the fills after it to fill)."""
    Settings = switch("drop_elbow", "drop it")

    def fill(self, landmarks, tracking=None, time_s=np.nan, markers=None, filled=None):
        landmarks[LANDMARK_INDEX["L_HLE"]] = np.nan
        return np.zeros(len(landmarks), bool)


def test_a_landmark_fill_registered_runs_first_and_the_rebuild_fills_after_it():
    options_model = hip_options((DropLeftElbow, *LANDMARK_FILLS))
    assert list(options_model.model_fields)[:2] == ["when_lost", "drop_elbow"]
    fills = LandmarkFills(options_model(drop_elbow=True), MarkerSet(present=LANDMARKS))
    landmarks = np.ones((len(LANDMARKS), 3))
    assert not fills.fill(landmarks).any() and np.isnan(landmarks[LANDMARK_INDEX["L_HLE"]]).all()
    assert [type(f) for f in LandmarkFills(HipOptions(rebuild=True), MarkerSet()).fills][0].__name__ == \
        "SegmentRebuilder"


@pytest.mark.parametrize("options, message", [
    (dict(limb_memory=True), "limb_memory steers the swivel, which is off: set swivel true, or limb_memory false"),
    (dict(limb_memory=True, body_model=True), "limb_memory and body_model steer the swivel"),
])
def test_a_fill_that_steers_another_is_refused_without_it(options, message):
    with pytest.raises(ValueError, match=message):
        FillOptions(**options)

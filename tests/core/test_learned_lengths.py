"""Learned bone lengths: the swivel's bones as long as they were on average while located."""
import numpy as np

from mocap_core.gapfill import LimbFiller
from mocap_core.hip_interpolation import HipInterpolator
from mocap_core.localization import Localizer
from mocap_core.profiles import LANDMARK_INDEX, load_profile
from mocap_core.recordings import read_recording
from mocap_core.skeleton import INDEX, Status
from tests.conftest import data_file
from tests.core.test_limb_memory import FORE, UPPER, left_arm_pose, mirrored, skeleton

GAP = 200          # the left elbow is lost from this frame on
NOISE = 0.003      # marker noise on the located elbow, metres (SD)
LAST_OFF = 0.015   # and in the last frame before the gap it is this far out along the upper arm


def run(learned: bool):
    """Both elbows seen for GAP frames with noise, the left one's last sighting 15 mm out along its
    upper arm; then the left elbow is lost."""
    rng = np.random.default_rng(1)
    filler = LimbFiller("left_arm", swivel=True, learned_lengths=learned)
    upper, fore = [], []
    for f in range(GAP + 300):
        left = left_arm_pose(0.01 * f)
        s, e, w = left
        if f < GAP:
            e = e + rng.normal(0.0, NOISE, 3)
            if f == GAP - 1:
                e = e + LAST_OFF * (e - s) / np.linalg.norm(e - s)
        pos, frames, status = skeleton((s, e, w), mirrored(left_arm_pose(0.01 * f)), elbow_l_seen=f < GAP)
        filler.fill(pos, frames, status)
        if f >= GAP:
            assert status[INDEX["elbow_l"]] == Status.ESTIMATED
            upper.append(np.linalg.norm(pos[INDEX["elbow_l"]] - s))
            fore.append(np.linalg.norm(w - pos[INDEX["elbow_l"]]))
    return np.array(upper), np.array(fore)


def test_the_gap_keeps_the_mean_length_not_the_last_frames_known_answer():
    upper, fore = run(True)
    # the mean of 200 noisy frames (and the one 15 mm out): within 2 mm of the true bones, every frame
    assert np.abs(upper - UPPER).max() < 0.002, f"{np.abs(upper - UPPER).max() * 1000:.1f} mm"
    assert np.abs(fore - FORE).max() < 0.002
    assert np.ptp(upper) < 1e-9  # one length through the gap: the bones are rigid
    # without: the last frame's lengths, its error kept for the whole gap
    upper_last, _ = run(False)
    assert np.abs(upper_last - UPPER).min() > 0.01


def dance_left_elbow_hidden(take: str):
    """A take of the 28-marker dance set: (its joints localized whole, the reference; the same with the left
    elbow's marker hidden from 1 s to the end; that first hidden frame)."""
    rec = read_recording(data_file("13_qualisys_dance_walk_mocaptoolbox_mcdemodata.mat"), take)
    prof = load_profile("dance28")
    lm, _ = HipInterpolator().fill_landmarks(prof.resolve(rec.labels).apply(rec.positions))
    truth = Localizer(prof.body).localize(lm).positions
    start = int(rec.rate_hz)
    hidden = lm.copy()
    hidden[start:, LANDMARK_INDEX["L_HLE"]] = np.nan
    return truth, Localizer(prof.body).localize(hidden), start


def test_learned_lengths_on_a_dancers_arm():
    """walk2 of the 28-marker set, the left elbow hidden from 1 s to the end (swivel and limb memory on).
    When the arm straightens past its bones' reach, the swivel puts the elbow on the shoulder-wrist
    line, and the last frame's lengths then keep that stretch: the forearm goes from 261 to 274 mm for
    the rest of the gap. The learned ones stay as they were, and the elbow comes out nearer."""
    truth, loc, start = dance_left_elbow_hidden("walk2")
    seen_fore = np.linalg.norm(truth[:start, INDEX["wrist_l"]] - truth[:start, INDEX["elbow_l"]], axis=1).mean()
    mean, stretch = {}, {}
    for learned in (False, True):
        pos, frames, status = loc.positions.copy(), loc.frames.copy(), loc.status.copy()
        filler = LimbFiller("left_arm", swivel=True, segment_carry=True, limb_memory=True, learned_lengths=learned)
        for f in range(len(pos)):
            filler.fill(pos[f], frames[f], status[f])
        assert (status[start:, INDEX["elbow_l"]] == Status.ESTIMATED).all()
        elbow = pos[start:, INDEX["elbow_l"]]
        mean[learned] = np.linalg.norm(elbow - truth[start:, INDEX["elbow_l"]], axis=1).mean()
        fore = np.linalg.norm(pos[start:, INDEX["wrist_l"]] - elbow, axis=1)
        stretch[learned] = np.median(fore[-60:]) - seen_fore  # the gap's last second
    assert stretch[False] > 0.008 and abs(stretch[True]) < 0.003, {k: round(v * 1000, 1) for k, v in stretch.items()}
    assert mean[True] < 0.021 and mean[True] < 0.92 * mean[False], {k: round(v * 1000, 1) for k, v in mean.items()}

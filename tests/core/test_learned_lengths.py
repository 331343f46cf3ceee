"""The swivel's bones as long as they were on average while located, not as in the last frame before the gap."""
import numpy as np

from mocap_core.fill_options import FillOptions
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


def run():
    """Both elbows seen for GAP frames with noise, the left one's last sighting 15 mm out along its
    upper arm; then the left elbow is lost."""
    rng = np.random.default_rng(1)
    filler = LimbFiller("left_arm", options=FillOptions(swivel=True))
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
    upper, fore = run()
    # the mean of 200 noisy frames (and the one 15 mm out): within 2 mm of the true bones, every frame; the last
    # frame's lengths would keep its 15 mm through the gap
    assert np.abs(upper - UPPER).max() < 0.002, f"{np.abs(upper - UPPER).max() * 1000:.1f} mm"
    assert np.abs(fore - FORE).max() < 0.002
    assert np.ptp(upper) < 1e-9  # one length through the gap: the bones are rigid


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
    When the arm straightens past its bones' reach, the swivel puts the elbow on the shoulder-wrist line;
    the last frame's lengths would keep that stretch (the forearm 261 -> 274 mm for the rest of the gap),
    the learned ones stay as they were."""
    truth, loc, start = dance_left_elbow_hidden("walk2")
    seen_fore = np.linalg.norm(truth[:start, INDEX["wrist_l"]] - truth[:start, INDEX["elbow_l"]], axis=1).mean()
    pos, frames, status = loc.positions.copy(), loc.frames.copy(), loc.status.copy()
    filler = LimbFiller("left_arm", options=FillOptions(swivel=True, segment_carry=True, limb_memory=True))
    for f in range(len(pos)):
        filler.fill(pos[f], frames[f], status[f])
    assert (status[start:, INDEX["elbow_l"]] == Status.ESTIMATED).all()
    elbow = pos[start:, INDEX["elbow_l"]]
    mean = np.linalg.norm(elbow - truth[start:, INDEX["elbow_l"]], axis=1).mean()
    fore = np.linalg.norm(pos[start:, INDEX["wrist_l"]] - elbow, axis=1)
    stretch = np.median(fore[-60:]) - seen_fore  # the gap's last second
    assert abs(stretch) < 0.003, f"{stretch * 1000:.1f} mm"
    assert mean < 0.021, f"{mean * 1000:.1f} mm"

"""The limb memory: a lost elbow's swivel from the limb's earlier poses and the other limb's, mirrored."""
import numpy as np

from mocap_core.fill_options import FillOptions
from mocap_core.gapfill import LimbFiller
from mocap_core.hip_interpolation import HipInterpolator
from mocap_core.limb_memory import LimbMemory
from mocap_core.localization import Localizer
from mocap_core.profiles import LANDMARK_INDEX, load_profile
from mocap_core.recordings import read_recording
from mocap_core.skeleton import INDEX, N_JOINTS, Status
from tests.conftest import data_file

UPPER, FORE = 0.28, 0.25
SLOPE = 4.0  # radians of swivel per metre the wrist goes forward


def left_arm_pose(t):
    """A left arm whose elbow swivel is a known function of where the wrist is (chest frame = world,
    x to the subject's left): shoulder, elbow, wrist."""
    shoulder = np.array([0.18, 0.0, 0.0])
    wrist = shoulder + np.array([0.12 + 0.08 * np.sin(t), 0.25 + 0.1 * np.sin(1.7 * t), -0.2 + 0.1 * np.cos(t)])
    d = wrist - shoulder
    dist = np.linalg.norm(d)
    axis = d / dist
    along = (UPPER ** 2 - FORE ** 2 + dist ** 2) / (2 * dist)
    radius = np.sqrt(UPPER ** 2 - along ** 2)
    e1 = np.array([0, 0, -1.0]) - (np.array([0, 0, -1.0]) @ axis) * axis  # "down", off the axis
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    swivel = SLOPE * (wrist[1] - 0.25)  # the further forward the wrist, the more the elbow turns out
    elbow = shoulder + along * axis + radius * (np.cos(swivel) * e1 + np.sin(swivel) * e2)
    return shoulder, elbow, wrist


def skeleton(left, right, elbow_l_seen=True):
    pos = np.zeros((N_JOINTS, 3))
    frames = np.tile(np.eye(3), (N_JOINTS, 1, 1))
    status = np.full(N_JOINTS, int(Status.LOCATED))
    pos[INDEX["spine3"]] = [0.0, 0.0, -0.05]
    for side, (s, e, w) in (("l", left), ("r", right)):
        pos[INDEX[f"clavicle_{side}"]] = [0.02 if side == "l" else -0.02, 0.0, -0.02]
        pos[INDEX[f"shoulder_{side}"]], pos[INDEX[f"elbow_{side}"]], pos[INDEX[f"wrist_{side}"]] = s, e, w
        pos[INDEX[f"hand_{side}"]] = w + (w - e) / np.linalg.norm(w - e) * 0.08
    if not elbow_l_seen:
        pos[INDEX["elbow_l"]] = np.nan
        status[INDEX["elbow_l"]] = Status.MISSING
    return pos, frames, status


def mirrored(pose):
    return tuple(p * np.array([-1.0, 1, 1]) for p in pose)


def run(memory: bool):
    """The right arm shows the motion for 3000 frames while the left elbow is lost after frame 0; the
    left wrist then goes over the same path, from another phase."""
    filler = LimbFiller("left_arm", options=FillOptions(swivel=True, limb_memory=memory))
    errors, own_poses = [], []
    for f in range(3000):
        right = mirrored(left_arm_pose(0.01 * f))
        left = left_arm_pose(0.01 * f + 2.0)
        pos, frames, status = skeleton(left, right, elbow_l_seen=f == 0)
        filler.fill(pos, frames, status)
        if f > 0:
            assert status[INDEX["elbow_l"]] == Status.ESTIMATED
            errors.append(np.linalg.norm(pos[INDEX["elbow_l"]] - left[1]))
            # on its circle: the bone lengths are kept
            assert abs(np.linalg.norm(pos[INDEX["elbow_l"]] - left[0]) - UPPER) < 1e-6
        if memory:
            own_poses.append(filler.get(LimbMemory).state[2, 0, 0])
    return np.array(errors), own_poses


def test_the_other_arms_mirrored_poses_give_the_swivel_known_answer():
    with_memory, own = run(True)
    without, _ = run(False)
    late = slice(700, None)  # once the right arm has been over the left wrist's path
    # the memory averages 20 poses along the path, so it blurs a swivel that turns this fast (4 rad/m):
    # 9 mm median, 36 mm at the 95th percentile
    assert np.median(with_memory[late]) < 0.012, f"{np.median(with_memory[late]) * 1000:.1f} mm"
    assert np.percentile(with_memory[late], 95) < 0.045
    # the carried bend direction alone cannot follow the swivel (110 mm)
    assert without[late].mean() > 5 * with_memory[late].mean()
    # the elbow was seen once, and its filled positions are never learned
    assert set(own) == {1}


def test_limb_memory_on_a_dancers_arm():
    """walk2 of the 28-marker set: nothing on the upper arm or forearm but the elbow's one marker, so the
    swivel is all there is; hidden from 1 s to the end, the right elbow comes out nearer with the memory."""
    rec = read_recording(data_file("13_qualisys_dance_walk_mocaptoolbox_mcdemodata.mat"), "walk2")
    prof = load_profile("dance28")
    lm, _ = HipInterpolator().fill_landmarks(prof.resolve(rec.labels).apply(rec.positions))
    truth = Localizer(prof.body).localize(lm).positions[:, INDEX["elbow_r"]]
    start = int(rec.rate_hz)
    hidden = lm.copy()
    hidden[start:, LANDMARK_INDEX["R_HLE"]] = np.nan
    loc = Localizer(prof.body).localize(hidden)
    mean = {}
    for memory in (False, True):
        pos, frames, status = loc.positions.copy(), loc.frames.copy(), loc.status.copy()
        filler = LimbFiller("right_arm", options=FillOptions(swivel=True, segment_carry=True,
                                                                   limb_memory=memory))
        for f in range(len(pos)):
            filler.fill(pos[f], frames[f], status[f])
        assert (status[start:, INDEX["elbow_r"]] == Status.ESTIMATED).all()
        mean[memory] = np.linalg.norm(pos[start:, INDEX["elbow_r"]] - truth[start:], axis=1).mean()
    assert mean[True] < 0.02 and mean[True] < 0.7 * mean[False], {k: round(v * 1000) for k, v in mean.items()}

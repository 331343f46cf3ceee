"""Joining limbs per frame: complete frames go at once, a late limb is held, never waited for."""
import numpy as np

from mocap_core.limb_join import LIMB_INDEX, LIMBS, FrameJoiner
from mocap_core.skeleton import N_JOINTS, Status


def torso(value=0.0):
    return (np.full((N_JOINTS, 3), value), np.tile(np.eye(3), (N_JOINTS, 1, 1)),
            np.full(N_JOINTS, Status.LOCATED, np.uint8), object())


def limb(limb_name, value):
    n = len(LIMB_INDEX[limb_name])
    return np.full((n, 3), value), np.tile(np.eye(3), (n, 1, 1)), np.full(n, Status.ESTIMATED, np.uint8)


def test_complete_frame_is_released_when_the_last_limb_arrives():
    j = FrameJoiner(max_wait_s=1.0)
    assert j.add_torso(1, 0.0, *torso()) == []
    for name in LIMBS[:-1]:
        assert j.add_limb(1, 0.0, name, *limb(name, 1.0)) == []
    out = j.add_limb(1, 0.0, LIMBS[-1], *limb(LIMBS[-1], 1.0))
    assert len(out) == 1 and out[0].frame == 1 and out[0].held_limbs == []
    assert (out[0].status[LIMB_INDEX["left_arm"]] == Status.ESTIMATED).all()


def test_late_limb_is_held_and_then_dropped():
    j = FrameJoiner(max_wait_s=0.02)
    j.add_torso(1, 0.0, *torso())
    for name in LIMBS:
        j.add_limb(1, 0.0, name, *limb(name, 1.0))
    j.add_torso(2, 0.01, *torso(0.5))
    for name in LIMBS[1:]:
        j.add_limb(2, 0.01, name, *limb(name, 2.0))
    out = j.release(0.05)  # left_arm of frame 2 never came in time
    assert [o.frame for o in out] == [2] and out[0].held_limbs == ["left_arm"]
    idx = LIMB_INDEX["left_arm"]
    assert (out[0].status[idx] == Status.HELD).all()
    np.testing.assert_allclose(out[0].positions[idx], 0.5)  # last pose moved with its root
    assert j.add_limb(2, 0.06, "left_arm", *limb("left_arm", 2.0)) == [] and j.late == 1


def test_a_newer_complete_frame_releases_older_ones_in_order():
    j = FrameJoiner(max_wait_s=10)
    j.add_torso(1, 0.0, *torso())
    j.add_torso(2, 0.0, *torso())
    for name in LIMBS:
        j.add_limb(1, 0.0, name, *limb(name, 1.0))
    out = []
    for name in LIMBS:
        out += j.add_limb(2, 0.0, name, *limb(name, 1.0))
    assert [o.frame for o in out] == [2]


def test_frame_numbers_jumping_back_start_a_new_stream():
    j = FrameJoiner(max_wait_s=1.0)
    for f in (500, 501):
        j.add_torso(f, 0.0, *torso())
        for name in LIMBS:
            j.add_limb(f, 0.0, name, *limb(name, 1.0))
    j.add_torso(3, 0.0, *torso())
    out = []
    for name in LIMBS:
        out += j.add_limb(3, 0.0, name, *limb(name, 1.0))
    assert [o.frame for o in out] == [3]


def test_limbs_that_come_before_their_torso_wait_for_it():
    """After a stall a stage may read a backlog of limbs before the torso queued beside them: the frames are
    joined when the torsos come, however long after max_wait_s; limbs whose torso was lost go once a later one comes."""
    j = FrameJoiner(max_wait_s=0.02)
    for f in (1, 2, 3):
        for name in LIMBS:
            assert j.add_limb(f, 0.001 * f, name, *limb(name, 1.0)) == []
    out = j.add_torso(2, 0.2, *torso())  # frame 1's torso never comes; frame 2's, 200 ms late
    out += j.add_torso(3, 0.2, *torso())
    assert [o.frame for o in out] == [2, 3] and all(o.held_limbs == [] for o in out) and j.late == 0


def test_limbs_lagging_many_frames_behind_lose_no_frame():
    """On a busy machine the limbs can fall 20 frames behind the torso: their frames go out held, in order, and
    the limbs' old frame numbers are late limbs, not a stream that started again."""
    j = FrameJoiner(max_wait_s=0.02)
    out = []
    for f in range(30):
        out += j.add_torso(f, f * 0.005, *torso())
    for f in range(30):
        for name in LIMBS:
            out += j.add_limb(f, 0.15 + f * 0.001, name, *limb(name, 1.0))
    out += j.release(1.0)
    assert [o.frame for o in out] == list(range(30))


def test_a_limb_stale_from_before_a_loop_does_not_silence_the_next_loop():
    """A take loops (frames 0-1099, then 0 again) while the left arm's node paused 0.15 s at the loop point: its last
    frames of the first loop arrive after the second loop began. They are dropped; every frame of the second loop
    is released once whole (none rejected as late because the stale limb's frame number was higher)."""
    rate, j, out = 120.0, FrameJoiner(max_wait_s=0.02), []

    def frame(f, t, skip=()):
        got = j.add_torso(f, t, *torso())
        for name in LIMBS:
            if name not in skip:
                got += j.add_limb(f, t, name, *limb(name, 1.0))
        return got

    for f in range(1100):
        frame(f, f / rate, skip=("left_arm",) if f >= 1082 else ())
    for f in range(1082, 1100):
        j.release(1100 / rate)
    start = 1100 / rate
    for f in range(18):  # the second loop's first 0.15 s; the paused arm's backlog comes then
        out += frame(f, start + f / rate, skip=("left_arm",))
    for f in range(1082, 1100):
        out += j.add_limb(f, start + 0.15, "left_arm", *limb("left_arm", 1.0))
    for f in range(18):
        out += j.add_limb(f, start + 0.15, "left_arm", *limb("left_arm", 1.0))
    for f in range(18, 1100):
        out += frame(f, start + f / rate)
    second = [o.frame for o in out]
    assert second[-1] == 1099 and sorted(set(second)) == second and len(second) >= 1090, (len(second), second[:20])

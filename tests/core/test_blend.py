"""The blend at both ends of a gap (mocap_core/blend.py: blend_transitions, blend_frames; LimbFiller's blend_half_life_s)."""
import math

import numpy as np
import pytest

from mocap_core import analytic_fill as af
from mocap_core import blend
from mocap_core.experiments import Gap, GapTake, gap_run, transition_moves
from mocap_core.fill_options import STUDIO as STUDIO_RIGID, FillOptions, HipOptions
from mocap_core.gapfill import LimbFiller
from mocap_core.pipeline import SkeletonPipeline
from mocap_core.profiles import load_profile
from mocap_core.recordings import read_recording
from mocap_core.skeleton import Status
from tests.conftest import data_file

# The studio's fills, measured against the localization of the complete take: without the rigid chain, which moves
# located joints onto the subject's bones (tests/core/test_rigid_chain.py).
STUDIO = STUDIO_RIGID.model_copy(update={"rigid": False})

LOCATED, ESTIMATED, HELD = int(Status.LOCATED), int(Status.ESTIMATED), int(Status.HELD)
VELOCITY = np.array([0.5, 0.0, 0.0])   # m/s, the joint's true motion: a straight line
BIAS = np.array([0.0, 0.05, 0.0])      # the estimate is 50 mm off the truth while the markers are lost
HALF_LIFE = 0.1
START = np.array([1.0, 2.0, 0.5])     # where the line starts (not the origin)


def run(rate_hz: float, lost: range, half_life: float = HALF_LIFE, step: float = 0.0, frames: int = 80,
        bias=lambda f: BIAS, velocity=VELOCITY, course: bool = True, fill=lambda f: ESTIMATED, path=None):
    """One joint moving along a line (or where ``path(frame)`` has it); in the ``lost`` frames its source is an
    estimate ``bias(frame)`` off the truth, of status ``fill(frame)``. Returns the output and the truth, per frame."""
    state = blend.BlendState.empty(1, step, half_life, course)
    out, truth = [], []
    for f in range(frames):
        state.advance_clock(f / rate_hz)
        true = START + velocity * f / rate_hz if path is None else path(f)
        status = np.array([fill(f) if f in lost else LOCATED], np.int64)
        positions = (true + (bias(f) if f in lost else 0.0)).reshape(1, 3).copy()
        state.blend(positions, status, np.array([0]))
        out.append(positions[0].copy())
        truth.append(true)
    return np.array(out), np.array(truth)


@pytest.mark.parametrize("rate_hz", [60.0, 250.0])
def test_a_lost_joint_goes_on_where_it_was_heading_then_eases_into_the_estimate_known_answer(rate_hz):
    loss = int(0.1 * rate_hz)
    out, truth = run(rate_hz, range(loss, 10_000), frames=int(1.3 * rate_hz))
    error = out - truth
    # the first lost frame is where the straight line led: the truth itself
    np.testing.assert_allclose(out[loss], truth[loss], atol=1e-12)
    # the offset from the estimate dies out as a critically damped spring, o0 (1 + w t) e^(-w t), halved
    # after the half-life whatever the frame rate; and the output leaves the markers' course (here the
    # line itself) for that by the weight c^2 / (c^2 + s^2): the line never bent (the acceleration's floor),
    # and no markers came back yet to tell how far the estimate misses (the prior)
    omega = blend.BLEND_X / HALF_LIFE
    for f in range(loss, len(out)):
        t = (f - loss) / rate_hz
        stray = blend.COURSE_K * 0.5 * blend.ACCEL_FLOOR * t * t
        weight = stray ** 2 / (stray ** 2 + blend.FILL_SD_PRIOR ** 2)
        expected = BIAS * (1 - (1 + omega * t) * math.exp(-omega * t)) * (1.0 if weight >= blend.EASED else weight)
        np.testing.assert_allclose(error[f], expected, atol=1e-12)
    half = loss + int(round(HALF_LIFE * rate_hz))
    assert error[half, 1] < BIAS[1] / 2  # on its course for longer than the spring alone would be
    assert weight >= blend.EASED  # and then on the estimate, with the spring alone
    # nothing twitches: the output's per-frame move exceeds the line's by at most 1.5x what the spring
    # alone adds at its fastest (the weight rises as t^4 while the spring's offset grows)
    extra = np.linalg.norm(np.diff(out, axis=0) - np.diff(truth, axis=0), axis=1)
    assert extra.max() < 1.5 * BIAS[1] * omega / math.e / rate_hz


@pytest.mark.parametrize("rate_hz", [60.0, 250.0])
def test_without_the_course_the_spring_alone_eases_into_the_estimate_known_answer(rate_hz):
    """blend_course false: the offset from the estimate dies out as a critically damped
    spring, o0 (1 + w t) e^(-w t), halved after the half-life whatever the frame rate."""
    loss = int(0.1 * rate_hz)
    out, truth = run(rate_hz, range(loss, 10_000), course=False)
    error = out - truth
    omega = blend.BLEND_X / HALF_LIFE
    for f in range(loss, len(out)):
        t = (f - loss) / rate_hz
        np.testing.assert_allclose(error[f], BIAS * (1 - (1 + omega * t) * math.exp(-omega * t)), atol=1e-12)
    half = loss + int(round(HALF_LIFE * rate_hz))
    assert abs(error[half, 1] - BIAS[1] / 2) < 0.002 * rate_hz / 60
    extra = np.linalg.norm(np.diff(out, axis=0) - np.diff(truth, axis=0), axis=1)
    assert extra.max() < BIAS[1] * omega / math.e / rate_hz + 1e-9


def test_returning_markers_are_met_without_a_step_known_answer():
    rate_hz, loss, back = 100.0, 10, 40
    out, truth = run(rate_hz, range(loss, back), frames=120)
    # the frame the markers come back, the output goes on with its own last step: it was still leaving the
    # markers' course for the estimate (both along the line here), so that step is the line's and a bit of
    # the estimate's bias
    np.testing.assert_allclose(out[back] - out[back - 1], out[back - 1] - out[back - 2], atol=1e-12)
    assert 0 < np.linalg.norm(out[back] - out[back - 1] - VELOCITY / rate_hz) < 1e-3  # (the line: 5 mm a frame)
    # then eases into them, and the offset is half gone after the half-life
    gap_at_return = np.linalg.norm(out[back] - truth[back])
    assert gap_at_return > 0.01
    half = back + int(HALF_LIFE * rate_hz)
    assert np.linalg.norm(out[half] - truth[half]) == pytest.approx(gap_at_return / 2, rel=0.05)
    assert np.linalg.norm(out[-1] - truth[-1]) < 1e-4  # (after 8 half-lives)


@pytest.mark.parametrize("lost_for", [1, 2, 4])
def test_markers_back_after_a_flicker_are_met_at_their_own_step_across_it_known_answer(lost_for):
    """A swing that stops short while its markers are lost for a frame or two (the Vicon take's left wrist at
    frame 172: 41 mm a frame, then 24): where they were seen a few frames before (FLICKER_FRAMES), their step
    across the gap is known, and the output goes on at that, not at its own step along the course, which ran on
    at the swing's pace. Its offset is then what the course overshot, eased out from rest."""
    rate_hz, loss = 120.0, 20
    back = loss + lost_for
    fast, slow = np.array([0.04, 0.0, 0.0]), np.array([0.01, 0.0, 0.0])  # metres a frame
    path = lambda f: START + fast * min(f, loss - 1) + slow * max(f - loss + 1, 0)  # noqa: E731
    exact = lambda f: np.zeros(3)  # noqa: E731  (the fill is right: the markers' course is what misses)
    out, truth = run(rate_hz, range(loss, back), bias=exact, path=path, frames=back + 60)
    across = (truth[back] - truth[loss - 1]) / (lost_for + 1)
    np.testing.assert_allclose(out[back] - out[back - 1], across, atol=1e-12)
    error = np.linalg.norm(out - truth, axis=1)
    assert error[back] == pytest.approx(error[back - 1], abs=1e-12)  # (no further off than where they came back)
    assert error[back:].max() == pytest.approx(error[back], abs=1e-12)
    # going on at the output's own step (as after a longer gap) would have put it over 20 mm further off
    own_step = out[back - 1] + (out[back - 1] - out[back - 2]) - truth[back]
    assert np.linalg.norm(own_step) > error[back] + 0.02
    assert error[-1] < 1e-3


@pytest.mark.parametrize("speed", [0.5, 3.0])  # m/s: 5 and 30 mm a frame at 100 Hz
def test_a_step_caps_how_fast_the_offset_closes_or_half_the_joints_own_step(speed):
    """reacquire_step_m caps the blend's own move a frame; a joint moving faster than four times that may be met
    or left at a quarter of its own step (PACE_SHARE), so a fast one does not fall behind its fill."""
    rate_hz, step = 100.0, 0.002
    velocity = np.array([speed, 0.0, 0.0])
    cap = max(step, blend.PACE_SHARE * speed / rate_hz)
    # far enough for the cap to bind, near enough for it to close the offset within MEET_S
    bias = lambda f: np.array([0.0, 0.9 * cap * blend.MEET_S * rate_hz, 0.0])  # noqa: E731
    out, truth = run(rate_hz, range(10, 10_000), step=step, velocity=velocity, bias=bias, frames=200)
    extra = np.linalg.norm(np.diff(out, axis=0) - np.diff(truth, axis=0), axis=1)
    assert extra.max() <= cap + 1e-12
    assert extra.max() > 0.99 * cap  # (the cap binds)
    spring, _ = run(rate_hz, range(10, 10_000), velocity=velocity, bias=bias, frames=200)
    uncapped = np.linalg.norm(np.diff(spring, axis=0) - np.diff(truth, axis=0), axis=1)
    assert uncapped.max() > 1.5 * cap  # (the spring alone moves faster than the cap)


def test_an_offset_the_step_cap_could_not_close_in_time_is_left_to_the_spring():
    """A source far off where it changed (frames replayed, a marker swapped for a moment): the cap would take seconds,
    the spring alone takes well under MEET_S + 0.1 s to come within 10 mm."""
    rate_hz, step = 100.0, 0.01
    bias = lambda f: np.array([0.0, 1.1 * step * blend.MEET_S * rate_hz, 0.0])  # noqa: E731
    capped, truth = run(rate_hz, range(10, 10_000), step=step, bias=bias, frames=100, course=False)
    spring, _ = run(rate_hz, range(10, 10_000), bias=bias, frames=100, course=False)
    np.testing.assert_allclose(capped, spring, atol=1e-12)
    settled = 10 + int((blend.MEET_S + 0.1) * rate_hz)
    assert np.linalg.norm(capped[settled:] - truth[settled:] - bias(0), axis=1).max() < 0.01


def test_an_estimate_that_jumps_to_another_source_mid_gap_is_met_smoothly_known_answer():
    """A held hand carried first by one bone, then by another, jumps with no change of status (the Vicon
    take's left wrist: 147 and 286 mm in a frame); faster than SOURCE_JUMP_M_S it is blended like a loss."""
    rate_hz, jump_at = 120.0, 30
    jump = np.array([0.0, 0.0, 0.3])
    out, truth = run(rate_hz, range(10, 10_000), bias=lambda f: BIAS + (jump if f >= jump_at else 0.0), frames=150)
    steps = np.diff(out, axis=0)
    np.testing.assert_allclose(steps[jump_at - 1], steps[jump_at - 2], atol=1e-12)  # goes on as it went
    extra = np.linalg.norm(steps - np.diff(truth, axis=0), axis=1)
    # the spring's pace (its offset: the jump and what was left of the loss's), no jump
    assert extra.max() < np.linalg.norm(jump + BIAS) * (blend.BLEND_X / HALF_LIFE) / math.e / rate_hz
    assert np.linalg.norm(out[-1] - truth[-1] - BIAS - jump) < 1e-4                   # then the new source


def test_an_estimate_that_corrects_itself_closes_its_offset_at_once_known_answer():
    """An estimate that jumps within itself has corrected itself (the Vicon take's rebuilt left elbow, back from
    61 to 4 mm off in a 4-5 m/s swing): with the step cap set, its offset starts closing at the cap's pace in the
    first frame, where a held joint's jump (another bone took it up) is eased from rest."""
    rate_hz, jump_at, step = 120.0, 30, 0.01
    jump = np.array([0.0, 0.0, 0.1])  # (over SOURCE_JUMP_M_S: 83 mm a frame at 120 Hz)
    bias = lambda f: BIAS + (jump if f >= jump_at else 0.0)  # noqa: E731
    runs = {}
    for fill in (ESTIMATED, HELD):
        out, truth = run(rate_hz, range(10, 10_000), step=step, bias=bias, frames=150, fill=lambda f, s=fill: s)
        source = truth + np.array([bias(f) for f in range(150)])
        steps = np.diff(out, axis=0)
        np.testing.assert_allclose(steps[jump_at - 1], steps[jump_at - 2], atol=1e-12)  # goes on as it went
        extra = np.linalg.norm(steps - np.diff(truth, axis=0), axis=1)
        assert extra.max() <= step + 1e-12  # never faster than the cap
        runs[fill] = out - source
    omega = blend.BLEND_X / HALF_LIFE
    dt = 1.0 / rate_hz
    start = runs[ESTIMATED][jump_at]
    at_cap = start * (-step / dt / np.linalg.norm(start))  # the offset's velocity: closing at the cap's pace
    expected, _ = blend.spring_step(start, at_cap, omega, dt, math.exp(-omega * dt))
    moved = np.linalg.norm(expected - start)  # (at most the cap: here the spring's own pace, 9.6 mm)
    np.testing.assert_allclose(runs[ESTIMATED][jump_at + 1], start + (expected - start) * min(1.0, step / moved),
                               atol=1e-12)
    closed = {fill: np.linalg.norm(runs[fill][jump_at]) - np.linalg.norm(runs[fill][jump_at + 1]) for fill in runs}
    assert closed[ESTIMATED] > 0.009 and closed[HELD] < 0.001  # (from rest: 1 % of the jump)
    half = {fill: np.argmax(np.linalg.norm(runs[fill][jump_at:], axis=1) < 0.05) for fill in runs}
    assert half[ESTIMATED] <= half[HELD] - 4  # half the jump eased out 4 frames sooner (6 against 11)
    assert np.linalg.norm(runs[ESTIMATED][-1]) < 1e-4  # then the new source


def test_a_fill_handed_to_another_mid_gap_is_met_smoothly_known_answer():
    """A held hand taken up by an estimate 60 mm away (7.2 m/s at 120 Hz, under SOURCE_JUMP_M_S; the Vicon
    take's right wrist at frame 979): the hand-over's jump is eased in, where the same jump within one
    fill is taken as the fill's own motion."""
    rate_hz, hand_over = 120.0, 200
    jump = np.array([0.0, 0.0, 0.06])
    bias = lambda f: BIAS + (jump if f >= hand_over else 0.0)  # noqa: E731
    out, truth = run(rate_hz, range(10, 10_000), bias=bias, frames=400,
                     fill=lambda f: HELD if f < hand_over else ESTIMATED)
    extra = np.linalg.norm(np.diff(out, axis=0) - np.diff(truth, axis=0), axis=1)
    assert extra[:hand_over - 1].max() < 0.1 * np.linalg.norm(jump)  # (the loss's own ease, long over)
    assert extra[hand_over - 1:].max() < np.linalg.norm(jump) * (blend.BLEND_X / HALF_LIFE) / math.e / rate_hz
    assert np.linalg.norm(out[-1] - truth[-1] - BIAS - jump) < 1e-4  # then the new fill
    same, _ = run(rate_hz, range(10, 10_000), bias=bias, frames=400)  # one fill throughout: its own motion
    assert np.linalg.norm(np.diff(same, axis=0)[hand_over - 1] - np.diff(truth, axis=0)[hand_over - 1]) > 0.05


def _estimated_then_held(rate_hz: float, hold_at: int, course: bool = True, lost_at: int = 10, off=np.zeros(3),
                         back_at: int = 10_000):
    """A joint lost at ``lost_at``, estimated ``off`` its truth (a line) until ``hold_at``, then held where the
    estimate last was while the truth goes on (the Vicon take's kicking knee, its shank's wand lost too), and
    estimated again from ``back_at``."""
    frozen = off + VELOCITY / rate_hz * (hold_at - 1)
    def bias(f):
        return frozen - VELOCITY / rate_hz * f if hold_at <= f < back_at else off
    return run(rate_hz, range(lost_at, 10_000), bias=bias, frames=hold_at + 60, course=course,
               fill=lambda f: HELD if hold_at <= f < back_at else ESTIMATED)


def test_an_estimate_given_up_for_a_hold_goes_on_along_its_course_known_answer():
    """A hold knows nothing of where the joint went: the output goes on along the estimate's course (its
    last step, dying out with HOLD_COURSE_S) and leaves it for the hold only as course_weight says, as after a
    loss of the markers."""
    rate_hz, hold_at = 120.0, 100
    out, truth = _estimated_then_held(rate_hz, hold_at)
    omega = blend.BLEND_X / HALF_LIFE
    step = VELOCITY / rate_hz
    dies = math.exp(-1.0 / rate_hz / blend.HOLD_COURSE_S)  # the course's step, a frame later
    def spring(n):  # the hold plus the spring's offset (the hand-over's jump, one step), eased from that frame
        t = (n + 1) / rate_hz
        return truth[hold_at - 1] + step * (1 + omega * t) * math.exp(-omega * t)
    for f in range(hold_at, len(out)):
        n = f - hold_at
        course = spring(0) + step * (1 - dies ** n) / (1 - dies)  # from where the output was, on at a dying step
        t = n / rate_hz
        stray = blend.COURSE_K * 0.5 * blend.ACCEL_FLOOR * t * t
        weight = stray ** 2 / (stray ** 2 + blend.FILL_SD_PRIOR ** 2)
        weight = 1.0 if weight >= blend.EASED else weight
        np.testing.assert_allclose(out[f], course + weight * (spring(n) - course), atol=1e-12)
    spring_alone, _ = _estimated_then_held(rate_hz, hold_at, course=False)
    ahead = hold_at + 4
    assert np.linalg.norm(out[ahead] - truth[ahead]) < 0.005  # (a step behind: 3 of the truth's 4 gone on)
    assert np.linalg.norm(spring_alone[ahead] - truth[ahead]) > 0.015  # (four steps behind, less the spring)


def test_a_hold_during_a_course_after_a_loss_goes_on_with_that_course():
    """Estimated for a few frames after a loss, then held (the Vicon take's left wrist at frame 337): the
    output is still leaving the markers' course, and it goes on doing so. Restarting the course from the hand-
    over moved the wrist 2.2x its normal step in one frame."""
    rate_hz, lost_at, hold_at = 120.0, 40, 48
    out, truth = _estimated_then_held(rate_hz, hold_at, lost_at=lost_at, off=BIAS)
    extra = np.linalg.norm(np.diff(out, axis=0) - np.diff(truth, axis=0), axis=1)
    # the ease goes on at its pace (1.4 mm a frame more than the line here, then rising to 5.4 at most)
    assert extra[hold_at - 1] < 1.5 * extra[hold_at - 2], extra[hold_at - 2:hold_at]
    assert extra.max() < 0.2 * np.linalg.norm(BIAS), extra.max()


def test_an_estimate_back_from_a_hold_ends_the_course_known_answer():
    """The estimate comes back while the output is still leaving the course for the hold: the output goes on
    from itself at its own last step, then eases into the estimate, as into returning markers (the Vicon
    take's left elbow stayed on a stale course for 0.3 s with the estimate back: 107 -> 106 mm)."""
    rate_hz, hold_at, back_at = 120.0, 18, 24
    out, truth = _estimated_then_held(rate_hz, hold_at, off=BIAS, back_at=back_at)
    np.testing.assert_allclose(out[back_at] - out[back_at - 1], out[back_at - 1] - out[back_at - 2], atol=1e-12)
    assert np.linalg.norm(out[back_at] - truth[back_at] - BIAS) > 0.01  # (still off the estimate there)
    assert np.linalg.norm(out[-1] - truth[-1] - BIAS) < 1e-3              # the estimate (0.2 mm off after 0.45 s)


def _step_out(rate_hz: float, turn: int, aside=np.zeros(3)):
    """An estimate steps 80 mm in a frame at ``turn`` (under SOURCE_JUMP_M_S at 120 Hz, so taken as its motion),
    then turns back at 40 mm a frame, ``aside`` from its line after that (a hand-over between two fills of the
    Vicon take's kicking knee). Returns the output and the source."""
    def bias(f):
        if f < turn:
            return BIAS
        if f == turn:
            return BIAS + np.array([0.08, 0.0, 0.0]) - VELOCITY / rate_hz
        return BIAS + aside + np.array([0.08, 0.0, 0.0]) - (0.04 * rate_hz + VELOCITY[0]) * np.array([1.0, 0, 0]) * (
            (f - turn) / rate_hz)
    out, truth = run(rate_hz, range(10, 10_000), bias=bias, frames=120)
    return out, truth + np.array([bias(f) for f in range(120)])


def test_a_jump_leaves_no_stale_step_behind_known_answer():
    """After the 80 mm step the source turns back 80 mm aside of its line: where that old step led is 144 mm
    away, and where it was heading before it 89 mm: a jump, met like one, once. The jumped source's step is
    not known, so it is not carried on: the next frame is not another jump (the old step kept made one every
    frame, each taken into the offset: 9.5 m off by the end, the Vicon take's knee 0.46 m in 5 frames)."""
    rate_hz, turn = 120.0, 40
    out, source = _step_out(rate_hz, turn, aside=np.array([0.0, 0.08, 0.0]))
    gap = np.linalg.norm(out - source, axis=1)
    assert gap[turn + 1] == pytest.approx(np.hypot(0.12, 0.08), abs=0.01)  # met like a jump: went on as it went
    assert gap[turn + 1:].max() <= gap[turn + 1] + 1e-9                     # and never drifts further off
    assert gap[-1] < 0.01                                                    # the offset dies out


def test_a_one_frame_spike_of_a_fill_is_not_carried_on_known_answer():
    """After the 80 mm step the source is back within the jump's threshold of where it was heading before
    it (40 mm): the step was a spike. The output goes on at its step from before the spike, not at the
    spike's, then eases in."""
    rate_hz, turn = 120.0, 40
    out, source = _step_out(rate_hz, turn)
    np.testing.assert_allclose(out[turn + 1] - out[turn], VELOCITY / rate_hz, atol=5e-4)
    gap = np.linalg.norm(out - source, axis=1)
    assert gap[turn + 1] == pytest.approx(0.04, abs=0.005)
    assert gap[turn + 1:].max() <= gap[turn + 1] + 1e-9
    assert gap[-1] < 0.01


def test_a_fast_estimate_is_followed_not_taken_for_a_jump():
    """A lost joint whose estimate moves at 5 m/s (a strike) is below SOURCE_JUMP_M_S: once the loss's
    offset has died out, the output is the estimate, step for step."""
    fast = np.array([5.0, 0.0, 0.0])
    out, truth = run(120.0, range(10, 10_000), velocity=fast, frames=150)
    np.testing.assert_allclose(out[-20:] - truth[-20:], np.tile(BIAS, (20, 1)), atol=1e-4)
    np.testing.assert_allclose(np.diff(out[-20:], axis=0), np.diff(truth[-20:], axis=0), atol=1e-5)


def test_an_estimate_faster_than_the_jump_threshold_on_a_curve_is_followed_not_frozen():
    """A kicking toe filled at 12.6 m/s (105 mm a frame at 120 Hz, over SOURCE_JUMP_M_S) along a curve: each step
    is within the threshold of the one before, so it is the source's motion, not a jump. The velocity used to
    keep the last step under the threshold; the curve then left it by more, every next frame was met as a jump,
    and the output stood still (the Vicon take's right toe, 4 frames at frame 490, 400 mm behind)."""
    rate_hz, radius, speed = 120.0, 0.6, 12.6
    state = blend.BlendState.empty(1, 0.01, HALF_LIFE, True)
    out, source = [], []
    for f in range(60):
        state.advance_clock(f / rate_hz)
        angle = speed / radius * f / rate_hz
        p = START + radius * np.array([np.cos(angle), np.sin(angle), 0.0])
        positions = p.reshape(1, 3).copy()
        state.blend(positions, np.array([ESTIMATED if f >= 5 else LOCATED], np.int64), np.array([0]))
        out.append(positions[0].copy())
        source.append(p)
    steps = np.linalg.norm(np.diff(out, axis=0), axis=1)
    assert steps.min() > 0.09  # never stands still
    np.testing.assert_allclose(out[-10:], source[-10:], atol=1e-3)


def test_a_flickering_marker_does_not_send_the_joint_coasting_off():
    """Markers lost and found every other frame (the Vicon take's real gaps are mostly 1-2 frames): every
    change restarts the blend, and each restart carries half the last step, so the output stays near the
    truth instead of coasting on at a stale velocity."""
    rate_hz = 120.0
    flicker = range(20, 60, 2)  # lost on even frames 20-58, found on odd ones
    out, truth = run(rate_hz, flicker, velocity=np.array([2.0, 0.0, 0.0]), frames=100)
    error = np.linalg.norm(out - truth, axis=1)
    assert error[20:60].max() < np.linalg.norm(BIAS), error[20:60].max()
    assert error[-1] < 1e-3


def test_a_joint_lost_right_after_the_first_frame_stays_where_it_was():
    """The first frame a filler sees is where every course starts (not the origin): a joint lost in the
    second frame, as the worst-case timing loses every joint, stays within one step of its truth."""
    rate_hz = 100.0
    out, truth = run(rate_hz, range(1, 10_000), frames=5)
    assert np.linalg.norm(out[1] - truth[1]) <= np.linalg.norm(VELOCITY) / rate_hz + 1e-12


def test_without_a_half_life_the_loss_jumps_and_the_return_closes_linearly_as_before():
    out, truth = run(100.0, range(10, 40), half_life=0.0, step=0.01)
    np.testing.assert_allclose(out[10:40] - truth[10:40], np.tile(BIAS, (30, 1)), atol=1e-12)  # a jump at loss
    closing = np.linalg.norm(out[40:46] - truth[40:46], axis=1)
    at_return = np.linalg.norm(BIAS - VELOCITY / 100.0)  # where the estimate was, less the joint's own step
    np.testing.assert_allclose(closing, np.maximum(at_return - 0.01 * np.arange(1, 7), 0.0), atol=1e-12)


def test_the_clock_keeps_the_last_interval_when_stamps_loop_or_are_missing():
    filler = LimbFiller("left_arm", options=FillOptions(blend_half_life_s=HALF_LIFE))
    for t in (0.0, 0.004, 0.008, 0.0, float("nan"), 5.0):  # a looping file, a missing stamp, a pause
        filler.clock.advance(t)
    assert filler.clock.frame_s == pytest.approx(0.004)


def test_short_gaps_on_a_dancers_elbow():
    """dance2 of the 28-marker set (no marker on the upper arm: the elbow's swivel is guessed), the left
    elbow hidden 0.1 s in every 0.5 s, the studio graphs' options with and without the blend. With it, each
    gap starts from where the markers were heading, so the fill is nearer, and the fill adds little motion
    of its own where the markers go and come back."""
    rec = read_recording(data_file("13_qualisys_dance_walk_mocaptoolbox_mcdemodata.mat"), "dance2")
    prof = load_profile("dance28")
    pipe = SkeletonPipeline(prof, rec.labels, fill_gaps=False)
    landmarks = pipe.landmark_map.apply(rec.positions)
    reference = pipe.solve_landmarks(pipe.landmarks(rec.positions)).positions
    runs = {}
    for half_life in (0.0, HALF_LIFE):
        runs[half_life] = gap_run(GapTake(landmarks, reference, prof, rec.rate_hz),
                                  Gap(["elbow_l"], int(rec.rate_hz), rec.n_frames, short_gaps=(6, 30)),
                                  fills=STUDIO.model_copy(update={"blend_half_life_s": half_life}))
    mean = {h: float(np.nanmean(r.error_m)) for h, r in runs.items()}
    moves = {h: transition_moves(r, reference)[0] for h, r in runs.items()}
    assert len(runs[HALF_LIFE].windows) > 40
    assert mean[HALF_LIFE] < 0.6 * mean[0.0], mean
    assert mean[HALF_LIFE] < 0.016, mean
    for event in ("loss", "return"):
        assert moves[HALF_LIFE][f"{event}_added_ratio"] < 1.2, moves
    assert moves[0.0]["loss_added_ratio"] > 2 * moves[HALF_LIFE]["loss_added_ratio"], moves


def _eased_loss(bias_m: float) -> float:
    """A joint on a circle (it accelerates), lost for 10 frames in every 40 at 100 Hz with a fill ``bias_m``
    off; how far the output has gone from the markers' course towards the fill 50 ms into the last gap."""
    rate_hz = 100.0
    state = blend.BlendState.empty(1, 0.0, HALF_LIFE)
    for f in range(400):
        state.advance_clock(f / rate_hz)
        angle = f / rate_hz
        true = START + 0.3 * np.array([math.cos(angle), math.sin(angle), 0.0])
        lost = f >= 40 and f % 40 < 10
        status = np.array([ESTIMATED if lost else LOCATED], np.int64)
        positions = (true + (np.array([0.0, 0.0, bias_m]) if lost else 0.0)).reshape(1, 3).copy()
        state.blend(positions, status, np.array([0]))
    return blend.course_weight(0.05, state.memory.trust[0])


def test_a_fill_that_missed_where_the_markers_came_back_is_trusted_later_after_a_loss():
    """The weight of the fill after a loss learns from the joint itself: how far its fill missed the returning
    markers (here 5 mm or 80 mm off), against how fast the joint's markers change course."""
    near, far = _eased_loss(0.005), _eased_loss(0.08)
    assert 0.0 < far < near < 1.0, (near, far)
    assert far < 0.05 and near > 10 * far, (near, far)


def test_short_gaps_on_a_dancers_knee_and_ankle():
    """dance2, the left knee and ankle hidden 0.1 s in every 0.5 s: the pose memory's fill misses the
    returning markers by 42 mm, so after a loss the output stays on the markers' course longer. With the
    studio options: 11.1 / 10.5 mm mean (18.0 / 18.0 with the blend's spring alone), and the fill adds at
    most 0.65x the joints' normal step where the markers go (1.01x; 1.63x before the pose memory tracked the
    pelvis frame)."""
    rec = read_recording(data_file("13_qualisys_dance_walk_mocaptoolbox_mcdemodata.mat"), "dance2")
    prof = load_profile("dance28")
    pipe = SkeletonPipeline(prof, rec.labels, fill_gaps=False)
    landmarks = pipe.landmark_map.apply(rec.positions)
    reference = pipe.solve_landmarks(pipe.landmarks(rec.positions)).positions
    means, moves = {}, {}
    for course in (False, True):
        run_ = gap_run(GapTake(landmarks, reference, prof, rec.rate_hz),
                       Gap(["knee_l", "ankle_l"], int(rec.rate_hz), rec.n_frames, short_gaps=(6, 30)),
                       hips=HipOptions(pose_memory=True), fills=STUDIO.model_copy(update={"blend_course": course}))
        means[course] = np.nanmean(run_.error_m, axis=0)
        moves[course] = transition_moves(run_, reference)
    assert (means[True] < 0.014).all() and (means[True] < 0.75 * means[False]).all(), means
    for move in moves[True]:
        assert move["loss_added_ratio"] < 1.0, move
        assert move["return_added_ratio"] < 1.5, move
    loss = {course: max(m["loss_added_ratio"] for m in moves[course]) for course in moves}
    assert loss[True] < 0.8 * loss[False], loss


def test_short_gaps_on_another_dancers_knee_and_ankle_come_back_without_a_twitch():
    """dance1, the left knee and ankle hidden 0.1 s in every 0.5 s, the studio options: where the markers go
    and where they come back the fill adds under 1.5x the joints' normal step."""
    rec = read_recording(data_file("13_qualisys_dance_walk_mocaptoolbox_mcdemodata.mat"), "dance1")
    prof = load_profile("dance28")
    pipe = SkeletonPipeline(prof, rec.labels, fill_gaps=False)
    landmarks = pipe.landmark_map.apply(rec.positions)
    reference = pipe.solve_landmarks(pipe.landmarks(rec.positions)).positions
    run_ = gap_run(GapTake(landmarks, reference, prof, rec.rate_hz),
                   Gap(["knee_l", "ankle_l"], int(rec.rate_hz), rec.n_frames, short_gaps=(6, 30)),
                   hips=HipOptions(pose_memory=True), fills=STUDIO)
    assert (np.nanmean(run_.error_m, axis=0) < 0.013).all(), np.nanmean(run_.error_m, axis=0)
    for move in transition_moves(run_, reference):
        assert move["loss_added_ratio"] < 1.5 and move["return_added_ratio"] < 1.5, move


def test_nearest_on_circle_known_answer():
    """The point of the circle of points 0.3 m from both ends of a 0.5 m line nearest a point off it: from the
    circle's centre, halfway, the point's direction across the line, at the circle's radius."""
    root, target = np.array([1.0, 2.0, 0.5]), np.array([1.5, 2.0, 0.5])
    point = np.array([1.2, 2.3, 0.6])
    got = af.nearest_on_circle(point, root, target, 0.3, 0.3)
    radius = math.sqrt(0.3 ** 2 - 0.25 ** 2)
    across = np.array([0.0, 0.3, 0.1]) / math.hypot(0.3, 0.1)
    np.testing.assert_allclose(got, np.array([1.25, 2.0, 0.5]) + radius * across, atol=1e-12)
    assert np.linalg.norm(got - root) == pytest.approx(0.3) and np.linalg.norm(got - target) == pytest.approx(0.3)
    # out of reach (the line longer than both bones): the point of the line nearest both
    np.testing.assert_allclose(af.nearest_on_circle(point, root, target + [0.5, 0, 0], 0.3, 0.3),
                               [1.3, 2.0, 0.5], atol=1e-12)


SWING_HZ = 1.0  # turns a second


def _swing(rate_hz: float, lost_at: int, other_lost_at: int = 10_000, frames: int = 80, stretch: float = 0.0,
           lost: int = 1, root: bool = False, other_back_at: int = 10_000):
    """A shoulder, elbow and wrist (a bent arm: bones 0.3 and 0.25 m, 0.6 rad apart) swinging rigidly about the
    shoulder at a turn a second; joint ``lost`` (1 the elbow, 2 the wrist, the limb's end) has its markers lost from
    ``lost_at``, its estimate BIAS off; the other of the two from ``other_lost_at`` (to ``other_back_at``), its
    estimate where it is; from ``lost_at`` on the wrist goes ``stretch`` metres a frame further out from the shoulder
    (skin sliding). Returns per frame the blend's course for joint ``lost``, whether one runs, and the truth (frames
    x 3 joints x 3).
    ``root``: the chain starts at a still joint before the shoulder (as a limb at its root), and the truth has it
    first (the indices above one on)."""
    first = int(root)
    lost, other = lost + first, 3 - lost + first
    state = blend.BlendState.empty(3 + first, 0.01, HALF_LIFE, True)
    courses, running, truths = [], [], []
    for f in range(frames):
        state.advance_clock(f / rate_hz)
        angle = 2 * math.pi * SWING_HZ * f / rate_hz
        elbow = START + 0.3 * np.array([math.cos(angle), math.sin(angle), 0.0])
        wrist = elbow + 0.25 * np.array([math.cos(angle + 0.6), math.sin(angle + 0.6), 0.0])
        wrist += stretch * max(f - lost_at, 0) * (wrist - START) / np.linalg.norm(wrist - START)
        truth = np.array([START - [0.15, 0.0, 0.0]] * first + [START, elbow, wrist])
        positions = truth.copy()
        status = np.full(3 + first, LOCATED, np.int64)
        if f >= lost_at:
            positions[lost] += BIAS
            status[lost] = ESTIMATED
        if other_lost_at <= f < other_back_at:
            status[other] = ESTIMATED
        state.blend(positions, status, np.arange(3 + first))
        courses.append(state.memory.course[lost].copy())
        running.append(state.memory.since_loss[lost] < math.inf)
        truths.append(truth)
    return np.array(courses), np.array(running), np.array(truths)


def test_a_lone_joints_course_keeps_its_distances_to_its_located_neighbours_known_answer():
    """An elbow lost while the arm swings about the shoulder: its markers' straight course flies off the arm;
    held to its distances from the located shoulder and wrist (as where the course began), it turns with them."""
    rate_hz, lost_at = 120.0, 20
    course, running, truth = _swing(rate_hz, lost_at)
    after = np.flatnonzero(running)
    assert after[0] == lost_at and len(after) >= 8  # (the course runs while the fill is eased in)
    first = course[lost_at]  # where the output was heading (the markers' last position and step)
    upper, lower = np.linalg.norm(first - truth[lost_at, 0]), np.linalg.norm(truth[lost_at, 2] - first)
    for f in after:
        assert np.linalg.norm(course[f] - truth[f, 0]) == pytest.approx(upper, abs=1e-12)
        assert np.linalg.norm(truth[f, 2] - course[f]) == pytest.approx(lower, abs=1e-12)
    # nearer the truth than the straight course (the markers' last step, on and on)
    straight = first + np.outer(after - lost_at, truth[lost_at - 1, 1] - truth[lost_at - 2, 1])
    on_circle = np.linalg.norm(course[after] - truth[after, 1], axis=1)
    off_line = np.linalg.norm(straight - truth[after, 1], axis=1)
    assert on_circle[-1] < off_line[-1] / 4, (on_circle[-1], off_line[-1])


def test_an_end_joints_course_keeps_its_distance_to_its_located_parent_known_answer():
    """A wrist (the limb's end) lost while the arm swings: its markers' straight course flies off the forearm; held
    to its distance from the located elbow (as where the course began), it turns with it."""
    rate_hz, lost_at = 120.0, 20
    course, running, truth = _swing(rate_hz, lost_at, lost=2)
    after = np.flatnonzero(running)
    assert after[0] == lost_at and len(after) >= 8
    reach = np.linalg.norm(course[lost_at] - truth[lost_at, 1])
    for f in after:
        assert np.linalg.norm(course[f] - truth[f, 1]) == pytest.approx(reach, abs=1e-12)
    straight = course[lost_at] + np.outer(after - lost_at, truth[lost_at - 1, 2] - truth[lost_at - 2, 2])
    on_sphere = np.linalg.norm(course[after] - truth[after, 2], axis=1)
    off_line = np.linalg.norm(straight - truth[after, 2], axis=1)
    assert on_sphere[-1] < off_line[-1] / 2, (on_sphere[-1], off_line[-1])


def test_an_end_joints_course_goes_on_straight_once_its_parent_is_lost():
    """Once the elbow is lost too, the wrist's course goes on straight at the step it had: its markers' last step,
    less the elbow's step then, plus the elbow's last step while it was seen."""
    rate_hz, lost_at, parent_lost_at = 120.0, 20, 24
    course, running, truth = _swing(rate_hz, lost_at, parent_lost_at, lost=2)
    assert running[parent_lost_at:parent_lost_at + 3].all()
    markers_step = truth[lost_at - 1, 2] - truth[lost_at - 2, 2]
    elbow_steps = np.diff(truth[:, 1], axis=0)  # (row f: the step into frame f + 1)
    carried = markers_step - elbow_steps[lost_at - 2] + elbow_steps[parent_lost_at - 2]
    steps = np.diff(course[parent_lost_at - 1:parent_lost_at + 3], axis=0)
    np.testing.assert_allclose(steps, np.tile(carried, (3, 1)), atol=1e-12)


@pytest.mark.parametrize("elbow_lost_for", [0, 2])
def test_an_end_joints_course_moves_with_its_located_parent_known_answer(elbow_lost_for):
    """A wrist lost while the whole arm moves along at 40 mm a frame, which then stops short (the Vicon take's left
    wrist, held at frames 335-363 while its elbow slowed from 26 to 5 mm a frame, ran on and came back 116 mm off its
    markers): its course carries its markers' last step less the elbow's then, plus the elbow's step now, so it stops
    with the arm, where the markers' last step ran on. An elbow lost with it and seen again before the stop carries
    it from there on."""
    rate_hz, lost_at, stop_at = 120.0, 20, 24
    arm = np.array([[0.0, 0.0, 0.0], [0.3, 0.0, 0.0], [0.5, 0.15, 0.0]])  # shoulder, elbow, wrist
    along = np.array([0.0, 0.04, 0.0])  # metres a frame
    state = blend.BlendState.empty(3, 0.01, HALF_LIFE, True)
    for f in range(lost_at + 12):
        state.advance_clock(f / rate_hz)
        truth = START + arm + along * min(f, stop_at)
        positions, status = truth.copy(), np.full(3, LOCATED, np.int64)
        if f >= lost_at:
            positions[2] += BIAS
            status[2] = ESTIMATED
        if lost_at <= f < lost_at + elbow_lost_for:
            status[1] = ESTIMATED  # (its estimate exact: the elbow's output stays on the truth)
        state.blend(positions, status, np.arange(3))
        if f >= lost_at:
            assert state.memory.since_loss[2] < math.inf  # (the course runs on: the fill is far from trusted yet)
            np.testing.assert_allclose(state.memory.course[2], truth[2], atol=1e-12)
    # the markers' last step, on and on from where the arm stopped, would be 0.28 m off by now (on the sphere, 122 mm)
    straight = truth[2] + along * (f - stop_at)
    assert np.linalg.norm(af.nearest_on_sphere(straight, truth[1], np.linalg.norm(arm[2] - arm[1])) - truth[2]) > 0.1


def test_a_joint_lost_with_its_child_keeps_its_distance_to_its_located_parent_but_not_to_the_limbs_root():
    """An elbow lost with its wrist, the shoulder located: the elbow's course keeps its distance to the shoulder, as
    an end joint's does to its parent. Not where the parent is the limb's root (the hip, the clavicle), which the
    trunk's skin markers put: a knee lost with its ankle went on straight (on dance2 the hip joint shook the sphere,
    and the knee's move where its markers went rose from 0.69 to 1.04x its normal step)."""
    rate_hz, lost_at = 120.0, 20
    course, running, truth = _swing(rate_hz, lost_at, lost_at, root=True)  # (the shoulder is the chain's second)
    after = np.flatnonzero(running)
    assert after[0] == lost_at and len(after) >= 8
    reach = np.linalg.norm(course[lost_at] - truth[lost_at, 1])
    for f in after:
        assert np.linalg.norm(course[f] - truth[f, 1]) == pytest.approx(reach, abs=1e-12)
    for wrist_back_at in (10_000, lost_at + 3):  # (the wrist seen again mid-course: the shoulder is still the root)
        course, running, truth = _swing(rate_hz, lost_at, lost_at, other_back_at=wrist_back_at)
        markers_step = truth[lost_at - 1, 1] - truth[lost_at - 2, 1]
        np.testing.assert_allclose(np.diff(course[lost_at:lost_at + 8], axis=0), np.tile(markers_step, (7, 1)),
                                   atol=1e-12)


def test_a_lone_joints_course_goes_on_straight_once_a_neighbour_is_lost():
    """The wrist lost too, mid-course: the elbow's course goes on from where it was at its step, without a jump."""
    rate_hz, lost_at, wrist_lost_at = 120.0, 20, 24
    course, running, truth = _swing(rate_hz, lost_at, wrist_lost_at)
    assert running[wrist_lost_at:wrist_lost_at + 3].all()
    markers_step = truth[lost_at - 1, 1] - truth[lost_at - 2, 1]  # the course's step
    steps = np.diff(course[wrist_lost_at - 1:wrist_lost_at + 3], axis=0)
    np.testing.assert_allclose(steps, np.tile(markers_step, (3, 1)), atol=1e-12)
    turned = np.diff(course[lost_at:wrist_lost_at], axis=0)  # (before, the circle turned it)
    assert np.linalg.norm(turned[-1] - markers_step) > 1e-3


def test_a_lone_joints_course_out_of_its_neighbours_reach_moves_with_their_line_known_answer():
    """The wrist slides away from the shoulder faster than the arm can reach: the circle of the elbow's distances
    shrinks to a point on their line (the Vicon take's right upper arm stretched 233 -> 280 mm in 8 frames as its
    shoulder was lost for two, and the course jumped 36 mm onto that line). Out of reach, the course keeps its
    place against the line as the line moves: the same distance from its midpoint, the same way along it."""
    rate_hz, lost_at = 120.0, 20
    course, running, truth = _swing(rate_hz, lost_at, stretch=0.015)
    first = course[lost_at]
    upper, lower = np.linalg.norm(first - truth[lost_at, 0]), np.linalg.norm(truth[lost_at, 2] - first)
    out = [f for f in np.flatnonzero(running) if f > lost_at
           and np.linalg.norm(truth[f, 2] - truth[f, 0]) > upper + lower]
    assert len(out) >= 5

    def against_line(f):
        mid, along = 0.5 * (truth[f, 0] + truth[f, 2]), truth[f, 2] - truth[f, 0]
        return np.linalg.norm(course[f] - mid), np.dot(course[f] - mid, along / np.linalg.norm(along))

    placed = np.array([against_line(f) for f in [out[0] - 1] + out])
    np.testing.assert_allclose(placed, np.tile(placed[0], (len(placed), 1)), atol=1e-12)
    # (its markers' straight course would have left the line: the shoulder and wrist swing)
    markers_step = truth[lost_at - 1, 1] - truth[lost_at - 2, 1]
    assert np.linalg.norm(course[out[-1]] - (course[out[0] - 1] + len(out) * markers_step)) > 0.03


def _kick(rate_hz: float, lost_at: int, frames: int = 40):
    """A heel between an ankle and a toe (0.1 m on, 0.02 m off their line) in a kick at 20 mm a frame that slows
    by 4 mm a frame from ``lost_at`` on and turns back; the toe's marker slides 4 mm a frame out and back over
    10 frames, out of the heel's reach for most of them. The heel's markers are lost from ``lost_at``, its
    estimate BIAS off. Returns per frame the blend's course and output for the heel, and the truth."""
    state = blend.BlendState.empty(3, 0.01, HALF_LIFE, True)
    x, courses, outputs, truths = 0.0, [], [], []
    for f in range(frames):
        state.advance_clock(f / rate_hz)
        x += 0.02 if f < lost_at else 0.02 - 0.004 * (f - lost_at)
        slid = 0.004 * max(0, min(f - lost_at, 10 - (f - lost_at)))
        ankle = START + [x, 0.0, 0.0]
        truth = np.array([ankle, ankle + [0.1, 0.02, 0.0], ankle + [0.2 + slid, 0.0, 0.0]])
        positions, status = truth.copy(), np.full(3, LOCATED, np.int64)
        if f >= lost_at:
            positions[1] += BIAS
            status[1] = ESTIMATED
        state.blend(positions, status, np.arange(3))
        courses.append(state.memory.course[1].copy())
        outputs.append(positions[1].copy())
        truths.append(truth)
    return np.array(courses), np.array(outputs), np.array(truths)


def test_a_lone_joint_back_within_its_neighbours_reach_does_not_jump():
    """The Vicon take's kicking right foot: out of its ankle's and toe's reach for 9 frames as the kick
    turned back, its course ran on straight 200 mm ahead and then fell onto the circle in one frame; its markers
    came back at 1.50x its own pace. Moved with its neighbours' line, the heel's course stays within 12 mm of the
    truth, and the output never moves more than 5 mm beyond the heel's own step."""
    rate_hz, lost_at = 120.0, 20
    course, output, truth = _kick(rate_hz, lost_at)
    gap = np.arange(lost_at + 1, len(truth))
    assert np.linalg.norm(course[gap] - truth[gap, 1], axis=1).max() < 0.012
    added = np.abs(np.linalg.norm(np.diff(output, axis=0), axis=1) - np.linalg.norm(np.diff(truth[:, 1], axis=0),
                                                                                     axis=1))
    assert added[lost_at:].max() < 0.005, added[lost_at:]


def test_a_missing_frame_leaves_no_stale_step_behind():
    """A joint missing for a frame (no source at all) has nothing to measure its next step from: at a steady
    2 m/s the acceleration the course weight learns from stays 0 across it, and the output goes on with its
    source."""
    rate_hz, velocity = 120.0, np.array([2.0, 0.0, 0.0])
    state = blend.BlendState.empty(1, 0.0, HALF_LIFE)
    for f in range(30):
        state.advance_clock(f / rate_hz)
        missing = f == 15
        positions = (START + velocity * f / rate_hz).reshape(1, 3)
        positions = np.full((1, 3), np.nan) if missing else positions.copy()
        status = np.array([int(Status.MISSING) if missing else LOCATED], np.int64)
        state.blend(positions, status, np.array([0]))
        if not missing:
            np.testing.assert_allclose(positions[0], START + velocity * f / rate_hz, atol=1e-12)
    acc = state.memory.trust[0, blend.ACC_SUM] / state.memory.trust[0, blend.ACC_N]
    assert state.memory.trust[0, blend.ACC_N] >= 20
    assert acc < 1e-6, acc


def test_the_output_stays_within_reach_of_a_fill_that_stands_still():
    """A joint lost at 5 m/s whose fill stays where the markers went (a held hand): the markers' course runs
    on at 42 mm a frame, the step cap lets the output leave it at 10, and without a bound it went 1.0 m off
    its fill. It stays within MAX_APART_M of the fill, and once the markers are back it closes on
    them at the cap, never further off than when they came back."""
    rate_hz, loss, back = 120.0, 20, 120
    fast = np.array([5.0, 0.0, 0.0])
    frozen = lambda f: -fast * (f - loss) / rate_hz  # the source stays where the markers were lost
    out, truth = run(rate_hz, range(loss, back), step=0.01, frames=200, bias=frozen, velocity=fast,
                     fill=lambda f: HELD)
    source = truth + np.array([frozen(f) if loss <= f < back else np.zeros(3) for f in range(200)])
    apart = np.linalg.norm(out - source, axis=1)
    assert apart[loss:back].max() == pytest.approx(blend.MAX_APART_M)  # it binds, and holds
    assert apart[back:].max() <= apart[back] + 1e-9
    assert np.diff(apart[back:back + 20]).max() < 0


def test_a_fill_further_off_than_the_bound_takes_over_without_a_twitch():
    """A fill 0.8 m off the truth where the markers go (past MAX_APART_M) is met as any other: the output goes
    on at the joint's own step there, and then only never drifts further from the fill than that."""
    rate_hz, loss = 120.0, 20
    far = np.array([0.0, 0.8, 0.0])
    out, truth = run(rate_hz, range(loss, 10_000), step=0.01, frames=120, bias=lambda f: far)
    np.testing.assert_allclose(out[loss] - out[loss - 1], VELOCITY / rate_hz, atol=1e-9)
    apart = np.linalg.norm(out - (truth + far), axis=1)
    assert apart[loss] == pytest.approx(0.8)
    assert apart[loss:].max() <= 0.8 + 1e-9


def test_a_bone_frame_whose_neighbour_changes_source_turns_on_smoothly():
    """A hand stays located while its wrist is lost: the hand's frame (the wrist's, in localization) is the fill's
    from then on. Its jump of 60 degrees is eased like its own change of source would be."""
    from mocap_core.ik.kernels import axis_angle

    state = blend.BlendState.empty(2, 0.01, HALF_LIFE, True)
    jump = axis_angle(np.array([0.0, 1.0, 0.0]), np.radians(60))
    out = []
    for f in range(80):
        state.advance_clock(f / 120.0)
        frames = np.stack([np.eye(3), jump if f >= 10 else np.eye(3)])
        status = np.array([ESTIMATED if f >= 10 else LOCATED, LOCATED], np.int64)
        state.blend(np.zeros((2, 3)), status, np.array([0, 1]), frames)
        out.append(frames[1].copy())
    turns = [np.degrees(np.arccos(np.clip((np.trace(a.T @ b) - 1) / 2, -1, 1))) for a, b in zip(out, out[1:])]
    assert max(turns) < 6.0 and np.degrees(np.arccos(np.clip((np.trace(out[-1].T @ jump) - 1) / 2, -1, 1))) < 2.0


def test_a_bone_frame_that_changes_source_turns_on_smoothly_known_answer():
    """A joint's frame turns 1 degree a frame about z while its markers are seen; from frame 20 its fill's frame is
    90 degrees off about x (the Vicon take's left wrist: its fill and its sliding markers up to 174 degrees apart),
    and from frame 80 the markers are back. The output's frame never turns more than 6 degrees in a frame (the
    source's own turn and a spring's share of the offset), and it ends on the source's frame."""
    from mocap_core.ik.kernels import axis_angle

    rate_hz, frames_n = 120.0, 140
    state = blend.BlendState.empty(1, 0.01, HALF_LIFE, True)
    off = axis_angle(np.array([1.0, 0.0, 0.0]), np.pi / 2)
    out = []
    for f in range(frames_n):
        state.advance_clock(f / rate_hz)
        filled = 20 <= f < 80
        source = axis_angle(np.array([0.0, 0.0, 1.0]), np.radians(f))
        frames = (off @ source if filled else source).reshape(1, 3, 3).copy()
        positions = (START + VELOCITY * f / rate_hz).reshape(1, 3).copy()
        state.blend(positions, np.array([ESTIMATED if filled else LOCATED], np.int64), np.array([0]), frames)
        out.append(frames[0].copy())
        if f in (79, frames_n - 1):
            want = off @ source if f == 79 else source
            assert np.degrees(np.arccos(np.clip((np.trace(out[-1].T @ want) - 1) / 2, -1, 1))) < 1.0
    turns = [np.degrees(np.arccos(np.clip((np.trace(a.T @ b) - 1) / 2, -1, 1))) for a, b in zip(out, out[1:])]
    assert max(turns) < 6.0, max(turns)
    assert np.degrees(np.arccos(np.clip((np.trace(out[20].T @ out[19]) - 1) / 2, -1, 1))) < 1.0  # (went on as it was)

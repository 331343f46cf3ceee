"""The blend: a joint that changes source (its markers lost or back, a fill handed to another) goes on where it
was heading, and the offset to the new source dies out as a critically damped spring (inertialization, as game
engines do); after a loss it leaves its markers' course for the fill only as that course grows less trustworthy
than the fill has been. Bone frames are blended the same way. Numba kernels; gapfill.LimbFiller keeps a
BlendState per limb and calls BlendState.blend after the fills (mocap_core.analytic_fill, the IK solvers).

With a half-life (blend_half_life_s) the output is the source (markers, or a fill's estimate) plus an offset. Where
the markers are lost or come back, the offset takes in the jump: the new source less where the old one was heading
(its last position plus its own last step), so the output goes on as it went. The offset then dies out as a
critically damped spring (Holden's, exact for any ``dt``), by at most ``step`` a frame when that is set (or
PACE_SHARE of the source's own step, if more; an offset too large for that cap to close within MEET_S is left to
the spring alone). At loss the offset is the truth the estimate has not got: over a
short gap it keeps the joint near its markers' last course. After a loss the output also stays on that course (the
markers' last step, on and on), leaving it for the fill as course_weight says, which learns from the joint how fast
its markers turn and how far its fill missed them where they came back (``trust``); ``step`` caps that too. Markers
that come back while the output is still leaving that course are met from the output as it went (its own last
step), not as the fill went; markers back within FLICKER_FRAMES of their last sighting are met at their own step
across the gap. An estimate that leaves its course faster than SOURCE_JUMP_M_S has changed source (a held hand
carried by another bone) and is met the same way; one handed between fills (estimated, held) without such a jump
has its jump taken into the offset. An estimate given up for a hold starts a course as a loss does, its step dying
out, and one back from a hold ends a course as returning markers do. The course of a lone joint between two located
ones keeps its distances to them, on their circle; out of their reach, it moves with their line. One whose parent
alone is located keeps its distance to it, unless that is the limb's root, and moves with it: its step is its
markers' last step relative to the parent's then, plus the parent's now. While a fill stands in, the output stays
within MAX_APART_M of it. A flickering marker swings the offset back and forth by the two sources' difference:
nothing builds up.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from numba import njit
from pydantic import BaseModel, Field

from mocap_core.analytic_fill import all_finite, nearest_on_circle, nearest_on_sphere
from mocap_core.fill_units import LimbFill, LimbFrame
from mocap_core.frame_clock import FrameClock
from mocap_core.ik.kernels import axis_angle, line_carry, mm, mv, rotation_vector, vdist, vnorm
from mocap_core.skeleton import ESTIMATED, HELD, LOCATED, MISSING

REACQUIRE_HELP = ("beyond the thesis: close the gap to returning markers by at most this many metres a frame (0 = the "
                  "thesis's method: jump)")
BLEND_HELP = ("beyond the thesis: when a joint's markers are lost or come back, go on where the joint was heading and "
              "let the offset to the new source die out as a critically damped spring that halves it in this many "
              "seconds (0 = off: a jump at loss)")
BLEND_COURSE_HELP = ("with blend_half_life_s: after a loss, stay on the markers' course and leave it for the fill only "
                     "as it grows less trustworthy than the fill has been where the markers came back (learned per "
                     "joint; false: the spring alone)")

# A critically damped spring from rest, offset o0, is o0 (1 + w t) e^(-w t): it is halved at t = BLEND_X / w.
BLEND_X = 1.6783469900166612
# Faster than this, an estimate has jumped to another source: no joint of the shared recordings moves so fast
# (strikes take a wrist to 4-7 m/s), while a held joint handed to another fill jumps at 18-34 m/s.
SOURCE_JUMP_M_S = 10.0
# A source seen again within this many frames (a flickering marker) gets its step from its last sighting, and
# returning markers are met at that step.
FLICKER_FRAMES = 5
# Seconds between frames when the caller gives no capture times (the blend's spring needs them).
DEFAULT_FRAME_S = 0.01
# After a loss, the output leaves the markers' course for the fill only as fast as the course can be trusted
# less than the fill (the dead blending of game engines, weighted): by w = c^2 / (c^2 + s^2), where
# c = COURSE_K * |a| t^2 / 2 is how far the course may have strayed t seconds on (|a| the joint's mean
# acceleration while located, at least ACCEL_FLOOR) and s the fill's RMS miss where the markers came back
# (FILL_SD_PRIOR counting as one such), the spring's offset included. Both are learned per joint, from the
# take's own frames. The spring's offset alone gives the course up at once, at the fill's own velocity.
COURSE_K = 3.0
# An estimate given up for a hold starts a course too, on the estimate's last step; that step dies out
# with this time constant: a fill's step says less of where a limb goes than its markers' did, and an arm that
# loses its estimate often does so slowing down. A loss of the markers keeps its course.
HOLD_COURSE_S = 0.05
ACCEL_FLOOR = 1.0       # m/s^2
FILL_SD_PRIOR = 0.01    # metres
MISS_SIGMAS = 3.0       # a miss counts at most this many RMS misses so far (winsorized: robust to a glitch)
# reacquire_step_m caps how far the blend moves the output off its source in a frame; a source moving over
# four times that may be left or met at a quarter of its own step, so a fast joint (a kicking foot) does not
# fall behind its fill and take long to meet its markers again.
PACE_SHARE = 0.25
# An offset the step cap could not close within this many seconds is left to the spring alone: a source that jumped
# far and back (frames replayed, a marker swapped for a moment) leaves no trace half a second on, where the cap
# would take seconds.
MEET_S = 0.4
EASED = 0.999           # the weight at which the fill is taken whole
# While a fill stands in for the markers, the output stays within this of it: the markers' course runs on
# straight at their last step, and a hand lost in a fast strike would otherwise fly far off its held fill, with
# the offsets that come back with it piling up gap after gap. It never binds on the shared recordings' tables.
MAX_APART_M = 0.5
# BlendState.trust's columns: |acceleration| summed while located and how many; the output's squared misses
# where the markers came back and how many; frames located in a row.
ACC_SUM, ACC_N, MISS_SQ, MISS_N, LOCATED_RUN = range(5)


class BlendMemory(NamedTuple):
    """What blend_transitions keeps per joint between frames: BlendState's arrays, as the kernels take them."""
    last_out: np.ndarray      # (n, 3) the last output
    out_step: np.ndarray      # (n, 3) and its last step
    last_raw: np.ndarray      # (n, 3) the source's last position, before the offset
    raw_vel: np.ndarray       # (n, 3) and its last step
    seen_raw: np.ndarray      # (n, 2, 3) where each kind of source (0 markers, 1 a fill) was last seen
    seen_age: np.ndarray      # (n, 2) and how many frames ago
    last_status: np.ndarray   # (n,)
    has_last: np.ndarray      # (1,) bool
    offset: np.ndarray        # (n, 3) the spring's offset
    offset_vel: np.ndarray    # (n, 3) and its velocity
    course: np.ndarray        # (n, 3) where the markers' course leads, since they were lost
    course_step: np.ndarray   # (n, 3) and its step
    since_loss: np.ndarray    # (n,) seconds since the markers were lost (inf: no loss being eased)
    eased: np.ndarray         # (n,) and how far it has gone from that course towards the fill (0-1)
    trust: np.ndarray         # (n, 5) what course_weight learns from (columns ACC_SUM ... LOCATED_RUN)
    prev_raw: np.ndarray      # (n, 3) the source's position a frame before last_raw
    prev_vel: np.ndarray      # (n, 3) and its step then
    course_len: np.ndarray    # (n, 2) a lone joint's distances to its two neighbours where its course began
    held_course: np.ndarray   # (n,) bool: that course began where an estimate was given up for a hold
    course_base: np.ndarray   # (n, 3) the parent's step that course_step moves with (parent alone located)
    offset_size: np.ndarray   # (n,) the offset's size where the source last changed (MEET_S)


class BlendSettings(NamedTuple):
    step: float       # reacquire_step_m: how far the blend may move the output off its source in a frame
    omega: float      # the spring's, from blend_half_life_s
    dt: float         # seconds since the last frame
    course_on: bool   # blend_course


class Change(NamedTuple):
    """How a joint's source changed this frame (_spring_blend)."""
    lost: bool            # markers lost
    gave_up: bool         # an estimate given up for a hold: met like a loss
    found_or_lost: bool   # markers lost or back
    jumped: bool          # a fill faster than any joint moves: another source
    spike: bool           # a fill out for one frame and back on its way
    handed: bool          # handed from one fill to another without such a jump
    back: bool            # an estimate back from a hold, on a course


@dataclass
class BlendState:
    """The blend of a limb: its settings (``step``: reacquire_step_m; ``omega``: the spring's, from
    blend_half_life_s), what blend_transitions keeps per joint between frames (``memory``) and blend_frames
    (the last frames and their turns), and the frame clock."""
    memory: BlendMemory
    last_frame: np.ndarray    # (n, 3, 3) the last output bone frame (NaN: none)
    turn_axis: np.ndarray     # (n, 3) the frame's offset where its source changed: a turn about this axis
    turn: np.ndarray          # (n, 3) by this angle (radians, column 0) times the spring's share (1), and its
    #                           velocity (2)
    step: float = 0.0
    omega: float = 0.0
    course_on: bool = True    # blend_course: after a loss, leave the markers' course as course_weight says
    clock: FrameClock = field(default_factory=lambda: FrameClock(DEFAULT_FRAME_S))  # (a limb's: shared with it)

    def __post_init__(self):
        self._memory = tuple(self.memory)  # (as blend_transitions takes it)

    @classmethod
    def empty(cls, n: int, step: float = 0.0, half_life_s: float = 0.0, course: bool = True,
              clock: FrameClock | None = None) -> "BlendState":
        memory = BlendMemory(np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3)),
                             np.zeros((n, 2, 3)), np.full((n, 2), 1 << 30, np.int64), np.zeros(n, np.int64),
                             np.zeros(1, bool), np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3)),
                             np.full(n, np.inf), np.zeros(n), np.zeros((n, 5)), np.zeros((n, 3)), np.zeros((n, 3)),
                             np.full((n, 2), np.nan), np.zeros(n, bool), np.zeros((n, 3)), np.zeros(n))
        return cls(memory, np.full((n, 3, 3), np.nan), np.zeros((n, 3)), np.zeros((n, 3)), step,
                   BLEND_X / half_life_s if half_life_s > 0 else 0.0, course, clock or FrameClock(DEFAULT_FRAME_S))

    @property
    def frame_s(self) -> float:
        return self.clock.frame_s

    def advance_clock(self, time_s: float) -> None:
        """The time since the last frame (FrameClock.advance)."""
        self.clock.advance(time_s)

    def blend(self, positions, status, idx, frames=None) -> None:
        """One frame of the limb's joints ``idx`` (arrays of the whole skeleton), in place; ``frames``, the bone
        frames, are blended too where given (blend_frames, with the spring's half-life)."""
        # (plain tuples: numba reads a NamedTuple of twenty arrays from Python microseconds slower than a tuple)
        m = self.memory
        if frames is not None and self.omega > 0:  # (before blend_transitions, which moves last_status on)
            blend_frames(frames, status, idx, m.last_status, m.has_last, (self.last_frame, self.turn_axis, self.turn),
                         self.omega, self.frame_s)
        blend_transitions(positions, status, idx, self._memory, self.step, self.omega, self.frame_s, self.course_on)


class Blend(LimbFill):
    """The blend as the IK stage's fill, last: the limb's output met without a twitch where a source changed."""

    class Settings(BaseModel):
        reacquire_step_m: float = Field(0.0, ge=0, description=REACQUIRE_HELP)
        blend_half_life_s: float = Field(0.0, ge=0, description=BLEND_HELP)
        blend_course: bool = Field(True, description=BLEND_COURSE_HELP)

    @classmethod
    def wanted(cls, options) -> bool:
        return options.reacquire_step_m > 0 or options.blend_half_life_s > 0

    def __init__(self, limb, options):
        super().__init__(limb, options)
        self.state = BlendState.empty(len(limb.joints), options.reacquire_step_m, options.blend_half_life_s,
                                      options.blend_course, limb.clock)  # (the limb advances it)

    def after(self, frame: LimbFrame) -> None:
        self.state.blend(frame.positions, frame.status, self.limb.joints, frame.frames)


@njit(cache=True)
def spring_step(x, v, omega, dt, decay):
    """One step of a critically damped spring towards 0 from ``x`` at velocity ``v`` (Holden's exact form for any
    ``dt``; ``decay`` = exp(-omega dt)): the new (x, v). For a number or a vector."""
    spring = v + omega * x
    return decay * (x + spring * dt), decay * (v - spring * omega * dt)


@njit(cache=True)
def blend_frames(frames, status, idx, last_status, has_last, turning, omega, dt):
    """A joint's bone frame that changes source (its or a neighbour's markers lost or back, a fill handed to
    another) goes on from the frame it had, and the turn between the two dies out as a critically damped spring
    (the positions' blend, for the bone frames a rig streams), in place: a wrist handed between sliding markers
    and a fill can otherwise turn half a turn in a frame. ``turning``: BlendState's (last_frame, turn_axis,
    turn)."""
    last_frame, turn_axis, turn = turning
    decay = math.exp(-omega * dt)
    n = idx.shape[0]
    this = np.empty((3, 3))
    for k in range(n):
        j = idx[k]
        this[:] = frames[j]
        frame = this
        s, was = status[j], last_status[k]
        if not all_finite(frame):
            last_frame[k] = np.nan
            turn[k, 1] = 0.0
            continue
        # a frame is built from its joint and the joints either side (a bone's frame runs to the next joint, the
        # hand's is the wrist's): a change of source of any of them is one of the frame's
        changed = s != was and s != MISSING and was != MISSING
        for m in (k - 1, k + 1):
            if 0 <= m < n and status[idx[m]] != last_status[m]:
                changed = True
        if has_last[0] and changed and all_finite(last_frame[k]):
            offset = rotation_vector(mm(last_frame[k], frame.T.copy()))  # the old frame, less the new one
            angle = vnorm(offset)
            if angle > 1e-12:
                turn_axis[k] = offset / angle
                turn[k, 0], turn[k, 1], turn[k, 2] = angle, 1.0, 0.0
            else:
                turn[k, 1] = 0.0
        elif turn[k, 1] != 0.0:
            turn[k, 1], turn[k, 2] = spring_step(turn[k, 1], turn[k, 2], omega, dt, decay)
            if abs(turn[k, 1]) < 1e-4:
                turn[k, 1] = 0.0
        if turn[k, 1] != 0.0:
            frame = mm(axis_angle(turn_axis[k], turn[k, 0] * turn[k, 1]), frame)
            frames[j] = frame
        last_frame[k] = frame


@njit(cache=True)
def _take_step(velocity, step, last_step, limit):
    """A source's step becomes its velocity unless it is faster than any joint moves and as far off its own last
    step (a jump, or two fills of one kind that are not one source), in place. (Faster alone is not enough: a
    fast joint filled along a curve leaves its last step by more than the threshold frame after frame, and would
    be met as a jump every frame, standing still.)"""
    if vnorm(step) <= limit or vdist(step, last_step) <= limit:
        velocity[:] = step


@njit(cache=True, inline="always")
def _change(raw, heading, s, was, k, mem, dt):
    """Classify the source's change (Change) and learn from it what course_weight needs."""
    since_loss, trust, last_raw, prev_raw, prev_vel = mem.since_loss, mem.trust, mem.last_raw, mem.prev_raw, mem.prev_vel
    lost = s != LOCATED and was == LOCATED
    gave_up = s == HELD and was == ESTIMATED and since_loss[k] == math.inf
    found_or_lost = (s == LOCATED) != (was == LOCATED)
    jumped = s != LOCATED and was != LOCATED and vdist(raw, heading) > SOURCE_JUMP_M_S * dt
    spike = jumped and s == was and vnorm(raw - (prev_raw[k] + 2.0 * prev_vel[k])) <= SOURCE_JUMP_M_S * dt
    jumped = jumped and not spike
    # handed from one fill to another (estimated, held) without such a jump: the new fill's jump goes into the
    # offset too. A course goes on through a hold; an estimate back from one ends it, and the output goes on
    # from itself at its own step into the estimate, as into returning markers
    handed = s != LOCATED and was != LOCATED and was != MISSING and s != was and not jumped
    trust[k, LOCATED_RUN] = trust[k, LOCATED_RUN] + 1 if s == LOCATED else 0
    if trust[k, LOCATED_RUN] >= 3 and vdist(raw, last_raw[k]) <= SOURCE_JUMP_M_S * dt:  # two markers' steps
        trust[k, ACC_SUM] += vdist(raw, heading) / (dt * dt)  # |acceleration|
        trust[k, ACC_N] += 1
    if s == LOCATED and was != LOCATED and was != MISSING:  # how far the output's course missed the markers
        # at most MISS_SIGMAS of the misses so far: one glitch (frames replayed) must not set the trust for good
        miss = min(vnorm(raw - (heading + mem.offset[k])), MISS_SIGMAS * math.sqrt(_fill_var(trust[k])))
        trust[k, MISS_SQ] += miss * miss
        trust[k, MISS_N] += 1
    back = handed and was == HELD and since_loss[k] < math.inf
    return Change(lost, gave_up, found_or_lost, jumped, spike, handed, back)


@njit(cache=True, inline="always")
def _new_offset(raw, heading, s, was, k, mem, cfg, c):
    """The offset where the source changed: the new source less where the old was heading, so the output goes on
    as it went; eased from rest."""
    offset, offset_vel, since_loss, raw_vel, seen_age = mem.offset, mem.offset_vel, mem.since_loss, mem.raw_vel, \
        mem.seen_age
    step, dt = cfg.step, cfg.dt
    kind = 0 if s == LOCATED else 1
    if since_loss[k] < math.inf:
        # the output left the spring's course for the markers': go on from it, at its own last step (a recall's
        # step can be jitter)
        offset[k] = mem.last_out[k] + mem.out_step[k] - heading
        since_loss[k] = math.inf
    offset[k] -= raw - heading
    since = seen_age[k, kind]  # frames since this kind of source was last seen
    across = (raw - mem.seen_raw[k, kind]) / since  # and its step since then
    if s == LOCATED and since <= FLICKER_FRAMES and vnorm(across) <= SOURCE_JUMP_M_S * dt:
        # markers back after a flicker: their step across it is measured, and the output goes on at that, not at
        # its own step along the course (which, through a fast swing, comes back well off the markers)
        offset[k] = mem.last_out[k] + across - raw
    offset_vel[k] = 0.0  # a new offset, eased from rest
    if c.jumped and s == ESTIMATED and was == ESTIMATED and step > 0 and vnorm(offset[k]) > 0:
        # an estimate that jumps within itself has corrected itself (a rebuild whose partners changed), where a
        # held joint that jumps was taken up by another bone: its offset starts closing at once, at the step cap
        offset_vel[k] = offset[k] * (-step / dt / vnorm(offset[k]))
    if c.found_or_lost and since <= FLICKER_FRAMES:
        _take_step(raw_vel[k], across, raw_vel[k].copy(), SOURCE_JUMP_M_S * dt)
    elif c.jumped:  # the new source's step is unknown: the old one kept would make every next frame a jump too
        raw_vel[k] = 0.0


@njit(cache=True, inline="always")
def _spring_blend(p, s, was, k, mem, cfg, decay, neighbours, scratch):
    """One joint's position ``p`` (status ``s``, ``was`` the frame before) plus its offset, in place; after
    a loss, eased from the markers' course into that (see blend_transitions). ``neighbours``: the joints
    before and after it in the chain, where both are located, or its parent, where that alone is (else NaN);
    ``scratch``: (6, 3), room for the vectors it works with."""
    offset, offset_vel, last_raw, raw_vel, prev_raw, prev_vel = mem.offset, mem.offset_vel, mem.last_raw, \
        mem.raw_vel, mem.prev_raw, mem.prev_vel
    step, omega, dt = cfg.step, cfg.omega, cfg.dt
    kind = 0 if s == LOCATED else 1
    # (rows by index: unpacked, they would be typed as any layout, and compile their callees once more)
    raw, heading, before_raw, before_step, before, last_step = (scratch[0], scratch[1], scratch[2], scratch[3],
                                                                scratch[4], scratch[5])
    raw[:] = p
    for e in range(3):
        heading[e] = last_raw[k, e] + raw_vel[k, e]  # where the source was heading
    before_raw[:] = last_raw[k]  # (the next frame's prev_raw / prev_vel, for its spike test)
    before_step[:] = raw_vel[k]  # (also the markers' last step, at a loss; the estimate's, given up)
    c = _change(raw, heading, s, was, k, mem, dt)
    spring_moved = 0.0
    limit = step  # how far the blend may move the output off its source this frame
    if c.spike:  # (ending a course, as a jump does)
        offset[k] = mem.last_out[k] + prev_vel[k] - raw
        offset_vel[k] = 0.0
        mem.since_loss[k] = math.inf
        raw_vel[k] = (raw - prev_raw[k]) * 0.5
    if c.handed and not c.back:
        offset[k] -= raw - heading
        offset_vel[k] = 0.0
    if was != MISSING and (c.found_or_lost or c.jumped or c.back):
        _new_offset(raw, heading, s, was, k, mem, cfg, c)
        mem.offset_size[k] = vnorm(offset[k])
    else:
        if c.spike or c.handed:
            mem.offset_size[k] = vnorm(offset[k])
        if was != MISSING and not c.handed and not c.spike:  # (a hand-over's jump is not the source's step)
            for e in range(3):  # (before and last_step as room for this step and the last)
                before[e] = raw[e] - last_raw[k, e]
                last_step[e] = last_raw[k, e] - prev_raw[k, e]
            _take_step(raw_vel[k], before, last_step, SOURCE_JUMP_M_S * dt)
        limit = max(step, PACE_SHARE * vnorm(raw_vel[k]))
        if mem.offset_size[k] * dt > limit * MEET_S:
            limit = math.inf
        before[:] = offset[k]
        for e in range(3):
            offset[k, e], offset_vel[k, e] = spring_step(before[e], offset_vel[k, e], omega, dt, decay)
        moved = vdist(offset[k], before)
        if step > 0 and moved > limit:
            for e in range(3):
                offset[k, e] = before[e] + (offset[k, e] - before[e]) * (limit / moved)
        spring_moved = min(moved, limit)
    last_raw[k] = raw
    prev_raw[k] = before_raw
    prev_vel[k] = before_step
    mem.seen_raw[k, kind] = raw
    mem.seen_age[k, kind] = 0
    p += offset[k]
    if (c.lost or c.gave_up) and cfg.course_on and mem.trust[k, ACC_N] > 0:
        _start_course(p, k, mem, neighbours, c.gave_up, before_step)
    elif mem.since_loss[k] < math.inf:
        _follow_course(p, k, mem, cfg, neighbours, limit - spring_moved)
    # a fill further off than that where it takes over is met as ever; from there on the output only may not
    # drift further from it
    if s != LOCATED and was != LOCATED and was != MISSING and not (c.gave_up or c.jumped or c.handed or c.spike):
        _keep_near(p, raw, k, mem, max(MAX_APART_M, vnorm(mem.last_out[k] - before_raw)))


@njit(cache=True, inline="always")
def _start_course(p, k, mem, neighbours, held, step):
    """The markers (or an estimate given up for a hold, ``held``) lost: the output goes on along their last
    ``step``."""
    mem.course[k], mem.course_step[k], mem.since_loss[k], mem.eased[k] = p, step, 0.0, 0.0
    mem.held_course[k] = held
    mem.course_len[k, 0] = vnorm(p - neighbours[0])  # (NaN unless both are located, or the parent alone)
    mem.course_len[k, 1] = vnorm(neighbours[1] - p)
    mem.course_base[k] = 0.0  # (the parent's step that course_step carries, where the parent alone is located)
    if k > 0:
        mem.course_base[k] = mem.out_step[k - 1]


@njit(cache=True, inline="always")
def _follow_course(p, k, mem, cfg, neighbours, room):
    """One frame further along the course after a loss, and as far towards the fill as course_weight says, the
    move at most ``room`` (what the step cap leaves of this frame's)."""
    course, course_step, course_len, course_base, last_out = mem.course, mem.course_step, mem.course_len, \
        mem.course_base, mem.last_out
    mem.since_loss[k] += cfg.dt
    course[k] += course_step[k]
    carried = False
    # A lone joint's course keeps its distances to its located neighbours, turning with them (an elbow swings
    # about the shoulder; its markers' straight course flies off the arm); once one is lost it goes on straight
    # from where it is. Neighbours out of reach of those distances (skin that slid) leave a circle shrunk to a
    # point on their line: there the course moves with their line, as it lay against it the frame before. A joint
    # lost while its parent alone is located (a hand, a toe; or one whose child is lost too) keeps its distance to
    # the parent and moves with it: its step is its markers' last step relative to the parent's then, plus the
    # parent's now; a course begun with the parent lost too is carried once the parent is back, at its distance
    # then. Not where the parent is the limb's root (the hip, the clavicle), which the trunk's skin markers put and
    # shake; never the root's child (k 1), whose neighbours are both given where both are located.
    if all_finite(course_len[k]) and all_finite(neighbours):
        if vnorm(neighbours[1] - neighbours[0]) <= course_len[k, 0] + course_len[k, 1]:
            course[k] = nearest_on_circle(course[k], neighbours[0], neighbours[1], course_len[k, 0],
                                          course_len[k, 1])
        elif all_finite(last_out[k - 1]) and all_finite(last_out[k + 1]):
            rot, shift = line_carry(last_out[k - 1], last_out[k + 1], neighbours[0], neighbours[1])
            course[k] = mv(rot, course[k] - course_step[k]) + shift
    elif k > 1 and np.isnan(course_len[k, 1]) and all_finite(neighbours[0]) and all_finite(last_out[k - 1]):
        change = neighbours[0] - last_out[k - 1] - course_base[k]  # (the parent's step, less the one carried)
        course[k] += change
        course_step[k] += change
        course_base[k] += change
        carried = True
        if np.isnan(course_len[k, 0]):  # (the parent located again: from here on)
            course_len[k, 0] = vnorm(course[k] - neighbours[0])
        course[k] = nearest_on_sphere(course[k], neighbours[0], course_len[k, 0])
    else:
        course_len[k] = np.nan
    if mem.held_course[k]:  # (a hold's course: its step dies out, HOLD_COURSE_S; relative to a parent that carries it)
        fade = math.exp(-cfg.dt / HOLD_COURSE_S)
        if carried:
            course_step[k] = course_base[k] + (course_step[k] - course_base[k]) * fade
        else:
            course_step[k] *= fade
    _ease(p, k, mem, cfg.step, room)


@njit(cache=True, inline="always")
def _ease(p, k, mem, step, room):
    """Move the output from the course towards the fill, as far as course_weight says and ``room`` allows."""
    course, eased = mem.course, mem.eased
    w = course_weight(mem.since_loss[k], mem.trust[k])
    w = 1.0 if w >= EASED else w
    apart = vdist(p, course[k])
    if step > 0 and (w - eased[k]) * apart > room:  # one cap on the two together
        w = eased[k] + max(room, 0.0) / apart
    eased[k] = min(w, 1.0)
    for e in range(3):
        p[e] = course[k, e] + eased[k] * (p[e] - course[k, e])
    if eased[k] == 1.0:
        mem.since_loss[k] = math.inf


@njit(cache=True, inline="always")
def _keep_near(p, raw, k, mem, reach):
    """The output no further than ``reach`` from the fill ``raw`` that stands in (the course and the offset go on
    from there)."""
    apart = vdist(p, raw)
    if apart > reach:
        p[:] = raw + (p - raw) * (reach / apart)
        mem.offset[k] = p - raw
        mem.offset_vel[k] = 0.0
        if mem.since_loss[k] < math.inf:
            mem.course[k] = p


@njit(cache=True)
def course_weight(t, trust):
    """How far the output has gone from the markers' course towards the fill, ``t`` seconds after a loss
    (``trust``: a joint's row of BlendState.trust)."""
    stray = COURSE_K * 0.5 * max(trust[ACC_SUM] / trust[ACC_N], ACCEL_FLOOR) * t * t
    fill_var = _fill_var(trust)
    return stray * stray / (stray * stray + fill_var)


@njit(cache=True, inline="always")
def _fill_var(trust):
    """The fill's mean squared miss where the markers came back (FILL_SD_PRIOR counting as one)."""
    return (FILL_SD_PRIOR * FILL_SD_PRIOR + trust[MISS_SQ]) / (1.0 + trust[MISS_N])


@njit(cache=True)
def _linear_return(p, s, was, last, offset, step):
    """reacquire_step_m alone: returning markers are met from where the estimate ``last`` was, the gap
    closed by at most ``step`` a frame; a joint that is not located has no offset."""
    if s == LOCATED and (was == ESTIMATED or was == HELD) and all_finite(last):
        offset[:] = last - p
    if s != LOCATED:
        offset[:] = 0.0
    size = vnorm(offset)
    if size > 0:
        offset *= min(1.0, max(0.0, (size - step) / size))
        p += offset


@njit(cache=True)
def blend_transitions(positions, status, idx, memory, step, omega, dt, course_on):
    """Meet a joint's change of source without a twitch (inertialization, as game engines do), in place.

    With ``omega`` 0 (reacquire_step_m alone): when a joint's markers come back, start where the estimate
    had it and close the gap by at most ``step`` metres a frame (a rate-limited decaying offset).
    With ``omega`` > 0 (blend_half_life_s): the spring, as the module's docstring tells.
    State per joint: ``last_out`` and ``out_step``, the output's last position and step; ``last_raw`` and
    ``raw_vel``, the source's; ``seen_raw`` and ``seen_age``, the last position of each kind of source
    (0 markers, 1 a fill) and frames since; ``course``, ``course_step``, ``since_loss`` and ``eased``, the
    markers' course after a loss and how far the output has left it; ``course_len``, a lone joint's distances to
    its neighbours where the course began; ``held_course``, whether it began at a hold; ``course_base``, the
    parent's step that the course's step carries (BlendMemory's fields, given as a plain tuple)."""
    mem = BlendMemory(*memory)
    (last_out, out_step, last_raw, raw_vel, seen_raw, seen_age, last_status, has_last, offset, offset_vel, course,
     course_step, since_loss, eased, trust, prev_raw, prev_vel, course_len, held_course, course_base, _) = memory
    cfg = BlendSettings(step, omega, dt, course_on)
    n = idx.shape[0]
    decay = math.exp(-omega * dt)
    neighbours, scratch = np.empty((2, 3)), np.empty((6, 3))
    for k in range(n):
        j = idx[k]
        s = status[j]
        seen_age[k, 0] += 1
        seen_age[k, 1] += 1
        if s == MISSING or not all_finite(positions[j]) or (omega == 0 and not has_last[0]):
            offset[k] = 0.0
            offset_vel[k] = 0.0
            raw_vel[k] = 0.0
            since_loss[k] = math.inf
            # nothing to measure the next steps from (the source's acceleration, the spike test): the position
            # from before this frame, kept, made the next two frames' samples a two-frame and a one-frame step
            last_raw[k] = np.nan
            trust[k, LOCATED_RUN] = 0
        elif omega > 0:
            was = last_status[k] if has_last[0] else MISSING  # the first frame comes from nothing
            neighbours[:] = np.nan
            if 0 < k < n - 1 and status[idx[k - 1]] == LOCATED and status[idx[k + 1]] == LOCATED:
                neighbours[0] = positions[idx[k - 1]]
                neighbours[1] = positions[idx[k + 1]]
            elif 1 < k and status[idx[k - 1]] == LOCATED:  # its parent alone (not the limb's root: _spring_blend)
                neighbours[0] = positions[idx[k - 1]]
            _spring_blend(positions[j], s, was, k, mem, cfg, decay, neighbours, scratch)
        else:
            _linear_return(positions[j], s, last_status[k], last_out[k], offset[k], step)
    for k in range(n):
        for e in range(3):
            out_step[k, e] = positions[idx[k], e] - last_out[k, e]
        last_out[k] = positions[idx[k]]
        last_status[k] = status[idx[k]]
    has_last[0] = True

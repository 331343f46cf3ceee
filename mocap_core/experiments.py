"""The thesis's experiments (chapter 4) as plain functions; `mocap eval` prints and plots them."""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from mocap_core.fill_options import FillOptions, HipOptions
from mocap_core.gapfill import GapFiller
from mocap_core.hip_interpolation import HIP_LANDMARKS, HipInterpolator
from mocap_core.ik.solvers import SolverParams
from mocap_core.localization import JOINT_LANDMARKS, JOINT_OF_LANDMARK
from mocap_core.pipeline import SkeletonPipeline
from mocap_core.profiles import LANDMARK_INDEX, LANDMARKS, Profile
from mocap_core.recordings import Recording
from mocap_core.skeleton import END_SITES, INDEX, JOINTS, Status

# What the worst case keeps (thesis 4.3: "all joints except the end-effectors and the pelvis"). The
# pelvis segment here is the pelvis with spine0 and both hip centres: all four come from the same
# three pelvis markers, and IK chains need a located root.
WORST_CASE_KEEP = frozenset({"pelvis", "spine0", "hip_l", "hip_r"} | END_SITES)
WORST_CASE_REMOVE = np.array([INDEX[j] for j in JOINTS if j not in WORST_CASE_KEEP])

# Thesis Tables 4.2 and 4.3 (ms per frame, C# on an Intel i3 M 370).
THESIS_TIMING_MS = {
    ("jacobian_transpose", False): (0.17, 2.59, 0.6, 0.48, 0.39),
    ("dls", False): (0.17, 4.16, 0.54, 0.43, 0.37),
    ("fabrik", False): (0.17, 3.24, 0.24, 0.23, 0.13),
    ("ccd", False): (0.16, 1.07, 0.41, 0.24, 0.28),
    ("jacobian_transpose", True): (0.17, 23.21, 3.69, 1.86, 3.59),
    ("dls", True): (0.17, 24.69, 3.48, 1.6, 3.65),
    ("fabrik", True): (2.42, 60.41, 22.03, 19.71, 12.23),
    ("ccd", True): (0.16, 5.08, 1.4, 0.72, 1.27),
}


@dataclass
class TimingRow:
    solver: str
    constraints: bool
    frames: int
    min_ms: float
    max_ms: float
    mean_ms: float
    median_ms: float
    std_ms: float
    mean_iterations: float
    mean_residual_mm: float
    max_best_ms: float = float("nan")  # the max over frames of each frame's fastest pass (see below)

    def as_dict(self) -> dict:
        return dict(self.__dict__)


def localize_take(rec: Recording, profile: Profile):
    pipe = SkeletonPipeline(profile, rec.labels, fill_gaps=False)
    chunk = pipe.solve_landmarks(pipe.landmarks(rec.positions))
    return chunk.positions, chunk.frames, chunk.status


def worst_case_timing(localized, solver: str, constraints: bool, params: SolverParams | None = None,
                      repeats: int = 1, fill_options: FillOptions | None = None) -> TimingRow:
    """Time the full-body gap fill of every frame with every joint but the kept ones removed.
    Frame 0 stays complete: the IK chains start from the previous frame's solution (thesis 3.6)."""
    pos0, frames0, status0 = localized
    params = (params or SolverParams())._replace(constraints=constraints)
    passes, iters, resid = [], [], []
    for _ in range(repeats):
        filler = GapFiller(solver, params, options=fill_options or FillOptions())
        times = []
        for f in range(len(pos0)):
            pos, frames, status = pos0[f].copy(), frames0[f].copy(), status0[f].copy()
            if f > 0:
                pos[WORST_CASE_REMOVE] = np.nan
                frames[WORST_CASE_REMOVE] = np.nan
                status[WORST_CASE_REMOVE] = Status.MISSING
            t = time.perf_counter()
            stats = filler.fill(pos, frames, status)
            dt = time.perf_counter() - t
            if f > 0:
                times.append(dt * 1000)
                iters.append(sum(s.iterations for s in stats.values()))
                resid.append(max(s.residual_m for s in stats.values()) * 1000)
        passes.append(times)
    t = np.concatenate(passes)
    # Every pass does exactly the same work (the solve is deterministic), so a frame's fastest pass
    # is its cost without the pauses a shared machine adds; the max of those is the steady worst case.
    best = np.min(passes, axis=0)
    return TimingRow(solver, constraints, len(t), t.min(), t.max(), t.mean(), float(np.median(t)), t.std(),
                     float(np.mean(iters)), float(np.mean(resid)), float(best.max()))


# -- accuracy with gaps (thesis 4.2) ------------------------------------------------------------------------
# Joints that go with another's markers: the hip markers give the pelvis, spine0 and both hip centres.
SEGMENT_OF = {"pelvis": ("pelvis", "spine0", "hip_l", "hip_r")}


def landmarks_of(joint: str) -> list[str]:
    """The landmarks whose loss takes a joint away ("remove by markers"); a landmark name (L_UOA) is
    itself."""
    if joint == "pelvis":  # every hip marker
        return list(HIP_LANDMARKS)
    if joint in LANDMARK_INDEX:
        return [joint]
    base, _, side = joint.rpartition("_")
    if base not in JOINT_LANDMARKS or side not in ("l", "r"):
        raise ValueError(f"cannot remove {joint!r} by markers (joints: pelvis, "
                         f"{', '.join(f'{j}_l/_r' for j in JOINT_LANDMARKS)}; or a landmark such as L_UOA)")
    return [f"{side.upper()}_{name}" for name in JOINT_LANDMARKS[base]]


def measured_joints(hidden: list[str], mode: str = "markers") -> list[str]:
    """The joints a gap run measures for what it hides (``mocap eval gaps --remove``): the joints named (pelvis: its
    segment), or, where only landmarks are named (L_USP), the joints those locate (wrist_l). ValueError, saying
    why, for a name that is neither a joint nor a landmark, for a joint no marker locates (``mode`` "markers"),
    and for landmarks that locate no joint (L_UOA alone)."""
    if not hidden:
        raise ValueError("nothing to remove: name a joint (elbow_l) or a landmark (L_USP)")
    for name in hidden:
        if name not in LANDMARK_INDEX and name not in SEGMENT_OF and name not in INDEX:
            raise ValueError(f"cannot remove {name!r}: neither a joint ({', '.join(JOINTS)}) nor a landmark "
                             f"(such as L_USP)")
        if mode == "markers":
            landmarks_of(name)  # (a joint no marker locates raises)
    joints = [k for j in hidden if j not in LANDMARK_INDEX for k in SEGMENT_OF.get(j, (j,))]
    if not joints:
        located = JOINT_OF_LANDMARK[:, [LANDMARK_INDEX[j] for j in hidden]].any(axis=1)
        joints = [JOINTS[i] for i in np.flatnonzero(located)]
    if not joints:
        verb = "locates" if len(hidden) == 1 else "locate"
        raise ValueError(f"{', '.join(hidden)} {verb} no joint: name one to measure with it (e.g. elbow_l,{hidden[0]})")
    return joints


@dataclass
class GapRun:
    solver: str
    constraints: bool
    mode: str                 # "markers" or "joint"
    joints: list[str]
    frames: np.ndarray        # frame indices of the gap(s)
    estimate: np.ndarray      # (F, len(joints), 3) over the whole take
    status: np.ndarray        # (F, len(joints))
    error_m: np.ndarray       # (len(frames), len(joints)) distance to the reference inside the gap(s)
    windows: list[tuple[int, int]] | None = None  # each gap's [first hidden frame, first frame back)

    def stats(self, j: int = 0) -> dict:
        e = self.error_m[:, j]
        e = e[np.isfinite(e)]
        if not e.size:
            return {k: float("nan") for k in ("min", "max", "mean", "median", "std", "variance", "missing")}
        return {"min": e.min(), "max": e.max(), "mean": e.mean(), "median": float(np.median(e)), "std": e.std(),
                "variance": e.var(), "missing": int((~np.isfinite(self.error_m[:, j])).sum())}


@dataclass
class GapTake:
    """A take as gap_run fills it: its landmarks (F, n_landmarks, 3), the complete take's solve to measure against
    (F, joints, 3), its profile and rate (which paces the fill's blends); the profile's tracking markers (F, n, 3)
    and the segment of each (LandmarkMap.tracking_of), which stay seen; ``partial``: its landmarks kept from some of
    their markers and their mask (PartialMeans.fill over the whole take), which fill those still lost after
    the rebuild and the pose memory, as in the hip node, but not the hidden ones."""
    landmarks: np.ndarray
    reference: np.ndarray
    profile: Profile
    rate_hz: float | None = None
    tracking: np.ndarray | None = None
    tracking_of: tuple[str, ...] = ()
    partial: tuple[np.ndarray, np.ndarray] | None = None


@dataclass
class Gap:
    """``joints`` hidden in frames [start, stop): their landmarks (mode "markers") or the joints themselves
    ("joint"); ``short_gaps`` (length, every), frames: in gaps of ``length`` frames instead, one starting every
    ``every`` frames from ``start`` on (a studio's occlusions are mostly short: a tenth of a second or less)."""
    joints: list[str]
    start: int
    stop: int
    mode: str = "markers"
    short_gaps: tuple[int, int] | None = None


def gap_run(take: GapTake, gap: Gap, solver: str = "ccd", constraints: bool = True,
            hips: HipOptions | None = None, fills: FillOptions | None = None,
            params: SolverParams | None = None) -> GapRun:
    """Hide the gap's joints in the take and fill them with the hip stage's ``hips`` (the pelvis when lost; lost
    limb landmarks rebuilt, recalled, a bony pair whose spacing jumped dropped), the solver and the fills; compare
    with the complete take."""
    from mocap_core.fill_units import MarkerSet
    from mocap_core.landmark_fills import LandmarkFills, fill_take
    from mocap_core.localization import Localizer

    hips, landmarks, rate_hz = hips or HipOptions(), take.landmarks, take.rate_hz
    joints = measured_joints(gap.joints, gap.mode)
    jidx = [INDEX[j] for j in joints]
    windows = gap_windows(gap.start, gap.stop, *(gap.short_gaps or (gap.stop - gap.start,) * 2))
    hidden = np.zeros(len(landmarks), bool)
    for a, b in windows:
        hidden[a:b] = True
    lm = landmarks.copy()
    hidden_lm = np.zeros(lm.shape[:2], bool)
    if gap.mode == "markers":
        for j in gap.joints:
            for name in landmarks_of(j):
                hidden_lm[hidden, LANDMARK_INDEX[name]] = True
        lm[hidden_lm] = np.nan
    lm, _ = HipInterpolator(when_lost=hips.when_lost).fill_landmarks(lm)
    # the profile's landmarks: those the complete take has somewhere
    present = [LANDMARKS[i] for i in np.flatnonzero(np.isfinite(landmarks).all(axis=2).any(axis=0))]
    frame_s = 1.0 / rate_hz if rate_hz else float("nan")
    landmark_fills = LandmarkFills(hips, MarkerSet(take.tracking_of, present))
    lm, rebuilt = fill_take(landmark_fills.fill, lm, tracking=take.tracking, time_s=np.arange(len(lm)) * frame_s)
    if take.partial is not None:  # (given whole, not LandmarkFills' own: it would keep the hidden landmarks from markers)
        kept = take.partial[1] & ~hidden_lm & np.isnan(lm).any(axis=2)
        lm[kept] = take.partial[0][kept]
        rebuilt |= kept
    loc = Localizer(take.profile.body).localize(lm, rebuilt)
    pos, frames, status = loc.positions, loc.frames, loc.status
    if gap.mode == "joint":
        for j in jidx:
            pos[hidden, j] = np.nan
            frames[hidden, j] = np.nan
            status[hidden, j] = Status.MISSING
    filler = GapFiller(solver, (params or SolverParams())._replace(constraints=constraints),
                       options=fills or FillOptions())
    for f in range(len(pos)):
        filler.fill(pos[f], frames[f], status[f], f * frame_s)
    err = np.linalg.norm(pos[hidden][:, jidx] - take.reference[hidden][:, jidx], axis=-1)
    return GapRun(solver, constraints, gap.mode, joints, np.flatnonzero(hidden), pos[:, jidx], status[:, jidx], err,
                  windows)


def gap_windows(start: int, stop: int, length: int, every: int) -> list[tuple[int, int]]:
    """Gaps of ``length`` frames, one starting every ``every`` frames from ``start``, inside [start, stop)."""
    if length < 1 or every < length:
        raise ValueError(f"short gaps of {length} frames every {every}: the length must be at least a frame and "
                         f"no more than the spacing")
    return [(a, min(a + length, stop)) for a in range(start, stop, every)]


def _steps(track: np.ndarray) -> np.ndarray:
    """Per-frame displacement of one point's track (F, 3): F - 1 distances."""
    return np.linalg.norm(np.diff(track, axis=0), axis=-1)


def transition_moves(run: GapRun, reference: np.ndarray, window: int = 3) -> list[dict]:
    """How each joint moves where its markers go (loss) and come back (return), next to its normal
    per-frame motion (the 95th percentile of the reference's per-frame displacement): the largest
    per-frame move within ``window`` frames of any gap's loss and of any return, and the largest move the
    fill adds to the reference's own there (|step of the estimate - step of the reference|), which
    leaves out the actor's own fast moves. NaN where no gap has a loss or return inside the take."""
    out = []
    for k, joint in enumerate(run.joints):
        est, ref = run.estimate[:, k], reference[:, INDEX[joint]]
        step = _steps(est)
        added = _steps(est - ref)  # |step of the estimate - step of the reference|
        normal = float(np.nanpercentile(_steps(ref), 95))
        row = {"joint": joint, "normal_step_m": normal}
        for event, frames in (("loss", [a for a, _ in run.windows]), ("return", [b for _, b in run.windows])):
            spans = [(max(0, f - window), min(len(step), f + window)) for f in frames if 0 < f < len(est)]
            move = max((np.nanmax(step[lo:hi]) for lo, hi in spans if hi > lo), default=float("nan"))
            add = max((np.nanmax(added[lo:hi]) for lo, hi in spans if hi > lo), default=float("nan"))
            row |= {f"{event}_move_m": float(move), f"{event}_ratio": move / normal if normal > 0 else float("nan"),
                    f"{event}_added_ratio": add / normal if normal > 0 else float("nan")}
        out.append(row)
    return out


# -- smoothness on a take's own gaps (no truth needed) -----------------------------------------------------
def turn_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The turn from each bone frame of ``a`` (..., 3, 3) to its twin in ``b``, degrees (NaN where one is unknown)."""
    relative = np.einsum("...ab,...ac->...bc", a, b)
    cos = (np.trace(relative, axis1=-2, axis2=-1) - 1) / 2
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def _turns_deg(frames: np.ndarray) -> np.ndarray:
    """Per-frame turn of one joint's bone frames (F, 3, 3), degrees: F - 1 angles (NaN where a frame is unknown)."""
    return turn_deg(frames[:-1], frames[1:])


@dataclass
class RealGapMoves:
    """How the filled joints of a solved take move, next to each joint's normal per-frame motion (the 95th
    percentile of its moves between two located frames): at every change of status between two frames
    where it has a position (a joint lost, found, or handed from one fill to another), and on every move
    into or out of a filled (estimated or held) frame. The actor's own fast moves are in both; at a change of
    status ``paced`` leaves them out: the move over the larger of the normal motion and the joint's own pace
    there (its moves between located frames nearest before and after the change, within PACE_WINDOW frames).
    A twitch is a move faster than the joint moved on either side of it."""
    changes: np.ndarray     # move / normal at each change of status
    paced: np.ndarray       # move / max(normal, the joint's own pace there) at each change of status
    filled: np.ndarray      # move / normal on each move into or out of a filled frame
    worst: list[tuple[float, str, int]]  # (move / normal, joint, frame) of the largest moves at a change
    # and the bone frames (what a rig streams), where given: on each move into or out of a filled frame, the
    # frame's turn in degrees and that turn over the joint's normal one (95th percentile between located frames)
    turned_deg: np.ndarray = field(default_factory=lambda: np.zeros(0))
    turned: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def row(self) -> dict:
        def over(a, x):
            return int((a > x).sum())
        return {"changes": len(self.changes), "changes_over_1_5": over(self.changes, 1.5),
                "changes_max": float(self.changes.max()) if len(self.changes) else float("nan"),
                "paced_over_1_5": over(self.paced, 1.5),
                "paced_max": float(self.paced.max()) if len(self.paced) else float("nan"),
                "filled_moves": len(self.filled), "filled_over_1_5": over(self.filled, 1.5),
                "filled_over_3": over(self.filled, 3.0),
                "filled_max": float(self.filled.max()) if len(self.filled) else float("nan"),
                "turns": len(self.turned), "turns_over_1_5": over(self.turned, 1.5),
                "turns_over_3": over(self.turned, 3.0), "turns_over_30_deg": over(self.turned_deg, 30.0),
                "turns_max_deg": float(self.turned_deg.max()) if len(self.turned_deg) else float("nan")}


@dataclass
class BlendLag:
    """How far a blend keeps the output off markers that are seen: in the frames where a joint is located in
    both solves, the blended output against the same solve without the blend (the markers' joint there).
    What is left of an offset where markers come back, eased out at the blend's pace."""
    located: int                 # joint-frames located in both
    over_50mm: int
    over_100mm: int
    largest_m: float
    worst: tuple[str, int]       # (joint, frame) of the largest
    # and the bone frames, where given: located joint-frames whose frame is turned off the markers' by over 30
    # degrees, and the largest turn (degrees)
    frames_over_30_deg: int = 0
    frames_largest_deg: float = float("nan")

    def row(self) -> dict:
        return {"located_over_50mm": self.over_50mm, "located_over_100mm": self.over_100mm,
                "located_off_max_m": self.largest_m, "located_frames_over_30_deg": self.frames_over_30_deg,
                "located_frames_off_max_deg": self.frames_largest_deg}

    def sentence(self) -> str:
        turned = "" if not np.isfinite(self.frames_largest_deg) else (
            f" Its bone frames are turned off the markers' by over 30 degrees in {self.frames_over_30_deg} of them, "
            f"at most {self.frames_largest_deg:.0f} degrees.")
        return (f"With the blend, the output is off its seen markers by over 50 mm in {self.over_50mm} of "
                f"{self.located} located joint-frames (over 100 mm in {self.over_100mm}), at most "
                f"{self.largest_m * 1000:.0f} mm ({self.worst[0]} at frame {self.worst[1]}): what is left of an "
                "offset where markers came back, eased out at the blend's pace." + turned)


def blend_lag(blended: np.ndarray, blended_status: np.ndarray, plain: np.ndarray,
              plain_status: np.ndarray, blended_frames: np.ndarray | None = None,
              plain_frames: np.ndarray | None = None) -> BlendLag:
    """``blended`` / ``plain``: (F, joints, 3) positions of one take solved with and without the blend, and
    their (F, joints) status; their (F, joints, 3, 3) bone frames if those are to be compared too."""
    both = (blended_status == Status.LOCATED) & (plain_status == Status.LOCATED)
    off = np.nan_to_num(np.where(both, np.linalg.norm(blended - plain, axis=-1), 0.0))
    f, j = np.unravel_index(int(np.argmax(off)), off.shape)
    lag = BlendLag(int(both.sum()), int((off > 0.05).sum()), int((off > 0.1).sum()), float(off[f, j]),
                   (JOINTS[j], int(f)))
    if blended_frames is not None and plain_frames is not None:
        turned = np.nan_to_num(np.where(both, turn_deg(blended_frames, plain_frames), 0.0))
        lag.frames_over_30_deg, lag.frames_largest_deg = int((turned > 30).sum()), float(turned.max())
    return lag


PACE_WINDOW = 10  # frames either side of a change of status searched for the joint's own pace


def _own_pace(step: np.ndarray, both: np.ndarray, change: int) -> float:
    """The larger of the moves between located frames (``both``) nearest before and after the move ``change``
    of ``step``, within PACE_WINDOW moves (0 when there is none)."""
    before = np.flatnonzero(both[max(0, change - PACE_WINDOW):change])
    after = np.flatnonzero(both[change + 1:change + 1 + PACE_WINDOW])
    pace = step[max(0, change - PACE_WINDOW) + before[-1]] if len(before) else 0.0
    return max(pace, step[change + 1 + after[0]]) if len(after) else pace


def real_gap_moves(positions: np.ndarray, status: np.ndarray, min_located: int = 100,
                   frames: np.ndarray | None = None) -> RealGapMoves:
    """``positions`` (F, joints, 3), ``status`` (F, joints) of a solved take, and its bone ``frames`` (F, joints, 3,
    3) if the turns are wanted too. Joints located in fewer than ``min_located`` frames have no normal motion to
    compare with and are left out."""
    changes, paced, filled, worst, turned_deg, turned = [], [], [], [], [], []
    filled_status = (int(Status.ESTIMATED), int(Status.HELD))
    for j, joint in enumerate(JOINTS):
        step = _steps(positions[:, j])
        located = status[:, j] == Status.LOCATED
        both = located[1:] & located[:-1]
        if both.sum() < min_located:
            continue
        normal = float(np.nanpercentile(step[both], 95))
        if not normal > 0:
            continue
        seen = status[:, j] != Status.MISSING
        change = (status[1:, j] != status[:-1, j]) & seen[1:] & seen[:-1]
        near_fill = np.isin(status[1:, j], filled_status) | np.isin(status[:-1, j], filled_status)
        changes.append(step[change] / normal)
        paced.append(np.array([step[c] / max(normal, _own_pace(step, both, c)) for c in np.flatnonzero(change)]))
        filled.append(step[near_fill & seen[1:] & seen[:-1]] / normal)
        worst += [(float(step[f] / normal), joint, int(f + 1)) for f in np.flatnonzero(change)]
        if frames is not None:
            turn = _turns_deg(frames[:, j])
            normal_turn = np.nanpercentile(turn[both], 95) if np.isfinite(turn[both]).any() else np.nan
            near = near_fill & np.isfinite(turn)
            if normal_turn > 0:
                turned_deg.append(turn[near])
                turned.append(turn[near] / normal_turn)
    worst.sort(reverse=True)
    return RealGapMoves(np.concatenate(changes) if changes else np.zeros(0),
                        np.concatenate(paced) if paced else np.zeros(0),
                        np.concatenate(filled) if filled else np.zeros(0), worst[:5],
                        np.concatenate(turned_deg) if turned_deg else np.zeros(0),
                        np.concatenate(turned) if turned else np.zeros(0))

"""`mocap eval` on real takes: the reports exist and say something that could be wrong."""
import csv
import subprocess
import sys

import numpy as np
import pytest

from mocap_core.experiments import blend_lag, measured_joints, real_gap_moves
from mocap_core.skeleton import INDEX, N_JOINTS, Status
from tests.conftest import REPO, data_file


def mocap(*args):
    return subprocess.run([sys.executable, "-m", "mocap_cli.main", *args], cwd=REPO, capture_output=True, text=True,
                          timeout=600)


def test_eval_gaps_writes_table_csv_and_plots(tmp_path):
    r = mocap("eval", "gaps", "--take", str(data_file("02_qualisys_walking_ezc3d_Qualisys.c3d")), "--profile",
              "qualisys_sports", "--remove", "knee_l,ankle_l", "--from", "0.5", "--to", "1.2", "--solvers",
              "ccd,fabrik", "--constraints", "on", "--report", str(tmp_path))
    assert r.returncode == 0, r.stderr
    rows = list(csv.DictReader(open(tmp_path / "gaps.csv")))
    assert {(x["mode"], x["solver"], x["joint"]) for x in rows} == {
        (m, s, j) for m in ("markers", "joint") for s in ("ccd", "fabrik") for j in ("knee_l", "ankle_l")}
    for x in rows:
        assert 0 <= float(x["min"]) <= float(x["mean"]) <= float(x["max"]) < 1.0  # a leg length
        assert int(x["missing"]) == 0
    md = (tmp_path / "gaps.md").read_text()
    assert "Loss and re-acquisition" in md and "| markers | ccd | on | knee_l |" in md
    for name in ("error_markers_constrained.png", "trajectory_joint_constrained.png"):
        assert (tmp_path / name).stat().st_size > 10_000


def test_eval_timing_reports_every_requested_solver(tmp_path):
    r = mocap("eval", "timing", "--take", str(data_file("02_qualisys_walking_ezc3d_Qualisys.c3d")), "--profile",
              "qualisys_sports", "--solvers", "ccd,dls", "--constraints", "on", "--report", str(tmp_path), "--json")
    assert r.returncode == 0, r.stderr
    rows = list(csv.DictReader(open(tmp_path / "timing.csv")))
    assert [x["solver"] for x in rows] == ["ccd", "dls"]
    for x in rows:
        assert int(x["frames"]) == 3 * 339 and 0 < float(x["min_ms"]) <= float(x["mean_ms"]) <= float(x["max_ms"])


def test_eval_gaps_with_short_gaps(tmp_path):
    """--gap-length/--gap-every: many short gaps instead of one; every gap's loss and return is measured."""
    r = mocap("eval", "gaps", "--take", str(data_file("02_qualisys_walking_ezc3d_Qualisys.c3d")), "--profile",
              "qualisys_sports", "--remove", "elbow_l", "--from", "0.3", "--gap-length", "0.05", "--gap-every", "0.2",
              "--solvers", "ccd", "--constraints", "on", "--mode", "markers", "--swivel", "--blend-half-life", "0.1",
              "--report", str(tmp_path), "--no-plots")
    assert r.returncode == 0, r.stderr
    md = (tmp_path / "gaps.md").read_text()
    assert "hidden 0.05 s (10 frames) in every 0.2 s from 0.30 s to 1.70 s (7 gaps, 70 frames)" in md
    assert "--blend-half-life 0.1" in md
    row = next(line for line in md.splitlines() if line.startswith("| markers | ccd | on | elbow_l | ") and "." in line
               and line.count("|") == 12)
    cells = [float(c) for c in row.split("|")[5:-1]]
    assert all(np.isfinite(cells)) and cells[0] > 0      # normal step, then loss and return moves
    moves = list(csv.DictReader(open(tmp_path / "transitions.csv")))   # the same rows, for `mocap eval targets`
    assert [(x["mode"], x["solver"], x["constraints"], x["joint"]) for x in moves] == [("markers", "ccd", "on",
                                                                                       "elbow_l")]
    assert float(moves[0]["normal_step_m"]) * 1000 == pytest.approx(cells[0], abs=0.05)
    assert float(moves[0]["return_added_ratio"]) == pytest.approx(cells[-1], abs=0.005)
    bad = mocap("eval", "gaps", "--take", str(data_file("02_qualisys_walking_ezc3d_Qualisys.c3d")), "--profile",
                "qualisys_sports", "--gap-length", "0.3", "--gap-every", "0.2", "--report", str(tmp_path))
    assert bad.returncode != 0 and "no more than the spacing" in bad.stderr


def test_what_eval_gaps_measures_for_what_it_hides():
    """Joints are measured as named (pelvis: its segment); landmarks alone, the joints they locate (a styloid: the
    wrist); a name that is neither, a joint no marker locates, and a landmark that locates none are refused,
    saying why, and `mocap eval gaps` says so before it reads the take."""
    assert measured_joints(["knee_l", "ankle_l"]) == ["knee_l", "ankle_l"]
    assert measured_joints(["pelvis"]) == ["pelvis", "spine0", "hip_l", "hip_r"]
    assert measured_joints(["elbow_l", "L_UOA"]) == ["elbow_l"]
    assert measured_joints(["L_USP"]) == ["wrist_l"] and measured_joints(["R_HLE", "R_FAL"]) == ["elbow_r", "ankle_r"]
    assert measured_joints(["spine1"], "joint") == ["spine1"]
    for hidden, mode, says in ((["foo_l"], "markers", "neither a joint"), (["spine1"], "markers", "by markers"),
                               (["L_UOA"], "markers", "locates no joint"), ([], "markers", "nothing to remove")):
        with pytest.raises(ValueError, match=says):
            measured_joints(hidden, mode)
    for remove, says in (("foo_l", "neither a joint"), ("L_UOA", "locates no joint")):
        r = mocap("eval", "gaps", "--remove", remove, "--report", "/nonexistent/never-written")
        assert r.returncode != 0 and says in r.stderr and "Traceback" not in r.stderr, r.stderr


def test_real_gap_moves_known_answer():
    """A joint located for 200 frames at 1 mm a frame, then estimated 10 mm off: one change of status, a
    move 11x its normal one; the frames it is filled move normally."""
    frames = 400
    positions = np.zeros((frames, N_JOINTS, 3))
    status = np.full((frames, N_JOINTS), int(Status.MISSING))
    k = INDEX["elbow_l"]
    positions[:, k, 0] = 0.001 * np.arange(frames)
    status[:, k] = Status.LOCATED
    positions[200:, k, 1] = 0.010
    status[200:, k] = Status.ESTIMATED
    moves = real_gap_moves(positions, status)
    assert len(moves.changes) == 1 and abs(moves.changes[0] - np.hypot(1, 10)) < 1e-6
    assert moves.worst[0][1:] == ("elbow_l", 200)
    assert len(moves.filled) == 200 and np.sum(moves.filled > 1.5) == 1
    assert abs(moves.paced[0] - np.hypot(1, 10)) < 1e-6  # the joint moved 1 mm a frame on either side


def test_real_gap_moves_turns_of_the_bone_frames_known_answer():
    """A joint's frame turns 1 degree a frame while located, then, estimated from frame 200 on, 40 degrees in one
    frame and 1 a frame after: one turn of 40 degrees (40x its normal) among the moves into or out of filled frames."""
    from mocap_core.ik.kernels import axis_angle

    frames = 400
    positions = np.zeros((frames, N_JOINTS, 3))
    positions[:, :, 0] = 0.001 * np.arange(frames)[:, None]
    status = np.full((frames, N_JOINTS), int(Status.LOCATED))
    bone = np.tile(np.eye(3), (frames, N_JOINTS, 1, 1))
    k = INDEX["shoulder_l"]
    angles = np.radians(np.arange(frames) + np.where(np.arange(frames) >= 200, 39.0, 0.0))
    bone[:, k] = [axis_angle(np.array([0.0, 0.0, 1.0]), a) for a in angles]
    status[200:, k] = Status.ESTIMATED
    moves = real_gap_moves(positions, status, frames=bone)
    assert len(moves.turned) == 200 and moves.row()["turns_over_30_deg"] == 1
    assert moves.turned_deg.max() == pytest.approx(40.0) and moves.turned.max() == pytest.approx(40.0)
    assert real_gap_moves(positions, status).row()["turns"] == 0  # (no frames given: no turns measured)


def test_real_gap_moves_leave_the_actors_own_pace_out():
    """A joint that speeds up to 5 mm a frame (5x its normal 1 mm) is lost and found while it moves so, the
    fill going on at that pace: over 1.5x its normal motion at both changes, but not beyond its own pace.
    A second joint's fill jumps 8 mm at its return while it moves at 5 mm: 13 / 5 = 2.6x beyond its pace."""
    frames = 400
    positions = np.zeros((frames, N_JOINTS, 3))
    status = np.full((frames, N_JOINTS), int(Status.LOCATED))
    steps = np.where((np.arange(frames) > 290) & (np.arange(frames) < 310), 0.005, 0.001)
    for joint in ("elbow_l", "knee_r"):
        positions[:, INDEX[joint], 0] = np.cumsum(steps)
        status[300:305, INDEX[joint]] = Status.ESTIMATED
    positions[305:, INDEX["knee_r"], 0] += 0.008  # (the knee's fill lagged 8 mm behind: it jumps at the return)
    moves = real_gap_moves(positions, status)
    assert len(moves.changes) == 4 and np.sum(moves.changes > 1.5) == 4
    assert np.sum(moves.paced > 1.5) == 1 and abs(moves.paced.max() - 13 / 5) < 1e-6
    assert moves.row()["paced_over_1_5"] == 1


def test_blend_lag_known_answer():
    """Two solves of one take: where a joint is located in both, how far the blended one is off the other."""
    frames = 10
    plain = np.zeros((frames, N_JOINTS, 3))
    status = np.full((frames, N_JOINTS), int(Status.LOCATED))
    blended = plain.copy()
    k = INDEX["foot_r"]
    blended[3:6, k, 2] = [0.3, 0.08, 0.02]   # an offset eased out over three frames
    blended[7, INDEX["hand_l"], 0] = 0.9       # far off, but estimated in the blended solve: not counted
    blended_status = status.copy()
    blended_status[7, INDEX["hand_l"]] = Status.ESTIMATED
    lag = blend_lag(blended, blended_status, plain, status)
    assert lag.located == frames * N_JOINTS - 1
    assert (lag.over_50mm, lag.over_100mm) == (2, 1)
    assert lag.largest_m == pytest.approx(0.3) and lag.worst == ("foot_r", 3)
    assert "300 mm (foot_r at frame 3)" in lag.sentence()


def test_eval_real_gaps_on_a_take_with_real_gaps(tmp_path):
    """The Vicon take's own gaps (6.6 % of its markers), no truth: the blend leaves fewer and smaller
    moves where a joint's status changes than the same options without it, and the thesis's method."""
    r = mocap("eval", "real-gaps", "--take", str(data_file("12_vicon_freeform_realgaps_nimble_nick_freeform_001.c3d")),
              "--profile", "vicon53", "--report", str(tmp_path))
    assert r.returncode == 0, r.stderr
    rows = {x["fill"]: x for x in csv.DictReader(open(tmp_path / "real_gaps.csv"))}
    assert list(rows) == ["thesis's method", "studio options without the blend", "studio options"]
    blend, without, thesis = rows["studio options"], rows["studio options without the blend"], rows["thesis's method"]
    assert int(blend["changes"]) > 500
    #
    assert int(blend["changes_over_1_5"]) < int(without["changes_over_1_5"]) < int(thesis["changes_over_1_5"]) / 5
    assert float(blend["changes_max"]) <= float(without["changes_max"]) < 3 < float(thesis["changes_max"])
    # beyond the joints' own pace (the actor's fast moves left out) the blend's few are almost all gone
    assert int(blend["paced_over_1_5"]) < int(without["paced_over_1_5"]) < int(thesis["paced_over_1_5"])
    assert float(blend["paced_max"]) <= float(blend["changes_max"])
    assert int(blend["filled_over_3"]) == 0 < int(thesis["filled_over_3"])
    # the bone frames a rig streams turn less at the fills than the thesis's method's, and far less with the
    # blend's frames, at a cost the sentence gives:
    # located frames turned off their markers' while an offset eases out (924, 796 of them on the left arm,
    # whose wrist markers slide and flip its located frames)
    assert int(blend["turns_over_3"]) * 2 < int(without["turns_over_3"]) < int(thesis["turns_over_3"])
    assert int(blend["turns_over_30_deg"]) * 2 < int(without["turns_over_30_deg"]) < int(thesis["turns_over_30_deg"])
    assert 0 < int(blend["located_frames_over_30_deg"]) < 0.05 * 27744
    # and it does not keep the output far off markers that are seen
    assert int(blend["located_over_100mm"]) < 250 and float(blend["located_off_max_m"]) < 0.6
    assert without["located_over_100mm"] == ""
    assert "located joint-frames" in (tmp_path / "real_gaps.md").read_text()
    assert (tmp_path / "moves_at_changes.png").stat().st_size > 10_000


def test_eval_real_gaps_on_a_take_without_gaps_says_so(tmp_path):
    r = mocap("eval", "real-gaps", "--take", str(data_file("02_qualisys_walking_ezc3d_Qualisys.c3d")), "--profile",
              "qualisys_sports", "--report", str(tmp_path))
    assert r.returncode == 0, r.stderr
    assert "no gaps to measure" in (tmp_path / "real_gaps.md").read_text()
    assert "nothing to measure" in r.stderr
    assert not (tmp_path / "moves_at_changes.png").exists()


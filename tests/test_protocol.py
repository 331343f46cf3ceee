"""The biomechanics protocol on a real take: a static trial (the karate take's stillest second) calibrates the subject,
a movement trial without the knee, ankle and elbow markers, and a profile without their landmarks, is solved with it
through the CLI; the static trial's markers ride their body segments' bones. On a synthetic one with clusters: knees
found from a range-of-motion trial's motion."""
from __future__ import annotations

import csv
import re
import subprocess
import sys

import numpy as np
import pytest
import yaml

from mocap_core.experiments import localize_take
from mocap_core.fit.calibration import calibrate, is_static
from mocap_core.fit.protocol import stillest_second
from mocap_core.fit.subject import load_subject
from mocap_core.profiles import PROFILE_DIR, load_profile
from mocap_core.recordings import Recording, read_recording, write_c3d
from mocap_core.skeleton import INDEX, JOINTS
from mocap_core.synthetic import THIGH, UPPER_ARM, running_take
from tests.conftest import REPO, data_file

ANATOMICAL = {"LKNE", "RKNE", "LANK", "RANK", "LELB", "RELB"}   # the karate set's knee, ankle and elbow markers


@pytest.fixture(scope="module")
def karate():
    rec = read_recording(data_file("08_cmu_135_02_karate_kata.c3d"))
    return rec.slice(0, int(12 * rec.rate_hz)), load_profile("cmu41")


def static_trial(rec):
    first, sway = stillest_second(rec.positions.astype(np.float64), rec.rate_hz)
    assert sway < 0.03, "the karate take stands still for a second near its start"
    return rec.slice(first, first + int(rec.rate_hz))


def test_a_static_trials_markers_ride_their_segments_bones(karate):
    """Standing still, a marker strays little on every bone near it: the profile's anatomy says which it rides (the
    knee marker the femur, the elbow marker the humerus, the shoulder marker the shoulder blade)."""
    rec, profile = karate
    still = static_trial(rec)
    assert is_static(still.positions) and not is_static(rec.positions)
    subject = calibrate(still.positions, still.labels, profile, still.rate_hz)
    bone = dict(zip(subject.labels, (JOINTS[b] if b >= 0 else None for b in subject.marker_bone)))
    for label, segment in zip(profile.columns(still.labels), profile.marker_bones(still.labels)):
        if segment:
            assert bone[label] in segment, f"{label} rides {bone[label]}, not its segment's {segment}"
    assert (bone["LKNE"], bone["LELB"], bone["LSHO"], bone["LFRM"]) == ("hip_l", "shoulder_l", "clavicle_l", "elbow_l")


def mocap(*args):
    done = subprocess.run([sys.executable, "-m", "mocap_cli.main", *args], cwd=REPO, capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    return done


@pytest.mark.timeout(900)
def test_static_then_movement_round_trip(karate, tmp_path):
    """`mocap calibrate` on the static trial, then `mocap solve --subject` (the studio stages) on a movement trial
    whose profile lacks the knee, ankle and elbow landmarks: every joint in every frame, the knees and ankles where
    the landmarks put them in the complete take."""
    rec, profile = karate
    write_c3d(static_trial(rec), tmp_path / "static.c3d")
    keep = [k for k, x in enumerate(rec.labels) if x.split(":")[-1] not in ANATOMICAL]
    write_c3d(Recording([rec.labels[k] for k in keep], rec.positions[:, keep], rec.rate_hz), tmp_path / "move.c3d")
    doc = yaml.safe_load((PROFILE_DIR / "cmu41.yaml").read_text())
    doc["name"] = "cmu41_clusters"
    doc["landmarks"] = {lm: v for lm, v in doc["landmarks"].items() if v not in ANATOMICAL}
    (tmp_path / "clusters.yaml").write_text(yaml.safe_dump(doc))

    mocap("calibrate", str(tmp_path / "static.c3d"), "--profile", "cmu41", "-o", str(tmp_path / "subject.yaml"))
    done = mocap("solve", str(tmp_path / "move.c3d"), "--profile", str(tmp_path / "clusters.yaml"), "--subject",
                 str(tmp_path / "subject.yaml"), "--joints-out", str(tmp_path / "out.csv"), "--quiet")
    assert "no landmark of profile cmu41_clusters locates elbow_l, elbow_r, knee_l" in done.stderr

    rows = list(csv.DictReader(open(tmp_path / "out.csv")))
    assert len(rows) == rec.n_frames
    assert all(r[f"{j}.status"] != "missing" for r in rows for j in JOINTS), "a joint missing in some frame"
    located = localize_take(rec, profile)[0]
    for j in ("knee_l", "knee_r", "ankle_l", "ankle_r"):
        got = np.array([[float(r[f"{j}.{a}"]) for a in "xyz"] for r in rows])
        assert np.linalg.norm(got - located[:, INDEX[j]], axis=1).mean() < 0.02, j

    explained = mocap("profile", "explain", "--profile", str(tmp_path / "clusters.yaml"), "--subject",
                      str(tmp_path / "subject.yaml")).stdout
    assert "from the subject's markers alone: elbow_l, elbow_r, knee_l, ankle_l, knee_r, ankle_r" in explained
    checked = mocap("check", str(tmp_path / "move.c3d"), "--profile", str(tmp_path / "clusters.yaml"), "--subject",
                    str(tmp_path / "subject.yaml"), "--report", str(tmp_path / "check"), "--no-plots").stdout
    joints = checked.split("## Joints the profile cannot locate")[1].split("##")[0]
    assert "knee_l: placed by subject" in joints and "needs" not in joints


@pytest.mark.timeout(900)
def test_eval_protocol_reports_the_static_trial_and_the_centres(tmp_path):
    """`mocap eval protocol` on the karate take's first 8 s and the walk (which never stands still)."""
    data_file("02_qualisys_walking_ezc3d_Qualisys.c3d")
    mocap("eval", "protocol", "--takes", "karate,qualisys_walk", "--seconds", "8", "--report", str(tmp_path))
    rows = list(csv.DictReader(open(tmp_path / "protocol.csv")))
    karate = [r for r in rows if r["take"] == "karate"]
    assert {(r["variant"], r["method"], r["subject"]) for r in karate} == {
        (v, m, s) for v in ("landmarks_off", "clusters", "worst", "worst_movement") for m in ("studio_subject", "fit_subject")
        for s in ("static", "complete")}
    assert all(float(r["every_joint_pct"]) == 100 for r in karate)
    text = (tmp_path / "protocol.md").read_text()
    assert "| qualisys_walk | none (stillest second sways" in text
    assert "| karate | hip_l | no |" in text and "moved" in text   # a kata's hips move too little to place them


def test_calibrate_says_where_the_motion_puts_the_joints(tmp_path):
    """`mocap calibrate` on a take with motion logs each functional centre, here refused for too little motion."""
    done = mocap("calibrate", str(data_file("08_cmu_135_02_karate_kata.c3d")), "--profile", "cmu41", "--seconds", "8",
                 "-o", str(tmp_path / "actor.yaml"))
    assert "a static trial" not in done.stderr
    hips = [line for line in done.stderr.splitlines() if "from motion: hip_l" in line]
    assert hips and re.search(r"it could be \d+ mm off \(at most 20\).*range-of-motion trial", hips[0]), hips


def cluster_trial(tmp_path, swing: str):
    """A synthetic runner with thigh, shank, upper arm and forearm clusters and no knee, ankle or elbow markers (a
    movement trial), its joints bending as in running or through a range-of-motion trial; a profile without the knee,
    ankle and elbow landmarks that lists the clusters under tracking. -> (take, profile path, true joint centres)."""
    rec, truth = running_take(12, 100, clusters=True, swing=swing, skin_m=0.001)
    keep = [k for k, x in enumerate(rec.labels) if x[2:] not in GONE]
    take = tmp_path / f"{swing}.c3d"
    write_c3d(Recording([rec.labels[k] for k in keep], rec.positions[:, keep], rec.rate_hz), take)
    doc = yaml.safe_load((PROFILE_DIR / "paf_running.yaml").read_text())
    doc["name"] = "paf_clusters"
    doc["landmarks"] = {lm: v for lm, v in doc["landmarks"].items() if lm[2:] not in GONE}
    doc["tracking"] = {f"{s}_{segment}": [f"{s}_{plate}{k}" for k in (1, 2, 3)] for s in "LR"
                       for segment, plate in (("thigh", "THI"), ("shank", "SHK"), ("upper_arm", "UAR"),
                                              ("forearm", "FAR"))}
    (tmp_path / "paf_clusters.yaml").write_text(yaml.safe_dump(doc))
    return take, tmp_path / "paf_clusters.yaml", truth


GONE = ("FLE", "TTC", "FAL", "HLE", "HME", "UOA")   # the PAF set's knee, ankle and elbow markers
FROM_MOTION = ("knee_l", "knee_r", "elbow_l", "elbow_r")


@pytest.mark.timeout(600)
def test_knees_and_elbows_no_landmark_locates_come_from_a_range_of_motion_trial(tmp_path):
    """Known answer: calibrated on a range-of-motion trial whose profile has no knee or elbow landmarks, the subject
    has knees and elbows where the clusters' motion puts them (and so the forearm down to the hand); a running trial
    solved with it has them in every frame, near the truth. A running trial alone bends the knees too little for its
    own clusters' wobble: refused, with the message."""
    rom, profile, _ = cluster_trial(tmp_path, "range_of_motion")
    run, _, truth = cluster_trial(tmp_path, "running")
    done = mocap("calibrate", str(rom), "--profile", str(profile), "-o", str(tmp_path / "rom.yaml"))
    assert "from motion: knee_l found" in done.stderr and "the subject has it from here" in done.stderr
    subject = load_subject(tmp_path / "rom.yaml")
    assert set(subject.from_motion) == set(FROM_MOTION)
    assert subject.known[[INDEX[j] for j in (*FROM_MOTION, "wrist_l", "hand_r")]].all()
    lengths = subject.lengths()
    assert abs(lengths[INDEX["knee_l"]] - THIGH) < 0.01 and abs(lengths[INDEX["elbow_l"]] - UPPER_ARM) < 0.01

    for how in ((), ("--fit",)):
        out = tmp_path / f"out{len(how)}.csv"
        mocap("solve", str(run), "--profile", str(profile), "--subject", str(tmp_path / "rom.yaml"), *how,
              "--allow-missing", "--joints-out", str(out), "--quiet")
        rows = list(csv.DictReader(open(out)))
        for j in FROM_MOTION:
            assert all(r[f"{j}.status"] != "missing" for r in rows), (how, j)
            got = np.array([[float(r[f"{j}.{a}"]) for a in "xyz"] for r in rows])
            assert np.linalg.norm(got - truth[:, INDEX[j]], axis=1).mean() < 0.01, (how, j)
    explained = mocap("profile", "explain", "--profile", str(profile), "--subject", str(tmp_path / "rom.yaml")).stdout
    assert "motion put the joint (no landmark did): elbow_l, elbow_r, knee_l" in explained

    done = mocap("calibrate", str(run), "--profile", str(profile), "-o", str(tmp_path / "run.yaml"))
    knees = [line for line in done.stderr.splitlines() if "from motion: knee_l" in line]
    assert knees and re.search(r"it could be \d+ mm off \(at most 20\).*range-of-motion trial", knees[0]), knees
    assert not load_subject(tmp_path / "run.yaml").known[INDEX["knee_l"]]

"""The rigid-skeleton fit as a node (launch/studio_fit.yaml) and through `mocap solve --fit`, on the real take
with real gaps."""
import csv
import re
import subprocess
import sys

import numpy as np
import yaml

from mocap_core.fit.compare import bone_lengths
from mocap_core.joints_csv import read_joints_csv
from mocap_core.skeleton import Status
from tests.conftest import REPO, data_file, launched

TAKE = "12_vicon_freeform_realgaps_nimble_nick_freeform_001.c3d"


def test_fit_graph_calibrates_live_and_then_solves_every_joint(tmp_path):
    """The calibration runs beside the frame path: every frame of the take comes out, the localization's (joints
    missing in the real gaps) until the first calibration is taken up, the whole rigid skeleton from then on."""
    lf = yaml.safe_load((REPO / "launch" / "studio_fit.yaml").read_text())
    for node in lf["nodes"]:
        if node["id"] == "source":
            node["params"] = {"path": str(data_file(TAKE))}
        if node["id"] == "fit":
            node.setdefault("params", {})["save_subject"] = str(tmp_path / "actor.yaml")
        if node["id"] == "log":
            node["params"]["path"] = str(tmp_path / "solved.csv")
        if node["id"] == "viewer":
            node["params"]["port"] = 0
    with launched(tmp_path, yaml.safe_dump(lf), "--until-done") as g:
        g.proc.wait(timeout=180)
        assert g.proc.returncode == 0, g.log()
    with open(tmp_path / "solved.csv") as f:
        rows = list(csv.DictReader(f))
    assert [int(r["frame"]) for r in rows] == list(range(1101))
    assert "calibrated the subject" in g.log()
    missing = np.array([int(r["missing"]) for r in rows])
    assert missing[:240].sum() > 0  # (the first calibration after 2 s)
    taken_up = int(re.search(r"calibrated the subject .* fitted from frame (\d+) on", g.log()).group(1))
    assert taken_up >= 240 and (missing[taken_up:] == 0).all()
    assert "Traceback" not in g.log()


def test_solve_fit_keeps_every_bone_and_reuses_a_subject(tmp_path):
    subject, out = tmp_path / "actor.yaml", tmp_path / "joints.csv"
    r = subprocess.run([sys.executable, "-m", "mocap_cli.main", "calibrate", str(data_file(TAKE)), "--profile",
                        "vicon53", "-o", str(subject)], cwd=REPO, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "markers on a bone" in r.stderr and yaml.safe_load(subject.read_text())["profile"] == "vicon53"
    r = subprocess.run([sys.executable, "-m", "mocap_cli.main", "solve", str(data_file(TAKE)), "--profile", "vicon53",
                        "--fit", "--subject", str(subject), "--joints-out", str(out), "--quiet"], cwd=REPO,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    frames, _, pos, status = read_joints_csv(out)
    assert len(frames) == 1101 and (status != Status.MISSING).all()
    lengths = bone_lengths(pos)
    assert np.abs(lengths / np.median(lengths, axis=0) - 1).max() < 0.001  # float32 CSV, rigid bones
    r = subprocess.run([sys.executable, "-m", "mocap_cli.main", "solve", str(data_file(TAKE)), "--profile", "vicon53",
                        "--fit", "--subject", str(tmp_path / "nobody.yaml"), "--joints-out", str(out)], cwd=REPO,
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "mocap calibrate" in r.stderr


def test_the_graph_fits_each_limb_to_a_subjects_markers_as_the_offline_solve_does(tmp_path):
    """ik_gapfill nodes given a subject file read markers/raw too and fit each limb to the markers riding it: the
    card's graph (a process per stage) outputs what the offline solve with that subject does, in the thesis's worst
    case (from frame 60 only the pelvis, head, hand and toe markers), where the markers move the limbs."""
    from mocap_core.fit.calibration import calibrate
    from mocap_core.pipeline import SkeletonPipeline
    from mocap_core.profiles import load_profile
    from mocap_core.recordings import read_recording, write_c3d
    from messages import decode
    from nodes.bags import read_bag
    from tests.conftest import pipeline_graph
    from tests.core.test_rigid_chain import _worst_case

    rec = read_recording(data_file("02_qualisys_walking_ezc3d_Qualisys.c3d"))
    prof = load_profile("qualisys_sports")
    subject = calibrate(rec.positions, rec.labels, prof, rec.rate_hz)
    subject.save(tmp_path / "actor.yaml")
    frames = 150
    hidden = _worst_case(rec, prof, 60)[:frames]
    take = tmp_path / "worst.c3d"
    write_c3d(type(rec)(rec.labels, hidden.astype(np.float32), rec.rate_hz, rec.source), take)
    bag = tmp_path / "solved.mcap"
    source = f"{{path: {take}, max_frames: {frames}, lockstep_topic: skeleton/solved, lockstep_timeout_s: 30}}"
    graph = pipeline_graph(source, extra=f"  - {{id: rec, kind: recorder, params: {{path: {bag}, "
                                         f"topics: [skeleton/solved]}}}}", retarget="{max_wait_ms: 5000}")
    for limb in ("torso", "left_arm", "right_arm", "left_leg", "right_leg"):
        graph = graph.replace(f"{{limb: {limb}}}", f"{{limb: {limb}, subject: {tmp_path / 'actor.yaml'}}}")
    with launched(tmp_path, graph, "--until-done") as g:
        g.proc.wait(timeout=180)
        assert g.proc.returncode == 0, g.log()
    solved = sorted((decode(x.data, x.topic) for x in read_bag(bag, ["skeleton/solved"])), key=lambda m: m.header.frame)
    assert [m.header.frame for m in solved] == list(range(frames))
    graph_pos = np.stack([m.positions for m in solved]).astype(np.float64)
    offline = {}
    for with_markers in (True, False):
        pipe = SkeletonPipeline(prof, rec.labels, rate_hz=rec.rate_hz)
        pipe.use(subject if with_markers else subject.__class__(**{**subject.__dict__, "labels": []}))
        offline[with_markers] = np.concatenate([c.positions for c in pipe.run(hidden.astype(np.float64))])
    assert np.nanmax(np.abs(graph_pos - offline[True])) < 1e-3
    assert np.nanmax(np.abs(offline[False] - offline[True])) > 0.01  # (the markers moved the limbs)


def solved_with_subject(tmp_path, take, profile, subject, frames: int) -> list:
    """The card's graph on ``take`` through ``profile``, each IK node with ``subject``: its skeleton/solved messages."""
    from messages import decode
    from nodes.bags import read_bag
    from tests.conftest import pipeline_graph

    bag = tmp_path / "solved.mcap"
    source = f"{{path: {take}, max_frames: {frames}, lockstep_topic: skeleton/solved, lockstep_timeout_s: 30}}"
    graph = pipeline_graph(source, profile=str(profile),
                           extra=f"  - {{id: rec, kind: recorder, params: {{path: {bag}, topics: [skeleton/solved]}}}}",
                           retarget="{max_wait_ms: 5000}")
    for limb in ("torso", "left_arm", "right_arm", "left_leg", "right_leg"):
        graph = graph.replace(f"{{limb: {limb}}}", f"{{limb: {limb}, subject: {subject}}}")
    with launched(tmp_path, graph, "--until-done") as g:
        g.proc.wait(timeout=180)
        assert g.proc.returncode == 0, g.log()
    solved = [decode(x.data, x.topic) for x in read_bag(bag, ["skeleton/solved"])]
    assert len(solved) == frames
    return solved


def test_the_graph_solves_a_movement_trial_with_a_static_trials_subject(tmp_path):
    """The biomechanics protocol live: a subject from the karate take's still second, then the card's graph on the
    take without its knee, ankle and elbow markers, through a profile without their landmarks: every joint in every
    frame (the subject's markers place what no landmark does)."""
    from mocap_core.fit.calibration import calibrate
    from mocap_core.fit.protocol import stillest_second
    from mocap_core.profiles import PROFILE_DIR, load_profile
    from mocap_core.recordings import read_recording, write_c3d
    from tests.test_protocol import ANATOMICAL

    rec = read_recording(data_file("08_cmu_135_02_karate_kata.c3d"))
    first, _ = stillest_second(rec.positions[:int(6 * rec.rate_hz)].astype(np.float64), rec.rate_hz)
    still = rec.slice(first, first + int(rec.rate_hz))
    calibrate(still.positions, still.labels, load_profile("cmu41"), rec.rate_hz).save(tmp_path / "actor.yaml")
    keep = [k for k, x in enumerate(rec.labels) if x.split(":")[-1] not in ANATOMICAL]
    frames = 150
    take = tmp_path / "move.c3d"
    write_c3d(type(rec)([rec.labels[k] for k in keep], rec.positions[600:600 + frames, keep], rec.rate_hz), take)
    doc = yaml.safe_load((PROFILE_DIR / "cmu41.yaml").read_text())
    doc["landmarks"] = {lm: v for lm, v in doc["landmarks"].items() if v not in ANATOMICAL}
    (tmp_path / "clusters.yaml").write_text(yaml.safe_dump({**doc, "name": "clusters"}))
    solved = solved_with_subject(tmp_path, take, tmp_path / "clusters.yaml", tmp_path / "actor.yaml", frames)
    assert all((np.asarray(m.status) != Status.MISSING).all() for m in solved), "a joint missing in some frame"


def test_the_graph_solves_knees_and_elbows_found_from_motion(tmp_path):
    """A subject whose knees and elbows a range-of-motion trial's motion put (no landmark does), then the card's graph
    on a running trial: those joints in every frame, near the synthetic runner's true centres."""
    from mocap_core.fit.calibration import calibrate
    from mocap_core.profiles import load_profile
    from mocap_core.recordings import read_recording
    from mocap_core.skeleton import INDEX
    from tests.test_protocol import FROM_MOTION, cluster_trial

    rom, profile, _ = cluster_trial(tmp_path, "range_of_motion")
    run, _, truth = cluster_trial(tmp_path, "running")
    rec = read_recording(rom)
    subject = calibrate(rec.positions, rec.labels, load_profile(profile), rec.rate_hz)
    assert set(subject.from_motion) == set(FROM_MOTION)
    subject.save(tmp_path / "actor.yaml")
    frames = 150
    solved = solved_with_subject(tmp_path, run, profile, tmp_path / "actor.yaml", frames)
    joints = [INDEX[j] for j in FROM_MOTION]
    for m in solved:
        assert (np.asarray(m.status)[joints] != Status.MISSING).all(), m.header.frame
        assert np.linalg.norm(m.positions[joints] - truth[m.header.frame, joints], axis=1).max() < 0.03

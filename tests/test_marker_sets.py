"""A newcomer's marker set through the CLI: the profile found from the labels, joints a profile cannot locate
named with what they need, several actors refused; each with its message and exit code."""
import subprocess
import sys

import pytest

from tests.conftest import REPO, data_file

KARATE = "08_cmu_135_02_karate_kata.c3d"
NO_KNEES = """name: no_knees
landmarks:
  SACR: mean(LBWT, RBWT)
  L_IAS: LFWT
  R_IAS: RFWT
  TV2: C7
  TV12: T10
  SME: STRN
  SGL: mean(LFHD, RFHD)
  L_HEAD: LFHD
  R_HEAD: RFHD
  L_SAE: LSHO
  R_SAE: RSHO
  L_HLE: LELB
  R_HLE: RELB
  L_RSP: LWRA
  L_USP: LWRB
  R_RSP: RWRA
  R_USP: RWRB
  L_HM2: LFIN
  R_HM2: RFIN
  L_FAL: LANK
  R_FAL: RANK
  L_FCC: LHEE
  R_FCC: RHEE
  L_FM2: LTOE
  R_FM2: RTOE
"""


def mocap(*args, timeout=300):
    return subprocess.run([sys.executable, "-m", "mocap_cli.main", *args], cwd=REPO, capture_output=True, text=True,
                          timeout=timeout)


def test_solve_without_a_profile_uses_the_one_the_labels_fit(tmp_path):
    r = mocap("solve", str(data_file(KARATE)), "--joints-out", str(tmp_path / "j.csv"), "--quiet")
    assert r.returncode == 0, r.stderr
    assert "profile auto: cmu41 fits the labels" in r.stderr


def test_a_profile_that_cannot_locate_some_joints_is_refused_and_named(tmp_path):
    profile = tmp_path / "no_knees.yaml"
    profile.write_text(NO_KNEES)
    out = tmp_path / "j.csv"
    r = mocap("solve", str(data_file(KARATE)), "--profile", str(profile), "--joints-out", str(out), "--quiet")
    assert r.returncode == 1 and not out.exists()
    assert "knee_l: needs L_FLE (left femur, lateral epicondyle (outside of the knee))" in r.stderr
    assert "--allow-missing" in r.stderr and "Traceback" not in r.stderr
    r = mocap("solve", str(data_file(KARATE)), "--profile", str(profile), "--joints-out", str(out), "--quiet",
              "--allow-missing")
    assert r.returncode == 0 and "never located: knee_r: needs R_FLE" in r.stderr
    r = mocap("check", str(data_file(KARATE)), "--profile", str(profile), "--no-plots", "--report", str(tmp_path))
    assert r.returncode == 0 and "- ankle_l: needs L_FLE" in r.stdout
    check = {line for line in r.stdout.splitlines() if line.startswith("- ") and ": needs " in line}
    r = mocap("profile", "explain", "--profile", str(profile))  # the same words as check
    assert r.returncode == 0 and check and check <= set(r.stdout.splitlines()), r.stdout[-800:]


def test_a_take_of_several_actors_is_solved_one_actor_at_a_time(tmp_path):
    import numpy as np

    from mocap_core.joints_csv import read_joints_csv
    from mocap_core.recordings import crowd, read_recording, write_c3d

    path = tmp_path / "two_actors.c3d"
    write_c3d(crowd(read_recording(data_file(KARATE)).slice(0, 240), ["actor1", "actor2"]), path)
    for profile in ("auto", "cmu41"):
        r = mocap("solve", str(path), "--profile", profile, "--joints-out", str(tmp_path / "j.csv"), "--quiet")
        assert r.returncode == 0, (profile, r.stderr)
        assert "2 actors in the take (actor1, actor2)" in r.stderr
        one, two = (read_joints_csv(tmp_path / f"j.{a}.csv")[2] for a in ("actor1", "actor2"))
        seen = np.isfinite(one).all(axis=-1)
        assert seen.mean() > 0.95 and (seen == np.isfinite(two).all(axis=-1)).all()
        assert np.allclose(two[seen] - one[seen], [3, 0, 0], atol=1e-5)   # the copy 3 m along x, solved alike
    # a subject file each, which the solve reads back by the actor's name
    r = mocap("calibrate", str(path), "-o", str(tmp_path / "actor.yaml"))
    assert r.returncode == 0, r.stderr
    r = mocap("solve", str(path), "--subject", str(tmp_path / "actor.{actor}.yaml"), "--joints-out",
              str(tmp_path / "fit.csv"), "--quiet")
    assert r.returncode == 0, r.stderr
    one, two = (read_joints_csv(tmp_path / f"fit.{a}.csv")[2] for a in ("actor1", "actor2"))
    seen = np.isfinite(one).all(axis=-1)
    assert seen.mean() > 0.95 and np.allclose(two[seen] - one[seen], [3, 0, 0], atol=1e-4)


def test_profile_explain_says_where_each_landmark_is_and_what_it_locates():
    r = mocap("profile", "explain", "--profile", "cmu41")
    assert r.returncode == 0, r.stderr
    text = r.stdout
    assert "L_FLE   left femur, lateral epicondyle (outside of the knee)" in text
    block = text[text.index("L_SAE"):text.index("R_SAE")]
    assert "without it: shoulder_l" in block and "cmu41: LSHO" in block


TAKES = ["02_qualisys_walking_ezc3d_Qualisys.c3d", "03_sprint_start_BTK_SprintMotion.trc", KARATE,
         "12_vicon_freeform_realgaps_nimble_nick_freeform_001.c3d", "13_qualisys_dance_walk_mocaptoolbox_mcdemodata.mat"]


@pytest.mark.parametrize("take", TAKES)
def test_profile_init_drafts_a_profile_that_locates_what_the_shipped_one_does(tmp_path, take):
    """No edits: the draft, as written, locates at least 90 % of the joint-frames the shipped profile locates."""
    from mocap_core.localization import Localizer
    from mocap_core.profiles import detect_profile, load_profile
    from mocap_core.recordings import read_recording

    out = tmp_path / "draft.yaml"
    r = mocap("profile", "init", str(data_file(take)), "-o", str(out))
    assert r.returncode == 0, r.stderr
    rec = read_recording(data_file(take))
    positions = rec.positions[:1200].astype(float)
    located = {}
    for name, profile in (("draft", load_profile(out)), ("shipped", detect_profile(rec.labels))):
        lm = profile.resolve(rec.labels).apply(positions)
        located[name] = int((Localizer(profile.body).localize(lm).status != 0).sum())
    assert located["draft"] >= 0.9 * located["shipped"], located
    assert "# Not found" in out.read_text() and "guessed from" in out.read_text()
    assert mocap("profile", "init", str(data_file(take)), "-o", str(out)).returncode == 1   # never overwrites


def test_a_draft_named_like_a_number_loads(tmp_path):
    from mocap_core.profiles import load_profile

    out = tmp_path / "01.yaml"  # (its stem was written unquoted, read back as the number 1)
    r = mocap("profile", "init", str(data_file(KARATE)), "-o", str(out))
    assert r.returncode == 0, r.stderr
    assert load_profile(out).name == "01"


def test_the_landmarks_page_is_what_profile_explain_makes():
    from mocap_cli.profile_cmd import landmarks_page

    assert (REPO / "docs" / "landmarks.md").read_text() == landmarks_page(), \
        "re-make it: mocap profile explain --markdown > docs/landmarks.md"


@pytest.mark.parametrize("take, shipped_profile", [(KARATE, "cmu41"),
                                                    ("12_vicon_freeform_realgaps_nimble_nick_freeform_001.c3d", "vicon53")])
@pytest.mark.parametrize("convention", ["opensim", "human_body", "motive", "qualisys_animation", "lowercase"])
def test_a_renamed_y_up_copy_solves_upright_with_no_profile(tmp_path, convention, take, shipped_profile):
    """A studio's own recording, first time: a take's labels renamed to another lab's convention and its
    world turned Y up. `mocap solve` with no profile drafts one, finds the up axis from the data, locates at least
    90 % of the joint-frames the shipped profile does, and its BVH (read back by bvhio) stands upright: the head
    above the hips along the BVH's Y in every frame."""
    import bvhio
    import numpy as np

    from mocap_core.joints_csv import read_joints_csv
    from mocap_core.recordings import read_recording, write_c3d
    from tests.core.test_profile_draft import HUMAN_BODY, MOTIVE, OPENSIM, QUALISYS_ANIMATION, renamed

    rec = read_recording(data_file(take)).slice(0, 600)
    table = {"opensim": OPENSIM, "human_body": HUMAN_BODY, "motive": MOTIVE, "qualisys_animation": QUALISYS_ANIMATION,
             "lowercase": None}[convention]
    prefix = "Q_" if convention == "qualisys_animation" else ""
    y_up = rec.positions[..., [0, 2, 1]] * np.array([1, 1, -1], np.float32)  # (x, y, z) -> (x, z, -y): Z up -> Y up
    copy = tmp_path / f"{convention}_y_up.c3d"
    write_c3d(type(rec)([renamed(x, table, prefix) for x in rec.labels], y_up, rec.rate_hz, rec.source), copy)
    shipped = tmp_path / "shipped.c3d"
    write_c3d(rec, shipped)
    results = {}
    for name, path, extra in (("copy", copy, []), ("shipped", shipped, ["--profile", shipped_profile])):
        csv_path, bvh = tmp_path / f"{name}.csv", tmp_path / f"{name}.bvh"
        r = mocap("solve", str(path), *extra, "--joints-out", str(csv_path), "--bvh-out", str(bvh))
        assert r.returncode == 0, r.stderr
        results[name] = (read_joints_csv(csv_path)[3], bvh, r.stderr)
    status, bvh, log = results["copy"]
    assert "drafted" in log.lower() and "mocap profile init" in log, log
    assert (status != 0).sum() >= 0.9 * (results["shipped"][0] != 0).sum()
    root = bvhio.readAsHierarchy(str(bvh))
    layout = {j.Name: j for j, _, _ in root.layout()}
    for f in range(0, len(status), 5):
        root.loadPose(f, recursive=True)
        assert layout["head"].PositionWorld.y > layout["pelvis"].PositionWorld.y + 0.3, f

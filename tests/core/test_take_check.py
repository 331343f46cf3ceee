"""`mocap check`: markers lost, and markers of one bone off their spacing, on made-up takes with known answers and on
the recordings whose faults docs/gap_filling.md traced by hand."""
import re
import subprocess
import sys

import numpy as np
import pytest

from mocap_core.profiles import Profile, load_profile
from mocap_core.recordings import read_recording
from mocap_core.take_check import marker_gaps, rigid_pairs, spacing_faults, used_markers
from tests.conftest import REPO, data_file

RATE_HZ = 100.0
DANCE = "13_qualisys_dance_walk_mocaptoolbox_mcdemodata.mat"
FOOT = Profile(name="foot", landmarks={"L_FAL": "Ankle", "L_FM2": "mean(BigToe, Pinkie)", "L_FCC": "Heel",
                                       "L_FLE": "Knee"})
LABELS = ["Ankle", "BigToe", "Pinkie", "Heel", "Knee", "Finger"]


def _foot(frames=300):
    """A foot walking along x at 1 m/s, its markers rigid to within 2 mm of noise, a knee 420 mm above the ankle;
    Finger is on no bone."""
    rng = np.random.default_rng(3)
    offsets = np.array([[0, 0, 0.08], [0.17, 0.02, 0.02], [0.15, -0.035, 0.02], [-0.06, 0, 0.03], [0, 0, 0.5],
                        [0.3, 0.3, 1.0]])
    x = np.arange(frames)[:, None, None] / RATE_HZ * np.array([1.0, 0, 0])
    return (offsets[None] + x + rng.normal(0, 0.001, (frames, len(LABELS), 3))).astype(np.float32)


def _faults(pos):
    return spacing_faults(pos, rigid_pairs(FOOT, LABELS), RATE_HZ)


def test_a_marker_put_wrong_is_found_on_every_pair_it_is_in_and_nowhere_else():
    pos = _foot()
    pos[100:150, 1, 0] += 0.08  # the big toe 80 mm forward: off its pinkie (58 mm), ankle (177) and heel (235)
    pos[155:158, 1, 0] += 0.08  # again 5 frames later: the same stretch (closer than 0.1 s)
    faults = _faults(pos)
    assert {frozenset((f.pair.a, f.pair.b)) for f in faults} == {
        frozenset(p) for p in (("Ankle", "BigToe"), ("BigToe", "Pinkie"), ("BigToe", "Heel"))}
    toes = [f for f in faults if {f.pair.a, f.pair.b} == {"BigToe", "Pinkie"}]
    assert len(toes) == 1 and (toes[0].start_s, toes[0].end_s, toes[0].frames) == (1.0, 1.57, 53)
    assert toes[0].usual_m == pytest.approx(np.hypot(0.02, 0.055), abs=0.002)
    assert 0.105 < toes[0].high_m < 0.12  # (0.1, 0.055) apart
    assert all(f.pair.bone == "L_foot" for f in faults)


def test_a_clean_take_has_no_fault_and_the_knee_is_on_no_pair_with_the_foot():
    assert _faults(_foot()) == []
    pairs = {(p.bone, p.a, p.b) for p in rigid_pairs(FOOT, LABELS)}
    assert ("L_shank", "Knee", "Ankle") in pairs  # the shank: knee and malleolus
    assert not any("Knee" in (a, b) and bone == "L_foot" for bone, a, b in pairs)
    assert not any("Finger" in (a, b) for _, a, b in pairs)


def test_gaps_are_counted_per_marker_the_longest_first():
    pos = _foot()
    pos[10:30, 3] = np.nan
    pos[50:55, 3] = np.nan
    pos[200:203, 1] = np.nan
    gaps = marker_gaps(pos, used_markers(FOOT, LABELS), RATE_HZ)
    assert [(g.label, g.lost, g.gaps, g.longest_s) for g in gaps[:2]] == [("Heel", 25, 2, 0.2), ("BigToe", 3, 1, 0.03)]
    assert {g.label for g in gaps} == {"Ankle", "BigToe", "Pinkie", "Heel", "Knee"}  # Finger: not the profile's


def _take_faults(take: str, profile: str):
    rec = read_recording(data_file(take.split(":")[0]), take.split(":")[1] if ":" in take else None)
    return spacing_faults(rec.positions, rigid_pairs(load_profile(profile), rec.labels), rec.rate_hz)


def _off(faults, a, b, start_s, end_s):
    """A pair's frames off within a window, and outside it."""
    mine = [f for f in faults if {f.pair.a, f.pair.b} == {a, b}]
    inside = sum(f.frames for f in mine if start_s <= f.start_s and f.end_s <= end_s)
    return inside, sum(f.frames for f in mine) - inside


def test_the_faults_traced_by_hand_are_found():
    # dance1: the left toe labels swap and wander from 6 s to 14 s (docs/gap_filling.md "dance1's toe markers"), 60 Hz
    inside, outside = _off(_take_faults(f"{DANCE}:dance1", "dance28"), "BigToe_L", "Pinkie_L", 5.5, 14)
    assert inside > 0.6 * 60 * 8 and outside < 0.2 * inside
    # walk1: the right toe markers stand still while the foot goes on, 2.5-3.2 s
    walk1 = _take_faults(f"{DANCE}:walk1", "dance28")
    inside, outside = _off(walk1, "Ankle_R", "BigToe_R", 2.4, 3.3)
    assert inside > 20 and outside == 0
    assert not any(f.pair.bone.startswith("L_") for f in walk1)  # its left leg and arm are sound
    # walk2: the left wrist markers jump apart, 4.2-4.85 s
    inside, outside = _off(_take_faults(f"{DANCE}:walk2", "dance28"), "Radius_L", "Ulna_L", 4.15, 4.9)
    assert inside > 20 and outside == 0
    # the Vicon take (120 Hz): the left inner wrist marker slid up the forearm until 1.6 s
    vicon = _take_faults("12_vicon_freeform_realgaps_nimble_nick_freeform_001.c3d", "vicon53")
    inside, outside = _off(vicon, "LIWR", "LWRE", 0, 1.7)
    assert inside > 0.8 * 120 * 1.6 and outside == 0


def test_a_clean_recording_has_none():
    assert _take_faults("02_qualisys_walking_ezc3d_Qualisys.c3d", "qualisys_sports") == []


def _mocap(*args):
    return subprocess.run([sys.executable, "-m", "mocap_cli.main", *args], cwd=REPO, capture_output=True, text=True,
                          timeout=120)


def test_mocap_check_writes_its_report_and_plot(tmp_path):
    r = _mocap("check", f"{data_file(DANCE)}:walk2", "--profile", "dance28", "--report", str(tmp_path))
    assert r.returncode == 0, r.stderr
    row = re.compile(r"^\| L_forearm \| Radius_L, Ulna_L \| 74 mm \| 4\.\d\d-4\.\d\d s \|", re.M)
    assert row.search((tmp_path / "check.md").read_text()) and row.search(r.stdout)
    assert (tmp_path / "check.png").stat().st_size > 10_000


def test_mocap_check_names_a_label_the_take_lacks(tmp_path):
    r = _mocap("check", str(data_file("02_qualisys_walking_ezc3d_Qualisys.c3d")), "--profile", "dance28",
               "--report", str(tmp_path))
    assert r.returncode != 0 and "is not in the recording" in r.stderr
    assert not (tmp_path / "check.md").exists()

"""Marker-set profiles and recording readers: real files, bad files, clear errors."""
import numpy as np
import pytest

from mocap_core.profiles import LANDMARK_INDEX, LANDMARKS, ProfileError, load_profile
from mocap_core.recordings import RecordingError, read_recording
from tests.conftest import data_file

SHIPPED = {"02_qualisys_walking_ezc3d_Qualisys.c3d": "qualisys_sports",
           "03_sprint_start_BTK_SprintMotion.trc": "btk_sprint",
           "08_cmu_135_02_karate_kata.c3d": "cmu41",
           "12_vicon_freeform_realgaps_nimble_nick_freeform_001.c3d": "vicon53",
           "13_qualisys_dance_walk_mocaptoolbox_mcdemodata.mat": "dance28"}


@pytest.mark.parametrize("file,profile", SHIPPED.items())
def test_every_shared_recording_has_a_profile_that_resolves(file, profile):
    rec = read_recording(data_file(file))
    lm = load_profile(profile).resolve(rec.labels).apply(rec.positions)
    assert lm.shape == (rec.n_frames, len(LANDMARK_INDEX), 3)
    for name in ("SACR", "L_IAS", "R_IAS", "L_SAE", "R_HLE", "L_FLE", "R_FAL", "L_FM2"):
        assert np.isfinite(lm[:, LANDMARK_INDEX[name]]).mean() > 0.9, name


def test_readers_give_metres_and_nan_for_occlusions():
    rec = read_recording(data_file("12_vicon_freeform_realgaps_nimble_nick_freeform_001.c3d"))
    assert rec.rate_hz == 120 and rec.positions.shape == (1101, 53, 3) and rec.positions.dtype == np.float32
    clav = rec.labels.index("Nick01:CLAV")
    assert np.isnan(rec.positions[:, clav]).all()                       # missing in every frame
    assert 0.05 < np.isnan(rec.positions[..., 0]).mean() < 0.08         # 6.6% gaps per the MANIFEST
    assert 0.3 < np.nanmax(np.abs(rec.positions)) < 5                   # metres, not millimetres
    trc = read_recording(data_file("03_sprint_start_BTK_SprintMotion.trc"))
    assert trc.rate_hz == 250 and trc.positions.shape == (788, 59, 3) and trc.labels[0] == "C7"
    mat = read_recording(f"{data_file('13_qualisys_dance_walk_mocaptoolbox_mcdemodata.mat')}:walk1")
    assert mat.rate_hz == 60 and mat.n_frames == 351


def test_actor_prefixes_are_stripped():
    rec = read_recording(data_file("08_cmu_135_02_karate_kata.c3d"))
    assert rec.labels[0] == "male:LFHD"
    lm = load_profile("cmu41").resolve(rec.labels).apply(rec.positions[:1])
    lfwt = rec.labels.index("male:LFWT")
    np.testing.assert_allclose(lm[0, LANDMARK_INDEX["L_IAS"]], rec.positions[0, lfwt], rtol=1e-6)


def test_truncated_and_corrupt_files_give_clear_errors(tmp_path):
    c3d = data_file("02_qualisys_walking_ezc3d_Qualisys.c3d").read_bytes()
    (tmp_path / "cut.c3d").write_bytes(c3d[:300_000])
    with pytest.raises(RecordingError, match="truncated"):
        read_recording(tmp_path / "cut.c3d")
    (tmp_path / "junk.c3d").write_bytes(b"\x00" * 100)
    with pytest.raises(RecordingError, match="junk.c3d"):
        read_recording(tmp_path / "junk.c3d")
    trc = data_file("03_sprint_start_BTK_SprintMotion.trc").read_text()
    (tmp_path / "cut.trc").write_text(trc[: len(trc) // 2])
    with pytest.raises(RecordingError, match="truncated"):
        read_recording(tmp_path / "cut.trc")
    with pytest.raises(RecordingError, match="not found"):
        read_recording(tmp_path / "none.c3d")
    with pytest.raises(RecordingError, match="no take 'dance9'"):
        read_recording(f"{data_file('13_qualisys_dance_walk_mocaptoolbox_mcdemodata.mat')}:dance9")


def test_malformed_values_name_the_file_and_place(tmp_path):
    """A TRC cell that is no number was a bare "could not convert string to float: 'x'"; a MAT take of -10 or 0
    frames was accepted (or a ValueError); infinite coordinates were taken as positions."""
    from scipy.io import loadmat, savemat

    lines = data_file("03_sprint_start_BTK_SprintMotion.trc").read_text().splitlines()
    cells = lines[9].split("\t")
    cells[5] = "x"
    lines[9] = "\t".join(cells)
    (tmp_path / "x.trc").write_text("\n".join(lines) + "\n")
    with pytest.raises(RecordingError, match=r"x\.trc line 10: not a number"):
        read_recording(tmp_path / "x.trc")
    cells[5] = "inf"
    lines[9] = "\t".join(cells)
    (tmp_path / "inf.trc").write_text("\n".join(lines) + "\n")
    rec = read_recording(tmp_path / "inf.trc")
    assert np.isfinite(rec.positions).all(axis=2).sum() == rec.positions[..., 0].size - 1
    cells[5] = "2e6"  # 2 km (the file's mm): past any capture volume, taken as no position as infinity is
    lines[9] = "\t".join(cells)
    (tmp_path / "far.trc").write_text("\n".join(lines) + "\n")
    rec = read_recording(tmp_path / "far.trc")
    assert np.isfinite(rec.positions).all(axis=2).sum() == rec.positions[..., 0].size - 1
    mat = loadmat(str(data_file("13_qualisys_dance_walk_mocaptoolbox_mcdemodata.mat")), squeeze_me=True,
                  struct_as_record=False)
    take = mat["walk1"]
    for frames in (-10, 0, float("inf")):
        fields = {name: getattr(take, name) for name in take._fieldnames}
        fields["nFrames"] = frames
        savemat(str(tmp_path / "bad.mat"), {"walk1": fields})
        with pytest.raises(RecordingError, match="take 'walk1' is malformed"):
            read_recording(tmp_path / "bad.mat")


def test_profile_errors_name_the_line(tmp_path):
    p = tmp_path / "mine.yaml"
    p.write_text("name: mine\nlandmarks:\n  SACR: SACR\n  L_IAS: LASI2\n  R_IAS: RASI\n")
    prof = load_profile(p)
    with pytest.raises(ProfileError, match=r"profile mine.yaml line 4: label LASI2 of L_IAS is not in the recording"):
        prof.resolve(["SACR", "LASI", "RASI"])
    p.write_text("name: mine\nlandmarks:\n  SACR: SACR\n  L_ELBOW: LELB\n")
    with pytest.raises(ProfileError, match="line 4: unknown landmark 'L_ELBOW'"):
        load_profile(p)
    p.write_text("name: mine\nlandmarks:\n  SACR: mean(A,, B)\n")
    with pytest.raises(ProfileError, match="line 3: bad expression"):
        load_profile(p)
    with pytest.raises(ProfileError, match="shipped profiles: .*cmu41"):
        load_profile("no_such_profile")


def test_tracking_markers_are_resolved_apart_from_the_landmarks(tmp_path):
    p = tmp_path / "mine.yaml"
    p.write_text("name: mine\nlandmarks:\n  SACR: SACR\ntracking:\n  L_forearm: [FRM]\n  R_shank: [SHN1, SHN2]\n")
    lmap = load_profile(p).resolve(["SHN2", "SACR", "FRM", "SHN1"])
    assert lmap.tracking_of == ("L_forearm", "R_shank", "R_shank")
    frame = np.arange(12.0).reshape(1, 4, 3)
    np.testing.assert_array_equal(lmap.tracking(frame)[0], frame[0, [2, 3, 0]])
    assert lmap.apply(frame).shape[1] == len(LANDMARKS)  # the landmarks are unchanged by them
    lmap = load_profile(p).resolve(["SACR", "FRM", "SHN1"])  # a lacking tracking marker only helps less
    assert lmap.tracking_of == ("L_forearm", "R_shank") and lmap.absent_tracking == ("SHN2",)
    p.write_text("name: mine\nlandmarks:\n  SACR: SACR\ntracking:\n  L_hip: [THI]\n")
    with pytest.raises(ProfileError, match="unknown tracking segment 'L_hip'.*L_thigh"):
        load_profile(p)


def test_a_marker_set_no_shipped_profile_fits_is_solved_with_a_draft(caplog):
    """The karate take without its finger markers fits no shipped profile (cmu41 names them): the labels are drafted
    into a profile in memory, the log says which landmarks it found, what it cannot locate and the command that
    writes it down; the solve locates every joint but the hands."""
    from mocap_core.pipeline import SkeletonPipeline
    from mocap_core.profiles import detect_profile, profile_for
    from mocap_core.skeleton import INDEX, Status

    rec = read_recording(data_file("08_cmu_135_02_karate_kata.c3d")).slice(0, 240)
    keep = [k for k, x in enumerate(rec.labels) if not x.endswith("FIN")]
    labels = [rec.labels[k] for k in keep]
    assert detect_profile(labels) is None
    with caplog.at_level("WARNING", logger="test.profile"):
        import logging
        profile = profile_for("auto", labels, logging.getLogger("test.profile"))
    assert profile.drafted and "L_HM2" not in profile.landmarks and profile.landmarks["L_FLE"] == "LKNE"
    assert "mocap profile init" in caplog.text and "hand_l" in caplog.text
    chunks = SkeletonPipeline(profile, labels, rate_hz=rec.rate_hz).run(rec.positions[:, keep])
    status = np.concatenate([c.status for c in chunks])
    hands = [INDEX["hand_l"], INDEX["hand_r"]]
    others = [j for j in range(status.shape[1]) if j not in hands]
    assert (status[:, others] != Status.MISSING).mean() > 0.99


def test_a_landmark_is_the_mean_of_its_markers_in_a_take_and_in_a_frame_alone():
    rec = read_recording(data_file("02_qualisys_walking_ezc3d_Qualisys.c3d"))
    profile = load_profile("qualisys_sports")
    lmap = profile.resolve(rec.labels)
    whole = lmap.apply(rec.positions)
    columns = [rec.labels.index(x) for x in profile.markers_of("SACR")]
    assert len(columns) == 2
    np.testing.assert_array_equal(whole[:, LANDMARK_INDEX["SACR"]],
                                  rec.positions[:, columns].astype(np.float64).mean(axis=1))
    for f in (0, 100):  # a frame as a node gets it (float32, any memory layout) maps as in the take
        np.testing.assert_array_equal(lmap.apply(np.asfortranarray(rec.positions[f])), whole[f])

"""The marker gate: what no body could do is dropped for the frame and counted; real motion passes."""
import numpy as np

from mocap_core.marker_gate import MarkerGate
from mocap_core.recordings import read_recording
from tests.conftest import DATA


def walking(n=50, rate=100.0):
    t = np.arange(n) / rate
    return np.stack([np.stack([1.5 * t + k * 0.1, np.zeros(n), np.ones(n)], axis=1) for k in range(4)], axis=1)


def test_a_glitched_frame_is_dropped_and_the_next_passes():
    x = walking()
    x[20, 1] = [1e30, 0, 0]      # a marker at 1e30 m
    x[30] += [1.0, 0.0, 0.0]     # the whole cloud 1 m off for one frame (100 m/s)
    gate, out = MarkerGate(), []
    for f in range(len(x)):
        out.append(gate.filter(x[f], f / 100.0)[1])
    out = np.array(out)
    assert out[20].tolist() == [False, True, False, False] and out[30].all()
    assert out.sum() == 5 and gate.dropped == 5


def test_a_first_position_away_from_the_body_is_dropped_and_a_steady_one_kept():
    x = walking()
    x[0, 2] += [5.0, 0, 0]  # a glitch in the first frame: 5 m from the others, no place accepted before
    gate = MarkerGate()
    assert [gate.filter(x[f], f / 100.0)[1][2] for f in range(5)] == [True, False, False, False, False]
    x = walking()
    x[:, 3] += [5.0, 0, 0]  # a prop 5 m away all along: dropped in its first frame only
    gate = MarkerGate()
    assert [gate.filter(x[f], f / 100.0)[1][3] for f in range(5)] == [True, False, False, False, False]


def test_a_repeated_or_backward_time_is_one_frame_on():
    """A duplicated timestamp (or a time that runs back) is not a licence to jump: the frame counts as one interval
    after the last, so a marker 2 m off in it is dropped."""
    x = walking()
    gate = MarkerGate()
    for f in range(10):
        gate.filter(x[f], f / 100.0)
    glitch = x[10].copy()
    glitch[1] += [2.0, 0, 0]
    assert gate.filter(glitch, 0.09)[1].tolist() == [False, True, False, False]  # stamped as the frame before
    assert not gate.filter(x[11], 0.11)[1].any()


def test_every_shared_recording_passes_untouched():
    for file, take in [("08_cmu_135_02_karate_kata.c3d", None), ("12_vicon_freeform_realgaps_nimble_nick_freeform_001.c3d", None),
                       ("03_sprint_start_BTK_SprintMotion.trc", None)]:
        rec = read_recording(DATA / file, take)
        gate = MarkerGate()
        gate.filter_take(rec.positions, 1 / rec.rate_hz)
        assert gate.dropped == 0, file


def test_one_glitched_frame_leaves_no_trace_a_second_later():
    """A marker at 1e30 m, a marker 100 m off, the whole cloud 1 m off, each for one frame of the karate take: a
    second later the studio solve is the clean one (before the gate, the shoulders stayed 2e26 m off for good: the
    localization's running body measures took the sample)."""
    from mocap_core.pipeline import SkeletonPipeline
    from mocap_core.profiles import load_profile

    rec = read_recording(DATA / "08_cmu_135_02_karate_kata.c3d").slice(0, 600)
    profile = load_profile("cmu41")

    def solve(markers):
        pipe = SkeletonPipeline(profile, rec.labels, options="studio", rate_hz=rec.rate_hz)
        return np.concatenate([c.positions for c in pipe.run(markers)])

    clean = solve(rec.positions)
    lsho = [x.split(":")[-1] for x in rec.labels].index("LSHO")
    for glitch in ("1e30", "100 m", "cloud"):
        markers = rec.positions.astype(np.float64)
        if glitch == "1e30":
            markers[200, lsho] = 1e30
        elif glitch == "100 m":
            markers[200, lsho] += 100.0
        else:
            markers[200] += 1.0
        after = solve(markers)[320:]
        assert np.nanmax(np.abs(after - clean[320:])) < 0.001, glitch


def test_a_glitch_where_a_marker_has_no_history_leaves_no_trace_half_a_second_later():
    """One marker 500 m off in the first frame, or in the first frame it is seen: half a second later the studio
    solve is within 10 mm of the clean one (before, a shoulder stayed 250 m off to the end, located: a marker with no
    accepted place was taken anywhere within 1 km)."""
    from mocap_core.pipeline import SkeletonPipeline
    from mocap_core.profiles import load_profile

    rec = read_recording(DATA / "08_cmu_135_02_karate_kata.c3d").slice(0, 480)
    profile = load_profile("cmu41")
    lsho = [x.split(":")[-1] for x in rec.labels].index("LSHO")

    def solve(markers):
        pipe = SkeletonPipeline(profile, rec.labels, rate_hz=rec.rate_hz)
        return np.concatenate([c.positions for c in pipe.run(markers)])

    late = rec.positions.astype(np.float64)
    late[:100, lsho] = np.nan  # the shoulder marker first seen in frame 100
    for first, markers in ((0, rec.positions.astype(np.float64)), (100, late)):
        clean = solve(markers)
        markers[first, lsho] += 500.0
        after = first + int(0.5 * rec.rate_hz)
        assert np.nanmax(np.linalg.norm(solve(markers)[after:] - clean[after:], axis=-1)) < 0.01, first


def test_frames_replayed_from_half_a_second_before_leave_no_trace_half_a_second_later():
    """Twelve frames of the take sent again, from 0.5 s before (a replay, a buffer resent): half a second after them
    the studio solve is within 10 mm of the clean one (before, a toe stayed 500-800 mm off for a second: the blend's
    step cap closed the offset 1 cm a frame, and its trust learned the replay's miss for good)."""
    from mocap_core.pipeline import SkeletonPipeline
    from mocap_core.profiles import load_profile

    rec = read_recording(DATA / "13_qualisys_dance_walk_mocaptoolbox_mcdemodata.mat", "walk2")
    profile = load_profile("dance28")

    def solve(markers):
        pipe = SkeletonPipeline(profile, rec.labels, rate_hz=rec.rate_hz)
        return np.concatenate([c.positions for c in pipe.run(markers)])

    clean = solve(rec.positions)
    half = int(rec.rate_hz / 2)
    for start in (half, rec.n_frames // 2):
        markers = rec.positions.astype(np.float64)
        markers[start:start + 12] = markers[start - half:start - half + 12]
        after = start + 12 + half
        assert np.nanmax(np.linalg.norm(solve(markers)[after:] - clean[after:], axis=-1)) < 0.01, start


def test_frames_of_any_memory_layout_and_dtype_run_the_one_compiled_gate():
    """A file's frames may come transposed (Fortran order) or as float32 off the wire: the gate takes them as the
    kernel it was warmed up with, and says the same of them (no second compile on a node's first frame)."""
    from mocap_core.marker_gate import _screen
    from mocap_core.warmup import warm_up

    warm_up(("markers",), stamp=False)
    x = walking().astype(np.float32)
    x[30] += [1.0, 0.0, 0.0]
    plain, other = MarkerGate(), MarkerGate()
    for f in range(len(x)):
        a = plain.filter(x[f].astype(np.float64), f / 100.0)
        b = other.filter(np.asfortranarray(x[f]), f / 100.0)
        assert np.array_equal(a[0], b[0], equal_nan=True) and np.array_equal(a[1], b[1])
    assert plain.dropped == other.dropped == 4
    assert len(_screen.signatures) == 1

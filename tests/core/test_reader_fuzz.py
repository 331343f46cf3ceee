"""Corrupt recordings: each reader, fed mutated copies of a real file (a fixed seed, a bounded time), either reads
it or raises one RecordingError naming the file; no crash, no hang, no other exception."""
import random
import time

import pytest

from mocap_core.recordings import RecordingError, read_recording
from tests.conftest import data_file

FILES = {
    "c3d": "12_vicon_freeform_realgaps_nimble_nick_freeform_001.c3d",
    "trc": "03_sprint_start_BTK_SprintMotion.trc",
    "mat": "13_qualisys_dance_walk_mocaptoolbox_mcdemodata.mat",
}
BUDGET_S = 15.0   # per reader; CI's minute for the three


def _mutants(data: bytes, rng: random.Random):
    while True:
        b = bytearray(data)
        how = rng.random()
        if how < 0.6:      # a few bytes anywhere, more often in the header and parameters
            for _ in range(rng.randint(1, 8)):
                at = rng.randrange(min(len(b), 16384)) if rng.random() < 0.7 else rng.randrange(len(b))
                b[at] = rng.randrange(256)
        elif how < 0.8:    # truncated
            del b[rng.randrange(len(b)):]
        else:              # a run of bytes replaced
            at = rng.randrange(len(b))
            b[at:at + 64] = bytes(rng.randrange(256) for _ in range(64))
        yield bytes(b)


@pytest.mark.timeout(120)
@pytest.mark.parametrize("kind", sorted(FILES))
def test_a_mutated_recording_reads_or_fails_clearly(tmp_path, kind):
    data = data_file(FILES[kind]).read_bytes()
    rng = random.Random(kind)
    path = tmp_path / f"mutant.{kind}"
    tried = read = 0
    end = time.monotonic() + BUDGET_S
    for mutant in _mutants(data, rng):
        if time.monotonic() > end:
            break
        path.write_bytes(mutant)
        t = time.monotonic()
        try:
            rec = read_recording(path)
            assert rec.positions.ndim == 3 and len(rec.labels) == rec.positions.shape[1]
            read += 1
        except RecordingError as e:
            assert str(path) in str(e), e
        assert time.monotonic() - t < 45, "a read took too long"
        tried += 1
    assert tried >= 20, tried


def test_a_c3d_that_crashes_ezc3d_is_a_clear_error(tmp_path):
    """One byte of the Vicon take's parameter section changed segfaulted the process inside ezc3d."""
    data = bytearray(data_file(FILES["c3d"]).read_bytes())
    data[4197] = 184
    path = tmp_path / "crashes_ezc3d.c3d"
    path.write_bytes(bytes(data))
    with pytest.raises(RecordingError, match="crashes_ezc3d.c3d: the C3D reader crashed on this file \\(signal 11\\)"):
        read_recording(path)

"""Every command the README shows, run as a user would (in a scratch directory rather than the repository's root,
so that what they write lands there), the README's stand-ins (take.c3d, your own take) given a real take of
../shared/data. A command that ends exits 0; a graph serves skeletons until
Ctrl-C stops it, and the tools find it while it runs. A command added to the README must be added here."""
import contextlib
import os
import shlex
import signal
import subprocess
import sys

import pytest

from tests.conftest import DATA, REPO, data_file, wait_for
from tests.test_readme_commands import COMMANDS

TAKE = "08_cmu_135_02_karate_kata.c3d"

WALKTHROUGH = [  # "your own recording, first time"
    ".venv/bin/mocap check take.c3d",
    ".venv/bin/mocap solve take.c3d --joints-out take.csv --bvh-out take.bvh",
    ".venv/bin/mocap profile init take.c3d -o profiles/myset.yaml",
]
WALKTHROUGH_LIVE = ".venv/bin/mocap qtm-sim take.c3d --loop"
OFFLINE = [  # in the README's order: the calibration before the solve that reads it
    ".venv/bin/mocap launch launch/studio.yaml --plan",
    ".venv/bin/mocap solve ../shared/data/08_cmu_135_02_karate_kata.c3d --profile cmu41 --joints-out karate.csv",
    ".venv/bin/mocap solve take.c3d --profile cmu41 --thesis --joints-out thesis.csv --bvh-out thesis.bvh",
    ".venv/bin/mocap solve take.c3d --profile cmu41 --bvh-out take.bvh --bvh-names mixamo",
    ".venv/bin/mocap solve ../shared/data --out-dir solved --bvh",
    ".venv/bin/mocap check take.c3d --profile cmu41",
    ".venv/bin/mocap eval gaps",
    ".venv/bin/mocap calibrate ../shared/data/08_cmu_135_02_karate_kata.c3d --profile cmu41 -o actor.yaml",
    ".venv/bin/mocap solve take.c3d --profile cmu41 --fit --subject actor.yaml --joints-out out.csv --bvh-out out.bvh",
    ".venv/bin/mocap solve take.c3d --profile cmu41 --fit --joints-out out.csv",
]
STUDIO = ".venv/bin/mocap launch launch/studio.yaml"
TOOLS = [".venv/bin/mocap topic list", ".venv/bin/mocap topic echo skeleton/solved --once",
         ".venv/bin/mocap node list"]
RECORD = ".venv/bin/mocap bag record -o take.mcap markers/raw skeleton/solved"
BAGS = [".venv/bin/mocap bag info take.mcap",
        ".venv/bin/mocap bag export take.mcap --foxglove take.fox.mcap",
        ".venv/bin/mocap bag play take.mcap --launch launch/studio.yaml",
        ".venv/bin/mocap bag play take.mcap --launch launch/studio.yaml --lockstep --restamp --record out.mcap"]
QTM = ".venv/bin/mocap qtm-sim ../shared/data/08_cmu_135_02_karate_kata.c3d --loop"
GRAPHS = [  # each serves a skeleton (or, pointed at machines that are not there, starts) until Ctrl-C
    (".venv/bin/mocap launch launch/studio.yaml --set source.path=take.c3d", True),
    (".venv/bin/mocap launch launch/qtm_unity.yaml", True),
    (".venv/bin/mocap launch launch/studio_fit.yaml", True),
    (".venv/bin/mocap launch launch/qtm_actors.yaml --set 'actors=[alice, bob]'", False),
    (".venv/bin/mocap launch launch/qtm_unity.yaml --set qtm.host=192.168.0.10 --set vmc.host=192.168.0.20", False),
]


def argv(command: str) -> list[str]:
    """As typed at the repository's root, for a scratch directory."""
    words = [str(REPO / w) if w.startswith("launch/") else
             w.replace("take.c3d", str(data_file(TAKE))).replace("../shared/data", str(DATA))
             for w in shlex.split(command)[1:]]
    return [sys.executable, "-m", "mocap_cli.main", *words]


def run(command: str, tmp_path, timeout: float = 300) -> str:
    done = subprocess.run(argv(command), cwd=tmp_path, env=_env(tmp_path), capture_output=True, text=True,
                          timeout=timeout)
    assert done.returncode == 0, f"`{command}` exited {done.returncode}:\n{done.stderr[-3000:]}"
    return done.stdout + done.stderr


@contextlib.contextmanager
def running(command: str, tmp_path):
    """A command that runs until Ctrl-C; stopped with it, and asked to exit 0."""
    log = open(tmp_path / "running.log", "a")
    proc = subprocess.Popen(argv(command), cwd=tmp_path, env=_env(tmp_path), stdout=log, stderr=subprocess.STDOUT)
    try:
        yield proc
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            code = proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            proc.kill()
            code = "killed after 15 s"
        log.close()
    assert code == 0, f"`{command}` after Ctrl-C: {code}\n{(tmp_path / 'running.log').read_text()[-3000:]}"


def _env(tmp_path) -> dict:
    return {**os.environ, "MOCAP_RUN_DIR": str(tmp_path / "run")}


def _serves_skeletons(tmp_path) -> bool:
    echo = subprocess.run(argv(".venv/bin/mocap topic echo skeleton/solved --once --timeout 2"), cwd=tmp_path,
                          env=_env(tmp_path), capture_output=True, text=True, timeout=60)
    return echo.returncode == 0 and "positions" in echo.stdout


def test_every_readme_command_is_run_here():
    graphs = [c for c, _ in GRAPHS]
    assert sorted(COMMANDS) == sorted(WALKTHROUGH + [WALKTHROUGH_LIVE] + OFFLINE + [STUDIO] + TOOLS + [RECORD] + BAGS
                                      + [QTM] + graphs)


@pytest.mark.timeout(900)
def test_the_walkthrough(tmp_path, default_ports):
    """From a recording to a BVH, a profile kept for editing, and the same take live through a QTM stand-in."""
    for command in WALKTHROUGH:
        run(command, tmp_path, timeout=600)
    assert (tmp_path / "take.csv").exists() and (tmp_path / "take.bvh").exists()
    assert "landmarks:" in (tmp_path / "profiles" / "myset.yaml").read_text()
    with running(WALKTHROUGH_LIVE, tmp_path), running(".venv/bin/mocap launch launch/qtm_unity.yaml", tmp_path):
        wait_for(lambda: _serves_skeletons(tmp_path), 120, "skeletons from the QTM stand-in's take")


@pytest.mark.timeout(900)  # ten commands, each a solve or a calibration of a whole take
def test_the_offline_commands(tmp_path):
    for command in OFFLINE:
        run(command, tmp_path, timeout=600)
    assert (tmp_path / "karate.csv").exists() and (tmp_path / "out.bvh").exists() and (tmp_path / "actor.yaml").exists()
    assert len(list((tmp_path / "solved").glob("*.bvh"))) >= 5


@pytest.mark.timeout(900)
def test_a_studio_session_its_tools_and_its_bags(tmp_path, default_ports):
    with running(STUDIO, tmp_path):
        wait_for(lambda: _serves_skeletons(tmp_path), 120, "skeletons from the studio graph")
        outputs = [run(command, tmp_path, timeout=60) for command in TOOLS]
        assert "skeleton/solved" in outputs[0] and "positions" in outputs[1] and "retarget" in outputs[2]
        with running(RECORD, tmp_path):
            wait_for(lambda: (tmp_path / "take.mcap").exists() and (tmp_path / "take.mcap").stat().st_size > 50_000,
                     60, "a recording")
    for command in BAGS:
        run(command, tmp_path, timeout=300)
    assert (tmp_path / "take.fox.mcap").exists() and (tmp_path / "out.mcap").exists()


@pytest.mark.timeout(900)
def test_the_live_graphs(tmp_path, default_ports):
    with running(QTM, tmp_path):
        for command, serves in GRAPHS:
            with running(command, tmp_path):
                if serves:
                    wait_for(lambda: _serves_skeletons(tmp_path), 120, f"skeletons from `{command}`")
                else:  # its machines are not here, or its actors not in the take: it starts, and waits
                    wait_for(lambda: list((tmp_path / "run").glob("*.graph.json")), 60, f"`{command}` started")

"""Shared test helpers: real launcher processes with their own registry dir, always cleaned up."""
from __future__ import annotations

import contextlib
import csv
import fcntl
import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data"


def pytest_sessionstart(session):
    """Compile (or load) the numba kernels once, before any test's timeout starts.

    On a fresh clone the first compile takes a minute or two; done inside the first test that needs
    it (often in a subprocess), it ate that test's timeout. The compiled code is cached on disk, so
    every node and CLI process the tests start afterwards only loads it.
    """
    from mocap_core.warmup import compile_kernels, kernels_cached, warm_up

    if not kernels_cached():  # in two processes, as the launcher does
        print(f"\nnumba kernels compiled and cached in {compile_kernels():.0f} s (first run on this checkout only)")
    warm_up()  # this process loads them too (in-process tests)


def data_file(name: str) -> Path:
    """A recording from ../shared/data; a missing file fails the test loudly (never a skip)."""
    path = DATA / name
    if not path.exists():
        pytest.fail(f"test recording {path} is missing: tests read the real recordings from ../shared/data")
    return path


def wait_for(predicate, timeout_s: float = 10.0, what: str = "condition"):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(0.02)
    raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")


def log_rows(path: Path) -> list[dict]:
    """The rows of a frame_log CSV that may still be being written: complete lines only (a buffered
    file is flushed in pieces), none while even the header line is incomplete."""
    try:
        text = Path(path).read_text()
    except FileNotFoundError:
        return []
    complete = text[: text.rfind("\n") + 1]
    return list(csv.DictReader(complete.splitlines())) if complete else []


def pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    # a zombie is dead for our purposes
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split(") ", 1)[1][0] != "Z"
    except OSError:
        return False


class Graph:
    def __init__(self, proc: subprocess.Popen, run_dir: Path, name: str, log_path: Path):
        self.proc, self.run_dir, self.name, self.log_path = proc, run_dir, name, log_path

    @property
    def registry_file(self) -> Path:
        return self.run_dir / f"{self.name}.graph.json"

    def registry(self) -> dict:
        return json.loads(self.registry_file.read_text())

    def node_pids(self) -> dict[str, int]:
        return {n["id"]: n["pid"] for n in self.registry()["nodes"] if n["pid"]}

    def log(self) -> str:
        return self.log_path.read_text()

    def cli(self, *args: str, timeout: float = 30) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-m", "mocap_cli.main", *args], cwd=REPO, env=self.env(),
                              capture_output=True, text=True, timeout=timeout)

    def heartbeats(self, seconds: float = 2.5) -> dict:
        """The latest heartbeat of every node, as `mocap node list` sees them."""
        from mocap_cli import topic_tools
        from mocap_cli.graph_registry import find_graph

        old = os.environ.get("MOCAP_RUN_DIR")
        os.environ["MOCAP_RUN_DIR"] = str(self.run_dir)
        try:
            return topic_tools.collect_heartbeats(find_graph(self.name), seconds)
        finally:
            if old is None:
                del os.environ["MOCAP_RUN_DIR"]
            else:
                os.environ["MOCAP_RUN_DIR"] = old

    def env(self) -> dict:
        return {**os.environ, "MOCAP_RUN_DIR": str(self.run_dir)}

    def stop(self, timeout: float = 5.0) -> float:
        t = time.monotonic()
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            self.proc.wait(timeout=timeout)
        return time.monotonic() - t


def pipeline_graph(source: str, profile: str = "qualisys_sports", extra: str = "", retarget: str = "{}") -> str:
    """The full graph of docs/design.md (source -> ... -> retarget) as launch-file text, with extra nodes."""
    limbs = "".join(f"  - {{id: {limb}, kind: ik_gapfill, params: {{limb: {limb}}}}}\n"
                    for limb in ("torso", "left_arm", "right_arm", "left_leg", "right_leg"))
    return (f"nodes:\n  - {{id: source, kind: file_source, params: {source}}}\n"
            f"  - {{id: hips, kind: hip_interpolation, params: {{profile: {profile}}}}}\n"
            f"  - {{id: localize, kind: joint_localization, params: {{profile: {profile}}}}}\n"
            f"{limbs}  - {{id: retarget, kind: retarget, params: {retarget}}}\n{extra}\n")


@contextlib.contextmanager
def launched(tmp_path: Path, launch_text: str, *extra: str, name: str = "g"):
    run_dir = tmp_path / "run"
    run_dir.mkdir(exist_ok=True)
    launch = tmp_path / f"{name}.yaml"
    launch.write_text(launch_text)
    log_path = tmp_path / f"{name}.log"
    env = {**os.environ, "MOCAP_RUN_DIR": str(run_dir)}
    with open(log_path, "w") as log:
        proc = subprocess.Popen([sys.executable, "-m", "mocap_cli.main", "launch", str(launch), "--name", name, *extra],
                                cwd=REPO, env=env, stdout=log, stderr=subprocess.STDOUT)
    graph = Graph(proc, run_dir, name, log_path)
    try:
        wait_for(lambda: graph.registry_file.exists() or proc.poll() is not None, 20, "the graph registry")
        yield graph
    finally:
        pids = []
        with contextlib.suppress(Exception):
            pids = list(graph.node_pids().values())
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
            try:
                proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        for pid in pids:  # never leave a stray node behind, whatever the test did
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)


def free_port(kind: int = socket.SOCK_STREAM) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextlib.contextmanager
def emulator(tmp_path, *args, port=0, file="12_vicon_freeform_realgaps_nimble_nick_freeform_001.c3d"):
    ready = tmp_path / f"port-{os.getpid()}-{port}"
    ready.unlink(missing_ok=True)
    log = open(tmp_path / "qtm_sim.log", "a")
    take = file if Path(file).is_absolute() else data_file(file)  # a shared recording, or one a test wrote
    proc = subprocess.Popen([sys.executable, "-m", "mocap_cli.main", "qtm-sim", str(take), "--port",
                             str(port), "--ready-file", str(ready), *args], cwd=REPO, stdout=log,
                            stderr=subprocess.STDOUT)
    try:
        wait_for(lambda: ready.exists() and ready.read_text(), 20, "the emulator to listen")
        yield proc, int(ready.read_text())
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
            try:
                proc.wait(5)
            except subprocess.TimeoutExpired:
                proc.kill()
        log.close()


@pytest.fixture
def default_ports():
    """The README's commands bind the graphs' default ports (viewer 8090, Foxglove 8765-8766, the QTM emulator 22223):
    a test that runs them holds this machine-wide lock, so a second test suite beside it waits rather than binds them
    too (give such a test a timeout that covers the wait)."""
    path = Path(tempfile.gettempdir()) / f"mocap-tests-default-ports-{os.getuid()}.lock"
    with open(path, "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        yield

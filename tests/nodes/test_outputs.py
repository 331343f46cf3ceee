"""Outputs: VMC received by a real OSC server, BVH read back by bvhio, the viewer in headless Chromium."""
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from collections import defaultdict

import numpy as np
import pytest

from messages import decode
from mocap_core.ik.kernels import quats_to_frames
from mocap_core.joints_csv import read_joints_csv
from mocap_core.rig import BONE_JOINT, BONE_PARENT, BONES, to_canonical, to_unity_position
from mocap_core.skeleton import JOINTS, Status
from nodes.bags import read_bag
from tests.conftest import REPO, data_file, launched, pipeline_graph, wait_for

TAKE = "02_qualisys_walking_ezc3d_Qualisys.c3d"
ARTIFACTS = REPO / "artifacts"


def free_port(kind=socket.SOCK_STREAM) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def pipeline(tmp_path, frames, extra=""):
    return pipeline_graph(f"{{path: {data_file(TAKE)}, max_frames: {frames}}}", extra=extra)


def test_vmc_stream_reproduces_the_solved_skeleton(tmp_path):
    from pythonosc.dispatcher import Dispatcher
    from pythonosc.osc_server import ThreadingOSCUDPServer

    got = defaultdict(list)
    lock = threading.Lock()

    def on_bone(address, name, *values):
        with lock:
            got[name].append(values)

    disp = Dispatcher()
    disp.map("/VMC/Ext/Bone/Pos", on_bone)
    disp.map("/VMC/Ext/T", lambda a, t: got["T"].append(t))
    server = ThreadingOSCUDPServer(("127.0.0.1", 0), disp)
    # UDP: a receiver that falls behind on a loaded host loses datagrams once the socket's buffer (208 KiB by
    # default, about 50 frames) is full; CI once got 171 of 200. This buffer holds the whole run.
    server.socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
    port = server.server_address[1]
    threading.Thread(target=server.serve_forever, daemon=True).start()
    bag = tmp_path / "rig.mcap"
    extra = f"""  - {{id: vmc, kind: vmc_output, params: {{port: {port}}}}}
  - {{id: rec, kind: recorder, params: {{path: {bag}, topics: [rig/pose, skeleton/solved]}}}}"""
    try:
        with launched(tmp_path, pipeline(tmp_path, 200, extra), "--until-done") as g:
            g.proc.wait(timeout=120)
            assert g.proc.returncode == 0, g.log()
        deadline = time.monotonic() + 10  # what the buffer still holds is handled
        while len(got["T"]) < 200 and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(0.2)
    finally:
        server.shutdown()
    # every humanoid bone arrives with every frame, with unit quaternions
    assert len(got["T"]) == 200
    for bone in BONES:
        assert len(got[bone]) == 200, bone
        q = np.array([v[3:7] for v in got[bone]])
        np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-5)
    rigs = {m.header.frame: m for m in (decode(x.data, x.topic) for x in read_bag(bag, ["rig/pose"]))}
    solved = {m.header.frame: m for m in (decode(x.data, x.topic) for x in read_bag(bag, ["skeleton/solved"]))}
    assert len(rigs) == 200
    checked = 0
    for f, rig in rigs.items():
        sk = solved[f]
        world = np.zeros((len(BONES), 3, 3))
        pos = np.zeros((len(BONES), 3))
        local = quats_to_frames(rig.rotations.astype(float))
        for b, p in enumerate(BONE_PARENT):  # forward kinematics on the rig, Unity frame
            if p < 0:
                world[b], pos[b] = local[b], rig.root_position
            else:
                world[b] = world[p] @ local[b]
                pos[b] = pos[p] + world[p] @ rig.positions[b]
        want = to_unity_position(sk.positions[BONE_JOINT].astype(float), "z")
        ok = sk.status[BONE_JOINT] != Status.MISSING
        assert np.abs(pos[ok] - want[ok]).max() < 0.005, f"frame {f}"
        # the rotations alone aim the limbs: T-pose bone directions carried by the world rotations
        for bone, child, rest_dir in (("LeftUpperArm", "LeftLowerArm", [-1, 0, 0]), ("RightLowerLeg", "RightFoot",
                                                                                       [0, -1, 0])):
            b, c = BONES.index(bone), BONES.index(child)
            d = want[c] - want[b]
            cos = (world[b] @ np.array(rest_dir, float)) @ (d / np.linalg.norm(d))
            assert cos > np.cos(np.radians(3)), (f, bone, np.degrees(np.arccos(min(1, cos))))
        checked += 1
    assert checked == 200


def test_bvh_read_back_by_bvhio_reproduces_the_joints(tmp_path):
    import bvhio

    bvh, csv_path = tmp_path / "take.bvh", tmp_path / "take.csv"
    r = subprocess.run([sys.executable, "-m", "mocap_cli.main", "solve", str(data_file(TAKE)), "--profile",
                        "qualisys_sports", "--joints-out", str(csv_path), "--bvh-out", str(bvh), "--quiet"],
                       cwd=REPO, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    frames, _, positions, status = read_joints_csv(csv_path)
    root = bvhio.readAsHierarchy(str(bvh))
    a = to_canonical("z")
    names = [j.Name for j, _, _ in root.layout()]
    assert [n for n in JOINTS if n in names] == [n for n in names if n in JOINTS] and len(names) >= 22
    worst = 0.0
    for f in range(0, len(frames), 7):
        root.loadPose(f, recursive=True)
        for joint, _, _ in root.layout():
            j = JOINTS.index(joint.Name)
            if status[f, j] == Status.MISSING:
                continue
            worst = max(worst, float(np.abs(np.array(list(joint.PositionWorld)) - a @ positions[f, j]).max()))
    assert worst < 0.005, f"BVH forward kinematics off by {worst * 1000:.2f} mm"


def test_bvh_on_disk_is_whole_after_every_second_so_a_crash_loses_at_most_one(tmp_path):
    """The BVH writer streams: mid-take, without close, another reader gets a whole BVH holding every frame up to the
    last second's flush (before, every frame stayed in memory until close, and a crash lost the take)."""
    import bvhio

    from mocap_core.bvh import BvhWriter
    from mocap_core.synthetic import running_take

    _, truth = running_take(seconds=3.5, rate_hz=100.0)
    writer = BvhWriter(tmp_path / "live.bvh", 100.0, "z")
    frames = np.tile(np.eye(3), (len(JOINTS), 1, 1))
    for f in range(len(truth)):
        writer.add(truth[f], frames)
    on_disk = bvhio.readAsHierarchy(str(tmp_path / "live.bvh"))  # the writer still open: as after a crash
    assert len(on_disk.Keyframes) == 300 and writer.frames == 350
    writer.close()
    assert len(bvhio.readAsHierarchy(str(tmp_path / "live.bvh")).Keyframes) == 350


CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync"]


def chromium(url, tmp_path, *args, budget_ms=2500, attempts=2):
    """One headless Chromium run. On a loaded 2-core machine a run now and then never returns (CI
    saw a screenshot hang for 60 s once in many runs); its whole process group is killed and the
    run tried once more, so a hang of the browser is not taken for a fault of the viewer."""
    cmd = [CHROMIUM, *FLAGS, f"--user-data-dir={tmp_path / 'chromium'}", "--window-size=1280,720",
           f"--virtual-time-budget={budget_ms}", *args, url]
    for attempt in range(attempts):
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                start_new_session=True)
        try:
            out, err = proc.communicate(timeout=45)
            return subprocess.CompletedProcess(cmd, proc.returncode, out, err)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()
            if attempt == attempts - 1:
                raise


@pytest.mark.timeout(300)  # three browser runs, each allowed a retry
def test_viewer_draws_a_moving_skeleton_in_headless_chromium(tmp_path):
    if CHROMIUM is None:
        pytest.fail("chromium is not installed: `make test` installs Debian's chromium package")
    port = free_port()
    extra = f"  - {{id: viewer, kind: viewer, params: {{port: {port}, up_axis: z}}}}"
    graph = pipeline_graph(f"{{path: {data_file(TAKE)}, loop: true}}", extra=extra)
    with launched(tmp_path, graph) as g:
        url = f"http://127.0.0.1:{port}/"
        wait_for(lambda: b'"skeleton": {' in _get(url + "state"), 60, "the viewer to get skeletons")
        doms = []
        for _ in range(2):
            dom = chromium(url, tmp_path, "--dump-dom").stdout
            doms.append(dom)
        ARTIFACTS.mkdir(exist_ok=True)
        shot = ARTIFACTS / "viewer.png"
        chromium(url, tmp_path, f"--screenshot={shot}")
        assert g.proc.poll() is None
    import re

    frames = [int(re.search(r'data-frame="(-?\d+)"', d).group(1)) for d in doms]
    bones = [int(re.search(r'data-bones="(\d+)"', d).group(1)) for d in doms]
    assert all(b >= 20 for b in bones), bones          # a skeleton is drawn
    assert frames[0] >= 0 and frames[1] != frames[0]   # and it changes as frames arrive
    assert shot.stat().st_size > 20_000


def _get(url):
    import urllib.request

    try:
        with urllib.request.urlopen(url, timeout=2) as r:
            return r.read()
    except OSError:
        return b""

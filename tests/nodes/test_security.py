"""CURVE on tcp links: a subscriber without an authorized key receives nothing; everything on loopback."""
import os
import socket
import time

import zmq
import zmq.auth

from mocap_cli.launch_file import load_launch_file
from mocap_cli.launcher import plan
from nodes import curve
from tests.conftest import REPO, launched, wait_for


def free_base_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1] - 20 if s.getsockname()[1] > 20000 else 30000


def receive(endpoint: str, topic: bytes, keys: tuple | None, seconds: float = 2.0) -> int:
    ctx = zmq.Context.instance()
    sock = ctx.socket(zmq.SUB)
    sock.setsockopt(zmq.LINGER, 0)
    if keys is not None:
        sock.curve_publickey, sock.curve_secretkey, sock.curve_serverkey = keys
    sock.setsockopt(zmq.SUBSCRIBE, topic)
    sock.connect(endpoint)
    n, end = 0, time.monotonic() + seconds
    while time.monotonic() < end:
        if sock.poll(100):
            sock.recv_multipart()
            n += 1
    sock.close()
    return n


def test_curve_refuses_unauthorized_subscribers(tmp_path):
    keys = curve.generate(tmp_path / "keys")
    port = free_base_port()
    out = tmp_path / "frames.csv"
    graph = f"""
transport: {{kind: tcp, base_port: {port}, curve_keys: {keys}}}
nodes:
  - {{id: src, kind: synthetic_source, params: {{rate_hz: 200, frames: 0}}}}
  - {{id: log, kind: frame_log, params: {{path: {out}}}, remaps: {{in: markers/raw}}}}
"""
    with launched(tmp_path, graph) as g:
        wait_for(lambda: out.exists() and len(out.read_text().splitlines()) > 20, 30, "frames over CURVE")
        src = next(n for n in g.registry()["nodes"] if n["id"] == "src")
        assert src["endpoint"].startswith("tcp://127.0.0.1:")  # loopback unless told otherwise
        server_public, _ = zmq.auth.load_certificate(str(keys / "server.key"))
        client_public, client_secret = zmq.auth.load_certificate(str(keys / "client.key_secret"))
        intruder_public, intruder_secret = zmq.curve_keypair()
        assert receive(src["endpoint"], b"markers/raw", (client_public, client_secret, server_public)) > 50
        assert receive(src["endpoint"], b"markers/raw", (intruder_public, intruder_secret, server_public)) == 0
        assert receive(src["endpoint"], b"markers/raw", None) == 0
        # the graph's own tools carry the keys
        echo = g.cli("topic", "echo", "markers/raw", "--once", "--timeout", "5")
        assert echo.returncode == 0 and "mocap.MarkerFrame" in echo.stdout
        # the launcher's control socket is not on tcp, where anyone could say "ready": an ipc path in a folder
        # only this user can open
        control = g.registry()["control"]
        assert control.startswith("ipc://")
        folder = os.path.dirname(control[len("ipc://"):])
        assert os.stat(folder).st_mode & 0o777 == 0o700
        # On plain tcp ZeroMQ keeps every subscription any peer sends (300,000 grow a publisher by about 0.9 GB:
        # plain tcp trusts its network); a stranger without an authorized key never gets that far
        grew = _flood_growth(src, server_public)
        n = len(out.read_text().splitlines())
        wait_for(lambda: len(out.read_text().splitlines()) > n + 50, 10, "frames still flowing")
    assert grew < 20, f"a stranger's subscriptions grew the publisher {grew:.0f} MB"


def _flood_growth(src: dict, server_public: bytes) -> float:
    """300,000 subscription messages (an XSUB sends each one) from a peer with a key of its own: MB grown."""
    import psutil

    proc = psutil.Process(src["pid"])
    before = proc.memory_info().rss
    ctx = zmq.Context()
    flood = ctx.socket(zmq.XSUB)
    flood.setsockopt(zmq.SNDTIMEO, 2000)
    flood.curve_publickey, flood.curve_secretkey = zmq.curve_keypair()
    flood.curve_serverkey = server_public
    flood.connect(src["endpoint"])
    try:
        for i in range(300_000):
            flood.send(b"\x01junk/%d/" % i + b"x" * 64)
    except zmq.Again:
        pass   # refused: nothing goes out to a publisher that never accepted the handshake
    time.sleep(2.0)
    flood.close(linger=0)
    ctx.term()
    return (proc.memory_info().rss - before) / 1e6


def test_default_transport_is_private(tmp_path):
    lf = load_launch_file(REPO / "launch" / "studio.yaml")
    for p in plan(lf, "/tmp/x", "ipc:///tmp/x/control"):
        assert p.spec.pub_endpoint.startswith("ipc://")
    f = tmp_path / "g.yaml"
    f.write_text("transport: {kind: ipc, curve_keys: /tmp/k}\nnodes: [{id: a, kind: relay}]\n")
    import pytest

    from mocap_cli.launch_file import LaunchError

    with pytest.raises(LaunchError, match="set transport.kind: tcp"):
        load_launch_file(f)


def test_a_bad_message_on_the_control_socket_never_stops_the_graph(tmp_path):
    """A peer sending `ready` with bytes that are no UTF-8 (and other junk) to the launcher's control socket: the
    launcher ignores it and the graph runs on (it used to die on a UnicodeDecodeError, taking every node down)."""
    import json

    graph = """
nodes:
  - {id: src, kind: synthetic_source, params: {rate_hz: 200, frames: 0}}
  - {id: a, kind: relay, remaps: {in: markers/raw, out: relayed}}
"""
    with launched(tmp_path, graph) as g:
        wait_for(lambda: "starting sources" in g.log(), 30, "the graph to start")
        control = json.loads(g.registry_file.read_text())["control"]
        sock = zmq.Context.instance().socket(zmq.DEALER)
        sock.setsockopt(zmq.LINGER, 2000)  # (delivered before the socket goes)
        sock.connect(control)
        for junk in ([b"ready", b"\xff\xfe"], [b"ready"], [b"\x00" * 64], [b"warm", b"x", b"y"]):
            sock.send_multipart(junk)
        sock.close()
        time.sleep(1.0)
        assert g.proc.poll() is None, g.log()
        nodes = g.cli("node", "list")
        assert all("running" in line for line in nodes.stdout.splitlines() if line.startswith(("src", "a "))), \
            nodes.stdout
    assert "Traceback" not in g.log()


def test_the_graph_registry_is_private(tmp_path, monkeypatch):
    """The registry folder was made 0755 with no owner check: now 0700, an older one of the user's tightened, and
    one that another user made refused with a clear error."""
    import os
    import stat

    import pytest

    from mocap_cli.graph_registry import RegistryError, registry_dir

    fresh = tmp_path / "fresh"
    monkeypatch.setenv("MOCAP_RUN_DIR", str(fresh))
    assert stat.S_IMODE(registry_dir().stat().st_mode) == 0o700
    old = tmp_path / "old"
    old.mkdir(mode=0o777)
    old.chmod(0o777)
    monkeypatch.setenv("MOCAP_RUN_DIR", str(old))
    assert stat.S_IMODE(registry_dir().stat().st_mode) == 0o700
    if os.getuid() == 0:  # (only root can give a folder away)
        theirs = tmp_path / "theirs"
        theirs.mkdir()
        os.chown(theirs, 65534, 65534)
        monkeypatch.setenv("MOCAP_RUN_DIR", str(theirs))
        with pytest.raises(RegistryError, match="belongs to another user"):
            registry_dir()


def test_generated_keys_are_readable_by_their_owner_only(tmp_path, caplog):
    keys = curve.generate(tmp_path / "keys")
    assert keys.stat().st_mode & 0o777 == 0o700 and (keys / "authorized").stat().st_mode & 0o777 == 0o700
    secrets = sorted(keys.glob("*.key_secret"))
    assert len(secrets) == 2 and all(p.stat().st_mode & 0o777 == 0o600 for p in secrets)
    # a secret others can read still works, with a warning that says how to close it
    secrets[0].chmod(0o644)
    with caplog.at_level("WARNING", logger="mocap.curve"):
        curve._load(secrets[0], secret=True)
    assert "chmod 600" in caplog.text

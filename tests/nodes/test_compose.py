"""docker-compose.yml is generated from the launch file; the two cannot drift apart."""
import json
import subprocess
import sys

import yaml

from mocap_cli.launch_file import load_launch_file
from tests.conftest import REPO

LAUNCH = "launch/qtm_studio.yaml"


def test_committed_compose_file_is_the_generated_one():
    r = subprocess.run([sys.executable, "-m", "mocap_cli.main", "compose", LAUNCH], cwd=REPO, capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert (REPO / "docker-compose.yml").read_text() == r.stdout, \
        "docker-compose.yml is stale: run `mocap compose launch/qtm_studio.yaml -o docker-compose.yml`"


def test_one_service_per_node_wired_over_tcp():
    doc = yaml.safe_load((REPO / "docker-compose.yml").read_text())
    services = doc["services"]
    lf = load_launch_file(REPO / LAUNCH)
    assert sorted(services) == sorted(n.id.replace("_", "-") for n in lf.nodes)
    specs = {name: json.loads(svc["command"][-1]) for name, svc in services.items()}
    binds = {s["pub_endpoint"] for s in specs.values()}
    for name, spec in specs.items():
        assert spec["bind_endpoint"].startswith("tcp://*:") and spec["pub_endpoint"] == \
            f"tcp://{name}:{spec['bind_endpoint'].rsplit(':', 1)[1]}"
        for endpoints in spec.get("sub_endpoints", {}).values():
            assert set(endpoints) <= binds, (name, endpoints)
        assert "control_endpoint" not in spec
    assert "${QTM_HOST" in specs["qtm"]["params"]["host"]
    assert all(svc["image"] == "mocap-graph:latest" for svc in services.values())


def test_a_graph_over_two_machines_gives_a_compose_file_each(tmp_path):
    """Each machine's services reach the other machine's nodes at its address, and publish what it reads."""
    from mocap_cli.compose import compose

    path = tmp_path / "spread.yaml"
    path.write_text("""
transport: {kind: tcp, host: 10.0.0.1}
hosts: {rack: 10.0.0.2}
actors: {alice: {host: rack}, bob: {}}
nodes:
  - {id: qtm, kind: qtm_ingest}
  - {id: hips, kind: hip_interpolation, per_actor: true}
""")
    here, rack = (yaml.safe_load(compose(str(path), host))["services"] for host in (None, "rack"))
    assert sorted(here) == ["hips-bob", "qtm"] and sorted(rack) == ["hips-alice"]
    alice = json.loads(rack["hips-alice"]["command"][-1])
    qtm_port = json.loads(here["qtm"]["command"][-1])["bind_endpoint"].rsplit(":", 1)[1]
    assert alice["sub_endpoints"]["mocap/alice/markers/raw"] == [f"tcp://10.0.0.1:{qtm_port}"]
    assert f"10.0.0.1:{qtm_port}:{qtm_port}" in here["qtm"]["ports"]          # read from the rack
    assert json.loads(here["hips-bob"]["command"][-1])["sub_endpoints"]["mocap/bob/markers/raw"] == \
        [f"tcp://qtm:{qtm_port}"]                                            # on this machine: by service name
    assert "depends_on" not in rack["hips-alice"]                             # nothing to wait for there

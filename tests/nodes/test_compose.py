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

"""The runtime registry: one JSON file per running graph (endpoints, topics, pids) for the CLI tools."""
from __future__ import annotations

import json
import os
from pathlib import Path


class RegistryError(Exception):
    pass


def registry_dir() -> Path:
    """The user's private registry folder (0700; an older one of the user's is made so). One that another user made
    is refused: its graph files tell the CLI tools which endpoints to connect to."""
    d = Path(os.environ.get("MOCAP_RUN_DIR") or f"/tmp/mocap-{os.getuid()}")
    d.mkdir(mode=0o700, parents=True, exist_ok=True)
    st = d.stat()
    if st.st_uid != os.getuid():
        raise RegistryError(f"graph registry {d} belongs to another user (uid {st.st_uid}); remove it or set "
                            "MOCAP_RUN_DIR to a folder of your own")
    if st.st_mode & 0o077:
        d.chmod(0o700)
    return d


def registry_path(graph: str) -> Path:
    return registry_dir() / f"{graph}.graph.json"


def write_registry(graph: str, data: dict) -> Path:
    path = registry_path(graph)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(data, indent=2))
    tmp.replace(path)  # atomic: readers never see half a file
    return path


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
        return True
    except ProcessLookupError:
        return False
    except PermissionError:
        return True


def running_graphs() -> list[dict]:
    graphs = []
    for path in sorted(registry_dir().glob("*.graph.json")):
        try:
            data = json.loads(path.read_text())
        except (OSError, ValueError):
            continue
        if _alive(int(data.get("launcher_pid", 0))):
            graphs.append(data)
        else:
            path.unlink(missing_ok=True)  # left by a launcher that was killed
    return graphs


class NoGraph(Exception):
    pass


def find_graph(name: str | None) -> dict:
    graphs = running_graphs()
    if name:
        for g in graphs:
            if g["name"] == name:
                return g
        raise NoGraph(f"no running graph named {name!r} (running: {', '.join(g['name'] for g in graphs) or 'none'})")
    if not graphs:
        raise NoGraph("no running graph found; start one with `mocap launch FILE.yaml` "
                      f"(registry: {registry_dir()})")
    if len(graphs) > 1:
        raise NoGraph(f"several graphs are running ({', '.join(g['name'] for g in graphs)}): pick one with --graph")
    return graphs[0]


def publishers_of(graph: dict, topic: str) -> list[str]:
    return [n["endpoint"] for n in graph["nodes"] if topic in n["publishes"] and n.get("endpoint")]

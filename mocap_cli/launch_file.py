"""The launch-file format (YAML validated by pydantic) and ``--set NODE.PARAM=VALUE`` overrides.

```yaml
name: studio                 # graph name (default: the file's stem)
namespace: ""                # optional topic prefix, e.g. mocap/actor1
transport: {kind: ipc}       # or {kind: tcp, host: 127.0.0.1, base_port: 7100}
actors: [actor1, actor2]     # optional: a copy of each per_actor node per actor (or {actor1: {fit.subject: a.yaml}})
hosts: {stage: 10.0.0.5}     # optional, tcp only: machines by name; a node's (or an actor's) host: runs it there
nodes:
  - id: source               # unique
    kind: file_source        # a name from nodes/registry.py, or package.module:Class
    params: {path: take.c3d}
    remaps: {markers/raw: markers/raw_take1}
    replicas: 1              # >1 runs N processes that split frames by frame number
    container: core          # optional: nodes with the same container share one process (inproc links)
    per_actor: true          # one copy per actor: id hips-actor1, topics under mocap/actor1/, container core-actor1
    host: stage              # run by `mocap launch FILE --host stage` on that machine (default: without --host)
```
"""
from __future__ import annotations

import argparse
import re
from pathlib import Path
from typing import Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator


class LaunchError(Exception):
    pass


class Transport(BaseModel):
    model_config = ConfigDict(extra="forbid")
    kind: Literal["ipc", "tcp"] = "ipc"
    host: str = Field("127.0.0.1", description="address nodes bind and connect to; loopback unless you say")
    base_port: int = Field(7100, ge=1024, le=65000)
    curve_keys: str | None = Field(None, description="directory of CURVE keys (tcp only): authenticated, "
                                   "encrypted links; make one with `mocap keys generate DIR`")

    @model_validator(mode="after")
    def _curve_needs_tcp(self):
        if self.curve_keys and self.kind != "tcp":
            raise ValueError("curve_keys secure tcp links; set transport.kind: tcp")
        return self


class NodeEntry(BaseModel):
    model_config = ConfigDict(extra="forbid")
    id: str = Field(pattern=r"^[A-Za-z0-9_\-]+$")
    kind: str
    params: dict[str, Any] = {}
    remaps: dict[str, str] = {}
    replicas: int = Field(1, ge=1, le=64)
    respawn: bool = True
    hwm: int = Field(1000, ge=1, le=10_000_000, description="messages queued per peer before the newest are dropped")
    keep_last: bool = Field(False, description="process only the newest queued frame; count the rest as drops")
    endpoint: str | None = Field(None, pattern=r"^(tcp|ipc|inproc)://\S+$",
                                 description="explicit endpoint to bind (multi-host graphs): tcp://HOST:PORT")
    container: str | None = Field(None, pattern=r"^[A-Za-z0-9_\-]+$",
                                  description="run in one OS process with the other nodes of this name, wired "
                                  "over inproc sockets (ROS 2's component containers): far less CPU a frame")
    host: str | None = Field(None, description="the name (in hosts:) of the machine that runs it: `mocap launch "
                             "FILE --host NAME` there; without host:, the launch without --host runs it")
    per_actor: bool = Field(False, description="one copy per actor of the launch file's actors:, its topics under "
                            "mocap/<actor>/, {actor} in its text params replaced, and its port, if it has one, the "
                            "node's plus the actor's place in the list")


class LaunchFile(BaseModel):
    model_config = ConfigDict(extra="forbid")
    name: str = Field("graph", pattern=r"^[A-Za-z0-9_\-.]+$", max_length=64,
                      description="names the graph's registry file and sockets: letters, digits, _ - .")
    namespace: str = ""
    transport: Transport = Transport()
    actors: dict[str, dict[str, Any]] = Field(default_factory=dict, description="the subjects in the stream (their "
                                              "labels' prefix), each with its own NODE.PARAM values if it needs them")
    hosts: dict[str, str] = Field(default_factory=dict, description="machines by name: the address each binds "
                                  "its nodes' tcp endpoints on and the others connect to")
    realtime: bool = Field(False, description="run the node processes under the SCHED_RR real-time policy, so a busy "
                           "machine delays no frame (needs an rtprio limit or CAP_SYS_NICE; docs/graph.md)")
    nodes: list[NodeEntry]

    @field_validator("actors", mode="before")
    @classmethod
    def _actor_list(cls, v):
        if isinstance(v, list):
            return {str(a): {} for a in v}
        return {a: ({} if params is None else params) for a, params in v.items()} if isinstance(v, dict) else v

    @model_validator(mode="after")
    def _actors_and_their_nodes(self):
        per_actor = {n.id for n in self.nodes if n.per_actor}
        if per_actor and not self.actors:
            raise ValueError(f"nodes {', '.join(sorted(per_actor))} are per_actor, but the file lists no actors:")
        if self.actors and not per_actor:
            raise ValueError("actors: is given, but no node is per_actor: true (mark the solving pipeline's nodes)")
        for actor, values in self.actors.items():
            if not re.match(r"^[A-Za-z0-9_\-]+$", actor):
                raise ValueError(f"actor {actor!r}: letters, digits, _ and - only (it names topics and nodes)")
            for key in values:
                node, dot, param = key.partition(".")
                if key == "host":
                    continue
                if not dot or node not in per_actor or not param:
                    raise ValueError(f"actor {actor}: {key!r} is not NODE.PARAM of a per_actor node "
                                     f"({', '.join(sorted(per_actor))}), or host")
        return self

    @model_validator(mode="after")
    def _hosts_known(self):
        named = [(f"node {n.id}", n.host) for n in self.nodes] + [(f"actor {a}", v.get("host"))
                                                                  for a, v in self.actors.items()]
        for who, host in named:
            if host is not None and host not in self.hosts:
                raise ValueError(f"{who}: host {host!r} is not in hosts: ({', '.join(self.hosts) or 'none given'})")
        hosts_of = {}
        for n in self.nodes:
            if n.container and hosts_of.setdefault(n.container, n.host) != n.host:
                raise ValueError(f"node {n.id}: container {n.container!r} is one process, on one host")
        if self.hosts and self.transport.kind != "tcp":
            raise ValueError("hosts: nodes on several machines talk over tcp; set transport: {kind: tcp}")
        return self

    def address(self, host: str | None) -> str:
        """Where the nodes of ``host`` bind and are reached (the transport's host for those without one)."""
        return self.hosts[host] if host else self.transport.host

    def copies(self, entry: NodeEntry, port_default: int | None = None) -> list[tuple[NodeEntry, str]]:
        """``entry`` as the graph runs it, with each copy's namespace: itself, or one per actor (see per_actor)."""
        if not entry.per_actor:
            return [(entry, self.namespace)]
        out = []
        for i, (actor, values) in enumerate(self.actors.items()):
            params = {k: v.replace("{actor}", actor) if isinstance(v, str) else v for k, v in entry.params.items()}
            port = params.get("port", port_default)
            if isinstance(port, int) and port > 0:
                params["port"] = port + i
            params.update({k.partition(".")[2]: v for k, v in values.items() if k.partition(".")[0] == entry.id})
            copy = entry.model_copy(update={"id": f"{entry.id}-{actor}", "params": params,
                                            "container": entry.container and f"{entry.container}-{actor}",
                                            "host": values.get("host", entry.host)})
            out.append((copy, "/".join(x for x in (self.namespace.strip("/"), "mocap", actor) if x)))
        return out

    @field_validator("nodes")
    @classmethod
    def _unique_ids(cls, nodes):
        ids = [n.id for n in nodes]
        dup = sorted({i for i in ids if ids.count(i) > 1})
        if dup:
            raise ValueError(f"duplicate node ids: {', '.join(dup)}")
        if not nodes:
            raise ValueError("a graph needs at least one node")
        return nodes

    @model_validator(mode="after")
    def _no_replicated_sources_with_endpoint(self):
        for n in self.nodes:
            if n.endpoint and n.replicas > 1:
                raise ValueError(f"node {n.id}: an explicit endpoint cannot be shared by {n.replicas} replicas")
            if n.container and n.replicas > 1:
                raise ValueError(f"node {n.id}: replicas split frames over processes; a container is one process")
            if n.container and n.container in self._ids():
                raise ValueError(f"node {n.id}: container {n.container!r} has the name of a node")
        if self.transport.curve_keys and any(n.container for n in self.nodes):
            raise ValueError("containers are not supported with curve_keys yet (their nodes share one process, "
                             "so one ZAP handler); run the secured graph without containers")
        return self

    def _ids(self) -> set[str]:
        return {n.id for n in self.nodes}


def parse_override(text: str) -> tuple[str, str, Any]:
    """``node.param=value`` -> (node, param, YAML-parsed value)."""
    key, eq, value = text.partition("=")
    node, dot, param = key.partition(".")
    if not eq or not dot or not node or not param:
        raise LaunchError(f"--set {text!r}: expected NODE.PARAM=VALUE, e.g. --set solver.solver=fabrik, or "
                          "actors=[alice, bob]")
    return node, param, _yaml_value(text, value) if value else ""


def _yaml_value(text: str, value: str) -> Any:
    """A --set value as YAML, or a LaunchError saying what is wrong with it."""
    try:
        if _expanded_size(yaml.compose(value), MAX_YAML_NODES) > MAX_YAML_NODES:
            raise LaunchError(f"--set {text!r}: the value expands to over {MAX_YAML_NODES} YAML nodes")
        return yaml.safe_load(value)
    except yaml.YAMLError as e:
        raise LaunchError(f"--set {text!r}: the value is not YAML ({' '.join(str(e).split())}); quote a text "
                          f"value: --set '{text.partition('=')[0]}=\"...\"'") from None


# The most YAML nodes a launch file may expand to (its aliases followed): a real graph has a few hundred; a "billion
# laughs" file of a few hundred bytes expands to billions, which validating would take minutes and gigabytes over.
MAX_YAML_NODES = 100_000


def _expanded_size(node, budget: int) -> int:
    """How many nodes the YAML graph holds with its aliases followed, counting no further than ``budget``."""
    count, stack = 0, [node]
    while stack and count <= budget:
        n = stack.pop()
        count += 1
        if isinstance(n, yaml.SequenceNode):
            stack.extend(n.value)
        elif isinstance(n, yaml.MappingNode):
            stack.extend(v for pair in n.value for v in pair)
    return count


def _is_param(node: dict, name: str) -> bool:
    """Whether the node's kind has a param of this name: it wins over the launch-file key of the same name
    (``--set qtm.host=...`` is QTM's address, not the machine that runs the node)."""
    from nodes.registry import UnknownKind, load_kind

    try:
        return name in load_kind(str(node.get("kind"))).Params.model_fields
    except UnknownKind:
        return False


def add_realtime_flag(parser: argparse.ArgumentParser) -> None:
    """``--realtime`` / ``--no-realtime``: over the launch file's ``realtime:`` (None: as the file says)."""
    parser.add_argument("--realtime", action=argparse.BooleanOptionalAction, default=None,
                        help="the nodes under real-time scheduling, or not (--no-realtime), whatever the file says")


def load_launch_file(path: str | Path, overrides: list[str] = ()) -> LaunchFile:
    """The launch file with the ``--set`` overrides applied, all of it validated together (an override gets the
    same checks as the file: a kind of null, 0 or 1000 replicas are refused with the node and the field named)."""
    path = Path(path)
    try:
        text = path.read_text()
        if _expanded_size(yaml.compose(text), MAX_YAML_NODES) > MAX_YAML_NODES:
            raise LaunchError(f"launch file {path}: expands to over {MAX_YAML_NODES} YAML nodes through its aliases; "
                              "a graph needs far fewer (write the nodes out)")
        raw = yaml.safe_load(text)
    except FileNotFoundError:
        raise LaunchError(f"launch file {path} not found") from None
    except UnicodeDecodeError as e:
        raise LaunchError(f"launch file {path}: not UTF-8 text (byte {e.start})") from None
    except RecursionError:
        raise LaunchError(f"launch file {path}: nested too deep to be a launch file") from None
    except yaml.YAMLError as e:
        raise LaunchError(f"launch file {path}: not valid YAML ({e})") from None
    if not isinstance(raw, dict) or not isinstance(raw.get("nodes"), list):
        raise LaunchError(f"launch file {path}: expected a mapping with a 'nodes' list")
    raw.setdefault("name", path.stem)
    by_id = {n["id"]: n for n in raw["nodes"] if isinstance(n, dict) and isinstance(n.get("id"), str)}
    for text in overrides:
        if text.partition("=")[0].strip() == "actors":  # the graph's own list: --set 'actors=[alice, bob]'
            raw["actors"] = _yaml_value(text, text.partition("=")[2])
            continue
        node, param, value = parse_override(text)
        if node not in by_id:
            raise LaunchError(f"--set {text!r}: no node {node!r} in {path} (nodes: {', '.join(map(str, by_id))})")
        if param in NodeEntry.model_fields and param not in ("id", "params") and not _is_param(by_id[node], param):
            by_id[node][param] = value
        else:
            by_id[node].setdefault("params", {})
            if not isinstance(by_id[node]["params"], dict):
                raise LaunchError(f"--set {text!r}: node {node}'s params are not a mapping")
            by_id[node]["params"][param] = value
    try:
        return LaunchFile.model_validate(raw)
    except ValidationError as e:
        lines = [f"  {'.'.join(str(p) for p in err['loc'])}: {err['msg']}" for err in e.errors()]
        said = f" (with --set {', '.join(overrides)})" if overrides else ""
        raise LaunchError(f"launch file {path}{said} is invalid:\n" + "\n".join(lines)) from None

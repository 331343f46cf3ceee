"""`mocap launch`: every node as its own OS process, wired as the launch file says.

1. Plan: resolve node kinds, validate their params, give each process a PUB endpoint, and for each
   topic work out who publishes it and how many subscribers each publisher must see.
2. Start: a process per node, forked from a parent that loaded the graph's node kinds and kernels once
   (nodes.forkserver), running what ``python -m nodes.run SPEC`` runs (a container's nodes share one process and
   get ``[SPEC, ...]``; between themselves they hand messages over as objects, heartbeats go over
   ``inproc://``). Each node reports "ready" over the
   control socket once its XPUB has seen all its expected subscribers; when every node is ready the
   sources get "start". No sleeps: a source cannot send before the graph is wired.
3. Watch: a node that dies is restarted with exponential backoff (0.1 s doubling to 5 s; reset
   after 10 s of good running) and the restart is logged. A source that exits 0 has finished.
4. Stop on SIGINT/SIGTERM: SIGTERM to every node, SIGKILL to any still alive after 1.5 s, so the
   whole graph is gone within 2 s. Nodes also get SIGTERM if the launcher itself is killed.
"""
from __future__ import annotations

import itertools
import json
import logging
import os
import multiprocessing
import shutil
import signal
import subprocess
import tempfile
import time
from dataclasses import dataclass, field

from pathlib import Path

import zmq

from mocap_cli.graph_registry import registry_path, write_registry
from mocap_cli.launch_file import LaunchError, LaunchFile, NodeEntry
from mocap_core.warmup import PARTS, ensure_compiled
from nodes import forkserver
from nodes.priority import REALTIME_PRIORITY, is_realtime
from nodes.registry import UnknownKind, load_kind
from nodes.runtime import DIAGNOSTICS, inproc_endpoint
from nodes.spec import NodeSpec

log = logging.getLogger("mocap.launch")
STOP_GRACE_S = 1.5
BACKOFF_FIRST_S, BACKOFF_MAX_S, BACKOFF_RESET_S = 0.1, 5.0, 10.0


@dataclass
class Proc:
    """One node of the plan: its spec and wiring, and whether it said "ready"."""
    spec: NodeSpec
    is_source: bool
    respawn: bool
    container: str | None = None
    host: str | None = None                 # the launch file's name of the machine that runs it
    ready: bool = False
    identity: bytes | None = None
    publishes: list[str] = field(default_factory=list)
    subscribes: list[str] = field(default_factory=list)
    kernels: tuple[str, ...] = ()           # the numba kernels it runs (mocap_core.warmup's parts)


@dataclass
class Process:
    """One OS process: a node, or a container of nodes that share one loop."""
    name: str
    nodes: list[Proc]
    os_process: multiprocessing.Process | None = None
    started_at: float = 0.0
    restarts: int = 0
    failures_in_row: int = 0
    restart_at: float | None = None
    finished: bool = False

    @property
    def label(self) -> str:
        if len(self.nodes) == 1 and self.nodes[0].container is None:
            return f"node {self.name}"
        return f"container {self.name} ({', '.join(n.spec.id for n in self.nodes)})"

    @property
    def is_source(self) -> bool:
        return any(n.is_source for n in self.nodes)

    @property
    def respawn(self) -> bool:
        return all(n.respawn for n in self.nodes)

    def argv(self) -> str:
        if len(self.nodes) == 1 and self.nodes[0].container is None:
            return self.nodes[0].spec.model_dump_json()
        return json.dumps([n.spec.model_dump(mode="json") for n in self.nodes])


def group(procs: list[Proc]) -> list[Process]:
    """Nodes to OS processes: one each, except that a container's nodes share one (in launch-file order)."""
    out: list[Process] = []
    by_container: dict[str, Process] = {}
    for p in procs:
        if p.container is None:
            out.append(Process(name=p.spec.id, nodes=[p]))
        elif p.container in by_container:
            by_container[p.container].nodes.append(p)
        else:
            by_container[p.container] = Process(name=p.container, nodes=[p])
            out.append(by_container[p.container])
    return out


def plan(lf: LaunchFile, sock_dir: str, control_endpoint: str) -> list[Proc]:
    """Turn a launch file into one NodeSpec per process, with endpoints and expected subscribers."""
    procs: list[Proc] = []
    tcp_ports = itertools.count(lf.transport.base_port + 1)
    for template in lf.nodes:
        try:
            cls = load_kind(template.kind)
        except UnknownKind as e:
            raise LaunchError(f"node {template.id}: {e}") from None
        if lf.actors and not template.per_actor and "actors" in cls.Params.model_fields:
            # a source splits the stream for the actors; an output shows them all
            template = template.model_copy(update={"params": {"actors": list(lf.actors), **template.params}})
        port = cls.Params.model_fields.get("port")
        for entry, namespace in lf.copies(template, port.default if port else None):
            procs += _node_procs(lf, entry, namespace, cls, sock_dir, control_endpoint, tcp_ports)
    for sub in procs:
        for topic in sub.subscribes:
            pubs = [p for p in procs if topic in p.publishes and p is not sub]
            # Within a container a message goes over as the object itself (ROS 2's intra-process
            # hand-off): no socket, no codec, and nothing for the publisher's XPUB to wait for.
            local = [p for p in pubs if _same_container(sub, p) and topic != DIAGNOSTICS]
            if local:
                sub.spec.local_topics.append(topic)
            pubs = [p for p in pubs if p not in local]
            sub.spec.sub_endpoints[topic] = [_endpoint_for(sub, p) for p in pubs]
            for p in pubs:
                p.spec.expected_subscribers[topic] = p.spec.expected_subscribers.get(topic, 0) + 1
    unfed = sorted({(p.spec.id, t) for p in procs for t in p.subscribes
                    if not p.spec.sub_endpoints[t] and t not in p.spec.local_topics})
    for node_id, topic in unfed:
        log.warning("node %s subscribes to %s but no node in the graph publishes it", node_id, topic)
    return procs


def _node_procs(lf: LaunchFile, entry: NodeEntry, namespace: str, cls, sock_dir: str, control_endpoint: str,
                tcp_ports) -> list[Proc]:
    """One launch-file node (or one actor's copy of it) as its processes: one, or one per replica."""
    try:
        params = cls.Params.model_validate(entry.params)
    except Exception as e:
        raise LaunchError(f"node {entry.id} ({entry.kind}): bad params: {e}") from None
    if entry.container and cls.is_source:
        raise LaunchError(f"node {entry.id}: a source ends its process when it finishes, so it cannot "
                          f"be in container {entry.container!r}")
    inputs, outputs = cls.inputs(params), cls.outputs(params)
    out = []
    for k in range(entry.replicas):
        pid = entry.id if entry.replicas == 1 else f"{entry.id}#{k}"
        if entry.endpoint:
            endpoint = entry.endpoint
        elif lf.transport.kind == "tcp":
            endpoint = f"tcp://{lf.address(entry.host)}:{next(tcp_ports)}"
        else:
            endpoint = f"ipc://{sock_dir}/{pid.replace('#', '-')}.pub"
        spec = NodeSpec(id=pid, kind=entry.kind, graph=lf.name, params=entry.params, remaps=entry.remaps,
                        namespace=namespace, pub_endpoint=endpoint, control_endpoint=control_endpoint,
                        replica=k, replicas=entry.replicas, hwm=entry.hwm, keep_last=entry.keep_last,
                        curve_keys=str(Path(lf.transport.curve_keys).resolve()) if lf.transport.curve_keys
                        else None, realtime=lf.realtime)
        out.append(Proc(spec=spec, is_source=cls.is_source, respawn=entry.respawn, container=entry.container,
                        host=entry.host, kernels=cls.kernels(params),
                        publishes=[spec.wire_topic(t) for t in outputs] + [DIAGNOSTICS],
                        subscribes=[spec.wire_topic(t) for t in inputs]))
    return out


def _same_container(a: Proc, b: Proc) -> bool:
    return a.container is not None and a.container == b.container and a.host == b.host


def _endpoint_for(sub: Proc, pub: Proc) -> str:
    """Where ``sub`` connects to reach ``pub``: inproc within a container (heartbeats), else the pub endpoint."""
    if _same_container(sub, pub):
        pub.spec.inproc = True
        return inproc_endpoint(pub.spec.id)
    return pub.spec.pub_endpoint


class Launcher:
    """Runs the nodes of one machine: those of ``host`` (a name in the file's hosts:), or those with no host:. The
    whole graph is planned, so they connect to the other machines' nodes, and a publisher waits for subscribers
    there as for local ones."""

    def __init__(self, lf: LaunchFile, launch_path: str = "", on_ready=None, host: str | None = None):
        self.lf = lf
        self.launch_path = launch_path
        self.on_ready = on_ready  # called once, when every node is ready and the sources start
        self.sock_dir = tempfile.mkdtemp(prefix=f"mocap-{lf.name[:20]}-", dir="/tmp")  # 0700: the user's only
        # The launcher's own processes are all on this host, whatever the transport: its control socket is an ipc
        # path in that directory, which no other user can open (over tcp anyone could say "ready").
        self.control_endpoint = f"ipc://{self.sock_dir}/control"
        if host is not None and host not in lf.hosts:
            raise LaunchError(f"--host {host}: not in the launch file's hosts: ({', '.join(lf.hosts) or 'none'})")
        self.procs = [p for p in plan(lf, self.sock_dir, self.control_endpoint) if p.host == host]
        if not self.procs:
            where = f"host {host}" if host else "the machine launched without --host"
            raise LaunchError(f"no node of the launch file runs on {where}")
        self.processes = group(self.procs)
        self.kernels = tuple(k for k in PARTS if any(k in p.kernels for p in self.procs))  # what this machine runs
        self.zctx = zmq.Context()
        self.control = self.zctx.socket(zmq.ROUTER)
        self.control.setsockopt(zmq.LINGER, 0)
        self.control.bind(self.control_endpoint)
        self.graph_started = False
        self.stop_requested = False
        self.exit_code = 0
        self.t0 = time.monotonic()
        self.registry = registry_path(lf.name)

    # -- processes -----------------------------------------------------------------------------------
    def _spawn(self, p: Process) -> None:
        p.os_process = forkserver.start(p.argv())
        p.started_at = time.monotonic()
        for n in p.nodes:
            n.ready, n.identity = False, None

    def _write_registry(self) -> None:
        write_registry(self.lf.name, {
            "name": self.lf.name, "launch_file": os.path.abspath(self.launch_path) if self.launch_path else "",
            "launcher_pid": os.getpid(), "control": self.control_endpoint,
            "curve_keys": str(Path(self.lf.transport.curve_keys).resolve()) if self.lf.transport.curve_keys else None,
            "nodes": [{"id": n.spec.id, "kind": n.spec.kind, "pid": p.os_process.pid if p.os_process else None,
                       "endpoint": n.spec.pub_endpoint, "publishes": n.publishes, "subscribes": n.subscribes,
                       "restarts": p.restarts, "process": p.name} for p in self.processes for n in p.nodes],
        })

    def start(self) -> None:
        try:  # up front: else every node process would compile the same kernels at once
            if ensure_compiled(log, self.kernels):
                self.t0 = time.monotonic()  # readiness and --duration count from the graph's start
        except subprocess.CalledProcessError as e:
            if self.stop_requested:  # Ctrl-C during the compile
                return
            raise LaunchError(f"compiling the numba kernels failed (exit {e.returncode}); "
                              "`python -m mocap_core.warmup` shows why") from None
        forkserver.preload(sorted({n.spec.kind for n in self.procs}), self.kernels)
        for p in self.processes:
            self._spawn(p)
        self._write_registry()
        log.info("graph %s: started %d nodes in %d processes", self.lf.name, len(self.procs), len(self.processes))

    def _on_control(self) -> None:
        while True:
            try:
                identity, verb, *rest = self.control.recv_multipart(zmq.NOBLOCK)
            except zmq.Again:
                return
            except ValueError:
                continue
            if verb == b"failed" and len(rest) >= 2:
                self._setup_failed(rest[0].decode(errors="replace"), rest[1].decode(errors="replace"))
                continue
            if verb != b"ready" or not rest:
                continue
            node_id = rest[0].decode(errors="replace")  # a stray peer's bytes name no node: ignored, never fatal
            for p in self.procs:
                if p.spec.id == node_id:
                    p.ready, p.identity = True, identity
                    if self.graph_started and p.is_source:
                        self.control.send_multipart([identity, b"start"])

    def _setup_failed(self, node_id: str, why: str) -> None:
        """A node's setup raised. Before the graph has started that is the configuration: stop, say so, exit 2
        (restarting would fail the same way, forever). Later (a restart) the node is retried with backoff."""
        if self.graph_started:
            log.error("node %s could not start again: %s", node_id, why)
            return
        log.error("node %s could not start: %s  (fix the launch file, or --set %s.PARAM=VALUE)", node_id, why,
                  node_id.split("#")[0])
        self.exit_code = 2
        self.stop_requested = True

    def _maybe_start(self, now: float) -> None:
        """Start the sources once every node is ready."""
        if self.graph_started or not all(n.ready or p.finished for p in self.processes for n in p.nodes):
            return
        self.graph_started = True
        log.info("graph %s ready in %.0f ms: starting sources", self.lf.name, (now - self.t0) * 1000)
        if self.lf.realtime:
            self._say_realtime()
        if self.on_ready is not None:
            self.on_ready()
        for n in self.procs:
            if n.is_source and n.identity:
                self.control.send_multipart([n.identity, b"start"])

    def _say_realtime(self) -> None:
        """Whether the node processes got the real-time scheduling the launch file asked for: said once."""
        running = [p for p in self.processes if p.os_process is not None and p.os_process.exitcode is None]
        normal = [p.name for p in running if not is_realtime(p.os_process.pid)]
        if not normal:
            log.info("realtime: %d node processes under SCHED_RR, priority %d", len(running), REALTIME_PRIORITY)
            return
        log.warning("realtime: %d of %d node processes run at normal priority (%s): this user may not use real-time "
                    "scheduling. Allow it with an rtprio limit (`ulimit -r %d`, or a line in "
                    "/etc/security/limits.conf) or CAP_SYS_NICE; until then a busy machine can delay frames "
                    "(--no-realtime: run at normal priority without this warning)",
                    len(normal), len(running), ", ".join(normal), REALTIME_PRIORITY)

    def _watch(self, now: float) -> None:
        for p in self.processes:
            if p.os_process is None:
                if p.restart_at is not None and now >= p.restart_at:
                    p.restart_at = None
                    for n in p.nodes:
                        n.spec = n.spec.model_copy(update={"restart": p.restarts})
                    self._spawn(p)
                    self._write_registry()
                    log.warning("restarted %s (restart #%d, pid %d)", p.label, p.restarts, p.os_process.pid)
                continue
            code = p.os_process.exitcode
            if code is None:
                continue
            p.os_process.close()
            p.os_process = None
            if code == 0 and p.is_source:
                p.finished = True
                log.info("source %s finished", p.name)
                continue
            if not p.respawn:
                log.error("%s exited with code %s; respawn is off", p.label, code)
                p.finished = True
                continue
            if now - p.started_at > BACKOFF_RESET_S:
                p.failures_in_row = 0
            delay = min(BACKOFF_FIRST_S * 2 ** p.failures_in_row, BACKOFF_MAX_S)
            p.failures_in_row += 1
            p.restarts += 1
            p.restart_at = now + delay
            how = f"signal {-code}" if code < 0 else f"code {code}"
            log.warning("%s died (%s); restarting in %.1f s", p.label, how, delay)

    def sources_done(self) -> bool:
        sources = [p for p in self.processes if p.is_source]
        return bool(sources) and all(p.finished for p in sources)

    def run(self, duration_s: float | None = None, until_done: bool = False, drain_s: float = 1.0) -> int:
        """Run until a signal, ``duration_s`` or (with ``until_done``) all sources finished + drain."""
        def on_signal(signum, _frame):
            self.stop_requested = True

        old = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
        done_at = None
        try:
            self.start()
            poller = zmq.Poller()
            poller.register(self.control, zmq.POLLIN)
            while not self.stop_requested:
                if poller.poll(50):
                    self._on_control()
                if self.stop_requested:  # Ctrl-C reaches the nodes too: their exits are no deaths
                    break
                now = time.monotonic()
                self._maybe_start(now)
                self._watch(now)
                if duration_s is not None and now - self.t0 >= duration_s:
                    break
                if until_done and self.sources_done():
                    done_at = done_at or now
                    if now - done_at >= drain_s:  # let the last frames flow through the graph
                        break
        finally:
            self.stop()
            for s, h in old.items():
                signal.signal(s, h)
        return self.exit_code

    def stop(self) -> None:
        alive = [p for p in self.processes if p.os_process is not None and p.os_process.exitcode is None]
        for p in alive:
            p.os_process.terminate()
        deadline = time.monotonic() + STOP_GRACE_S
        for p in alive:
            p.os_process.join(max(0.0, deadline - time.monotonic()))
            if p.os_process.exitcode is None:
                log.warning("%s (pid %d) did not stop within %.1f s of SIGTERM: killing it", p.label,
                            p.os_process.pid, STOP_GRACE_S)
                p.os_process.kill()
                p.os_process.join()
        self.control.close(linger=0)
        self.zctx.term()
        self.registry.unlink(missing_ok=True)
        shutil.rmtree(self.sock_dir, ignore_errors=True)
        log.info("graph %s stopped", self.lf.name)

    def status(self) -> list[dict]:
        return [{"id": n.spec.id, "process": p.name, "pid": p.os_process.pid if p.os_process else None,
                 "restarts": p.restarts, "finished": p.finished} for p in self.processes for n in p.nodes]


def dump_plan(lf: LaunchFile) -> str:
    procs = plan(lf, "/tmp/mocap-plan", "ipc:///tmp/mocap-plan/control")
    return json.dumps({p.name: [n.spec.model_dump() for n in p.nodes] for p in group(procs)}, indent=2)

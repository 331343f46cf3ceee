"""A live web viewer (default http://127.0.0.1:8090): markers, located joints, IK-estimated joints
in red (as in thesis Figure 4.4), held joints in orange, bones (every actor's, named, in a stream of several),
and a panel of every node's rate,
latency and drops from the heartbeats. One self-contained page (canvas, no library, nothing from a
CDN) that polls ``/state``; ``/events`` streams the same as Server-Sent Events at up to ``max_fps``.
Drag to orbit, wheel to zoom. On loopback it answers only to 127.0.0.1 and localhost (no DNS rebinding); at
most 32 clients at once, each let go after 10 s of silence.
"""
from __future__ import annotations

import json
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from messages import Heartbeat, MarkerFrame, SkeletonFrame
from mocap_core.skeleton import JOINTS, PARENT_INDEX
from mocap_core.world import DEFAULT_UP, to_canonical
from nodes.actor_split import actor_in, skeletons_of
from nodes.runtime import Node

PAGE = Path(__file__).with_name("viewer.html")


LOOPBACK = {"127.0.0.1", "localhost", "::1"}
CLIENT_TIMEOUT_S = 10.0
MAX_CLIENTS = 32  # browser tabs and scripts; more at once are turned away, not given a thread each


class _BoundedServer(ThreadingHTTPServer):
    daemon_threads = True

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.slots = threading.BoundedSemaphore(MAX_CLIENTS)

    def process_request(self, request, client_address):
        if not self.slots.acquire(blocking=False):
            self.shutdown_request(request)
            return
        super().process_request(request, client_address)

    def process_request_thread(self, request, client_address):
        try:
            super().process_request_thread(request, client_address)
        finally:
            self.slots.release()


class Params(BaseModel):
    model_config = ConfigDict(extra="forbid")
    host: str = "127.0.0.1"
    port: int = Field(8090, ge=0, le=65535)
    max_fps: float = Field(30.0, gt=0)
    actors: list[str] = Field(default_factory=list, description="show each of these actors' skeleton "
                              "(mocap/<actor>/skeleton/solved); the launch file's actors: sets it")


class Viewer(Node):
    kind = "viewer"
    Params = Params
    subscribes = {"skeleton/solved": SkeletonFrame, "markers/raw": MarkerFrame, "diagnostics": Heartbeat}

    @classmethod
    def inputs(cls, params):
        if not params.actors:
            return cls.subscribes
        return {**skeletons_of(params.actors),
                "markers/raw": MarkerFrame, "diagnostics": Heartbeat}

    def setup(self) -> None:
        # skeletons: by actor ("" for a stream of one); skeleton: the latest of them
        self.state = {"skeleton": None, "skeletons": {}, "markers": None, "nodes": {}, "frame": -1, "up": DEFAULT_UP}
        self.version = 0
        self.cond = threading.Condition()
        viewer = self

        loopback = self.params.host in LOOPBACK

        class Handler(BaseHTTPRequestHandler):
            timeout = CLIENT_TIMEOUT_S  # a client that sends nothing, or stops reading, is let go

            def log_message(self, *args):
                pass

            def do_GET(self):
                host = (self.headers.get("Host") or "").rsplit(":", 1)[0].strip("[]")
                if loopback and host not in LOOPBACK:  # another name for this address: DNS rebinding
                    self.send_error(403, "this viewer answers to 127.0.0.1 and localhost only")
                    return
                if self.path in ("/", "/index.html"):
                    body = PAGE.read_bytes()
                    self.send_response(200)
                    self.send_header("Content-Type", "text/html; charset=utf-8")
                    self.send_header("Content-Length", str(len(body)))
                    self.end_headers()
                    self.wfile.write(body)
                elif self.path == "/events":
                    self.send_response(200)
                    self.send_header("Content-Type", "text/event-stream")
                    self.send_header("Cache-Control", "no-cache")
                    self.end_headers()
                    viewer.stream(self.wfile)
                elif self.path == "/state":
                    body = viewer.snapshot().encode()
                    self.send_response(200)
                    self.send_header("Content-Type", "application/json")
                    self.end_headers()
                    self.wfile.write(body)
                else:
                    self.send_error(404)

        self.server = _BoundedServer((self.params.host, self.params.port), Handler)
        self.url = f"http://{self.params.host}:{self.server.server_address[1]}/"
        threading.Thread(target=self.server.serve_forever, daemon=True).start()
        self.log.info("viewer at %s", self.url)

    def snapshot(self) -> str:
        with self.cond:
            return json.dumps({**self.state, "joints": JOINTS, "parents": PARENT_INDEX.tolist(),
                               "to_y_up": to_canonical(self.state["up"]).tolist()})

    def stream(self, out) -> None:
        seen = -1
        period = 1.0 / self.params.max_fps
        try:
            while True:
                with self.cond:
                    self.cond.wait_for(lambda: self.version != seen, timeout=1.0)
                    seen = self.version
                out.write(f"data: {self.snapshot()}\n\n".encode())
                out.flush()
                time.sleep(period)
        except (BrokenPipeError, ConnectionResetError, OSError):
            return

    def on_message(self, topic, msg) -> None:
        with self.cond:
            if isinstance(msg, SkeletonFrame):
                pos = np.where(np.isfinite(msg.positions), msg.positions, np.nan)
                skeleton = {"positions": [None if np.isnan(p).any() else [round(float(v), 4) for v in p] for p in pos],
                            "status": msg.status.tolist()}
                actor = actor_in(topic)
                self.state["skeleton"] = self.state["skeletons"][actor] = skeleton
                self.state["frame"] = msg.header.frame
                self.state["up"] = msg.header.up_axis or self.state["up"]
            elif isinstance(msg, MarkerFrame):
                self.state["markers"] = [[round(float(v), 4) for v in p] for p in msg.positions
                                         if np.isfinite(p).all()]
            elif isinstance(msg, Heartbeat):
                self.state["nodes"][msg.node] = {
                    "kind": msg.kind, "state": msg.state,
                    "in_hz": sum(v for t, v in msg.rates_hz.items() if t in msg.received),
                    "out_hz": sum(v for t, v in msg.rates_hz.items() if t in msg.published),
                    "p50_ms": msg.latency.p50_ms, "p99_ms": msg.latency.p99_ms,
                    "drops": sum(msg.drops.values()), "errors": sum(msg.errors.values())}
            self.version += 1
            self.cond.notify_all()

    def teardown(self) -> None:
        self.server.shutdown()

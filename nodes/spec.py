"""What the launcher tells a node process: who it is, its params and its wiring (passed as JSON)."""
from __future__ import annotations

from typing import Any

from pydantic import BaseModel, Field


class NodeSpec(BaseModel):
    id: str                                   # unique in the graph; replicas get "<id>#<k>"
    kind: str
    graph: str = "standalone"
    params: dict[str, Any] = {}
    remaps: dict[str, str] = {}               # logical topic -> topic on the wire
    namespace: str = ""                       # prefix for every topic, e.g. "mocap/actor1"
    pub_endpoint: str | None = None           # where subscribers reach this node's PUB socket
    bind_endpoint: str | None = None          # where it binds, when that differs (containers: tcp://*:PORT)
    sub_endpoints: dict[str, list[str]] = {}  # wire topic -> publisher endpoints to connect
    expected_subscribers: dict[str, int] = {} # wire topic -> subscriber count to wait for
    inproc: bool = False                      # also bind inproc://ID, for nodes in the same container
    local_topics: list[str] = []              # wire topics handed over in-process by container neighbours
    control_endpoint: str | None = None       # the launcher's ROUTER socket (ready/start handshake)
    replica: int = 0
    replicas: int = 1
    keep_last: bool = Field(False, description="handle only the newest queued message per topic; older ones "
                            "are dropped and counted (outputs that render, not stages that need every frame)")
    hwm: int = Field(1000, description="ZeroMQ high-water mark: queued messages per peer before drops")
    curve_keys: str | None = None             # directory of CURVE keys (nodes/curve.py); None = plain
    restart: int = 0                          # the launcher's restarts of it so far (a sink appends after the first)
    realtime: bool = False                    # run its process under SCHED_RR (nodes.priority)

    def wire_topic(self, logical: str) -> str:
        """Remap, then prefix the namespace unless the name is absolute ("/x") or ``diagnostics`` (as in ROS)."""
        topic = self.remaps.get(logical, logical)
        if self.namespace and not topic.startswith("/") and topic != "diagnostics":
            topic = f"{self.namespace.strip('/')}/{topic}"
        return topic.lstrip("/")

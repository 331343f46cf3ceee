"""Streams the skeleton to the Foxglove app live, through foxglove-sdk's WebSocket server (default
ws://127.0.0.1:8765; in Foxglove: Open connection > Foxglove WebSocket). Topics and schemas: nodes/foxglove_scene.py
(``/skeleton`` and ``/markers`` as SceneUpdate for the 3D panel, ``/tf`` as FrameTransforms; several actors are
entities and frames named for them). At most
``max_rate_hz`` frames a second (the newest), like the viewer: a display needs no more."""
from __future__ import annotations

import time

import foxglove
from pydantic import BaseModel, ConfigDict, Field

from messages import MarkerFrame, SkeletonFrame
from nodes.foxglove_legacy import LegacyRelay, legacy_port
from nodes.foxglove_scene import Channels
from nodes.actor_split import actor_in, skeletons_of
from nodes.runtime import Node


class Params(BaseModel):
    model_config = ConfigDict(extra="forbid")
    host: str = "127.0.0.1"
    port: int = Field(8765, ge=0, le=65535)
    legacy_port: int | None = Field(-1, ge=-1, le=65535, description="a port for clients that speak only "
                                    "foxglove.websocket.v1 (Lichtblick, older Foxglove): -1 the next after port (any "
                                    "free one if port is 0), null none")
    max_rate_hz: float = Field(60.0, gt=0)
    actors: list[str] = Field(default_factory=list, description="show each of these actors' skeleton "
                              "(mocap/<actor>/skeleton/solved); the launch file's actors: sets it")


class FoxgloveOutput(Node):
    kind = "foxglove_output"
    Params = Params
    subscribes = {"skeleton/solved": SkeletonFrame, "markers/raw": MarkerFrame}

    @classmethod
    def inputs(cls, params):
        if not params.actors:
            return cls.subscribes
        return {**skeletons_of(params.actors), "markers/raw": MarkerFrame}

    def setup(self) -> None:
        self.context = foxglove.Context()
        self.server = foxglove.start_server(name="mocap", host=self.params.host, port=self.params.port,
                                            context=self.context)
        self.channels = Channels(self.context)
        self.next: dict[str, float] = {}  # per topic: when the next frame may go out
        self.log.info("Foxglove WebSocket at ws://%s:%d", self.params.host, self.server.port)
        self.legacy = None
        p = self.params
        port = legacy_port(p.port, p.legacy_port)
        if port is not None:
            upstream = "127.0.0.1" if p.host in ("0.0.0.0", "", "::") else p.host
            self.legacy = LegacyRelay(p.host, port, f"ws://{upstream}:{self.server.port}", self.log)
            self.legacy.start()
            self.log.info("and for foxglove.websocket.v1 clients (Lichtblick) at ws://%s:%d", p.host, self.legacy.port)

    def on_message(self, topic, msg) -> None:
        now = time.monotonic()
        if now < self.next.get(topic, 0.0):
            return
        self.next[topic] = now + 1.0 / self.params.max_rate_hz
        actor = actor_in(topic)
        self.channels.log(msg, msg.header.entry_time_ns or time.time_ns(), actor)

    def teardown(self) -> None:
        if self.legacy is not None:
            self.legacy.stop()
        self.server.stop()

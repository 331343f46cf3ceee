"""Records topics of the graph into an MCAP bag (the in-graph twin of `mocap bag record`).

As a node it is wired by the launcher like any subscriber, so sources wait for it: nothing is
lost at start-up. SIGINT/SIGTERM finish the file after the frames already queued for it are
written (``drain_on_stop``); after SIGKILL everything but the last chunk is readable. It never
truncates a file that exists: a recorder restarted after a crash (or a graph launched again with
the same path) writes the take's next piece, ``path.1.mcap`` and so on, and reading the path reads
every piece (nodes/bags.py).
"""
from __future__ import annotations

import platform

from pydantic import BaseModel, ConfigDict, Field

from messages import Message
from nodes.bags import BagWriter, free_piece
from nodes.runtime import Node


class Params(BaseModel):
    model_config = ConfigDict(extra="forbid")
    path: str = Field(description="output .mcap file")
    topics: list[str] = Field(default_factory=lambda: ["markers/raw"], description="logical topics to record")
    launch_file: str = ""
    actor_topics: list[str] = Field(default_factory=list, description="logical topics to record for each actor "
                                    "(mocap/<actor>/<topic>), e.g. skeleton/solved")
    actors: list[str] = Field(default_factory=list, description="the actors of actor_topics; the launch file's "
                              "actors: sets it")


class Recorder(Node):
    kind = "recorder"
    Params = Params
    drain_on_stop = True  # frames already queued when the launcher stops the graph still reach the file

    @classmethod
    def inputs(cls, params):
        per_actor = [f"mocap/{a}/{t}" for a in params.actors for t in params.actor_topics]
        return {t: Message for t in params.topics + per_actor}

    def setup(self) -> None:
        import mcap
        import messages

        path = free_piece(self.params.path)
        if str(path) != self.params.path:
            self.log.warning("%s exists: recording the take's next piece, %s (read as one with it)",
                             self.params.path, path.name)
        self.bag = BagWriter(path, {
            "graph": self.ctx.spec.graph, "node": self.ctx.spec.id, "launch_file": self.params.launch_file,
            "python": platform.python_version(), "mcap": getattr(mcap, "__version__", "?"),
            "messages": ",".join(f"{m.SCHEMA}:{m.VERSION}" for m in messages.ALL_MESSAGES)})
        self.marker_set = None

    def on_message(self, topic, msg) -> None:
        raise AssertionError("the recorder stores raw bytes; see on_raw")

    def on_raw(self, wire_topic: str, payload: bytes, msg: Message) -> None:
        self.bag.write(wire_topic, payload, self.ctx.received_ns, msg.header.capture_time_s * 1e9)
        if msg.SCHEMA == "mocap.MarkerSet":
            self.marker_set = msg

    def teardown(self) -> None:
        if self.marker_set is not None:
            self.bag.add_metadata("marker_set", {"labels": ",".join(self.marker_set.labels),
                                                 "rate_hz": self.marker_set.rate_hz, "source": self.marker_set.source})
        self.bag.close()
        self.log.info("wrote %d messages to %s", self.bag.count, self.bag.path)

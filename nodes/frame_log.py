"""Writes one CSV line per received message (frame, seq, publisher, latency): a test and debugging sink."""
from __future__ import annotations

from pathlib import Path

from pydantic import BaseModel, ConfigDict

from messages import Message
from nodes.runtime import Node


class Params(BaseModel):
    model_config = ConfigDict(extra="forbid")
    path: str


class FrameLog(Node):
    kind = "frame_log"
    drain_on_stop = True  # a sink: frames already queued when the graph stops still reach the file
    Params = Params
    subscribes = {"in": Message}  # any schema: the codec's check is relaxed for the base class
    timer_period_s = 0.1           # flush ten times a second rather than one write call per message

    def setup(self):
        path = Path(self.params.path)
        path.parent.mkdir(parents=True, exist_ok=True)
        # restarted by the launcher: go on after what the run before wrote (a launch starts the file afresh)
        again = self.ctx.spec.restart > 0 and path.exists() and path.stat().st_size > 0
        self.file = open(path, "a" if again else "w")
        if not again:
            self.file.write("frame,seq,publisher,schema,latency_us,estimated,held,missing,received_ns\n")

    def on_message(self, topic, msg):
        # Latency at arrival (before decoding), as a bare pyzmq sink measures it.
        latency_us = (self.ctx.received_ns - msg.header.entry_time_ns) / 1e3 if msg.header.entry_time_ns else ""
        h = msg.header
        counts = ""
        status = getattr(msg, "status", None)
        if status is not None:  # skeletons: how many joints IK estimated, held, or could not give
            counts = f"{int((status == 2).sum())},{int((status == 3).sum())},{int((status == 0).sum())}"
        else:
            counts = ",,"
        self.file.write(f"{h.frame},{h.seq},{h.publisher},{h.schema_name},{latency_us},{counts},"
                        f"{self.ctx.received_ns}\n")

    def on_timer(self):
        self.file.flush()

    def teardown(self):
        self.file.close()

"""Republishes every marker frame unchanged: a hop for transport tests and benchmarks."""
from __future__ import annotations

from messages import MarkerFrame
from nodes.runtime import Node


class Relay(Node):
    kind = "relay"
    subscribes = {"in": MarkerFrame}
    publishes = {"out": MarkerFrame}

    def on_message(self, topic, msg):
        self.ctx.publish("out", msg, source=msg)

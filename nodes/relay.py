"""Relays: republish every marker frame unchanged (hops for transport tests and benchmarks, and a
way to bridge a topic to another name or host).

``relay`` decodes each frame, as any node that reads its input does, and publishes it as its own
(new sequence, its id as publisher). ``raw_relay`` reads only the header and forwards the bytes as
they came, like ROS 2's ``topic_tools relay``: the source's sequence numbers pass through, so a drop
anywhere upstream still shows as a gap downstream, and the first node that reads the frame checks
its arrays.
"""
from __future__ import annotations

from messages import MarkerFrame
from nodes.runtime import Node


class Relay(Node):
    kind = "relay"
    subscribes = {"in": MarkerFrame}
    publishes = {"out": MarkerFrame}

    def on_message(self, topic, msg):
        self.ctx.publish("out", msg, source=msg)


class RawRelay(Node):
    kind = "raw_relay"
    subscribes = {"in": MarkerFrame}
    publishes = {"out": MarkerFrame}
    header_only = True

    def setup(self):
        self.out = self.ctx.wire_topic("out")

    def on_raw(self, wire_topic, payload, msg):
        self.ctx.send_raw(self.out, payload)

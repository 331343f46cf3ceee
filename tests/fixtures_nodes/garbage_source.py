"""A test source that mixes valid marker frames with garbage, foreign and wrong-schema messages."""
import time

import msgpack
import numpy as np
from pydantic import BaseModel

from messages import Heartbeat, MarkerFrame, encode
from nodes.runtime import Node


class Params(BaseModel):
    frames: int = 50


class GarbageSource(Node):
    kind = "garbage_source"
    Params = Params
    publishes = {"markers/raw": MarkerFrame}
    is_source = True

    def setup(self):
        self.i = 0

    def tick(self):
        if self.i >= self.params.frames:
            return None
        wire = self.ctx.wire_topic("markers/raw")
        labels = ["A", "B"]
        good = MarkerFrame(header=MarkerFrame.make_header(self.i, self.i / 100, time.time_ns()), labels=labels,
                           positions=np.zeros((2, 3), np.float32), flags=np.zeros(2, np.uint8))
        self.ctx.publish("markers/raw", good)
        bad = [b"\xc1garbage", msgpack.packb({"x": 1}), encode(good)[:-5],
               encode(Heartbeat(header=Heartbeat.make_header(), node="x", kind="y", pid=1, state="running",
                                uptime_s=0))]
        self.ctx.send_raw(wire, bad[self.i % len(bad)])
        self.i += 1
        return 0.005

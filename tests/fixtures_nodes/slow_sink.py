"""A consumer that takes too long per frame (for the slow-consumer test)."""
import time

from pydantic import BaseModel

from messages import MarkerFrame
from nodes.runtime import Node


class Params(BaseModel):
    delay_s: float = 0.05


class SlowSink(Node):
    kind = "slow_sink"
    Params = Params
    subscribes = {"markers/raw": MarkerFrame}

    def on_message(self, topic, msg):
        time.sleep(self.params.delay_s)

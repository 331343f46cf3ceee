"""A consumer that takes too long per frame, or to start (slow-consumer and start-up tests)."""
import time

from pydantic import BaseModel

from messages import MarkerFrame
from nodes.runtime import Node


class Params(BaseModel):
    delay_s: float = 0.05
    setup_s: float = 0.0   # a node that takes this long to get ready (the graph waits for it)


class SlowSink(Node):
    kind = "slow_sink"
    Params = Params
    subscribes = {"markers/raw": MarkerFrame}

    def setup(self):
        time.sleep(self.params.setup_s)

    def on_message(self, topic, msg):
        time.sleep(self.params.delay_s)

"""Publishes garbage on many topics: random bytes, truncated and wrong-schema messages, NaN floods,
unknown labels and big payloads (for the bad-input test)."""
import numpy as np
from pydantic import BaseModel

from messages import Heartbeat, MarkerFrame, Message, SkeletonFrame, encode
from mocap_core.skeleton import N_JOINTS
from nodes.runtime import Node


class Params(BaseModel):
    topics: list[str]


class Fuzzer(Node):
    kind = "fuzzer"
    Params = Params
    is_source = True

    @classmethod
    def outputs(cls, params):
        return {t: Message for t in params.topics}

    def setup(self):
        self.rng = np.random.default_rng(7)
        self.i = 0
        sk = SkeletonFrame(header=SkeletonFrame.make_header(10**9), positions=np.full((N_JOINTS, 3), np.nan, np.float32),
                           rotations=np.zeros((N_JOINTS, 3, 3), np.float32), status=np.zeros(N_JOINTS, np.uint8))
        mf = MarkerFrame(header=MarkerFrame.make_header(10**9), labels=["nobody", "knows"],
                         positions=np.full((2, 3), np.nan, np.float32), flags=np.zeros(2, np.uint8))
        hb = Heartbeat(header=Heartbeat.make_header(), node="x", kind="y", pid=1, state="running", uptime_s=0)
        self.samples = [lambda: self.rng.bytes(int(self.rng.integers(1, 300))), lambda: encode(sk)[:-7],
                        lambda: encode(hb), lambda: encode(mf), lambda: encode(sk), lambda: b"\x81" * 3,
                        lambda: self.rng.bytes(200_000)]

    def tick(self):
        topic = self.params.topics[self.i % len(self.params.topics)]
        payload = self.samples[(self.i // len(self.params.topics)) % len(self.samples)]()
        self.ctx.send_raw(self.ctx.wire_topic(topic), payload)
        self.i += 1
        return 0.004

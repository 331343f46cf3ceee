"""A source of synthetic marker frames: markers on circles, for wiring tests and benchmarks."""
from __future__ import annotations

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from messages import MarkerFrame, MarkerSet
from nodes.runtime import Node


class Params(BaseModel):
    model_config = ConfigDict(extra="forbid")
    rate_hz: float = Field(100.0, gt=0)
    frames: int = Field(1000, ge=0, description="how many frames to send; 0 = forever")
    markers: int = Field(35, ge=1)


class SyntheticSource(Node):
    kind = "synthetic_source"
    Params = Params
    publishes = {"markers/raw": MarkerFrame, "markers/set": MarkerSet}
    is_source = True

    def setup(self) -> None:
        p = self.params
        self.labels = [f"M{i:02d}" for i in range(p.markers)]
        self.frame = 0
        self.phase = np.linspace(0, 2 * np.pi, p.markers, endpoint=False)

    def tick(self) -> float | None:
        p = self.params
        if p.frames and self.frame >= p.frames:
            return None
        if self.frame == 0:
            self.ctx.publish("markers/set", MarkerSet(header=MarkerSet.make_header(up_axis="+z"), labels=self.labels,
                                                      rate_hz=p.rate_hz, source="synthetic"))
        t = self.frame / p.rate_hz
        pos = np.stack([np.cos(self.phase + t), np.sin(self.phase + t), np.full(p.markers, 1.0)], axis=1)
        msg = MarkerFrame(header=MarkerFrame.make_header(self.frame, t, up_axis="+z"), labels=self.labels,
                          positions=pos.astype(np.float32), flags=np.zeros(p.markers, np.uint8))
        self.ctx.publish("markers/raw", msg)  # entry time stamped there, as the frame goes out
        self.frame += 1
        return 1.0 / p.rate_hz

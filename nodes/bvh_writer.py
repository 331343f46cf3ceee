"""Records ``skeleton/solved`` into a BVH file while the graph streams, on disk a second at a time (a crash loses
at most the last second). Like the recorder it never truncates a file that exists: a writer restarted after a crash
goes on in ``path.1.bvh`` (and so on)."""
from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from messages import SkeletonFrame
from mocap_core.bvh import NAMINGS, BvhWriter
from mocap_core.world import DEFAULT_UP
from nodes.bags import free_piece
from nodes.runtime import Node
from nodes.skeleton_codec import from_message


class Params(BaseModel):
    model_config = ConfigDict(extra="forbid")
    path: str
    rate_hz: float = Field(120.0, gt=0, description="the capture rate (BVH frame time)")
    names: Literal[tuple(NAMINGS)] = Field("mocap", description="joint names: the skeleton model's or a common rig's")


class BvhWriterNode(Node):
    kind = "bvh_writer"
    Params = Params
    subscribes = {"skeleton/solved": SkeletonFrame}

    def setup(self) -> None:
        self.bvh: BvhWriter | None = None  # opened on the first frame, whose header says the world's up axis

    def on_message(self, topic, msg) -> None:
        if self.bvh is None:
            path = free_piece(self.params.path)
            if str(path) != self.params.path:
                self.log.warning("%s exists: writing the take's next piece, %s", self.params.path, path.name)
            self.bvh = BvhWriter(path, self.params.rate_hz, msg.header.up_axis or DEFAULT_UP, names=self.params.names)
        pos, frames, _ = from_message(msg)
        self.bvh.add(pos, frames)

    def teardown(self) -> None:
        if self.bvh is not None:
            self.bvh.close()
            self.log.info("wrote %d frames to %s", self.bvh.frames, self.bvh.path)

"""The node API: a node kind is a class with typed ``Params``, the topics it reads and writes, and handlers
(compare ROS 2 rclpy or ezmsg units). What it sees of the graph is its context (nodes.transport.NodeContext):
publish, count an error, its logger."""
from __future__ import annotations

from typing import TYPE_CHECKING, Any, ClassVar

from pydantic import BaseModel, ConfigDict

from messages import Message

if TYPE_CHECKING:
    from nodes.transport import NodeContext


class NoParams(BaseModel):
    model_config = ConfigDict(extra="forbid")


class Node:
    """Base class of every node kind. Subclasses declare their contract as class attributes."""

    kind: ClassVar[str] = ""
    Params: ClassVar[type[BaseModel]] = NoParams
    subscribes: ClassVar[dict[str, type[Message]]] = {}   # logical topic -> message type
    publishes: ClassVar[dict[str, type[Message]]] = {}
    is_source: ClassVar[bool] = False                     # sources wait for the launcher's "start"
    timer_period_s: ClassVar[float | None] = None         # call on_timer() this often (to the next whole ms)
    drain_on_stop: ClassVar[bool] = False                 # handle frames already queued when stopped
    # Forward bytes without reading them (a relay): the runtime checks only each message's header
    # (schema, version, sequence, as ROS 2's topic_tools relay reads none of its messages) and calls
    # on_raw with msg=None; whoever reads the message downstream checks the rest.
    header_only: ClassVar[bool] = False

    @classmethod
    def inputs(cls, params: BaseModel) -> dict[str, type[Message]]:
        """Topics this node reads with these params (default: the class's ``subscribes``)."""
        return cls.subscribes

    @classmethod
    def outputs(cls, params: BaseModel) -> dict[str, type[Message]]:
        """Topics this node writes with these params (default: the class's ``publishes``)."""
        return cls.publishes

    @classmethod
    def kernels(cls, params: BaseModel) -> tuple[str, ...]:
        """The numba kernels (parts of mocap_core.warmup) this node runs with these params: the launcher
        compiles them up front and the node loads them before setup(), so its first frame is not late."""
        return ()

    def __init__(self, params: BaseModel, ctx: "NodeContext"):
        self.params = params
        self.ctx = ctx
        self.log = ctx.log

    def setup(self) -> None:
        """Open files, build state. Called once before any message."""

    def on_message(self, topic: str, msg: Message) -> None:
        """Handle one decoded message of a logical topic."""

    def on_raw(self, wire_topic: str, payload: bytes, msg: Message | None) -> None:
        """Handle one message with its exact wire bytes (default: call on_message). ``msg`` is the
        decoded message, or None for a ``header_only`` node given bytes from a socket."""
        self.on_message(self.ctx.logical_topic(wire_topic), msg)

    def tick(self) -> float | None:
        """Sources: produce output. Return seconds until the next call, or None when finished."""
        return None

    def on_timer(self) -> None:
        """Called every ``timer_period_s`` when the class sets one."""

    def teardown(self) -> None:
        """Close files. Called once on shutdown, also after an error."""




def params_of(node_cls: type[Node], overrides: dict[str, Any]) -> BaseModel:
    return node_cls.Params.model_validate(overrides)

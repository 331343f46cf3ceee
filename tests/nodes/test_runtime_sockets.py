"""The runtime's socket handling, in one process over inproc sockets: message framing, and how a
publisher tells whether anyone outside its process subscribes (ZeroMQ matches prefixes)."""
import time

import numpy as np
import zmq

from messages import MarkerFrame, decode, encode
from nodes.relay import Relay
from nodes.runtime import NodeLoop
from nodes.spec import NodeSpec


def frame(n: int) -> bytes:
    return encode(MarkerFrame(header=MarkerFrame.make_header(n, n / 100, 1), labels=["a"],
                              positions=np.zeros((1, 3), np.float32), flags=np.zeros(1, np.uint8)))


def relay(zctx: zmq.Context, feed: str) -> NodeLoop:
    spec = NodeSpec(id="r", kind="relay", remaps={"in": "m/raw", "out": "m/out"}, pub_endpoint=f"inproc://{feed}-out",
                    sub_endpoints={"m/raw": [f"inproc://{feed}"]})
    loop = NodeLoop(spec, Relay, zctx)
    loop.node.setup()
    return loop


def pump(loop: NodeLoop, until, seconds: float = 2.0) -> None:
    poller = zmq.Poller()
    for s in loop.sockets():
        poller.register(s, zmq.POLLIN)
    end = time.monotonic() + seconds
    while not until() and time.monotonic() < end:
        loop.step(dict(poller.poll(10)))


def test_messages_of_one_or_three_parts_are_counted_as_bad_framing_and_the_rest_go_on():
    zctx = zmq.Context()
    feed = zctx.socket(zmq.PUB)
    feed.bind("inproc://framing")
    loop = relay(zctx, "framing")
    out = zctx.socket(zmq.SUB)
    out.connect("inproc://framing-out")
    out.subscribe(b"m/out")
    try:
        time.sleep(0.1)
        feed.send_multipart([b"m/raw"])                        # one part: no payload
        feed.send_multipart([b"m/raw", frame(1), b"extra"])    # three parts
        feed.send_multipart([b"m/raw", frame(2)])              # a good one after them
        stats = loop.ctx.stats.received
        pump(loop, lambda: stats["m/raw"].count >= 1)
        assert loop.ctx.stats.errors["bad_framing"] == 2, dict(loop.ctx.stats.errors)
        assert stats["m/raw"].count == 1
        assert out.poll(1000), "the good frame was not relayed"
        topic, payload = out.recv_multipart()
        assert topic == b"m/out" and decode(payload, "m/out", MarkerFrame).header.frame == 2
    finally:
        loop.ctx.close()
        out.close(0)
        feed.close(0)
        zctx.term()


def test_an_outside_subscriber_is_seen_by_prefix_and_forgotten_when_it_leaves():
    zctx = zmq.Context()
    feed = zctx.socket(zmq.PUB)
    feed.bind("inproc://prefix")
    loop = relay(zctx, "prefix")
    ctx = loop.ctx
    try:
        assert not ctx.has_subscribers("out")
        sub = zctx.socket(zmq.SUB)
        sub.connect("inproc://prefix-out")
        sub.subscribe(b"m/")          # a prefix, as `mocap bag record --all` or a namespace tap would
        pump(loop, lambda: ctx.has_subscribers("out"))
        assert ctx.has_subscribers("out"), "a prefix subscription covers m/out"
        assert not ctx._has_outside("x/out")
        sub.unsubscribe(b"m/")
        pump(loop, lambda: not ctx.has_subscribers("out"))
        assert not ctx.has_subscribers("out"), "the subscriber left"
        sub.close(0)
    finally:
        ctx.close()
        feed.close(0)
        zctx.term()

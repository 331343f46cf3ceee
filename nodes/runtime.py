"""The small runtime every node shares: typed params, typed pub/sub, heartbeat, clean shutdown. By concern: the
node API (nodes.node), the transport a node sees (nodes.transport), its statistics (nodes.node_stats) and the
loop that runs it (nodes.node_loop); this module names them together.

A node is a class with ``Params`` (a pydantic model), the topics it reads (``subscribes``) and
writes (``publishes``), and handlers. The runtime owns the sockets and the loop:

- one XPUB socket per node (bound at the endpoint the launcher chose) for every topic it writes and
  for its heartbeat; XPUB lets it see its subscribers arrive, which is how the graph knows it is
  wired before a source starts (no sleeps);
- one SUB socket connected to every publisher of every topic it reads; frames are multipart
  ``[topic, msgpack payload]``;
- a malformed or foreign message is counted, logged with topic and reason, and skipped;
- a ``header_only`` node (a relay) is handed the bytes of each message whose header alone was
  checked, and the first node downstream that decodes it checks the rest;
- a 1 Hz :class:`~messages.Heartbeat` on ``diagnostics`` with rates, latency percentiles
  (from the header's entry time), drops (sequence gaps per publisher) and error counts;
- in a container (several nodes in one process), a message for a neighbour is handed over as the
  object itself, like ROS 2's intra-process communication: no codec and no socket, and it is encoded
  only when someone outside the process subscribes; its arrays are made read-only, so one subscriber
  cannot change what another sees (the same as arrays decoded from bytes);
- SIGINT/SIGTERM end the loop; sockets close with LINGER 0, except that a source that finished
  flushes what it already sent (at most FLUSH_S), and a node with ``drain_on_stop`` (the recorder)
  handles what is already queued for it before it tears down: a last frame is not lost to a race
  with ZeroMQ's I/O thread.
"""
from __future__ import annotations

from nodes.node import Node, NoParams, params_of
from nodes.node_loop import NodeLoop, configure_logging, run_node, run_nodes, wire_hand_over
from nodes.node_stats import DIAGNOSTICS, percentiles
from nodes.transport import NodeContext, inproc_endpoint

__all__ = ["DIAGNOSTICS", "Node", "NodeContext", "NodeLoop", "NoParams", "configure_logging", "inproc_endpoint",
           "params_of", "percentiles", "run_node", "run_nodes", "wire_hand_over"]

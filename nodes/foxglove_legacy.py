"""Foxglove's WebSocket protocol under its older name, for clients that offer only ``foxglove.websocket.v1``
(Lichtblick, Foxglove releases before the SDK renamed it ``foxglove.sdk.v1``): the SDK's server refuses them at
the handshake. The protocol is the same, so a relay on a port of its own accepts the old name and passes every
message, unchanged, both ways to the SDK's server.
"""
from __future__ import annotations

import asyncio
import threading

from websockets.asyncio.client import connect
from websockets.asyncio.server import serve
from websockets.exceptions import ConnectionClosed

LEGACY = "foxglove.websocket.v1"
CURRENT = "foxglove.sdk.v1"


def legacy_port(port: int, legacy: int | None) -> int | None:
    """Where the relay listens, for a server on ``port`` and a ``legacy_port`` param: that port, or (-1) the port
    after the server's (any free one where the server takes any, 0); None: no relay."""
    if legacy is None or legacy >= 0:
        return legacy
    return port + 1 if port else 0


class LegacyRelay:
    """Serves ``LEGACY`` clients on ``host:port`` (0: any free port; ``port`` says which once started), each relayed
    to the SDK's server at ``upstream`` (ws://HOST:PORT)."""

    def __init__(self, host: str, port: int, upstream: str, log):
        self.host, self.port, self.upstream, self.log = host, port, upstream, log
        self.loop = asyncio.new_event_loop()
        self.started = threading.Event()
        self.stopping: asyncio.Event | None = None
        self.failed: BaseException | None = None
        self.thread = threading.Thread(target=self.loop.run_until_complete, args=(self._serve(),), daemon=True,
                                       name="foxglove-legacy")

    def start(self) -> None:
        self.thread.start()
        self.started.wait(10)
        if self.failed is not None:
            raise self.failed

    def stop(self) -> None:
        if self.stopping is not None:
            self.loop.call_soon_threadsafe(self.stopping.set)
        self.thread.join(timeout=1.0)

    async def _serve(self) -> None:
        self.stopping = asyncio.Event()
        try:
            server = await serve(self._relay, self.host, self.port, subprotocols=[LEGACY], max_size=None)
        except OSError as e:
            self.failed = e
            self.started.set()
            return
        async with server:
            self.port = server.sockets[0].getsockname()[1]
            self.started.set()
            await self.stopping.wait()

    async def _relay(self, client) -> None:
        try:
            async with connect(self.upstream, subprotocols=[CURRENT], max_size=None) as upstream:
                both = [asyncio.create_task(_pipe(client, upstream)), asyncio.create_task(_pipe(upstream, client))]
                await asyncio.wait(both, return_when=asyncio.FIRST_COMPLETED)  # either side closing ends both
                for task in both:
                    task.cancel()
        except (OSError, ConnectionClosed) as e:
            self.log.warning("Foxglove client on the legacy protocol dropped: %s", e)


async def _pipe(source, sink) -> None:
    try:
        async for message in source:
            await sink.send(message)
    except ConnectionClosed:
        pass

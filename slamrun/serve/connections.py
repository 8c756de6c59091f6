"""The server's connections, bounded: at most max_connections() open at once. A connection that arrives at the cap
makes room by closing the oldest connection that is not answering a request (of the client holding the most), so a
client holding slow connections never keeps another out; only when every connection is answering one is the
newcomer closed. A connection that is not answering a
request is closed IDLE_S after it opened or after its last answer (a client that never finishes its headers, sends
them a byte at a time, or keeps an idle connection open). One line per kind of refusal on stderr, at most every
LOG_EVERY_S, with the count since the last.

aiohttp has no header timeout, keeps idle connections for an hour and accepts until the process runs out of file
descriptors (1,100 slow connections: nothing answered for 45 s, 116 MB of EMFILE tracebacks); this wraps its
protocol with asyncio's public protocol interface.
"""

from __future__ import annotations

import asyncio
import resource
import sys
import time
from collections.abc import Callable

IDLE_S = 10.0
LOG_EVERY_S = 10.0


def max_connections() -> int:
    """256, or a quarter of the file descriptors this process may open when that is fewer (files and the ledger
    need the rest)."""
    soft, _ = resource.getrlimit(resource.RLIMIT_NOFILE)
    return 256 if soft == resource.RLIM_INFINITY else max(8, min(256, soft // 4))


class Refusals:
    """Counts of refusals by kind, printed as one line per kind at most every LOG_EVERY_S."""

    def __init__(self, clock: Callable[[], float] = time.monotonic):
        self.clock = clock
        self.pending: dict[str, int] = {}
        self.last: dict[str, float] = {}

    def note(self, kind: str) -> None:
        self.pending[kind] = self.pending.get(kind, 0) + 1
        now = self.clock()
        if kind not in self.last or now - self.last[kind] >= LOG_EVERY_S:
            since = "the last such line" if kind in self.last else "the server started"
            n, self.pending[kind], self.last[kind] = self.pending[kind], 0, now
            print(f"slamrun serve: {kind}: {n} since {since}", file=sys.stderr, flush=True)


class Watch:
    """The open connections, each with whether it is answering a request and since when it has not been."""

    def __init__(self, limit: int | None = None, idle_s: float = IDLE_S):
        self.limit = limit or max_connections()
        self.idle_s = idle_s
        self.open: dict[object, _Guarded] = {}  # the aiohttp handler -> its guarded protocol
        self.refusals = Refusals()

    def room_for(self, client: str) -> bool:
        """Whether a connection may be admitted: under the cap, or after the oldest connection answering no request
        of the client holding the most was closed to make room (one client's slow connections never keep another
        out). A client is its address: every local viewer is 127.0.0.1, so the cap is shared and no client has a
        smaller bound of its own (64 streaming tabs of one browser are legitimate)."""
        if len(self.open) < self.limit:
            return True
        counts: dict[str, int] = {}
        for c in self.open.values():
            counts[c.client] = counts.get(c.client, 0) + 1
        idle = [c for c in self.open.values() if c.busy == 0]
        if not idle:
            self.refusals.note(f"refused connections over the cap of {self.limit} open at once, all answering")
            return False
        oldest = min(idle, key=lambda c: (-counts[c.client], c.opened))  # the crowding client's oldest first
        self.refusals.note(f"closed the oldest idle connections at the cap of {self.limit} open, to make room")
        oldest.abort()
        return True

    def factory(self, make: Callable[[], asyncio.Protocol]) -> Callable[[], asyncio.Protocol]:
        return lambda: _Guarded(make(), self)

    def begin(self, handler: object) -> None:
        """A request's headers were read: the connection is answering it."""
        if (conn := self.open.get(handler)) is not None:
            conn.busy += 1

    def end(self, handler: object) -> None:
        if (conn := self.open.get(handler)) is not None:
            conn.busy -= 1
            conn.since = time.monotonic()

    def sweep(self) -> None:
        """Close every connection idle (no request being answered) for more than idle_s."""
        now = time.monotonic()
        for conn in list(self.open.values()):
            if conn.busy == 0 and now - conn.since > self.idle_s:
                self.refusals.note(f"closed connections idle or without a whole request for {self.idle_s:g} s")
                conn.close()

    async def sweeping(self) -> None:
        while True:
            await asyncio.sleep(min(1.0, self.idle_s / 4))
            self.sweep()


class _Guarded(asyncio.Protocol):
    """aiohttp's protocol for one connection, refused past the cap and closed by `Watch.sweep` when idle."""

    def __init__(self, inner: asyncio.Protocol, watch: Watch):
        self.inner, self.watch = inner, watch
        self.transport: asyncio.Transport | None = None
        self.busy, self.since, self.admitted = 0, time.monotonic(), False
        self.opened, self.client = self.since, ""

    def connection_made(self, transport) -> None:
        self.transport = transport
        peer = transport.get_extra_info("peername")
        self.client = str(peer[0]) if isinstance(peer, tuple) and peer else str(peer)
        if not self.watch.room_for(self.client):
            transport.abort()
            return
        self.admitted = True
        self.watch.open[self.inner] = self
        self.inner.connection_made(transport)

    def close(self) -> None:
        if self.transport is not None:
            self.transport.close()

    def abort(self) -> None:
        """Closed at once to make room (it answers no request): gone from the open ones now, not at its loss."""
        self.watch.open.pop(self.inner, None)
        if self.transport is not None:
            self.transport.abort()

    def data_received(self, data: bytes) -> None:
        if self.admitted:
            self.inner.data_received(data)

    def eof_received(self):
        return self.inner.eof_received() if self.admitted else None

    def connection_lost(self, exc) -> None:
        if self.admitted:
            self.watch.open.pop(self.inner, None)
            self.inner.connection_lost(exc)

    def pause_writing(self) -> None:
        if self.admitted:
            self.inner.pause_writing()

    def resume_writing(self) -> None:
        if self.admitted:
            self.inner.resume_writing()

"""A log sink with a size cap: keeps the head and the tail, says how much was dropped between."""

from __future__ import annotations

import os
import select
import threading
import time
from collections import deque
from pathlib import Path
from typing import BinaryIO


class Tap:
    """What a reader writes into a log through: once cut, a reader that was given up on writes nothing more."""

    def __init__(self, log: CappedLog):
        self.log = log
        self._open = True
        self._lock = threading.Lock()

    def write(self, data: bytes) -> None:
        with self._lock:
            if self._open:
                self.log.write(data)

    def cut(self) -> None:
        with self._lock:
            self._open = False


class CappedLog:
    """Head and tail of a process's output. A write error (a full disk) never stops the pump, so the
    process is never blocked on a full pipe; `close()` raises it afterwards."""

    def __init__(self, path: Path, cap_bytes: int):
        self.path = path
        self.head_cap = cap_bytes // 2
        self.tail_cap = cap_bytes - self.head_cap
        self._fh = open(path, "wb")
        self._head_written = 0
        self._tail: deque[bytes] = deque()
        self._tail_size = 0
        self.dropped = 0
        self.received = 0  # every byte given to write(), kept or dropped: how a reader sees the stream still comes
        self.error: OSError | None = None
        self.cut_short: str | None = None  # why the stream's end may be missing, said at its end by close()
        self._closed = False
        self._lock = threading.Lock()  # a pump given up on may still write while close() runs

    @property
    def truncated(self) -> bool:
        return self.dropped > 0

    def write(self, data: bytes) -> None:
        with self._lock:
            self.received += len(data)
            if self.error is None and not self._closed:  # else keep draining; an error is raised by close()
                self._write(data)

    def _write(self, data: bytes) -> None:
        if self._head_written < self.head_cap:
            take = data[: self.head_cap - self._head_written]
            try:
                self._fh.write(take)
                self._fh.flush()
            except OSError as exc:
                self.error = exc
                return
            self._head_written += len(take)
            data = data[len(take) :]
        if not data:
            return
        self._tail.append(data)
        self._tail_size += len(data)
        while self._tail_size > self.tail_cap:
            first = self._tail[0]
            excess = self._tail_size - self.tail_cap
            if len(first) <= excess:
                self._tail.popleft()
                self._tail_size -= len(first)
                self.dropped += len(first)
            else:
                self._tail[0] = first[excess:]
                self._tail_size -= excess
                self.dropped += excess

    def close(self) -> None:
        with self._lock:
            if self._closed:
                return
            self._closed = True
            self._close()

    def _close(self) -> None:
        try:
            if self.error is None:
                if self.dropped:
                    self._fh.write(f"\n[slamrun: log capped, {self.dropped} bytes dropped here]\n".encode())
                for chunk in self._tail:
                    self._fh.write(chunk)
                if self.cut_short:
                    self._fh.write(f"\n[slamrun: {self.cut_short}]\n".encode())
        except OSError as exc:
            self.error = exc
        try:
            self._fh.close()
        except OSError as exc:
            self.error = self.error or exc
        if self.error is not None:
            raise self.error

    def wait_for(self, reader: threading.Thread, stall_s: float, clock=time.monotonic) -> bool:
        """Wait until `reader`, the thread that writes a finished process's output into this log, reaches the end of
        it, for as long as bytes keep coming (a loaded machine delivers a flooded log slowly). False when nothing came
        for `stall_s` and the reader still runs."""
        seen, since = self.received, clock()
        while reader.is_alive():
            reader.join(timeout=min(0.5, stall_s))
            if self.received != seen:
                seen, since = self.received, clock()
            elif clock() - since >= stall_s and reader.is_alive():
                return False
        return True

    def pump(self, stream: BinaryIO, stop: threading.Event | None = None) -> threading.Thread:
        """Copy a pipe into the log in a background thread until EOF, or until `stop` is set and nothing is
        left to read (a process that escaped its run may hold the pipe open forever)."""
        fd = stream.fileno()

        def loop() -> None:
            while True:
                ready, _, _ = select.select([fd], [], [], 0.1)
                if not ready:
                    if stop is not None and stop.is_set():
                        return
                    continue
                try:
                    chunk = os.read(fd, 65536)
                except OSError:
                    return
                if not chunk:
                    return
                self.write(chunk)

        t = threading.Thread(target=loop, daemon=True, name="log-pump")
        t.start()
        return t


def tail(path: Path, n_bytes: int = 4000) -> str:
    """The last bytes of a log, decoded leniently."""
    try:
        with open(path, "rb") as f:
            f.seek(0, 2)
            size = f.tell()
            f.seek(max(0, size - n_bytes))
            return f.read().decode(errors="replace")
    except OSError:
        return ""

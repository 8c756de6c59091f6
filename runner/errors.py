"""One exception family. The CLI catches `SlamRunError` and prints its one-line message."""

from __future__ import annotations


class SlamRunError(Exception):
    """Root of every error this project raises on purpose."""


class SpecError(SlamRunError):
    """The campaign spec is invalid (lists every problem at once)."""

    def __init__(self, source: str, problems: list[str]):
        self.source = source
        self.problems = problems
        lines = "\n".join(f"  {p}" for p in problems)
        super().__init__(f"{source}: {len(problems)} problem(s) in the spec:\n{lines}")


class DatasetError(SlamRunError):
    """A sequence folder or one of its files is missing or malformed."""


class TrajectoryFormatError(SlamRunError):
    """A trajectory file cannot be parsed; the message names the file and line."""


class MethodFailure(SlamRunError):
    """A method ran but produced no usable trajectory: this is data, not a bug.

    `kind` is one of the method failure kinds (not_initialized, lost, no_output, crashed, timeout, oom).
    """

    def __init__(self, kind: str, message: str):
        self.kind = kind
        super().__init__(message)


class InfraError(SlamRunError):
    """An infrastructure fault (image missing, daemon gone, disk full): retried, never the method's result."""


class DaemonUnreachable(InfraError):
    """The Docker daemon stopped answering: the campaign stops starting runs until it is back."""


class DiskFullError(InfraError):
    """The results or cache disk is full: the campaign stops; finished runs and the ledger stay intact."""


def is_disk_full(exc: BaseException) -> bool:
    """An OSError for a full disk or quota, or SQLite's 'database or disk is full'."""
    import errno
    import sqlite3

    if isinstance(exc, OSError):
        return exc.errno in (errno.ENOSPC, errno.EDQUOT)
    return isinstance(exc, sqlite3.OperationalError) and "full" in str(exc)


class LedgerLostError(SlamRunError):
    """The ledger file vanished (or was replaced) while a campaign ran: no new run starts."""


class LedgerLockedError(SlamRunError):
    """Another runner holds the results directory."""

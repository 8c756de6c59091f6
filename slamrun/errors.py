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


class MetricError(SlamRunError):
    """A metric cannot be computed for this pair of trajectories (nothing to pair, too few poses, ...)."""


class MethodFailure(SlamRunError):
    """A method ran but produced no usable trajectory: this is data, not a bug.

    `kind` is one of the method failure kinds (not_initialized, lost, no_output, crashed, timeout, oom).
    """

    def __init__(self, kind: str, message: str):
        self.kind = kind
        super().__init__(message)


class InfraError(SlamRunError):
    """An infrastructure fault (image missing, daemon gone, disk full): retried, never the method's result."""


class Contended(InfraError):
    """A run lost (or never initialised) while its threads waited for a CPU longer than the spec's contention_pct:
    the machine's load, not the method, is the likelier cause. Retried as an infrastructure fault."""


class BackendUnreachable(InfraError):
    """The engine runs go through stopped answering: the campaign stops starting runs until it is back (runs not
    started stay pending, never `infra`)."""


class DaemonUnreachable(BackendUnreachable):
    """The Docker daemon stopped answering."""


class SchedulerUnreachable(BackendUnreachable):
    """The Dask scheduler stopped answering."""


class StorageError(InfraError):
    """The results or cache disk cannot be written (full, or read-only): the campaign stops; finished runs and
    the ledger stay intact. `why` says which ("the disk is full", ...)."""

    def __init__(self, message: str, why: str = "the disk is full"):
        self.why = why
        super().__init__(message)


def storage_problem(exc: BaseException) -> str | None:
    """Why a write failed for the storage's sake (a full disk or quota, a read-only filesystem, no permission;
    SQLite's 'database or disk is full' and 'readonly database' too), or None for any other error."""
    import errno
    import sqlite3

    if isinstance(exc, OSError):
        if exc.errno in (errno.ENOSPC, errno.EDQUOT):
            return "the disk is full"
        if exc.errno == errno.EROFS:
            return "the folder is on a read-only filesystem"
        if exc.errno in (errno.EACCES, errno.EPERM):
            return "writing there is not permitted"
        return None
    if isinstance(exc, sqlite3.OperationalError):
        text = str(exc)
        if "full" in text:
            return "the disk is full"
        if "readonly" in text or "read-only" in text:
            return "the folder is on a read-only filesystem"
    return None


class LedgerLostError(SlamRunError):
    """The ledger file vanished (or was replaced) while a campaign ran: no new run starts."""


class LedgerLockedError(SlamRunError):
    """Another runner holds the results directory."""


def one_line(exc: BaseException, limit: int = 300) -> str:
    """Someone else's exception as `Type: message` on one line, at most `limit` characters of message (its type
    alone when it has none): what a plug-in, a method class or a reader raised, named without a traceback."""
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text[:limit]}" if text else type(exc).__name__

"""Download sequences: resumable (HTTP Range), sizes verified (Content-Length), unpacked into DEST/<sequence>/.

Each sequence's archive as its authors publish it (TUM-Mono's sequence_XX.zip, EuRoC's zip holding `mav0/`, a .tgz
or a .tar holding the sequence's folder, ...): which archives and where is each layout module's `Download` (its
address overridable with an environment variable or --url: a mirror). KITTI is not downloaded: its site asks each
user to register and agree to its terms first.

Bounded on a hostile or broken server and archive: a download that gets fewer than STALL_BYTES in any stretch of
SLAMRUN_DOWNLOAD_STALL_S seconds (60 by default; headers included) is ended with a message naming the address, its
part kept for the next run to resume; an archive is unpacked only if what it states it holds fits in the free space
and in UNPACK_RATIO times its own size (a zip bomb is refused before anything is inflated), and the bytes inflated
are counted against what each member states.
"""

from __future__ import annotations

import http.client
import math
import os
import shutil
import socket
import threading
import time
import urllib.error
import urllib.request
import zipfile
from collections.abc import Callable
from pathlib import Path

from slamrun.core.archives import ZIP_ERRORS, copy_member, files_of, stated_total
from slamrun.errors import DatasetError

CHUNK = 1 << 20
STALL_S = 60.0  # SLAMRUN_DOWNLOAD_STALL_S overrides it
STALL_BYTES = 64 * 1024  # fewer than this in STALL_S seconds is a stalled download
UNPACK_RATIO = 100  # an archive may unpack to this many times its size (a sequence's images barely compress), plus:
UNPACK_SLACK = 64 * 2**20
MAX_MEMBERS = 200_000  # files in one archive (a TUM-VI or EuRoC sequence: some thousands)


def stall_seconds() -> float:
    """The seconds without progress that end a download: SLAMRUN_DOWNLOAD_STALL_S, or STALL_S."""
    raw = os.environ.get("SLAMRUN_DOWNLOAD_STALL_S")
    if raw is None:
        return STALL_S
    try:
        value = float(raw)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise DatasetError(f"SLAMRUN_DOWNLOAD_STALL_S={raw!r}: expected a number of seconds above 0 (default 60)")
    return value


class _Watchdog:
    """Ends a stalled download: when fewer than STALL_BYTES arrive in a stretch of `stall_s` seconds (the wait
    for the headers included), it shuts the connection's socket down from its own thread, so a read blocked on it
    returns; `stalled` then holds the bytes of that stretch. A server that sends one byte now and then, or stops
    after its headers, or never finishes them, is left within two stretches."""

    def __init__(self, stall_s: float):
        self.stall_s = stall_s
        self.received = 0  # body bytes, counted by the reader
        self.stalled: int | None = None
        self._sock: socket.socket | None = None
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._watch, name="download-watchdog", daemon=True)

    def __enter__(self) -> _Watchdog:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._done.set()
        self._thread.join()

    def attach(self, sock: socket.socket) -> None:
        """The socket to shut down (the latest: a redirect or TLS makes another)."""
        self._sock = sock
        if self.stalled is not None:  # stalled while it was connecting
            self._shut()

    def _watch(self) -> None:
        mark, since = 0, time.monotonic()
        while not self._done.wait(min(1.0, self.stall_s / 4)):
            if time.monotonic() - since < self.stall_s:
                continue
            if self.received - mark < STALL_BYTES:
                self.stalled = self.received - mark
                self._shut()
                return
            mark, since = self.received, time.monotonic()

    def _shut(self) -> None:
        sock = self._sock
        if sock is not None:
            try:  # the plain socket's shutdown, also under TLS: the blocked read sees the end of the stream
                socket.socket.shutdown(sock, socket.SHUT_RDWR)
            except OSError:
                pass


def _watched(base: type[http.client.HTTPConnection], watch: _Watchdog) -> type[http.client.HTTPConnection]:
    """`base` whose sockets (the TCP one, then the TLS one) are handed to `watch`."""

    class Watched(base):
        def __init__(self, *args, **kw):
            super().__init__(*args, **kw)
            create = self._create_connection

            def created(*a, **k):
                sock = create(*a, **k)
                watch.attach(sock)
                return sock

            self._create_connection = created

        def connect(self) -> None:
            super().connect()
            watch.attach(self.sock)

    return Watched


class _WatchedHTTP(urllib.request.HTTPHandler):
    def __init__(self, watch: _Watchdog):
        super().__init__()
        self.watch = watch

    def http_open(self, req):
        return self.do_open(_watched(http.client.HTTPConnection, self.watch), req)


class _WatchedHTTPS(urllib.request.HTTPSHandler):
    def __init__(self, watch: _Watchdog):
        super().__init__()
        self.watch = watch

    def https_open(self, req):
        return self.do_open(_watched(http.client.HTTPSConnection, self.watch), req, context=self._context)


# what a connection that broke, stalled or answered nonsense raises while it is read
CONNECTION_ERRORS = (OSError, http.client.HTTPException, ValueError)


def _kept(part: Path) -> str:
    size = part.stat().st_size if part.exists() else 0
    return f"; the {size:,} bytes received are kept in {part}" if size else ""


def _stalled(url: str, part: Path, watch: _Watchdog, exc: BaseException | None) -> DatasetError | None:
    """The error of a download the watchdog or the socket's timeout ended, or None when it was neither."""
    if watch.stalled is not None:
        what = f"the server stalled ({watch.stalled:,} bytes in {watch.stall_s:g} s, fewer than {STALL_BYTES:,})"
    elif isinstance(exc, TimeoutError) or isinstance(getattr(exc, "reason", None), TimeoutError):
        what = f"the server sent nothing for {watch.stall_s:g} s"
    else:
        return None
    return DatasetError(
        f"{url}: {what}{_kept(part)}; run the same command again to resume (or try a mirror with --url; "
        "SLAMRUN_DOWNLOAD_STALL_S sets the wait)"
    )


def fetch(
    url: str, dest: Path, progress: Callable[[int, int], None] | None = None, stall_s: float | None = None
) -> Path:
    """Download url to dest, resuming a partial `dest.part`; the size must match Content-Length. A download
    that stalls (`_Watchdog`; `stall_s` seconds, default SLAMRUN_DOWNLOAD_STALL_S or 60) ends with its part kept."""
    part = dest.with_name(dest.name + ".part")
    have = part.stat().st_size if part.exists() else 0
    req = urllib.request.Request(url, headers={"Range": f"bytes={have}-"} if have else {})
    with _Watchdog(stall_seconds() if stall_s is None else stall_s) as watch:
        opener = urllib.request.build_opener(_WatchedHTTP(watch), _WatchedHTTPS(watch))
        try:
            resp = opener.open(req, timeout=watch.stall_s)
        except urllib.error.HTTPError as exc:
            exc.close()
            if exc.code == 416 and have:  # nothing left to fetch: the part is complete
                part.rename(dest)
                return dest
            raise DatasetError(f"{url}: HTTP {exc.code} {exc.reason}; check the address (--url)") from None
        except CONNECTION_ERRORS as exc:
            reason = getattr(exc, "reason", exc)
            raise _stalled(url, part, watch, exc) or DatasetError(
                f"{url}: cannot download ({reason}); run the same command again to resume"
            ) from None
        with resp:
            total = _receive(url, resp, part, have, watch, progress)
    size = part.stat().st_size
    if total is not None and size != total:
        raise DatasetError(f"{url}: got {size:,} of {total:,} bytes; run the same command again to resume")
    part.rename(dest)
    return dest


def _receive(url, resp, part: Path, have: int, watch: _Watchdog, progress) -> int | None:
    """Append the response's body to `part` (from `have`, or anew when the server ignored the range); returns the
    whole file's size as the server states it, if it does."""
    if have and resp.status != 206:  # the server ignored the range: start over
        have = 0
    length = resp.headers.get("Content-Length")
    total = have + int(length) if length is not None and length.isdigit() else None
    with open(part, "ab" if have else "wb") as f:
        done = have
        while True:
            try:
                chunk = resp.read1(CHUNK)  # what has arrived: a slow server is seen between its bytes
            except CONNECTION_ERRORS as exc:
                f.flush()
                raise _stalled(url, part, watch, exc) or DatasetError(
                    f"{url}: the connection broke ({exc}){_kept(part)}; run the same command again to resume"
                ) from None
            if not chunk:
                break
            watch.received += len(chunk)
            f.write(chunk)
            done += len(chunk)
            if progress:
                progress(done, total or 0)
    if watch.stalled is not None:  # the watchdog's shutdown ends the stream like the server's end
        raise _stalled(url, part, watch, None)
    return total


def remote_archives(dataset: str, names: list[str], base_url: str | None = None) -> list[tuple[str, str]]:
    """(sequence folder name, archive address) of each named sequence of layout `dataset`, by its module's
    `Download`; names are checked against the dataset's sequences."""
    from slamrun.datasets.layouts import get

    layout = get(dataset)
    how = layout.download
    if how is None:
        raise DatasetError(layout.manual_download or f"{dataset}: slamrun does not download this layout")
    base = (base_url or how.base_url).rstrip("/")
    found = {name: how.archive(name, base) for name in names}
    bad = [name for name, where in found.items() if where is None]
    if bad:
        raise DatasetError(f"--sequences: {', '.join(bad)}: not {dataset} sequences; known: {how.known}")
    return [where for where in found.values() if where is not None]


def download_archives(
    dataset: str,
    dest: Path,
    names: list[str],
    base_url: str | None = None,
    progress_factory: Callable[[str], Callable[[int, int], None]] | None = None,
    log: Callable[[str], None] = print,
) -> list[Path]:
    """Download and unpack sequences of layout `dataset` into DEST/<sequence>/ (present ones skipped), each from
    its archive as the dataset's site serves it; each unpacked folder must be a sequence of that layout (else the
    archive is deleted and nothing is kept)."""
    from slamrun.datasets.layouts import detect, holds_sequence

    wanted = remote_archives(dataset, names, base_url)
    dest.mkdir(parents=True, exist_ok=True)
    done = []
    for name, url in wanted:
        folder = dest / name
        if holds_sequence(folder):
            log(f"{name}: present")
            done.append(folder)
            continue
        archive = dest / url.rsplit("/", 1)[-1]
        if not archive.exists():
            fetch(url, archive, progress_factory(name) if progress_factory else None)
        tmp = dest / f".{name}.unpack"
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir()
        try:
            _extract(archive, tmp)
            inner = tmp / name if (tmp / name).is_dir() else tmp  # EuRoC's zip holds mav0/ at its top
            if not holds_sequence(inner) or detect(inner) != dataset:
                archive.unlink()
                raise DatasetError(f"{archive}: holds no {dataset} sequence {name} (deleted); is the address right?")
            os.rename(inner, folder)
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        archive.unlink()
        done.append(folder)
    return done


def _extract(archive: Path, into: Path) -> None:
    """A zip, .tgz or .tar, members kept inside `into` (no absolute paths, no `..`, no links out), bounded: what
    the archive states it holds must fit in the free space and in UNPACK_RATIO times its size (else a bomb: the
    archive is deleted, nothing is unpacked), and no member may give more than it states."""
    limit = UNPACK_RATIO * archive.stat().st_size + UNPACK_SLACK
    free = shutil.disk_usage(into).free
    if archive.suffix == ".zip":
        _extract_zip(archive, into, limit, free)
    else:
        _extract_tar(archive, into, limit, free)


def _bomb(archive: Path, what: str, limit: int, kind: str) -> DatasetError:
    """The error of an archive that states more than it may hold; the archive is deleted."""
    size = archive.stat().st_size
    archive.unlink()
    return DatasetError(
        f"{archive}: {what}, more than the {limit:,} bytes an archive of {size:,} bytes may unpack to "
        f"({UNPACK_RATIO} times its size): a {kind} bomb? (deleted; nothing unpacked); check the address (--url)"
    )


def _no_space(archive: Path, into: Path, needed: int, free: int) -> DatasetError:
    return DatasetError(
        f"{archive}: unpacks to {needed:,} bytes or more, and {free:,} are free in {into.parent}; free some space "
        "and run the same command again"
    )


def _extract_zip(archive: Path, into: Path, limit: int, free: int) -> None:
    try:
        zf = zipfile.ZipFile(archive)
    except ZIP_ERRORS:
        archive.unlink()
        raise DatasetError(f"{archive}: not a zip file (deleted); run the same command again") from None
    with zf:
        infos = files_of(zf)
        for member in zf.namelist():
            if member.startswith("/") or ".." in Path(member).parts:
                raise DatasetError(f"{archive}: member {member!r} would land outside the folder; refused")
        if len(infos) > MAX_MEMBERS:
            raise _bomb(archive, f"{len(infos):,} files (at most {MAX_MEMBERS:,})", limit, "zip")
        total = stated_total(infos)
        if total > limit:
            raise _bomb(archive, f"its members state {total:,} bytes", limit, "zip")
        if total > free:
            raise _no_space(archive, into, total, free)
        for info in infos:
            target = into / info.filename
            target.parent.mkdir(parents=True, exist_ok=True)
            with open(target, "wb") as out:
                try:
                    copy_member(zf, info, out, f"{archive}:{info.filename}", DatasetError)
                except DatasetError as exc:
                    archive.unlink()
                    raise DatasetError(f"{exc} (deleted); run the same command again") from None


def _extract_tar(archive: Path, into: Path, limit: int, free: int) -> None:
    """Member by member: each one's stated size (and its header) counted before it is extracted."""
    import gzip
    import lzma
    import tarfile
    import zlib

    used = count = 0
    try:
        with tarfile.open(archive) as tar:
            for member in tar:
                used += member.size + tarfile.BLOCKSIZE
                count += 1
                if count > MAX_MEMBERS:
                    raise _bomb(archive, f"more than {MAX_MEMBERS:,} members", limit, "tar")
                if used > limit:
                    raise _bomb(archive, f"{member.name} states {member.size:,} bytes", limit, "tar")
                if used > free:
                    raise _no_space(archive, into, used, free)
                tar.extract(member, into, filter="data")
    except tarfile.FilterError as exc:
        raise DatasetError(f"{archive}: {exc}; refused") from None
    except (tarfile.TarError, EOFError, zlib.error, gzip.BadGzipFile, lzma.LZMAError) as exc:
        archive.unlink()
        raise DatasetError(f"{archive}: not a readable archive ({exc}; deleted); run the same command again") from None

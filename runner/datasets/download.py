"""Download TUM-Mono sequences: resumable (HTTP Range), sizes verified, unpacked into DEST/sequence_XX/.

The dataset's address lives here only (TUM_MONO_URL), overridable with SLAMRUN_TUM_MONO_URL or --url.
Each sequence is one zip (`sequence_XX.zip`) holding the folder `sequence_XX/`.
"""

from __future__ import annotations

import os
import shutil
import urllib.error
import urllib.request
import zipfile
from collections.abc import Callable
from pathlib import Path

from runner.errors import DatasetError

TUM_MONO_URL = os.environ.get("SLAMRUN_TUM_MONO_URL", "https://vision.in.tum.de/mono/dataset")
CHUNK = 1 << 20


def parse_sequences(text: str) -> list[int]:
    """'1-5,7,10-12' → [1, 2, 3, 4, 5, 7, 10, 11, 12] (TUM-Mono numbers 1..50)."""
    out: list[int] = []
    for part in text.split(","):
        part = part.strip()
        try:
            if "-" in part:
                a, b = (int(v) for v in part.split("-", 1))
                out += list(range(a, b + 1))
            elif part:
                out.append(int(part))
        except ValueError:
            raise DatasetError(f"--sequences {text!r}: expected numbers and ranges like 1-5,7") from None
    bad = [n for n in out if not 1 <= n <= 50]
    if bad:
        raise DatasetError(f"--sequences {text!r}: TUM-Mono has sequences 1 to 50, not {bad}")
    return sorted(set(out))


def fetch(url: str, dest: Path, progress: Callable[[int, int], None] | None = None, timeout: float = 60) -> Path:
    """Download url to dest, resuming a partial `dest.part`; the size must match Content-Length."""
    part = dest.with_name(dest.name + ".part")
    have = part.stat().st_size if part.exists() else 0
    req = urllib.request.Request(url, headers={"Range": f"bytes={have}-"} if have else {})
    try:
        resp = urllib.request.urlopen(req, timeout=timeout)  # noqa: S310 - the dataset's configured address
    except urllib.error.HTTPError as exc:
        if exc.code == 416 and have:  # nothing left to fetch: the part is complete
            part.rename(dest)
            return dest
        raise DatasetError(f"{url}: HTTP {exc.code} {exc.reason}; check the address (--url)") from None
    except (urllib.error.URLError, OSError) as exc:
        raise DatasetError(f"{url}: cannot download ({exc}); run the same command again to resume") from None
    with resp:
        if have and resp.status != 206:  # the server ignored the range: start over
            have = 0
        length = resp.headers.get("Content-Length")
        total = have + int(length) if length is not None else None
        with open(part, "ab" if have else "wb") as f:
            done = have
            while chunk := resp.read(CHUNK):
                f.write(chunk)
                done += len(chunk)
                if progress:
                    progress(done, total or 0)
    size = part.stat().st_size
    if total is not None and size != total:
        raise DatasetError(f"{url}: got {size} of {total} bytes; run the same command again to resume")
    part.rename(dest)
    return dest


def download_tum_mono(
    dest: Path,
    numbers: list[int],
    base_url: str = TUM_MONO_URL,
    progress_factory: Callable[[str], Callable[[int, int], None]] | None = None,
    log: Callable[[str], None] = print,
) -> list[Path]:
    """Download and unpack sequences; sequences already unpacked are skipped."""
    dest.mkdir(parents=True, exist_ok=True)
    done = []
    for n in numbers:
        name = f"sequence_{n:02d}"
        folder = dest / name
        if (folder / "times.txt").exists():
            log(f"{name}: present")
            done.append(folder)
            continue
        archive = dest / f"{name}.zip"
        if not archive.exists():
            fetch(f"{base_url.rstrip('/')}/{name}.zip", archive, progress_factory(name) if progress_factory else None)
        unpack(archive, dest, name)
        archive.unlink()
        done.append(folder)
    return done


def unpack(archive: Path, dest: Path, name: str) -> Path:
    """Unpack atomically: into a temporary folder, then renamed; the archive must hold `name/`."""
    tmp = dest / f".{name}.unpack"
    shutil.rmtree(tmp, ignore_errors=True)
    try:
        with zipfile.ZipFile(archive) as zf:
            bad = zf.testzip()
            if bad:
                raise DatasetError(f"{archive}: member {bad} is corrupt; delete the file and download again")
            zf.extractall(tmp)
    except zipfile.BadZipFile:
        archive.unlink()
        raise DatasetError(f"{archive}: not a zip file (deleted); run the same command again") from None
    inner = tmp / name if (tmp / name).is_dir() else tmp
    if not (inner / "times.txt").exists():
        raise DatasetError(f"{archive}: holds no {name}/times.txt; is the address right?")
    os.rename(inner, dest / name)
    shutil.rmtree(tmp, ignore_errors=True)
    return dest / name

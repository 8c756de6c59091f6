"""Download sequences: resumable (HTTP Range), sizes verified (Content-Length), unpacked into DEST/<sequence>/.

TUM-Mono: one zip per sequence (`sequence_XX.zip` holding `sequence_XX/`). EuRoC, TUM RGB-D and TUM-VI: each
sequence's archive as its authors publish it (a zip holding `mav0/`, a .tgz or a .tar holding the sequence's folder).
The datasets' addresses live here only, each overridable with an environment variable or --url (a mirror). KITTI
is not downloaded: its site asks each user to register and agree to its terms first.
"""

from __future__ import annotations

import os
import re
import shutil
import urllib.error
import urllib.request
import zipfile
from collections.abc import Callable
from pathlib import Path

from runner.errors import DatasetError

TUM_MONO_URL = os.environ.get("SLAMRUN_TUM_MONO_URL", "https://vision.in.tum.de/mono/dataset")
EUROC_URL = os.environ.get("SLAMRUN_EUROC_URL", "http://robotics.ethz.ch/~asl-datasets/ijrr_euroc_mav_dataset")
TUM_RGBD_URL = os.environ.get("SLAMRUN_TUM_RGBD_URL", "https://vision.in.tum.de/rgbd/dataset")
TUM_VI_URL = os.environ.get("SLAMRUN_TUM_VI_URL", "https://vision.in.tum.de/tumvi/exported/euroc/512_16")
KITTI_HOWTO = (
    "KITTI odometry is not downloaded by slamrun: its site (https://www.cvlibs.net/datasets/kitti/eval_odometry.php) "
    "asks each user to register and agree to its terms. Download data_odometry_gray.zip, data_odometry_calib.zip and "
    "data_odometry_poses.zip there, unpack them into one folder (they share dataset/sequences/NN/ and add "
    "dataset/poses/), and give a spec `layout: kitti` with `path: <folder>/dataset/sequences` and sequences such as "
    '["00", "05"] (ground truth for 00-10).'
)
EUROC_SEQUENCES = {
    "machine_hall": ["MH_01_easy", "MH_02_easy", "MH_03_medium", "MH_04_difficult", "MH_05_difficult"],
    "vicon_room1": ["V1_01_easy", "V1_02_medium", "V1_03_difficult"],
    "vicon_room2": ["V2_01_easy", "V2_02_medium", "V2_03_difficult"],
}
TUM_VI_ROOMS = {"corridor": 5, "magistrale": 6, "outdoors": 8, "room": 6, "slides": 3}
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


def _euroc_archive(name: str, base: str) -> tuple[str, str] | None:
    group = next((g for g, seqs in EUROC_SEQUENCES.items() if name in seqs), None)
    return None if group is None else (name, f"{base}/{group}/{name}/{name}.zip")


def _tum_rgbd_archive(name: str, base: str) -> tuple[str, str] | None:
    full = name if name.startswith("rgbd_dataset_") else f"rgbd_dataset_{name}"
    found = re.fullmatch(r"rgbd_dataset_(freiburg[123])_[a-z0-9_]+", full)
    return None if found is None else (full, f"{base}/{found.group(1)}/{full}.tgz")


def _tum_vi_archive(name: str, base: str) -> tuple[str, str] | None:
    full = name if name.startswith("dataset-") else f"dataset-{name}_512_16"
    found = re.fullmatch(r"dataset-([a-z]+)(\d+)_512_16", full)
    if found is None or not 1 <= int(found.group(2)) <= TUM_VI_ROOMS.get(found.group(1), 0):
        return None
    return full, f"{base}/{full}.tar"


# dataset -> (sequence name -> (folder, archive address) or None when it is not one of the dataset's, default base)
ARCHIVES = {
    "euroc": (_euroc_archive, EUROC_URL),
    "tum-rgbd": (_tum_rgbd_archive, TUM_RGBD_URL),
    "tum-vi": (_tum_vi_archive, TUM_VI_URL),
}


def remote_archives(dataset: str, names: list[str], base_url: str | None = None) -> list[tuple[str, str]]:
    """(sequence folder name, archive address) of each named sequence of EuRoC, TUM RGB-D or TUM-VI; names are
    checked against the dataset's sequences (TUM RGB-D: any rgbd_dataset_freiburg{1,2,3}_... name)."""
    if dataset not in ARCHIVES:
        raise DatasetError(f"{dataset}: slamrun downloads tum-mono, euroc, tum-rgbd and tum-vi")
    archive, default = ARCHIVES[dataset]
    base = (base_url or default).rstrip("/")
    found = {name: archive(name, base) for name in names}
    bad = [name for name, where in found.items() if where is None]
    if bad:
        known = {
            "euroc": ", ".join(s for seqs in EUROC_SEQUENCES.values() for s in seqs),
            "tum-rgbd": "rgbd_dataset_freiburg1_xyz, freiburg2_desk, ... (the benchmark's folder names)",
            "tum-vi": ", ".join(f"{room}1-{n}" for room, n in TUM_VI_ROOMS.items())
            + " (e.g. room1, dataset-room1_512_16)",
        }[dataset]
        raise DatasetError(f"--sequences: {', '.join(bad)}: not {dataset} sequences; known: {known}")
    return [where for where in found.values() if where is not None]


def download_archives(
    dataset: str,
    dest: Path,
    names: list[str],
    base_url: str | None = None,
    progress_factory: Callable[[str], Callable[[int, int], None]] | None = None,
    log: Callable[[str], None] = print,
) -> list[Path]:
    """Download and unpack EuRoC, TUM RGB-D or TUM-VI sequences into DEST/<sequence>/ (present ones skipped); each
    unpacked folder must be a sequence of that layout."""
    from runner.datasets.layouts import detect, holds_sequence

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
    """A zip, .tgz or .tar, members kept inside `into` (no absolute paths, no `..`, no links out)."""
    import tarfile

    if archive.suffix == ".zip":
        try:
            with zipfile.ZipFile(archive) as zf:
                bad = zf.testzip()
                if bad:
                    raise DatasetError(f"{archive}: member {bad} is corrupt; delete the file and download again")
                for member in zf.namelist():
                    if member.startswith("/") or ".." in Path(member).parts:
                        raise DatasetError(f"{archive}: member {member!r} would land outside the folder; refused")
                zf.extractall(into)
        except zipfile.BadZipFile:
            archive.unlink()
            raise DatasetError(f"{archive}: not a zip file (deleted); run the same command again") from None
        return
    try:
        with tarfile.open(archive) as tar:
            tar.extractall(into, filter="data")
    except tarfile.FilterError as exc:
        raise DatasetError(f"{archive}: {exc}; refused") from None
    except (tarfile.TarError, EOFError) as exc:
        archive.unlink()
        raise DatasetError(f"{archive}: not a readable archive ({exc}; deleted); run the same command again") from None

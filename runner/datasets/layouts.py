"""The dataset layouts slamrun reads, recognised from a sequence folder's own files, each with its reader and its
default metrics. `open_sequence` is the one entry point: whatever the layout, a validated `Sequence`.

| layout    | recognised by                         | ground truth                                    |
|-----------|---------------------------------------|-------------------------------------------------|
| tum-mono  | times.txt + camera.txt                | groundtruthSync.txt (start and end segments)    |
| euroc     | mav0/cam0/ (no dso/camchain.yaml)     | mav0/state_groundtruth_estimate0/data.csv + T_BS |
| tum-vi    | mav0/cam0/ and dso/camchain.yaml      | mav0/mocap0/data.csv + T_cam_imu (partial)      |
| kitti     | image_0/ + calib.txt                  | ../../poses/NN.txt (00-10)                      |
| tum-rgbd  | rgb.txt                               | groundtruth.txt, nearest within 0.02 s          |
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from pathlib import Path

from runner.datasets.sequence import Sequence, folder_identity
from runner.errors import DatasetError

LAYOUTS = ("tum-mono", "euroc", "kitti", "tum-rgbd", "tum-vi")
DEFAULT_METRICS = {
    "tum-mono": ("tum-mono",),
    "euroc": ("ate", "rpe"),
    "kitti": ("ate", "rpe", "kitti"),
    "tum-rgbd": ("ate", "rpe"),
    "tum-vi": ("ate", "rpe"),
}
GROUNDTRUTH_FILES = {
    "tum-mono": "groundtruthSync.txt",
    "euroc": "mav0/state_groundtruth_estimate0/data.csv",
    "kitti": "poses/NN.txt beside sequences/",
    "tum-rgbd": "groundtruth.txt",
    "tum-vi": "mav0/mocap0/data.csv",
}


# the file whose presence makes a folder a sequence of the layout (its frame list)
FRAME_LISTS = {
    "tum-mono": "times.txt",
    "euroc": "mav0/cam0/data.csv",
    "kitti": "times.txt",
    "tum-rgbd": "rgb.txt",
    "tum-vi": "mav0/cam0/data.csv",
}


def holds_sequence(root: Path) -> bool:
    """Whether a folder holds a sequence of some layout: its frame list (a synthetic sequence not generated yet, or
    one that lost it, does not)."""
    layout = detect(root) if root.is_dir() else None
    return layout is not None and (root / FRAME_LISTS[layout]).is_file()


def detect(root: Path) -> str | None:
    """The layout of a sequence folder, from the files it holds; None when it holds none of them."""
    if (root / "mav0" / "cam0").is_dir():
        return "tum-vi" if (root / "dso" / "camchain.yaml").exists() else "euroc"
    if (root / "image_0").is_dir() or (root / "calib.txt").exists():
        return "kitti"
    if (root / "rgb.txt").exists():
        return "tum-rgbd"
    if (root / "times.txt").exists() or (root / "camera.txt").exists():
        return "tum-mono"
    return None


def _reader(layout: str) -> Callable[[Path], Sequence]:
    if layout == "tum-mono":
        from runner.datasets.tum_mono import open_sequence as reader
    elif layout in ("euroc", "tum-vi"):
        from runner.datasets.euroc import open_euroc, open_tum_vi

        reader = open_euroc if layout == "euroc" else open_tum_vi
    elif layout == "kitti":
        from runner.datasets.kitti import open_kitti as reader
    elif layout == "tum-rgbd":
        from runner.datasets.tum_rgbd import open_tum_rgbd as reader
    else:
        raise DatasetError(f"unknown layout {layout!r}; known: {', '.join(LAYOUTS)}")
    return reader


def open_sequence(root: str | Path, layout: str | None = None) -> Sequence:
    """Open and validate a sequence folder; one DatasetError lists every problem. With `layout`, the folder must
    be of that layout (a folder holding none of the layouts' files is read as that layout, to name what is
    missing); without, it is recognised."""
    root = Path(root)
    found = detect(root) if root.is_dir() else None
    if layout is not None and found is not None and found != layout:
        raise DatasetError(f"{root}: a {found} sequence (by its files), but its dataset says layout: {layout}")
    return _reader(found or layout or "tum-mono")(root)


def sequence_identity(root: str | Path) -> str:
    """A short digest of a sequence's content as methods see it, for run keys: new data makes new runs; "none"
    when the folder holds no sequence yet (a synthetic sequence not generated)."""
    root = Path(root)
    if not holds_sequence(root):
        return "none"
    layout = detect(root)
    if layout == "tum-mono":
        from runner.datasets.tum_mono import sequence_identity as tum_mono_identity

        return tum_mono_identity(root)
    try:
        seq = open_sequence(root, layout)
    except DatasetError:
        return "invalid"  # validation names the problem before any run
    images = seq.images_dir or seq.root
    stamp = tuple((p.stat().st_size, p.stat().st_mtime_ns) if p.is_file() else None for p in seq.key_files)
    return _cached_identity(seq.key_files, images, seq.frame_names, stamp, _stat(images))


def _stat(p: Path) -> tuple:
    st = p.stat()
    return (st.st_size, st.st_mtime_ns, st.st_ino)


@functools.lru_cache(maxsize=1024)
def _cached_identity(key_files: tuple[Path, ...], images: Path, names: tuple[str, ...], *_stamps) -> str:
    return folder_identity(list(key_files), images, list(names))

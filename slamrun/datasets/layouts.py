"""The dataset layouts slamrun reads: one list, each layout's module giving everything about it (slamrun.datasets.
protocol.Layout), and layouts from other Python packages through the entry-point group `slamrun.datasets`
(`name = "package.module:LAYOUT"`, a `Layout` value). `open_sequence` is the one entry point: whatever the layout,
a validated `Sequence`.

| layout    | recognised by                             | ground truth                                         |
|-----------|-------------------------------------------|------------------------------------------------------|
| tum-vi    | mav0/cam0/ and dso/camchain.yaml          | mav0/mocap0/data.csv + T_cam_imu (partial)           |
| euroc     | mav0/cam0/ (no dso/camchain.yaml)         | mav0/state_groundtruth_estimate0/data.csv + T_BS     |
| kitti     | image_0/ or calib.txt                     | ../../poses/NN.txt (00-10)                           |
| icl-nuim  | a *.gt.freiburg, or associations.txt      | the *.gt.freiburg, mirrored into a y-down camera     |
| tum-rgbd  | rgb.txt                                   | groundtruth.txt, nearest within 0.02 s               |
| tartanair | image_left/ or pose_left.txt              | pose_left.txt, NED carried to the camera's axes      |
| tum-mono  | times.txt or camera.txt                   | groundtruthSync.txt (start and end segments)         |

A folder is of the first layout, in this order, that recognises it; plug-in layouts are tried after the built-in
ones, by name. A plug-in that cannot be loaded, or a name two packages (or a built-in) register, is named with its
reason (`plugin_errors`) and never breaks the others; whatever a plug-in's functions raise is a DatasetError naming
the plug-in.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterator, Mapping
from dataclasses import replace
from pathlib import Path

from slamrun.core.metrics import RpeInterval
from slamrun.core.suggest import did_you_mean
from slamrun.datasets import euroc, icl_nuim, kitti, tartanair, tum_mono, tum_rgbd, tum_vi
from slamrun.datasets.plugin_checks import TIME_LIMITS_S, bounded, checked_reader
from slamrun.datasets.protocol import METRICS, Layout
from slamrun.datasets.sequence import Sequence, folder_identity
from slamrun.errors import DatasetError, SlamRunError, one_line
from slamrun.plugins import Provider, discover

BUILT_IN: tuple[Layout, ...] = (
    tum_vi.LAYOUT,
    euroc.LAYOUT,
    kitti.LAYOUT,
    icl_nuim.LAYOUT,
    tum_rgbd.LAYOUT,
    tartanair.LAYOUT,
    tum_mono.LAYOUT,
)
_BY_NAME = {layout.name: layout for layout in BUILT_IN}
LAYOUTS = ("tum-mono", "euroc", "kitti", "tum-rgbd", "tum-vi", "icl-nuim", "tartanair")  # as the README lists them
PLUGIN_GROUP = "slamrun.datasets"


# ---------------------------------------------------------------------------------------------------- plug-ins


def _guard(fn: Callable | None, who: str, what: str) -> Callable | None:
    """`fn` of a plug-in: whatever it raises but a SlamRunError (or an interrupt) becomes a DatasetError naming
    the plug-in and what it was doing."""
    if fn is None:
        return None

    @functools.wraps(fn)
    def guarded(*args):
        try:
            return fn(*args)
        except (SlamRunError, KeyboardInterrupt):
            raise
        except BaseException as exc:  # noqa: BLE001 - someone else's package: named, never a traceback
            where = f" on {args[0]}" if args else ""
            raise DatasetError(f"{who}: {what}{where} failed: {one_line(exc)}") from None

    return guarded


def _adopt(layout: Layout, provider: str) -> Layout:
    """A plug-in's layout with its provider recorded and every function of it guarded (its exceptions named) and
    bounded in time; what its reader gives is checked as built-in readers check their files (plugin_checks)."""
    who = f"plug-in layout {layout.name} ({provider})"

    def wrap(fn: Callable | None, what: str, limit: str = "other") -> Callable | None:
        guarded = _guard(fn, who, what)
        return None if guarded is None else bounded(guarded, TIME_LIMITS_S[limit], who, what)

    return replace(
        layout,
        provider=provider,
        recognise=wrap(layout.recognise, "recognising a folder", "recognise"),
        read=checked_reader(_guard(layout.read, who, "reading the sequence"), who),
        synth=wrap(layout.synth, "writing a synthetic sequence", "synth"),
        synth_outside=wrap(layout.synth_outside, "naming its files beside the sequence"),
        synth_name_problem=wrap(layout.synth_name_problem, "checking a sequence name"),
        identity=wrap(layout.identity, "the sequence's identity", "read"),
        file_note=wrap(layout.file_note, "a note on a ground-truth file"),
    )


def _accept(name: str, layout, provider: Provider, where: str) -> Layout | str:
    """A plug-in's layout, checked (its kind, name, functions, frame list, metrics) and adopted; or why not."""
    if not isinstance(layout, Layout):
        return f"plug-in {where} is {type(layout).__name__}, not a slamrun.datasets.Layout"
    if layout.name != name:
        return f"plug-in {where}: its layout's name is {layout.name!r}, not {name!r}"
    if not (callable(layout.recognise) and callable(layout.read)):
        return f"plug-in {where}: its layout's recognise and read must be functions"
    if not (isinstance(layout.frame_list, str) and layout.frame_list):
        return f"plug-in {where}: its layout's frame_list must be a relative path"
    if not (isinstance(layout.default_metrics, tuple) and set(layout.default_metrics) <= set(METRICS)):
        return f"plug-in {where}: its layout's default_metrics must be a tuple of {', '.join(METRICS)}"
    return _adopt(layout, str(provider))


@functools.cache
def _plugins() -> tuple[dict[str, Layout], dict[str, str]]:
    """(name -> plug-in layout, name -> why it is not registered), loaded once, on first need (slamrun/plugins.py:
    one guard for a broken plug-in of any kind)."""
    found = discover(PLUGIN_GROUP, _BY_NAME, "layout", _accept)
    return found.loaded, found.errors


def plugin_errors() -> dict[str, str]:
    """Plug-in layouts that could not be registered, with why."""
    return dict(_plugins()[1])


def get(name: str) -> Layout:
    """The layout called `name`; DatasetError listing the known ones (or why a plug-in of that name is not)."""
    if name in _BY_NAME:
        return _BY_NAME[name]
    plugins, errors = _plugins()
    if name in plugins:
        return plugins[name]
    if name in errors:
        raise DatasetError(f"layout {name!r}: {errors[name]}")
    raise DatasetError(f"unknown layout {name!r}{did_you_mean(name, names())} (known: {', '.join(names())})")


def names() -> tuple[str, ...]:
    return LAYOUTS + tuple(_plugins()[0])


class _ByLayout(Mapping):
    """A read-only view of one field of every layout, by name (plug-ins included)."""

    def __init__(self, field: str):
        self._field = field

    def __getitem__(self, name: str):
        try:
            return getattr(get(name), self._field)
        except DatasetError:
            raise KeyError(name) from None

    def __iter__(self) -> Iterator[str]:
        return iter(names())

    def __len__(self) -> int:
        return len(names())


DEFAULT_METRICS: Mapping[str, tuple[str, ...]] = _ByLayout("default_metrics")
GROUNDTRUTH_FILES: Mapping[str, str] = _ByLayout("groundtruth_file")
DEFAULT_RPE: Mapping[str, RpeInterval] = _ByLayout("rpe")
FRAME_LISTS: Mapping[str, str] = _ByLayout("frame_list")


# ---------------------------------------------------------------------------------------------------- sequences


def detect_layout(root: Path) -> Layout | None:
    """The layout of a sequence folder, from the files it holds (the first that recognises it); None when none
    does."""
    for layout in BUILT_IN:
        if layout.recognise(root):
            return layout
    for layout in _plugins()[0].values():
        try:
            if layout.recognise(root):
                return layout
        except DatasetError:  # a plug-in that cannot look at a folder never decides another's: skipped here,
            continue  # named where its own layout is asked for (open_sequence with layout:)
    return None


def detect(root: Path) -> str | None:
    """The name of a sequence folder's layout, from the files it holds; None when it holds none of them."""
    layout = detect_layout(root) if root.is_dir() else None
    return None if layout is None else layout.name


def holds_sequence(root: Path) -> bool:
    """Whether a folder holds a sequence of some layout: its frame list (a synthetic sequence not generated yet, or
    one that lost it, does not)."""
    layout = detect_layout(root) if root.is_dir() else None
    return layout is not None and layout.holds(root)


def open_sequence(root: str | Path, layout: str | None = None) -> Sequence:
    """Open and validate a sequence folder; one DatasetError lists every problem. With `layout`, the folder must
    be of that layout (a folder holding none of the layouts' files is read as that layout, to name what is
    missing); without, it is recognised."""
    root = Path(root)
    asked = get(layout) if layout is not None else None
    if asked is not None and root.is_dir() and asked.recognise(root):
        return asked.read(root)
    found = detect_layout(root) if root.is_dir() else None
    if asked is not None and found is not None:
        raise DatasetError(f"{root}: a {found.name} sequence (by its files), but its dataset says layout: {layout}")
    return (found or asked or _BY_NAME["tum-mono"]).read(root)


def sequence_identity(root: str | Path) -> str:
    """A short digest of a sequence's content as methods see it, for run keys: new data makes new runs; "none"
    when the folder holds no sequence yet (a synthetic sequence not generated)."""
    root = Path(root)
    if not holds_sequence(root):
        return "none"
    layout = detect_layout(root)
    assert layout is not None
    if layout.identity is not None:
        return layout.identity(root)
    try:
        seq = layout.read(root)
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

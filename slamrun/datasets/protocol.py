"""What a dataset layout is: everything slamrun knows about one layout, given by the layout's own module (or a
plug-in package) as one `Layout` value, and registered in one list (slamrun.datasets.layouts).

A layout recognises its folders from their files, reads one into a `Sequence` (frames in order, times in seconds,
the camera, the ground truth in the camera's frame at the frames' times), names its default metrics, writes a
synthetic sequence with its quirks (`slamrun synth --layout NAME`) and says how its sequences are downloaded.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from slamrun.core.metrics import RpeInterval
from slamrun.results.catalogue import METRIC_NAMES

if TYPE_CHECKING:  # the synthetic writers import the renderer (scipy) only when a sequence is generated
    from slamrun.datasets.sequence import Sequence
    from slamrun.datasets.synth import Synth

METRICS = METRIC_NAMES  # the metrics a layout's default_metrics may name (core/metric_table.py)

# (staged file, its place): files a synthetic writer puts beside the sequence's folder, moved there once the
# folder is in place (KITTI's poses/NN.txt)
Placed = list[tuple[Path, Path]]


@dataclass(frozen=True)
class Download:
    """How a layout's sequences are downloaded: each named sequence's folder and archive address under a base
    address (the dataset's site, overridable with an environment variable or --url: a mirror)."""

    base_url: str
    archive: Callable[[str, str], tuple[str, str] | None]  # (name, base) -> (folder, archive address) or None
    known: str  # the sequence names, as an error lists them
    default: tuple[str, ...] = ()  # downloaded when --sequences is not given (empty: they must be named)
    parse: Callable[[str], list[str]] | None = None  # --sequences text -> names (default: comma-separated)

    def names(self, text: str | None) -> list[str]:
        """The sequences `--sequences TEXT` names (the default ones without it)."""
        if text is None:
            return list(self.default)
        if self.parse is not None:
            return self.parse(text)
        return [n.strip() for n in text.split(",") if n.strip()]


def _nothing_outside(out: Path) -> tuple[Path, ...]:
    return ()


@dataclass(frozen=True)
class Layout:
    """One dataset layout. `name` is what a spec's `layout:` and `slamrun synth --layout` say.

    `recognise(folder)` tells, from the files a folder holds, whether it is a sequence of this layout; layouts are
    tried in the registry's order (built-in ones first). `frame_list` is the path whose presence makes a folder
    hold a sequence (a file; a folder when it ends in "/"): a synthetic sequence not generated yet lacks it.
    `read(folder)` validates and reads it (one DatasetError listing every problem). `synth(tmp, synth)` writes a
    synthetic sequence into `tmp` and returns the files it staged beside it (`synth_outside(out)` names their
    places in advance, so that nothing of a user's is replaced). `identity(folder)`, when given, is the content
    digest of the sequence for run keys (default: its key files and frames). `file_note(path)` says what one of
    the layout's ground-truth files given to `slamrun evaluate` as it is means, when it is one (built-in layouts
    only: evaluating a file never loads the plug-ins).
    """

    name: str
    title: str  # the dataset as people name it, with what slamrun reads of it
    recognise: Callable[[Path], bool]
    frame_list: str
    read: Callable[[Path], Sequence]
    groundtruth_file: str  # where the ground truth lies, as messages name it
    default_metrics: tuple[str, ...] = ("ate", "rpe")
    rpe: RpeInterval = RpeInterval(1.0, "s")  # RPE's interval by default: one second of the sequence
    synth: Callable[[Path, Synth], Placed] | None = None
    synth_outside: Callable[[Path], tuple[Path, ...]] = _nothing_outside
    synth_name_problem: Callable[[str], str | None] | None = None  # a sequence name the writer cannot use
    fixed_size: tuple[int, int] | None = None  # the one image size the layout's published camera has
    download: Download | None = None
    manual_download: str = ""  # why and how to fetch it by hand, where slamrun does not download it
    identity: Callable[[Path], str] | None = None
    file_note: Callable[[Path], str | None] | None = None
    provider: str = field(default="built-in", compare=False)  # a plug-in's distribution and version

    def holds(self, root: Path) -> bool:
        """Whether `root` holds this layout's frame list (a sequence, not only a folder of its kind)."""
        p = root / self.frame_list
        return p.is_dir() if self.frame_list.endswith("/") else p.is_file()

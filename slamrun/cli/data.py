"""slamrun dataset download, synth, list-datasets and new-dataset: the layouts, and getting sequences, real or
generated."""

from __future__ import annotations

import sys
import time
from pathlib import Path

from slamrun.cli.console import console

BUILT_IN = "tum-mono, euroc, kitti, tum-rgbd, tum-vi, icl-nuim, tartanair"  # and plug-ins: slamrun list-datasets


def add_commands(sub) -> None:
    ds = sub.add_parser("dataset", help="dataset tools")
    dsub = ds.add_subparsers()
    dl = dsub.add_parser(
        "download",
        help="download dataset sequences (resumable, sizes checked)",
        description="Download and unpack dataset sequences. Run the same command again to resume an interrupted "
        "download. A download that gets less than 64 KiB in SLAMRUN_DOWNLOAD_STALL_S seconds (default 60) is ended, "
        "its part kept; an archive that states more than 100 times its size unpacked (a zip bomb) is refused.",
    )
    dl.add_argument("name", help=f"the dataset's layout ({BUILT_IN}, or a plug-in's)")
    dl.add_argument("dest", type=Path, help="folder to download into")
    dl.add_argument(
        "--sequences",
        help="tum-mono: numbers and ranges (default 1-50); euroc: names (default all eleven, e.g. MH_01_easy); "
        "icl-nuim: names (default all eight, e.g. lr_kt0,of_kt2); tum-rgbd and tum-vi: names, comma-separated "
        "(e.g. freiburg1_xyz,freiburg2_desk; room1,room2)",
    )
    dl.add_argument("--url", help="base address of the archives (a mirror; default: the dataset's site)")
    dl.set_defaults(func=cmd_download)
    sy = sub.add_parser("synth", help="write a synthetic sequence in a dataset's layout")
    sy.add_argument("out", type=Path, help="the sequence folder to write")
    sy.add_argument("--frames", type=int, default=300, help="number of frames")
    sy.add_argument("--seed", type=int, default=0, help="random seed of the scene and its texture")
    sy.add_argument(
        "--size",
        default="640x480",
        help="image size WIDTHxHEIGHT (tum-rgbd, icl-nuim and tartanair: always their published camera's 640x480)",
    )
    sy.add_argument("--scene", choices=["indoor", "outdoor"], default="indoor", help="room or courtyard scale")
    sy.add_argument(
        "--motion",
        choices=["default", "plain", "hard"],
        default="default",
        help="the camera path's envelope: default (the seed's loop within the plain loop's speed, rotation rate and "
        "start parallax), plain (that loop), hard (faster, less start parallax: on purpose)",
    )
    sy.add_argument(
        "--layout",
        default="tum-mono",
        help=f"the dataset layout to write ({BUILT_IN}, or a plug-in's; kitti: OUT is sequences/NN, its poses go to "
        "poses/NN.txt beside sequences/; tum-rgbd: OUT's name holds freiburg1, 2 or 3, whose published camera it "
        "uses)",
    )
    sy.set_defaults(func=cmd_synth)
    ld = sub.add_parser("list-datasets", help="the dataset layouts slamrun reads, built-in and plug-in")
    ld.set_defaults(func=cmd_list_datasets)
    nd = sub.add_parser("new-dataset", help="write a dataset layout package of one's own: reader, writer, test")
    nd.add_argument("name", help="the layout's name (lower case, digits, -)")
    nd.add_argument("--dest", type=Path, help="the package folder to write (default ./slamrun-dataset-NAME)")
    nd.set_defaults(func=cmd_new_dataset)


def cmd_download(args) -> int:
    from rich.progress import BarColumn, DownloadColumn, Progress, TextColumn, TransferSpeedColumn

    from slamrun.datasets import download as dl
    from slamrun.datasets.layouts import get
    from slamrun.errors import DatasetError

    layout = get(args.name)
    if layout.download is None:
        raise DatasetError(layout.manual_download or f"{args.name}: slamrun does not download this layout")
    names = layout.download.names(args.sequences)
    if not names:
        raise DatasetError(f"{args.name}: name the sequences to download with --sequences (they are many GB each)")
    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        DownloadColumn(),
        TransferSpeedColumn(),
        console=console.real(),
        disable=not sys.stdout.isatty(),
    ) as progress:

        def factory(name):
            task = progress.add_task(name, total=None)
            return lambda done, total: progress.update(task, completed=done, total=total or None)

        folders = dl.download_archives(args.name, args.dest, names, args.url, factory, progress.console.print)
    console.print(f"{len(folders)} sequence(s) in {args.dest}")
    return 0


def cmd_synth(args) -> int:
    from slamrun.datasets.make_synthetic import generate
    from slamrun.errors import DatasetError

    try:
        w, h = (int(v) for v in args.size.lower().split("x"))
    except ValueError:
        raise DatasetError(f"--size {args.size!r}: expected WIDTHxHEIGHT, e.g. 640x480") from None
    t0 = time.monotonic()
    out = generate(args.out, args.frames, args.seed, (w, h), args.scene, args.layout, args.motion)
    console.print(f"{out}: {args.frames} frames, {args.layout} layout, in {time.monotonic() - t0:.1f} s")
    return 0


def cmd_list_datasets(args) -> int:
    from rich.table import Table

    from slamrun.datasets.layouts import get, names, plugin_errors

    t = Table(title="dataset layouts")
    for c in ("name", "dataset", "metrics", "synth", "download", "from"):
        t.add_column(c)
    for layout in (get(name) for name in names()):
        t.add_row(
            layout.name,
            layout.title,
            ", ".join(layout.default_metrics),
            "yes" if layout.synth is not None else "no",
            "yes" if layout.download is not None else "by hand" if layout.manual_download else "no",
            layout.provider,
        )
    console.print(t)
    for name, why in sorted(plugin_errors().items()):
        console.print(f"not registered: {name}: {why}")
    return 0


def cmd_new_dataset(args) -> int:
    from slamrun.cli.images import next_steps
    from slamrun.images.scaffold_dataset import new_dataset

    dest = args.dest or Path(f"slamrun-dataset-{args.name}")
    files = new_dataset(args.name, dest)
    return next_steps(dest, len(files), [
        (f"pip install -e {dest}", f"registers {args.name} (entry point slamrun.datasets)"),
        ("slamrun list-datasets", f"{args.name} is listed, from its package"),
        (f"pytest {dest}/tests", "its reader on its synthetic sequence"),
        (f"slamrun synth OUT --layout {args.name}", "a synthetic sequence in the layout"),
    ])  # fmt: skip

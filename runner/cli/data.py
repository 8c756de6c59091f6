"""slamrun dataset download and synth: getting sequences, real or generated."""

from __future__ import annotations

import sys
import time
from pathlib import Path

from runner.cli.console import console


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
    dl.add_argument("name", choices=["tum-mono", "euroc", "tum-rgbd", "tum-vi", "kitti"], help="the dataset")
    dl.add_argument("dest", type=Path, help="folder to download into")
    dl.add_argument(
        "--sequences",
        help="tum-mono: numbers and ranges (default 1-50); euroc: names (default all eleven, e.g. MH_01_easy); "
        "tum-rgbd and tum-vi: names, comma-separated (e.g. freiburg1_xyz,freiburg2_desk; room1,room2)",
    )
    dl.add_argument("--url", help="base address of the archives (a mirror; default: the dataset's site)")
    dl.set_defaults(func=cmd_download)
    sy = sub.add_parser("synth", help="write a synthetic sequence in a dataset's layout")
    sy.add_argument("out", type=Path, help="the sequence folder to write")
    sy.add_argument("--frames", type=int, default=300, help="number of frames")
    sy.add_argument("--seed", type=int, default=0, help="random seed of the scene and its texture")
    sy.add_argument("--size", default="640x480", help="image size WIDTHxHEIGHT")
    sy.add_argument("--scene", choices=["indoor", "outdoor"], default="indoor", help="room or courtyard scale")
    sy.add_argument(
        "--layout",
        choices=["tum-mono", "euroc", "kitti", "tum-rgbd", "tum-vi"],
        default="tum-mono",
        help="the dataset layout to write (kitti: OUT is sequences/NN, its poses go to poses/NN.txt beside "
        "sequences/; tum-rgbd: OUT's name holds freiburg1, 2 or 3, whose published camera it uses)",
    )
    sy.set_defaults(func=cmd_synth)


def cmd_download(args) -> int:
    from rich.progress import BarColumn, DownloadColumn, Progress, TextColumn, TransferSpeedColumn

    from runner.datasets import download as dl
    from runner.errors import DatasetError

    if args.name == "kitti":
        raise DatasetError(dl.KITTI_HOWTO)
    if args.name == "tum-mono":
        numbers = dl.parse_sequences(args.sequences or "1-50")
    elif args.sequences:
        names = [n.strip() for n in args.sequences.split(",") if n.strip()]
    elif args.name == "euroc":
        names = [s for seqs in dl.EUROC_SEQUENCES.values() for s in seqs]
    else:
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

        if args.name == "tum-mono":
            folders = dl.download_tum_mono(
                args.dest, numbers, args.url or dl.TUM_MONO_URL, factory, progress.console.print
            )
        else:
            folders = dl.download_archives(args.name, args.dest, names, args.url, factory, progress.console.print)
    console.print(f"{len(folders)} sequence(s) in {args.dest}")
    return 0


def cmd_synth(args) -> int:
    from runner.datasets.synth import generate

    w, h = (int(v) for v in args.size.lower().split("x"))
    t0 = time.monotonic()
    out = generate(args.out, args.frames, args.seed, (w, h), args.scene, args.layout)
    console.print(f"{out}: {args.frames} frames, {args.layout} layout, in {time.monotonic() - t0:.1f} s")
    return 0

"""slamrun native-build: compile a GPU method's extensions into slamrun's cache, for `backend: local`."""

from __future__ import annotations

from pathlib import Path

from slamrun.cli.console import console


def add_commands(sub) -> None:
    nb = sub.add_parser(
        "native-build",
        help="compile a GPU method for backend: local with this Python's PyTorch, into the cache",
    )
    nb.add_argument("method", help="the method to build (`slamrun list-methods` names those with a native build)")
    nb.add_argument("--sources", type=Path, help="folder holding the pinned source archive (no network needed)")
    nb.add_argument("--source-url", help="base address of the source archives (default https://github.com)")
    nb.add_argument("--arch", help="CUDA compute capability to build for, e.g. 9.0 (default: this machine's GPU)")
    nb.add_argument("--jobs", type=int, help="parallel compile jobs (default: all cores)")
    nb.add_argument("--eigen", type=Path, help="folder holding Eigen 3.4's Eigen/Core (default: the system's)")
    nb.add_argument(
        "--weights",
        action="append",
        default=[],
        metavar="NAME.pth=FILE",
        help="the network (dpvo.pth, droid.pth): a file, or URL#sha256=HEX",
    )
    nb.add_argument(
        "--standin-model",
        action="store_true",
        help="without --weights: an untrained stand-in network from a fixed seed (plumbing only, accuracy meaningless)",
    )
    nb.add_argument(
        "--unpack-only", action="store_true", help="unpack and patch the source into --into, compile nothing (a check)"
    )
    nb.add_argument("--into", type=Path, help="the build folder (default: slamrun's cache, where the method looks)")
    nb.set_defaults(func=cmd_native_build)


def cmd_native_build(args) -> int:
    from slamrun.cli.images import _pair
    from slamrun.images.native import NativeOptions, build, unpack_only

    opts = NativeOptions(
        sources_dir=args.sources,
        source_url=args.source_url,
        arch=args.arch,
        eigen=args.eigen,
        weights=dict(_pair(w) for w in args.weights),
        standin_model=args.standin_model,
        into=args.into,
    )
    if args.jobs:
        opts.jobs = args.jobs
    if args.unpack_only:
        unpack_only(opts, args.method, log=lambda m: print(m, flush=True))
        return 0
    record = build(args.method, opts, log=lambda m: print(m, flush=True))
    console.print(f"{args.method}: {record['weights']}")
    return 0

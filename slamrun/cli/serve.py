"""slamrun serve: a live page of a campaign (or a folder of campaigns) in a browser, read-only."""

from __future__ import annotations

import os
import sys
from pathlib import Path

from slamrun.errors import SlamRunError


def _port(text: str) -> int:
    import argparse

    try:
        port = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a port number, 0 to 65535") from None
    if not 0 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"{port}: expected a port number, 0 to 65535 (0: any free port)")
    return port


def add_commands(sub) -> None:
    s = sub.add_parser(
        "serve",
        help="a live page of a campaign in a browser: progress, lanes, failures, medians, figures, paths (read-only)",
    )
    s.add_argument(
        "results",
        type=Path,
        help="a campaign's results folder, a folder of several (listed), or a spec (its results folder); one that "
        "holds no campaign yet is waited for",
    )
    s.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1: this machine only)")
    s.add_argument("--port", type=_port, default=8765, help="port (default 8765; 0: any free port)")
    s.add_argument(
        "--token",
        default=os.environ.get("SLAMRUN_SERVE_TOKEN"),
        help="the token asked beyond loopback (default: $SLAMRUN_SERVE_TOKEN, else a random one, printed)",
    )
    s.add_argument("--interval", type=float, default=1.0, help="seconds between checks of the ledger (default 1)")
    s.set_defaults(func=cmd_serve)


def cmd_serve(args) -> int:
    from slamrun.serve.server import serve

    if not 0.1 <= args.interval <= 60:
        raise SlamRunError(f"--interval {args.interval}: expected 0.1 to 60 seconds")
    return serve(served_folder(args.results), args.host, args.port, args.token, args.interval)


def served_folder(path: Path) -> Path:
    """The folder to serve: `path`, or where `path` is a file, the results folder of the spec it is."""
    if not path.is_file():
        return path
    from slamrun.engine.spec_file import load_spec

    results = load_spec(path, check_files=False, check_gpu=False).results
    print(f"slamrun serve: {path} is a spec; serving its results folder {results}", file=sys.stderr, flush=True)
    return results

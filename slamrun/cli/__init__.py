"""slamrun: the command line. Thin: each command group's module (campaign, evaluate, analysis, images, data)
adds its subcommands, whose functions call library functions; errors become one line."""

from __future__ import annotations

import argparse
import os
import sys

from slamrun.cli import analysis, campaign, data, evaluate, images, native, serve
from slamrun.errors import SlamRunError, storage_problem

GROUPS = (campaign, evaluate, analysis, images, native, data, serve)


def main(argv: list[str] | None = None) -> int:
    parser = _parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        code = args.func(args) or 0
        sys.stdout.flush()  # a reader that went away is known here, not at the interpreter's exit
        return code
    except BrokenPipeError:
        return _reader_gone()
    except SlamRunError as exc:
        print(f"slamrun: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("slamrun: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # a full disk, a read-only filesystem: said as such, in one line; anything else raises
        why = storage_problem(exc)
        if why is None:
            raise
        where = f" ({exc.filename})" if getattr(exc, "filename", None) else ""
        print(
            f"slamrun: error: {why}{where}: {exc}; make room (or fix the folder) and run the command again; "
            "what was written before is kept",
            file=sys.stderr,
        )
        return 1


def _reader_gone() -> int:
    """The reader of slamrun's output closed it (`slamrun stats --json | head -c 10`): end quietly, as a Unix
    tool killed by SIGPIPE does (exit 141), with what is still buffered dropped instead of a traceback."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except OSError:
        pass
    return 141


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("slamrun")
    except PackageNotFoundError:
        return "unknown (not installed)"


class _PrintVersion(argparse.Action):
    """--version, read from the installed package only when asked (importlib.metadata costs every command 30 ms)."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, **kw):
        super().__init__(option_strings, dest, nargs=0, help="show the version and exit", **kw)

    def __call__(self, parser, namespace, values, option_string=None):
        print(f"slamrun {_version()}")
        parser.exit()


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="slamrun", description="Run and compare monocular SLAM/VO methods.")
    p.add_argument("--version", action=_PrintVersion)
    sub = p.add_subparsers()
    for group in GROUPS:
        group.add_commands(sub)
    return p

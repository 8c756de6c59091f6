"""Files from outside, read with bounds: regular files only (a FIFO, a device or a socket is refused without
blocking on it), at most a given size, and YAML with its aliases and nesting bounded before anything is built.

Every reader of a user's file (dataset files, calibration YAML, trajectories, archives' listings) goes through
these, so a hostile or careless input ends in one clear error naming the file, within bounded time and memory.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import TYPE_CHECKING

from slamrun.errors import SlamRunError

if TYPE_CHECKING:
    import yaml

MiB = 2**20
YAML_MAX_VALUES = 100_000  # values of a YAML document once its aliases are expanded
YAML_MAX_BYTES = MiB  # a calibration or spec file is a page of YAML


def _kind(mode: int) -> str:
    for test, name in (
        (stat.S_ISFIFO, "a FIFO (named pipe)"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISSOCK, "a socket"),
        (stat.S_ISDIR, "a folder"),
    ):
        if test(mode):
            return name
    return "not a regular file"


def regular_file_problem(path: Path, what: str = "file") -> str | None:
    """Why `path` (links followed) is not a regular file slamrun may read, or None. Never blocks."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return f"{path}: {what} not found"
    except OSError as exc:
        return f"{path}: cannot read {what} ({exc.strerror})"
    if not stat.S_ISREG(st.st_mode):
        return f"{path}: {_kind(st.st_mode)}; expected {what} as a regular file"
    return None


def read_bounded(path: Path | str, limit: int, what: str = "file", error: type[SlamRunError] = SlamRunError) -> bytes:
    """The bytes of a regular file of at most `limit` bytes, or `error` naming the file and why (missing, a FIFO,
    a device, a socket, a folder, too large, unreadable). Opened without blocking; reads at most limit + 1 bytes."""
    path = Path(path)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except FileNotFoundError:
        raise error(f"{path}: {what} not found") from None
    except IsADirectoryError:
        raise error(f"{path}: a folder; expected {what} as a regular file") from None
    except OSError as exc:
        raise error(f"{path}: cannot open {what} ({exc.strerror})") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise error(f"{path}: {_kind(st.st_mode)}; expected {what} as a regular file")
        if st.st_size > limit:
            raise error(f"{path}: {st.st_size:,} bytes; {what} is at most {limit:,} bytes")
        chunks, size = [], 0
        while size <= limit:
            chunk = os.read(fd, min(limit + 1 - size, 8 * MiB))
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
        if size > limit:  # it grew while read
            raise error(f"{path}: more than {limit:,} bytes; {what} is at most {limit:,} bytes")
        return b"".join(chunks)
    except OSError as exc:
        raise error(f"{path}: cannot read {what} ({exc.strerror})") from None
    finally:
        os.close(fd)


def read_text_bounded(
    path: Path | str, limit: int, what: str = "file", error: type[SlamRunError] = SlamRunError
) -> str:
    """`read_bounded` decoded as UTF-8 (a binary file is `error`, naming the byte)."""
    data = read_bounded(path, limit, what, error)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise error(f"{path}: not a text file (byte {exc.start} is not UTF-8)") from None


def expanded_size(root: yaml.Node) -> int:
    """How many values a YAML node stands for with every alias expanded (an alias is the same node object
    again; a recursive alias counts once). Iterative: any depth."""
    import yaml

    memo: dict[int, int] = {}
    stack: list[tuple[yaml.Node, bool]] = [(root, False)]
    while stack:
        node, children_done = stack.pop()
        if id(node) in memo and not children_done:
            continue
        if isinstance(node, yaml.SequenceNode):
            children = list(node.value)
        elif isinstance(node, yaml.MappingNode):
            children = [n for pair in node.value for n in pair]
        else:
            memo[id(node)] = 1
            continue
        if children_done:
            memo[id(node)] = 1 + sum(memo.get(id(c), 1) for c in children)
        else:
            memo[id(node)] = 1  # in progress: a child that refers back to it counts once
            stack.append((node, True))
            stack.extend((c, False) for c in children if id(c) not in memo)
    return memo[id(root)]


def parse_yaml(text: str, source: str, error: type[SlamRunError] = SlamRunError, max_values: int = YAML_MAX_VALUES):
    """A YAML document (safe types only) parsed once, with its aliases' expansion and its nesting bounded before
    any value is built; `error` names `source`, the line and what is wrong. Returns (value, root node)."""
    import yaml  # PyYAML only where a YAML file is read (evaluating trajectory files needs none)

    loader = yaml.SafeLoader(text)
    try:
        try:
            node = loader.get_single_node()
        except RecursionError:
            raise error(f"{source}: YAML nested too deeply to be a calibration or spec file") from None
        except yaml.YAMLError as exc:
            mark = getattr(exc, "problem_mark", None)
            where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark else ""
            raise error(f"{source}: {where}not valid YAML ({getattr(exc, 'problem', None) or exc})") from None
        if node is None:
            return None, None
        if (n := expanded_size(node)) > max_values:
            raise error(f"{source}: its YAML aliases expand to {n:,} values (at most {max_values:,}): an alias bomb?")
        try:
            return loader.construct_document(node), node
        except RecursionError:
            raise error(f"{source}: YAML nested too deeply to be a calibration or spec file") from None
        except yaml.YAMLError as exc:
            raise error(f"{source}: not valid YAML ({getattr(exc, 'problem', None) or exc})") from None
    finally:
        loader.dispose()


def load_yaml_file(
    path: Path | str,
    what: str = "YAML file",
    error: type[SlamRunError] = SlamRunError,
    limit: int = YAML_MAX_BYTES,
    max_values: int = YAML_MAX_VALUES,
):
    """A YAML file from outside: a regular file of at most `limit` bytes, parsed with `parse_yaml`'s bounds."""
    return parse_yaml(read_text_bounded(path, limit, what, error), str(path), error, max_values)[0]

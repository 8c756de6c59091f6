"""Trajectories: the TUM reader/writer pair and readers for the other formats methods write.

A `Trajectory` holds camera-to-world poses sorted by time: timestamps (N,), positions (N, 3) and
unit quaternions (N, 4) in `qx qy qz qw` order. The `qx qy qz qw` convention lives only here.

A file whose timestamps repeat or go backward is read into time order, one pose per timestamp (the first in
the file), and its rows as the file holds them are kept beside (`Trajectory.as_read`): the rows evo reads,
which ATE, RPE and KITTI's metric associate as evo does (slamrun.core.metrics).
"""

from __future__ import annotations

import io
import warnings
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from functools import cached_property, lru_cache
from pathlib import Path

import numpy as np

from slamrun.errors import TrajectoryFormatError

try:  # the compiled reader of plain tables (setup.py); without it Arrow's CSV reader does its work
    from slamrun.core import _tumparse
except ImportError:  # pragma: no cover - a build without a C compiler
    _tumparse = None

NON_UNIT_TOL = 1e-3  # |q| further than this from 1 counts as non-unit (renormalised)
FAR_FROM_UNIT_TOL = 0.1  # |q| further than this from 1 counts as far from unit (a converter bug upstream)


@dataclass(frozen=True)
class ReadReport:
    """What a reader had to repair, so that it is reported rather than hidden."""

    n_rows: int = 0
    was_unsorted: bool = False
    n_duplicates_dropped: int = 0
    n_quat_non_unit: int = 0
    n_quat_far_from_unit: int = 0
    max_quat_norm_error: float = 0.0
    n_nonfinite_dropped: int = 0  # rows with a NaN or infinite timestamp, position or quaternion


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Camera-to-world poses, sorted by strictly increasing timestamp.

    `as_read`: a file's rows in the file's order, a repeated timestamp's every row included, where they differ
    from these (a file out of time order or with a repeated timestamp); None where they are the same rows, and for
    a trajectory built in memory."""

    timestamps: np.ndarray
    positions: np.ndarray
    quaternions: np.ndarray  # qx qy qz qw, unit length
    report: ReadReport = field(default_factory=ReadReport)
    as_read: Trajectory | None = None

    def __len__(self) -> int:
        return len(self.timestamps)

    def rows_as_read(self) -> Trajectory:
        """The rows as the file held them (what evo reads from it): `as_read`, or these rows where the file's
        were in strictly increasing time order."""
        return self if self.as_read is None else self.as_read

    @cached_property
    def finite_rows(self) -> np.ndarray:
        """Which rows have a finite position (a groundtruthSync holds NaN rows); computed once."""
        return np.isfinite(self.positions).all(axis=1)

    def rotations(self) -> np.ndarray:
        """Rotation matrices (N, 3, 3)."""
        return quat_to_rotmat(self.quaternions)

    def with_timestamps(self, timestamps: np.ndarray) -> Trajectory:
        """The same poses at other times (re-sorted), e.g. mapping mirror time back to original time."""
        moved = from_arrays(np.asarray(timestamps, float), self.positions, self.quaternions)
        return Trajectory(moved.timestamps, moved.positions, moved.quaternions, report=self.report)


def from_arrays(timestamps: np.ndarray, positions: np.ndarray, quaternions: np.ndarray) -> Trajectory:
    """Build a trajectory from rows in any order: sort, drop duplicate timestamps, normalise quaternions."""
    data = np.column_stack([timestamps, positions, quaternions]).astype(float, copy=False)
    return _normalise(data, source="<arrays>")


def from_matrices(timestamps: np.ndarray, matrices: np.ndarray) -> Trajectory:
    """Build a trajectory from (N, 3, 4) or (N, 4, 4) camera-to-world matrices."""
    matrices = np.asarray(matrices, float)
    quats = rotmat_to_quat(matrices[:, :3, :3])
    return from_arrays(np.asarray(timestamps, float), matrices[:, :3, 3], quats)


# ---------------------------------------------------------------- readers


def read_tum(path: str | Path) -> Trajectory:
    """Read a TUM file (`timestamp tx ty tz qx qy qz qw`, `#` comments, blank lines allowed); the file's own rows
    in `as_read` where its timestamps repeat or go backward."""
    data = _read_table(path, ncols=8)
    return _normalise(data, source=str(path), keep_as_read=True)


def read_tum_many(
    paths: Sequence[str | Path], batch_bytes: int = 1 << 22
) -> Iterator[Trajectory | TrajectoryFormatError]:
    """`read_tum` for many files, in order: each item is the trajectory or the error naming that file.

    Plain files (single spaces, one row per line, no comments) are parsed together, a batch of up to
    `batch_bytes` at a time, which saves the parser's fixed cost per file; any other file, or a batch
    the parser refuses, takes the one-file path with its exact error messages.
    """
    pending: list[tuple[Path, bytes | TrajectoryFormatError]] = []
    size = 0

    def flush() -> Iterator[Trajectory | TrajectoryFormatError]:
        texts = [(i, _skip_header(data)) for i, (_, data) in enumerate(pending) if isinstance(data, bytes)]
        done: dict[int, Trajectory | None] = {}
        parsed = _parse_plain([text for _, text in texts], 8) if _tumparse is not None else None
        if parsed is not None:
            table, rows = parsed
            read = [(i, n) for (i, _), n in zip(texts, rows, strict=True) if n > 0]
            if read:
                counts = np.array([n for _, n in read], int)
                done = dict(zip((i for i, _ in read), _normalise_batch(list(table.T), counts), strict=True))
        elif len(texts) > 1:  # Arrow over the texts joined: rows counted by newlines, so each must end in one
            plain = [(i, text) for i, text in texts if text[-1:] == b"\n"]
            columns = _fast_columns(b"".join(text for _, text in plain), 8)
            counts = np.array([text.count(b"\n") for _, text in plain], int)
            if columns is not None and len(columns[0]) == counts.sum():  # else a blank line or a stray character
                done = dict(zip((i for i, _ in plain), _normalise_batch(columns, counts), strict=True))
        for i, (path, data) in enumerate(pending):
            if isinstance(data, TrajectoryFormatError):
                yield data
                continue
            if (traj := done.get(i)) is not None:
                yield traj
                continue
            try:
                yield _normalise(_read_table(path, ncols=8, data=data), source=str(path), keep_as_read=True)
            except TrajectoryFormatError as exc:
                yield exc

    for path in map(Path, paths):
        try:
            data: bytes | TrajectoryFormatError = _read_bytes(path)
        except TrajectoryFormatError as exc:
            data = exc
        pending.append((path, data))
        size += len(data) if isinstance(data, bytes) else 0
        if size >= batch_bytes:
            yield from flush()
            pending, size = [], 0
    yield from flush()


def _skip_header(data: bytes) -> bytes:
    """The text after leading `#` comment lines (a header such as write_tum's)."""
    start = 0
    while data.startswith(b"#", start):
        start = data.find(b"\n", start) + 1
        if start == 0:
            return b""
    return data[start:] if start else data


def read_kitti(path: str | Path, timestamps: np.ndarray) -> Trajectory:
    """Read KITTI poses (12 numbers per row, a 3x4 [R|t] row-major); timestamps come from the frames."""
    data = _read_table(path, ncols=12)
    timestamps = np.asarray(timestamps, float)
    if len(timestamps) != len(data):
        raise TrajectoryFormatError(
            f"{path}: {len(data)} KITTI poses but {len(timestamps)} timestamps; expected one pose per frame"
        )
    return from_matrices(timestamps, data.reshape(-1, 3, 4))


def read_timestamped_3x4(path: str | Path) -> Trajectory:
    """Read rows of `timestamp r11 r12 r13 tx r21 r22 r23 ty r31 r32 r33 tz` (13 numbers)."""
    data = _read_table(path, ncols=13)
    return from_matrices(data[:, 0], data[:, 1:].reshape(-1, 3, 4))


def read_4x4_matrices(path: str | Path, timestamps: np.ndarray | None = None) -> Trajectory:
    """Read 4x4 matrices: rows of 17 numbers (timestamp + 16) or of 16 numbers with given timestamps."""
    data = _read_bytes(path)
    text = _read_text(path, data)
    first = next((ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")), "")
    ncols = len(first.replace(",", " ").split())
    if ncols == 17:
        data = _read_table(path, ncols=17, data=data)
        return from_matrices(data[:, 0], data[:, 1:].reshape(-1, 4, 4))
    if ncols == 4:  # one matrix row per line, four lines per matrix
        rows = _read_table(path, ncols=4, data=data)
        if len(rows) % 4:
            raise TrajectoryFormatError(f"{path}: {len(rows)} rows of 4 numbers; expected a multiple of 4")
        mats = rows.reshape(-1, 4, 4)
    else:
        mats = _read_table(path, ncols=16, data=data).reshape(-1, 4, 4)
    if timestamps is None or len(timestamps) != len(mats):
        n_ts = "no" if timestamps is None else len(timestamps)
        raise TrajectoryFormatError(f"{path}: {len(mats)} matrices but {n_ts} timestamps; expected one each")
    return from_matrices(np.asarray(timestamps, float), mats)


def read_euroc_csv(path: str | Path) -> Trajectory:
    """Read an EuRoC/ASL state csv (`#timestamp` in nanoseconds, p_RS_R x y z, q_RS w x y z, then velocities and
    biases, ignored): the poses of the body (IMU) frame S in the reference frame R, at times in seconds."""
    text = _read_text(path)
    stamps, rows = [], []
    for n, line in enumerate(text.splitlines(), start=1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        cells = [c.strip() for c in line.split(",")]
        if len(cells) < 8:
            raise TrajectoryFormatError(
                f"{path}:{n}: {len(cells)} columns; expected at least 8 (#timestamp [ns], p_RS_R_x, p_RS_R_y, "
                "p_RS_R_z, q_RS_w, q_RS_x, q_RS_y, q_RS_z, ...)"
            )
        if not (cells[0].isascii() and cells[0].isdigit()):
            raise TrajectoryFormatError(
                f"{path}:{n}: timestamp {cells[0][:40]!r} is not a whole number of nanoseconds (ASCII digits 0-9)"
            )
        if len(cells[0].lstrip("0")) > 19 or int(cells[0]) >= 2**63:  # 19 digits: int() is quick and bounded
            raise TrajectoryFormatError(f"{path}:{n}: timestamp {cells[0][:40]} ns is beyond 2^63 - 1 (int64)")
        try:
            values = [float(c) for c in cells[1:8]]
        except ValueError:
            raise TrajectoryFormatError(f"{path}:{n}: a pose value is not a number: {line[:80]!r}") from None
        stamps.append(int(cells[0]))
        rows.append(values)
    if not rows:
        raise TrajectoryFormatError(f"{path}: no pose row (an EuRoC state csv has one per line after its header)")
    ns = np.array(stamps, dtype=np.int64)
    t = (ns // 1_000_000_000).astype(float) + (ns % 1_000_000_000).astype(float) * 1e-9
    data = np.array(rows)
    return _normalise(np.column_stack([t, data[:, 0:3], data[:, 4:7], data[:, 3]]), str(path), keep_as_read=True)


def read_times(path: str | Path) -> np.ndarray:
    """Frame times in seconds from a times file: one number per line (KITTI), or `id time [exposure]` rows
    (TUM-Mono): the last column of one, the second of the other."""
    text = _read_text(path)
    out = []
    for n, line in enumerate(text.splitlines(), start=1):
        cells = line.split()
        if not cells or cells[0].startswith("#"):
            continue
        try:
            out.append(float(cells[0] if len(cells) == 1 else cells[1]))
        except ValueError:
            raise TrajectoryFormatError(f"{path}:{n}: {line[:60]!r} is not a time in seconds") from None
    return np.array(out)


def write_tum(path: str | Path, traj: Trajectory) -> None:
    """Write a TUM file with full precision, the rows as read where a file's were out of time order or repeated
    a timestamp (`as_read`); `read_tum` reads it back exactly."""
    rows = traj.rows_as_read()
    data = np.column_stack([rows.timestamps, rows.positions, rows.quaternions])
    buf = io.StringIO()
    buf.write("# timestamp tx ty tz qx qy qz qw\n")
    np.savetxt(buf, data, fmt="%.17g")
    Path(path).write_text(buf.getvalue())


# ---------------------------------------------------------------- rotations


def rotmat_to_quat(rot: np.ndarray) -> np.ndarray:
    """Rotation matrices (N, 3, 3) → unit quaternions (N, 4) `qx qy qz qw`, with qw >= 0.

    Magnitudes by Sarabandi and Thomas (2018) with threshold eta = 0; signs taken relative to the
    largest component, which stays well defined near 180 degrees where qw -> 0.
    """
    r = np.asarray(rot, float)
    single = r.ndim == 2
    r = r.reshape(-1, 3, 3)
    r11, r12, r13 = r[:, 0, 0], r[:, 0, 1], r[:, 0, 2]
    r21, r22, r23 = r[:, 1, 0], r[:, 1, 1], r[:, 1, 2]
    r31, r32, r33 = r[:, 2, 0], r[:, 2, 1], r[:, 2, 2]
    d32, d13, d21 = r32 - r23, r13 - r31, r21 - r12
    s12, s13, s23 = r12 + r21, r13 + r31, r23 + r32

    def component(diag: np.ndarray, num: np.ndarray, den: np.ndarray) -> np.ndarray:
        with np.errstate(invalid="ignore", divide="ignore"):
            alt = 0.5 * np.sqrt(np.maximum(num, 0.0) / den)
        return np.where(diag > 0.0, 0.5 * np.sqrt(np.maximum(1.0 + diag, 0.0)), np.nan_to_num(alt))

    w = component(r11 + r22 + r33, d32**2 + d13**2 + d21**2, 3.0 - r11 - r22 - r33)
    x = component(r11 - r22 - r33, d32**2 + s12**2 + s13**2, 3.0 - r11 + r22 + r33)
    y = component(-r11 + r22 - r33, d13**2 + s12**2 + s23**2, 3.0 + r11 - r22 + r33)
    z = component(-r11 - r22 + r33, d21**2 + s13**2 + s23**2, 3.0 + r11 + r22 - r33)
    q = np.stack([x, y, z, w], axis=1)

    # Signs relative to the largest component (taken positive).
    sign = np.ones_like(q)
    ref = np.argmax(q, axis=1)
    sgn = lambda v: np.where(v < 0.0, -1.0, 1.0)  # noqa: E731
    for idx, cols in (
        (3, {0: d32, 1: d13, 2: d21}),
        (0, {3: d32, 1: s12, 2: s13}),
        (1, {3: d13, 0: s12, 2: s23}),
        (2, {3: d21, 0: s13, 1: s23}),
    ):
        m = ref == idx
        for col, v in cols.items():
            sign[m, col] = sgn(v[m])
    q = q * sign
    q *= np.where(q[:, 3:4] < 0.0, -1.0, 1.0)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return q[0] if single else q


def quat_to_rotmat(q: np.ndarray) -> np.ndarray:
    """Unit quaternions (N, 4) `qx qy qz qw` → rotation matrices (N, 3, 3)."""
    q = np.asarray(q, float)
    single = q.ndim == 1
    q = q.reshape(-1, 4)
    x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    r = np.empty((len(q), 3, 3))
    r[:, 0, 0] = 1 - 2 * (y * y + z * z)
    r[:, 0, 1] = 2 * (x * y - z * w)
    r[:, 0, 2] = 2 * (x * z + y * w)
    r[:, 1, 0] = 2 * (x * y + z * w)
    r[:, 1, 1] = 1 - 2 * (x * x + z * z)
    r[:, 1, 2] = 2 * (y * z - x * w)
    r[:, 2, 0] = 2 * (x * z - y * w)
    r[:, 2, 1] = 2 * (y * z + x * w)
    r[:, 2, 2] = 1 - 2 * (x * x + y * y)
    return r[0] if single else r


# ---------------------------------------------------------------- internals


def _read_bytes(path: str | Path) -> bytes:
    try:
        with open(path, "rb", buffering=0) as f:  # one read into the bytes object, no buffer between
            return f.readall()
    except FileNotFoundError:
        raise TrajectoryFormatError(f"{path}: no such trajectory file") from None
    except IsADirectoryError:
        raise TrajectoryFormatError(f"{path}: a folder, expected a trajectory file") from None
    except OSError as exc:  # a regular file whose read fails: /proc/self/mem (EIO), no permission, a lost mount
        raise TrajectoryFormatError(f"{path}: cannot be read ({exc.strerror or exc})") from None


def _read_text(path: str | Path, data: bytes | None = None) -> str:
    try:
        return (_read_bytes(path) if data is None else data).decode()
    except UnicodeDecodeError:
        raise TrajectoryFormatError(f"{path}: not a text file; expected numbers in rows") from None


def _read_table(path: str | Path, ncols: int, data: bytes | None = None) -> np.ndarray:
    """Parse rows of `ncols` numbers separated by spaces or commas; errors name the file and line."""
    data = _read_bytes(path) if data is None else data
    table = _fast_table(_skip_header(data), ncols)
    if table is not None:
        return table
    text = _read_text(path, data)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # "input contained no data"
            table = np.loadtxt(io.StringIO(text.replace(",", " ")), comments="#", ndmin=2, dtype=float)
    except ValueError:
        table = None
    if table is not None and (table.size == 0 or table.shape[1] == ncols):
        return table.reshape(-1, ncols)
    # Slow path: find the first offending line for the message.
    for lineno, line in enumerate(text.splitlines(), start=1):
        body = line.split("#", 1)[0].replace(",", " ").split()
        if not body:
            continue
        if len(body) != ncols:
            raise TrajectoryFormatError(f"{path}:{lineno}: {len(body)} values, expected {ncols}: {line.strip()[:80]!r}")
        try:
            [float(v) for v in body]
        except ValueError:
            raise TrajectoryFormatError(f"{path}:{lineno}: not a number in {line.strip()[:80]!r}") from None
    raise TrajectoryFormatError(f"{path}: cannot parse as rows of {ncols} numbers")


@lru_cache(maxsize=8)
def _arrow_options(ncols: int) -> tuple:
    import pyarrow as pa
    import pyarrow.csv as pa_csv

    return (
        pa_csv.ReadOptions(autogenerate_column_names=True, use_threads=False, block_size=1 << 24),
        pa_csv.ParseOptions(delimiter=" ", quote_char=False),
        pa_csv.ConvertOptions(column_types={f"f{i}": pa.float64() for i in range(ncols)}, null_values=[]),
    )


def _fast_table(data: bytes, ncols: int) -> np.ndarray | None:
    """The common case (numbers separated by single spaces) as an (N, ncols) table, by the compiled reader or
    else Arrow's; None when the text needs the careful path."""
    if _tumparse is not None:
        table, rows = _parse_plain([data], ncols)
        if rows[0] > 0:
            return table
    columns = _fast_columns(data, ncols)
    return None if columns is None else np.stack(columns, axis=1)


def _parse_plain(texts: list[bytes], ncols: int) -> tuple[np.ndarray, list[int]]:
    """Texts of rows of `ncols` numbers separated by single spaces, each row ending in a newline (the last one
    may not), by the compiled reader, exactly as strtod reads them: the rows of all such texts one after the
    other (a column-major table), and each text's row count (-1: not of that form, none of its rows taken)."""
    data, rows = _tumparse.parse_many(texts, ncols)
    columns = np.frombuffer(data, np.float64).reshape(ncols, -1)  # each column contiguous
    return columns[:, : sum(n for n in rows if n > 0)].T, rows


def _fast_columns(data: bytes, ncols: int) -> list[np.ndarray] | None:
    """The common case (numbers separated by single spaces) parsed by Arrow's CSV reader (correctly
    rounded, like strtod, and ~2x faster), one float64 array per column; None when the text needs the
    careful path (comments, commas, tabs, repeated spaces, a ragged row, anything that is not a number)."""
    if not data or data[:1] in b" \t\r\n":  # Arrow reads a leading separator as an empty field
        return None
    import pyarrow as pa
    import pyarrow.csv as pa_csv

    read, parse, convert = _arrow_options(ncols)
    try:
        table = pa_csv.read_csv(pa.py_buffer(data), read_options=read, parse_options=parse, convert_options=convert)
    except (pa.ArrowInvalid, UnicodeDecodeError):
        return None
    if table.num_columns != ncols:
        return None
    columns = []
    for col in table.columns:  # the float64 buffers as they are (Arrow's to_numpy imports pandas: 0.3 s a process)
        if col.type != pa.float64() or col.null_count:
            return None
        parts = [np.frombuffer(c.buffers()[1], np.float64)[c.offset : c.offset + len(c)] for c in col.chunks]
        columns.append(np.concatenate(parts) if len(parts) != 1 else parts[0])
    return columns


def _quat_norms(qx: np.ndarray, qy: np.ndarray, qz: np.ndarray, qw: np.ndarray) -> np.ndarray:
    """|q| row by row, with one order of operations for every reader (results bit-identical)."""
    return np.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)


def _normalise_batch(columns: list[np.ndarray], rows: np.ndarray) -> list[Trajectory | None]:
    """`_normalise` for consecutive files parsed together: file k holds the next rows[k] rows (at least one)
    of the 8 TUM columns. Each is computed over the whole batch at once; a file that needs repair work (a
    NaN or infinite value, time not strictly increasing, a zero quaternion) gets None, for `_normalise`."""
    t, x, y, z, qx, qy, qz, qw = columns
    starts = np.concatenate(([0], np.cumsum(rows)[:-1]))
    ends = starts + rows
    total = t + x  # a row whose sum is not finite holds a NaN or an infinity (or overflows)
    for col in (y, z, qx, qy, qz, qw):
        total += col
    norm = _quat_norms(qx, qy, qz, qw)
    row_ok = np.isfinite(total) & (norm >= 1e-12)
    row_ok[:-1] &= t[1:] > t[:-1]  # time strictly increasing...
    row_ok[ends - 1] |= np.isfinite(total[ends - 1]) & (norm[ends - 1] >= 1e-12)  # ...within each file
    clean = np.logical_and.reduceat(row_ok, starts)
    err = np.abs(norm - 1.0)
    non_unit = np.add.reduceat(err > NON_UNIT_TOL, starts)
    far = np.add.reduceat(err > FAR_FROM_UNIT_TOL, starts)
    max_err = np.maximum.reduceat(err, starts)
    times = t.copy()  # writable, like `_normalise`'s (Arrow's buffers are read-only)
    positions = np.column_stack((x, y, z))
    with np.errstate(invalid="ignore", divide="ignore"):  # a zero or NaN quaternion's file is left out below
        quats = np.column_stack((qx, qy, qz, qw)) / norm[:, None]
    out: list[Trajectory | None] = []
    for k in range(len(rows)):
        if not clean[k]:
            out.append(None)
            continue
        a, b = starts[k], ends[k]
        report = ReadReport(
            n_rows=int(rows[k]),
            n_quat_non_unit=int(non_unit[k]),
            n_quat_far_from_unit=int(far[k]),
            max_quat_norm_error=float(max_err[k]),
        )
        out.append(Trajectory(times[a:b], positions[a:b], quats[a:b], report=report))
    return out


def _line_of_time(source: str, stamp: float) -> int | None:
    """The number of the first line of the file `source` whose first number is `stamp`, or None (no such file, or
    one too large to scan)."""
    try:
        path = Path(source)
        if not path.is_file() or path.stat().st_size > 64 << 20:
            return None
        with open(path, errors="replace") as fh:
            for n, line in enumerate(fh, start=1):
                cells = line.split("#", 1)[0].replace(",", " ").split()
                try:
                    if cells and float(cells[0]) == stamp:
                        return n
                except ValueError:
                    continue
    except OSError:
        return None
    return None


def _normalise(data: np.ndarray, source: str, keep_as_read: bool = False) -> Trajectory:
    """Rows of `t x y z qx qy qz qw` into a Trajectory: rows with a NaN or infinity dropped, quaternions normalised,
    sorted by time with one row per timestamp (the first); with `keep_as_read` (a file's rows), the finite rows
    in their order as `as_read` where that differs."""
    n_rows = len(data)
    finite = np.isfinite(data).all(axis=1)
    n_nonfinite = 0
    if not finite.all():  # a row that is not a pose: dropped and counted
        n_nonfinite = int(np.count_nonzero(~finite))
        data = data[finite]
    if len(data) == 0:
        empty = np.zeros((0, 3)), np.zeros((0, 4))
        return Trajectory(np.zeros(0), *empty, report=ReadReport(n_rows=n_rows, n_nonfinite_dropped=n_nonfinite))
    norm = _quat_norms(*data[:, 4:8].T)
    if (norm < 1e-12).any():
        bad = int(np.flatnonzero(norm < 1e-12)[0])
        stamp = float(data[bad, 0])
        line = _line_of_time(source, stamp)
        where = f"{source}:{line}" if line else source
        raise TrajectoryFormatError(f"{where}: a zero quaternion (no rotation) at timestamp {stamp:.9g}")
    step = np.diff(data[:, 0])
    was_unsorted = bool(np.any(step < 0))
    n_dup = 0
    rows = None  # the rows in time order, one per timestamp, where that is not every row in the file's order
    if not np.all(step > 0):  # sort and drop duplicates only when needed (most files are in order)
        order = np.argsort(data[:, 0], kind="stable")
        keep = np.ones(len(data), bool)
        keep[1:] = np.diff(data[order, 0]) != 0
        n_dup = int(np.count_nonzero(~keep))
        rows = order[keep]
    kept_norm = norm if rows is None else norm[rows]
    finite_err = np.abs(kept_norm - 1.0)
    report = ReadReport(
        n_rows=n_rows,
        was_unsorted=was_unsorted,
        n_duplicates_dropped=n_dup,
        n_quat_non_unit=int(np.count_nonzero(finite_err > NON_UNIT_TOL)),
        n_quat_far_from_unit=int(np.count_nonzero(finite_err > FAR_FROM_UNIT_TOL)),
        max_quat_norm_error=float(finite_err.max()) if finite_err.size else 0.0,
        n_nonfinite_dropped=n_nonfinite,
    )
    quat = data[:, 4:8] / norm[:, None]
    if rows is None:
        return Trajectory(data[:, 0].copy(), data[:, 1:4].copy(), quat, report=report)
    as_read = Trajectory(data[:, 0], data[:, 1:4], quat, report=report) if keep_as_read else None
    return Trajectory(data[rows, 0], data[rows, 1:4], quat[rows], report=report, as_read=as_read)

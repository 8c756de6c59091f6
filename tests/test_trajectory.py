"""Trajectory readers and writers, on synthetic values and on the real files in shared/data."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from slamrun.core.trajectory import (
    from_arrays,
    read_4x4_matrices,
    read_kitti,
    read_timestamped_3x4,
    read_tum,
    rotmat_to_quat,
    write_tum,
)
from slamrun.errors import TrajectoryFormatError
from tests.conftest import SHARED_DATA as DATA

# the study's TUM files (evo_test_data beside them holds KITTI poses and other datasets' formats)
REAL_FILES = sorted(
    f for folder in ("dso_tum_mono_examples", "study_trajectories") for f in (DATA / folder).glob("*.txt")
)


def _same_rotation(q1: np.ndarray, q2: np.ndarray) -> np.ndarray:
    """|<q1, q2>| == 1 when both quaternions encode the same rotation."""
    return np.abs(np.sum(q1 * q2, axis=1))


def test_rotmat_to_quat_random_matches_scipy():
    rots = Rotation.random(5000, random_state=1)
    q = rotmat_to_quat(rots.as_matrix())
    np.testing.assert_allclose(_same_rotation(q, rots.as_quat()), 1.0, atol=1e-12)
    assert (q[:, 3] >= 0).all()


@pytest.mark.parametrize("eps", [0.0, 1e-12, 1e-9, 1e-6, 1e-3])
def test_rotmat_to_quat_near_180_degrees(eps):
    rng = np.random.default_rng(2)
    axes = rng.normal(size=(500, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    rots = Rotation.from_rotvec(axes * (np.pi - eps))
    q = rotmat_to_quat(rots.as_matrix())
    np.testing.assert_allclose(_same_rotation(q, rots.as_quat()), 1.0, atol=1e-9)
    np.testing.assert_allclose(Rotation.from_quat(q).as_matrix(), rots.as_matrix(), atol=1e-9)


def test_rotmat_to_quat_identity_and_axes():
    for axis in np.eye(3):
        for angle in (0.0, np.pi / 2, np.pi):
            r = Rotation.from_rotvec(axis * angle)
            q = rotmat_to_quat(r.as_matrix()[None])[0]
            assert abs(abs(q @ r.as_quat()) - 1) < 1e-12


def test_tum_round_trip(tmp_path):
    rng = np.random.default_rng(3)
    t = np.sort(rng.uniform(0, 100, 200))
    traj = from_arrays(t, rng.normal(size=(200, 3)), Rotation.random(200, random_state=3).as_quat())
    write_tum(tmp_path / "a.txt", traj)
    back = read_tum(tmp_path / "a.txt")
    np.testing.assert_array_equal(back.timestamps, traj.timestamps)
    np.testing.assert_array_equal(back.positions, traj.positions)
    np.testing.assert_allclose(back.quaternions, traj.quaternions, rtol=0, atol=1e-15)


def test_sorts_drops_duplicates_and_normalises(tmp_path):
    f = tmp_path / "t.txt"
    f.write_text("# comment\n\n3 0 0 0 0 0 0 2\n1 1 0 0 0 0 0 1\n1 9 9 9 0 0 0 1\n2,2,0,0,0,0,0,1\n")
    traj = read_tum(f)
    np.testing.assert_array_equal(traj.timestamps, [1, 2, 3])
    assert traj.positions[0, 0] == 1  # the first of the duplicates is kept
    assert traj.report.was_unsorted and traj.report.n_duplicates_dropped == 1
    rows = traj.rows_as_read()  # every row as the file holds it, for the metrics that follow evo
    np.testing.assert_array_equal(rows.timestamps, [3, 1, 1, 2])
    np.testing.assert_array_equal(rows.positions[:, 0], [0, 1, 9, 2])
    np.testing.assert_allclose(rows.quaternions[0], [0, 0, 0, 1])
    assert traj.report.n_quat_non_unit == 1 and traj.report.n_quat_far_from_unit == 1
    np.testing.assert_allclose(np.linalg.norm(traj.quaternions, axis=1), 1.0)


@pytest.mark.parametrize(
    "content, where",
    [("1 2 3\n", ":1: 3 values, expected 8"), ("1 0 0 0 0 0 0 1\n2 0 0 x 0 0 0 1\n", ":2: not a number")],
)
def test_bad_rows_name_file_and_line(tmp_path, content, where):
    f = tmp_path / "bad.txt"
    f.write_text(content)
    with pytest.raises(TrajectoryFormatError, match=f"bad.txt{where}"):
        read_tum(f)


def test_zero_quaternion_and_missing_file(tmp_path):
    f = tmp_path / "z.txt"
    f.write_text("1 0 0 0 0 0 0 0\n")
    with pytest.raises(TrajectoryFormatError, match="zero quaternion"):
        read_tum(f)
    with pytest.raises(TrajectoryFormatError, match="no such trajectory file"):
        read_tum(tmp_path / "missing.txt")


def test_empty_file_is_an_empty_trajectory(tmp_path):
    f = tmp_path / "e.txt"
    f.write_text("# nothing\n")
    assert len(read_tum(f)) == 0


def test_matrix_formats_agree(tmp_path):
    rots = Rotation.random(20, random_state=4)
    pos = np.arange(60, dtype=float).reshape(20, 3)
    t = np.arange(20) * 0.05
    m34 = np.concatenate([rots.as_matrix(), pos[:, :, None]], axis=2)
    np.savetxt(tmp_path / "kitti.txt", m34.reshape(20, 12))
    np.savetxt(tmp_path / "ts34.txt", np.column_stack([t, m34.reshape(20, 12)]))
    m44 = np.tile(np.eye(4), (20, 1, 1))
    m44[:, :3, :] = m34
    np.savetxt(tmp_path / "ts44.txt", np.column_stack([t, m44.reshape(20, 16)]))
    np.savetxt(tmp_path / "rows44.txt", m44.reshape(80, 4))
    for traj in (
        read_kitti(tmp_path / "kitti.txt", t),
        read_timestamped_3x4(tmp_path / "ts34.txt"),
        read_4x4_matrices(tmp_path / "ts44.txt"),
        read_4x4_matrices(tmp_path / "rows44.txt", t),
    ):
        np.testing.assert_allclose(traj.positions, pos)
        np.testing.assert_allclose(_same_rotation(traj.quaternions, rots.as_quat()), 1, atol=1e-12)
    with pytest.raises(TrajectoryFormatError, match="20 KITTI poses but 3 timestamps"):
        read_kitti(tmp_path / "kitti.txt", t[:3])


@pytest.mark.parametrize("path", REAL_FILES, ids=lambda p: p.name)
def test_every_real_file_parses(path):
    traj = read_tum(path)
    assert len(traj) > 100
    assert np.all(np.diff(traj.timestamps) > 0)
    np.testing.assert_allclose(np.linalg.norm(traj.quaternions, axis=1), 1.0, atol=1e-12)
    rows = [ln for ln in path.read_text().splitlines() if ln.strip() and not ln.startswith("#")]
    raw = np.array([[float(v) for v in ln.split()] for ln in rows])
    assert traj.report.n_rows == len(raw)
    assert traj.report.was_unsorted == bool(np.any(np.diff(raw[:, 0]) < 0))
    assert traj.report.n_duplicates_dropped == len(raw) - len(np.unique(raw[:, 0]))
    norm_err = np.abs(np.linalg.norm(raw[:, 4:8], axis=1) - 1)
    assert traj.report.n_quat_far_from_unit == np.count_nonzero(norm_err > 0.1)


def test_real_files_are_there(shared_data):
    """The parametrised test below runs once per file: make sure there are files to run it on."""
    assert len(REAL_FILES) >= 15


def test_real_file_facts(shared_data):
    """Facts stated in shared/data/README.md: backward runs decrease; some CNN-SVO norms are in the thousands."""
    assert read_tum(DATA / "study_trajectories/dso_bw__sequence_47_9.txt").report.was_unsorted
    assert read_tum(DATA / "study_trajectories/dsm_bw__sequence_47_6.txt").report.was_unsorted
    cnn = read_tum(DATA / "study_trajectories/cnn-svo_fw__sequence_48_8.txt").report
    assert cnn.max_quat_norm_error > 1000 and cnn.n_quat_far_from_unit > 500
    assert not read_tum(DATA / "dso_tum_mono_examples/sequence_01.txt").report.was_unsorted


@pytest.mark.parametrize("reader", ["compiled", "arrow"])
def test_read_tum_many_matches_read_tum_file_by_file(tmp_path, monkeypatch, reader):
    """Batched reading gives each file exactly what read_tum gives it, errors included, in order; by the
    compiled reader, and by Arrow's where that is not built."""
    from slamrun.core import trajectory
    from slamrun.core.trajectory import read_tum_many, write_tum
    from slamrun.errors import TrajectoryFormatError

    if reader == "arrow":
        monkeypatch.setattr(trajectory, "_tumparse", None)
    else:
        need_compiled_reader()

    rng = np.random.default_rng(3)

    def rows(n: int, t0: float) -> str:
        data = np.column_stack([t0 + np.arange(n) / 30, rng.normal(size=(n, 3)), rng.normal(size=(n, 4))])
        return "".join(" ".join(f"{v:.9f}" for v in row) + "\n" for row in data)

    files = {
        "plain_a.txt": rows(50, 1.0),
        "plain_b.txt": rows(70, 5.0),
        "header.txt": "# timestamp tx ty tz qx qy qz qw\n" + rows(20, 2.0),
        "blank_line.txt": rows(5, 3.0) + "\n" + rows(5, 9.0),
        "comment_mid.txt": rows(5, 3.0) + "# relocalised\n" + rows(5, 9.0),
        "no_final_newline.txt": rows(6, 4.0).rstrip("\n"),
        "crlf.txt": rows(8, 6.0).replace("\n", "\r\n"),
        "seven_columns.txt": rows(4, 1.0) + "1 2 3 4 5 6 7\n",
        "unsorted.txt": "".join(reversed(rows(9, 7.0).splitlines(keepends=True))),
        "duplicate_time.txt": rows(4, 2.0) + rows(4, 2.0 + 3 / 30),
        "nan_row.txt": rows(4, 3.0) + "3.5 nan 0 0 0 0 0 1\n" + rows(4, 4.0),
        "inf_last_row.txt": rows(4, 3.0) + "9 1 2 3 0 0 0 inf\n",
        "zero_quaternion.txt": rows(4, 3.0) + "9 1 2 3 0 0 0 0\n",
        "unit_quaternions.txt": "".join(f"{1 + i / 30:.9f} 1 2 3 0 0 0.6 0.8\n" for i in range(12)),
        "one_row.txt": "5 1 2 3 0 0 0 2\n",
        "empty.txt": "",
        "plain_c.txt": rows(30, 8.0),
    }
    paths = []
    for name, text in files.items():
        (tmp_path / name).write_text(text)
        paths.append(tmp_path / name)
    write_tum(tmp_path / "written.txt", read_tum(paths[0]))
    paths += [tmp_path / "written.txt", tmp_path / "missing.txt"]

    def check(subset: list, batch_bytes: int) -> list:
        got = list(read_tum_many(subset, batch_bytes=batch_bytes))
        assert len(got) == len(subset)
        for path, item in zip(subset, got, strict=True):
            try:
                want = read_tum(path)
            except TrajectoryFormatError as exc:
                assert isinstance(item, TrajectoryFormatError) and str(item) == str(exc), path.name
                continue
            assert not isinstance(item, TrajectoryFormatError), (path.name, item)
            for a, b in ((item.timestamps, want.timestamps), (item.positions, want.positions)):
                assert np.array_equal(a, b), path.name
            assert np.array_equal(item.quaternions, want.quaternions), path.name
            assert item.report == want.report, path.name
            assert (item.as_read is None) == (want.as_read is None), path.name
            for a, b in ((item.rows_as_read(), want.rows_as_read()),):
                assert np.array_equal(a.timestamps, b.timestamps) and np.array_equal(a.positions, b.positions)
                assert np.array_equal(a.quaternions, b.quaternions), path.name
        return got

    got = check(paths, batch_bytes=2000)  # small batches: several flushes
    assert isinstance(got[-1], TrajectoryFormatError) and "missing.txt" in str(got[-1])
    assert isinstance(got[paths.index(tmp_path / "seven_columns.txt")], TrajectoryFormatError)
    plain = [tmp_path / "plain_a.txt", tmp_path / "plain_b.txt", tmp_path / "plain_c.txt"]
    parsed_together = {"plain_a", "header", "unsorted", "duplicate_time", "nan_row", "inf_last_row", "zero_quaternion"}
    parsed_together |= {"unit_quaternions", "one_row", "written", "no_final_newline", "missing", "empty"}
    for odd in paths:  # each odd file between plain ones, in one batch
        got = check([plain[0], odd, plain[1], plain[2]], batch_bytes=1 << 22)
        if reader == "compiled" or odd.stem in parsed_together:  # the plain files' rows were parsed as one batch
            assert got[0].positions.base is got[3].positions.base is not None, f"{odd.name}: not read as one batch"


def need_compiled_reader():
    """The compiled reader of plain tables; skipped with the reason where it is not built (failed under CI)."""
    import os

    from slamrun.core import trajectory

    if trajectory._tumparse is None:
        why = "slamrun.core._tumparse is not built (a C compiler and `pip install -e .`, as `make install` does)"
        if os.environ.get("CI") == "true":
            pytest.fail(why)
        pytest.skip(reason=why)
    return trajectory._tumparse


def test_compiled_reader_reads_numbers_exactly_as_python_does():
    """Every number as Python's float() (correctly rounded) reads it, bit for bit, whatever the format; a text
    that is not rows of single-space-separated numbers is refused (-1), never misread."""
    from slamrun.core import trajectory

    tumparse = need_compiled_reader()
    rng = np.random.default_rng(0)
    values = np.concatenate(
        [
            rng.normal(size=4000) * 10.0 ** rng.integers(-40, 40, 4000),
            rng.uniform(-1e6, 1e6, 4000),
            [0.0, -0.0, 1e-320, 5e-324, 1.7976931348623157e308, 2.0**53 + 1, 123456789012345678901.0],
            [12345678.0, 123456789.0, 1234567812345678.0, 1e-8, 99999999.0, 100000000.0, 9999999999999999999.0],
        ]
    )
    values = np.concatenate([values, np.zeros(-len(values) % 8)])
    for fmt in ("%.17g", "%.15g", "%.9f", "%.6e", "%.3f", "%.25f", "%.0f", "%+.12E", "%.30g", "%.7f", "%.8f", "%.16f"):
        text = "".join(" ".join(fmt % v for v in row) + "\n" for row in values.reshape(-1, 8)).encode()
        table, rows = trajectory._parse_plain([text], 8)
        if max(map(len, text.split())) > 127:  # 1.8e308 in %.9f: a number that long is left to the careful path
            assert rows == [-1], fmt
            continue
        got = table.ravel()  # row by row
        want = np.array([float(v) for v in text.split()])
        assert rows == [len(values) // 8] and np.array_equal(got.view(np.int64), want.view(np.int64)), fmt
    forms = {
        b"1 2 3\n4 5 6": 2,  # no newline after the last row
        b"-0 +1. .5\n007 1E+2 2e-3\n": 2,
        b"": 0,
        b"1 2\n": -1,  # a short row
        b"1  2 3\n": -1,  # two spaces
        b"1 2 3 \n": -1,
        b"1 2 3\n\n": -1,  # a blank line
        b"1 2 3\r\n": -1,
        b"1 2 x\n": -1,
        b"1 2 nan\n": -1,  # not a plain number: the careful path reads it
        b"1 2 1e\n": -1,
        b"1 2 .\n": -1,
        b"1 2 -\n": -1,
        b"1 2 3\x004 5 6\n": -1,
        b"# 1 2 3\n": -1,
        b"1,2,3\n": -1,
    }
    table, rows = trajectory._parse_plain(list(forms), 3)
    assert rows == list(forms.values())
    assert table.ravel().tolist() == [1, 2, 3, 4, 5, 6, -0.0, 1, 0.5, 7, 100, 0.002]
    with pytest.raises(TypeError, match=r"texts\[1\]: bytes expected"):
        tumparse.parse_many([b"1\n", "1\n"], 1)


def test_compiled_reader_agrees_with_arrow_on_real_files(shared_data, monkeypatch):
    """The study's trajectory files, read by the compiled reader and by Arrow's: the same arrays and reports."""
    from slamrun.core import trajectory

    need_compiled_reader()
    files = sorted((DATA / "study_trajectories").glob("*.txt")) + sorted((DATA / "dso_tum_mono_examples").glob("*.txt"))
    compiled = list(trajectory.read_tum_many(files))
    monkeypatch.setattr(trajectory, "_tumparse", None)
    arrow = list(trajectory.read_tum_many(files))
    for path, a, b in zip(files, compiled, arrow, strict=True):
        for name in ("timestamps", "positions", "quaternions"):
            assert np.array_equal(getattr(a, name), getattr(b, name)), (path.name, name)
        assert a.report == b.report, path.name

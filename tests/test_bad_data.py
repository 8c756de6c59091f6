"""Bad and hostile dataset files (issue 37, items 3, 4 and EuRoC's part of 7): each is named by `slamrun validate`
with its file (and line), before any run, within seconds and bounded memory, with no traceback; what only view
preparation can find is a dataset error naming the file, never a method's failure.

Every case is a real synthetic sequence of its layout (make_synthetic.generate), damaged as a user's or a
hostile file would be, read by real `slamrun` processes (the hostile ones under an address-space limit).
"""

from __future__ import annotations

import os
import resource
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import cv2
import numpy as np
import pytest

from slamrun.datasets.make_synthetic import generate
from slamrun.errors import DatasetError
from tests.conftest import fake_method, write_spec
from tests.test_campaign import ledger_rows

NAMES = {
    "tum-mono": "seq",
    "euroc": "V1",
    "kitti": "00",
    "tum-rgbd": "rgbd_dataset_freiburg1_synth",
    "tum-vi": "room1",
}
METHOD_FAILURES = {"not_initialized", "lost", "no_output", "crashed", "timeout", "oom"}
LIMIT_AS = 2 * 2**30  # the address space a hostile case is read in (slamrun itself takes about 0.5 GiB of it)


@pytest.fixture(scope="module")
def pristine(tmp_path_factory) -> dict[str, Path]:
    """One small synthetic sequence per layout (KITTI's under sequences/, poses/ beside it)."""
    root = tmp_path_factory.mktemp("pristine")
    out = {}
    for layout, name in NAMES.items():
        parent = root / layout / ("sequences" if layout == "kitti" else "")
        out[layout] = generate(parent / name, frames=12, seed=4, size=(160, 120), layout=layout)
    return out


@pytest.fixture
def seq(pristine, tmp_path):
    """A fresh copy of a layout's sequence, to damage: seq("kitti") -> its folder."""

    def copy(layout: str) -> Path:
        src = pristine[layout]
        if layout == "kitti":
            shutil.copytree(src.parent.parent, tmp_path / "kitti")
            return tmp_path / "kitti" / "sequences" / NAMES[layout]
        shutil.copytree(src, tmp_path / layout / NAMES[layout])
        return tmp_path / layout / NAMES[layout]

    return copy


def spec_for(folder: Path, layout: str, tmp_path: Path, **kw) -> Path:
    datasets = [{"name": "d", "path": str(folder.parent), "sequences": [folder.name], "layout": layout}]
    return write_spec(tmp_path, folder.parent, [fake_method()], datasets=datasets, **kw)


def slamrun(*args: str, timeout: float = 60) -> subprocess.CompletedProcess:
    """`slamrun ARGS` in a process whose address space is limited to LIMIT_AS; a process still running after
    `timeout` s fails the test (TimeoutExpired)."""

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (LIMIT_AS, resource.RLIM_INFINITY))

    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "COLUMNS": "250"}
    return subprocess.run(
        [sys.executable, "-m", "slamrun.cli", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        preexec_fn=limit,
        env=env,
    )


def refused(folder: Path, layout: str, tmp_path: Path, *expected: str) -> str:
    """`slamrun validate` on a spec of the sequence: exit 1, one clear message holding each of `expected`, no
    traceback, nothing written."""
    spec = spec_for(folder, layout, tmp_path)
    out = slamrun("validate", str(spec))
    said = " ".join((out.stdout + out.stderr).split())  # rich wraps long lines
    assert out.returncode == 1, said
    assert "Traceback" not in said and "Error:" not in said.replace("DatasetError", ""), said
    for part in expected:
        assert part in said, f"{part!r} not in {said!r}"
    assert not (tmp_path / "results").exists() and not (tmp_path / "cache").exists()
    return said


def set_line(path: Path, lineno: int, text: str) -> None:
    lines = path.read_text().splitlines()
    lines[lineno - 1] = text
    path.write_text("\n".join(lines) + "\n")


def data_lines(path: Path) -> list[int]:
    """The line numbers of a listing's rows (not blank, not a # comment)."""
    return [n for n, t in enumerate(path.read_text().splitlines(), 1) if t.strip() and not t.startswith("#")]


# ------------------------------------------------------------ 3: frame times


@pytest.mark.parametrize("value", ["nan", "inf"])
def test_kitti_times_that_are_not_finite_are_named_with_their_line(seq, tmp_path, value):
    root = seq("kitti")
    set_line(root / "times.txt", 5, value)
    refused(root, "kitti", tmp_path, "times.txt:5", value)


def test_tum_mono_times_that_are_not_finite_are_named_with_their_line(seq, tmp_path):
    root = seq("tum-mono")
    times = root / "times.txt"
    row = times.read_text().splitlines()[2].split()
    set_line(times, 3, f"{row[0]} nan {row[2]}")
    refused(root, "tum-mono", tmp_path, "times.txt:3", "nan")
    last = len(times.read_text().splitlines())
    row = times.read_text().splitlines()[2].split()
    set_line(times, 3, f"{row[0]} 1.066667 {row[2]}")
    row = times.read_text().splitlines()[-1].split()
    set_line(times, last, f"{row[0]} inf {row[2]}")
    refused(root, "tum-mono", tmp_path, f"times.txt:{last}", "inf")
    row = times.read_text().splitlines()[-1].split()
    set_line(times, last, f"{row[0]} 1.366667 nan")  # an exposure that is not a number of milliseconds
    refused(root, "tum-mono", tmp_path, f"times.txt:{last}", "exposure")


def test_tum_rgbd_nan_time_is_named_with_its_line(seq, tmp_path):
    root = seq("tum-rgbd")
    listing = root / "rgb.txt"
    n = data_lines(listing)[4]
    set_line(listing, n, "nan " + listing.read_text().splitlines()[n - 1].split()[1])
    refused(root, "tum-rgbd", tmp_path, f"rgb.txt:{n}", "nan")


def damage_p0(root: Path) -> None:
    p0 = (root / "calib.txt").read_text().splitlines()[0].split()
    set_line(root / "calib.txt", 1, " ".join(["P0:", p0[1], p0[2], "nan", *p0[4:11], "inf", p0[12]]))


def damage_distortion(root: Path) -> None:
    sensor = root / "mav0/cam0/sensor.yaml"
    lines = sensor.read_text().splitlines()
    lines = [
        "distortion_coefficients: [-30.0, 500.0, 0.0, 0.0]" if x.startswith("distortion_coefficients:") else x
        for x in lines
    ]
    sensor.write_text("\n".join(lines) + "\n")


def damage_kitti_pose(root: Path) -> None:
    poses = root.parent.parent / "poses" / "00.txt"
    row = poses.read_text().splitlines()[2].split()
    set_line(poses, 3, " ".join([*row[:3], "1e308", *row[4:]]))


@pytest.mark.parametrize(
    ("layout", "damage", "named"),
    [
        ("kitti", lambda root: set_line(root / "times.txt", 12, "inf"), "times.txt:12"),
        ("tum-rgbd", lambda root: set_line(root / "rgb.txt", 4, "nan rgb/x.png"), "rgb.txt:4"),
        ("kitti", damage_p0, "calib.txt:1"),
        ("euroc", damage_distortion, "sensor.yaml"),
        ("kitti", damage_kitti_pose, "poses/00.txt:3"),
    ],
    ids=["inf-last-time", "nan-rgb-time", "nan-p0", "degenerate-distortion", "pose-1e308"],
)
def test_bad_data_never_reaches_a_method(seq, tmp_path, layout, damage, named):
    """The probe's campaigns: `inf` as the last time made the backward view all nan/inf and a good method was
    charged `no_output`; a `nan` in rgb.txt crashed the report; a nan P0 or degenerate distortion gave a nan camera
    and `not_initialized`; a 1e308 translation gave `done` with ATE = Inf. The campaign now refuses the sequence
    before any run, naming the file: nothing is written, nothing charged."""
    from slamrun.engine.campaign import run_campaign
    from slamrun.engine.spec_file import load_spec

    root = seq(layout)
    damage(root)
    spec = spec_for(root, layout, tmp_path, directions=["forward", "backward"], lanes=1)
    with pytest.raises(DatasetError, match=named):
        run_campaign(load_spec(spec), log=lambda *a: None)
    assert not (tmp_path / "results").exists()


# ------------------------------------------------------------ 3: calibration


def test_kitti_projection_that_is_not_finite_is_named_with_its_line(seq, tmp_path):
    root = seq("kitti")
    calib = root / "calib.txt"
    p0 = calib.read_text().splitlines()[0].split()
    set_line(calib, 1, " ".join(["P0:", p0[1], p0[2], "nan", *p0[4:11], "inf", p0[12]]))
    refused(root, "kitti", tmp_path, "calib.txt:1", "finite")


@pytest.mark.parametrize(
    ("key", "value"),
    [
        ("distortion_coefficients", "[-30.0, 500.0, 0.0, 0.0]"),
        ("intrinsics", "[1.0e-300, 97.2, 71.2, 68.4]"),
    ],
)
def test_euroc_calibration_that_cannot_be_rectified_is_refused(seq, tmp_path, key, value):
    """Degenerate radial-tangential coefficients, or a focal length of 1e-300: the rectified camera is not
    finite (the view was a nan camera and black frames; the method was charged not_initialized)."""
    root = seq("euroc")
    sensor = root / "mav0/cam0/sensor.yaml"
    text = sensor.read_text().splitlines()
    text = [f"{key}: {value}" if line.startswith(f"{key}:") else line for line in text]
    sensor.write_text("\n".join(text) + "\n")
    refused(root, "euroc", tmp_path, "sensor.yaml", "rectif")


def test_a_camera_whose_rectification_maps_most_of_the_view_outside_the_frame_is_refused(seq, tmp_path):
    """A principal point just right of the image: every number finite, but the cropped view would sample outside
    the frame for most of its pixels."""
    root = seq("euroc")
    sensor = root / "mav0/cam0/sensor.yaml"
    lines = sensor.read_text().splitlines()
    lines = ["intrinsics: [97.6, 97.3, 200.0, 68.4]" if x.startswith("intrinsics:") else x for x in lines]
    sensor.write_text("\n".join(lines) + "\n")
    refused(root, "euroc", tmp_path, "sensor.yaml", "outside")


# ------------------------------------------------------------ 3: ground truth


def test_kitti_ground_truth_of_an_implausible_magnitude_is_named_with_its_line(seq, tmp_path):
    """A translation of 1e308 m gave `done` with ATE = Inf."""
    root = seq("kitti")
    poses = root.parent.parent / "poses" / "00.txt"
    row = poses.read_text().splitlines()[2].split()
    row[3] = "1e308"
    set_line(poses, 3, " ".join(row))
    refused(root, "kitti", tmp_path, "poses/00.txt:3", "1e+308")


def test_euroc_ground_truth_of_an_implausible_magnitude_is_named_with_its_line(seq, tmp_path):
    root = seq("euroc")
    csv = root / "mav0/state_groundtruth_estimate0/data.csv"
    n = data_lines(csv)[6]
    cells = csv.read_text().splitlines()[n - 1].split(",")
    cells[2] = "-3e12"
    set_line(csv, n, ",".join(cells))
    refused(root, "euroc", tmp_path, f"data.csv:{n}", "-3e+12")


# ------------------------------------------------------------ 3: frames


def write_frame(path: Path, size: tuple[int, int]) -> None:
    img = (np.arange(size[0] * size[1]) % 251).astype(np.uint8).reshape(size[1], size[0])
    assert cv2.imwrite(str(path), img)


def test_a_euroc_frame_of_another_size_mid_sequence_is_named(seq, tmp_path):
    """It was silently remapped with the calibration of another size."""
    root = seq("euroc")
    frame = sorted((root / "mav0/cam0/data").iterdir())[6]
    write_frame(frame, (80, 60))
    refused(root, "euroc", tmp_path, f"data/{frame.name}", "80x60", "160x120")


def test_a_kitti_frame_of_another_size_mid_sequence_is_named(seq, tmp_path):
    """It was copied into the view as it is."""
    root = seq("kitti")
    write_frame(root / "image_0/000007.png", (200, 100))
    refused(root, "kitti", tmp_path, "image_0/000007.png", "200x100", "160x120")


def test_a_tum_mono_zip_member_of_another_size_is_named(seq, tmp_path):
    root = seq("tum-mono")
    zpath = root / "images.zip"
    with zipfile.ZipFile(zpath) as zf:
        members = {n: zf.read(n) for n in zf.namelist()}
    name = sorted(members)[5]
    members[name] = cv2.imencode(".jpg", np.zeros((60, 80), np.uint8))[1].tobytes()
    with zipfile.ZipFile(zpath, "w", zipfile.ZIP_STORED) as zf:
        for n, data in members.items():
            zf.writestr(n, data)
    refused(root, "tum-mono", tmp_path, f"images.zip: member {name}", "80x60")


def test_a_zero_byte_frame_is_named(seq, tmp_path):
    root = seq("kitti")
    (root / "image_0/000004.png").write_bytes(b"")
    refused(root, "kitti", tmp_path, "image_0/000004.png", "empty")
    root = seq("euroc")
    frame = sorted((root / "mav0/cam0/data").iterdir())[3]
    frame.write_bytes(b"")
    refused(root, "euroc", tmp_path, f"data/{frame.name}", "empty")


def test_a_frame_only_view_preparation_finds_broken_is_a_dataset_error_never_the_methods(seq, tmp_path):
    """A frame whose header is whole (validate reads headers) and whose pixels are not: KITTI's view copied it
    as it was. Now the view's preparation decodes every frame: the run is infra naming the frame, never a method's
    failure, and a good frame elsewhere is not affected."""
    from slamrun.engine.campaign import run_campaign
    from slamrun.engine.spec_file import load_spec

    root = seq("kitti")
    frame = root / "image_0/000008.png"
    data = frame.read_bytes()
    frame.write_bytes(data[:33] + bytes(len(data) - 33))  # signature and IHDR kept, the rest zeros
    spec = spec_for(root, "kitti", tmp_path, directions=["forward"], lanes=1, retries=0)
    res = run_campaign(load_spec(spec), log=lambda *a: None)
    rows = ledger_rows(res.results)
    assert rows and all(r["status"] != "done" and r["failure"] not in METHOD_FAILURES for r in rows), rows
    assert all("image_0/000008.png" in r["message"] for r in rows), [r["message"] for r in rows]
    assert all("Traceback" not in r["message"] for r in rows)


# ------------------------------------------------------------ 4: hostile files, bounded


def alias_bomb() -> str:
    """YAML anchors a0..a8 (about 1 KB) of which *a8 stands for 10^9 values."""
    levels = ["a0: &a0 [x, x, x, x, x, x, x, x, x, x]"]
    levels += [f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 10)}]" for i in range(1, 9)]
    return "\n".join(levels) + "\n"


def test_an_alias_bomb_in_euroc_sensor_yaml_is_refused_in_bounded_time_and_memory(seq, tmp_path):
    root = seq("euroc")
    sensor = root / "mav0/cam0/sensor.yaml"
    sensor.write_text(alias_bomb() + sensor.read_text().replace("camera_model: pinhole", "camera_model: *a8"))
    refused(root, "euroc", tmp_path, "sensor.yaml", "alias")


def test_an_alias_bomb_in_tum_vi_camchain_is_refused_in_bounded_time_and_memory(seq, tmp_path):
    root = seq("tum-vi")
    chain = root / "dso/camchain.yaml"
    text = chain.read_text().replace("distortion_model: equidistant", "distortion_model: *a8")
    chain.write_text(alias_bomb() + text)
    refused(root, "tum-vi", tmp_path, "camchain.yaml", "alias")


def test_deeply_nested_calibration_yaml_is_refused(seq, tmp_path):
    root = seq("euroc")
    sensor = root / "mav0/cam0/sensor.yaml"
    sensor.write_text(sensor.read_text() + "nested: " + "[" * 20_000 + "]" * 20_000 + "\n")
    refused(root, "euroc", tmp_path, "sensor.yaml", "nested too deeply")


def test_a_kitti_frame_linked_to_dev_zero_is_refused_by_validate_and_campaign(seq, tmp_path):
    """It passed validate; the campaign then read it until MemoryError."""
    root = seq("kitti")
    frame = root / "image_0/000003.png"
    frame.unlink()
    frame.symlink_to("/dev/zero")
    refused(root, "kitti", tmp_path, "image_0/000003.png", "character device")
    spec = spec_for(root, "kitti", tmp_path, directions=["forward"], lanes=1)
    out = slamrun("campaign", str(spec), timeout=120)
    said = " ".join((out.stdout + out.stderr).split())
    assert out.returncode == 1 and "image_0/000003.png" in said and "Traceback" not in said, said
    assert not (tmp_path / "results").exists()


def test_a_fifo_as_a_frame_or_beside_the_frames_never_blocks(seq, tmp_path):
    root = seq("kitti")
    frame = root / "image_0/000005.png"
    frame.unlink()
    os.mkfifo(frame)  # nobody writes it: a plain open() blocks for ever
    refused(root, "kitti", tmp_path, "image_0/000005.png", "FIFO")

    tum = seq("tum-mono")  # frames in images/, and a FIFO there that is no frame: validate and campaign end
    images = tum / "images"
    images.mkdir()
    with zipfile.ZipFile(tum / "images.zip") as zf:
        zf.extractall(images)
    (tum / "images.zip").unlink()
    os.mkfifo(images / "notes")
    (tmp_path / "t").mkdir()
    spec = spec_for(tum, "tum-mono", tmp_path / "t", directions=["forward"], lanes=1, evaluate=False)
    out = slamrun("validate", str(spec))
    assert out.returncode == 0, out.stdout + out.stderr
    out = slamrun("campaign", str(spec), timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr
    rows = ledger_rows(tmp_path / "t" / "results")
    assert [r["status"] for r in rows] == ["done"], [(r["failure"], r["message"]) for r in rows]


def test_a_sparse_2_gib_frame_is_refused_without_reading_it(seq, tmp_path):
    root = seq("kitti")
    with open(root / "image_0/000006.png", "r+b") as fh:
        fh.truncate(2 * 2**30)  # its PNG header first, then 2 GiB of holes
    refused(root, "kitti", tmp_path, "image_0/000006.png", "at most")


def zip_bomb_member(zf: zipfile.ZipFile, name: str, head: bytes, zero_blocks: int) -> None:
    """Write member `name` into `zf`: `head` and then `zero_blocks` times 64 MiB of zeros, deflated (under 2 MB
    on disk; the deflate blocks of zeros are made once and repeated, so writing it inflates nothing)."""
    import zlib

    zeros = bytes(64 * 2**20)
    c = zlib.compressobj(9, zlib.DEFLATED, -15)
    first = c.compress(head) + c.flush(zlib.Z_FULL_FLUSH)
    block = c.compress(zeros) + c.flush(zlib.Z_FULL_FLUSH)  # the dictionary is reset: each block is the same
    raw = first + block * zero_blocks + c.flush()
    crc = zlib.crc32(head)
    for _ in range(zero_blocks):
        crc = zlib.crc32(zeros, crc)
    info = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))
    info.compress_type = zipfile.ZIP_DEFLATED
    info.file_size, info.compress_size, info.CRC = len(head) + zero_blocks * len(zeros), len(raw), crc
    info.header_offset = zf.fp.tell()
    zf.fp.write(info.FileHeader(zip64=False))
    zf.fp.write(raw)
    zf.filelist.append(info)
    zf.NameToInfo[name] = info
    zf.start_dir = zf.fp.tell()


def test_a_zip_member_beyond_the_frame_cap_is_refused_without_inflating_it(seq, tmp_path):
    """A TUM-Mono images.zip whose first member inflates to 1.5 GiB (its JPEG, then zeros)."""
    root = seq("tum-mono")
    zpath = root / "images.zip"
    with zipfile.ZipFile(zpath) as zf:
        members = {n: zf.read(n) for n in zf.namelist()}
    first = sorted(members)[0]
    with zipfile.ZipFile(zpath, "w") as zf:
        zip_bomb_member(zf, first, members[first], 24)
        for n in sorted(members)[1:]:
            zf.writestr(n, members[n])
    with zipfile.ZipFile(zpath) as zf:
        assert zf.getinfo(first).file_size > 1.5 * 2**30 and zpath.stat().st_size < 4 * 2**20
    refused(root, "tum-mono", tmp_path, f"images.zip: member {first}", "at most")


# ------------------------------------------------------------ 7: EuRoC stamps


@pytest.mark.parametrize(
    ("stamp", "why"),
    [
        ("9223372036854775808", "2^63"),  # one above int64
        ("١٤٠٣٦٣٦٥٧٩٧٦٣٥٥٥٥٨٤", "ASCII digits"),  # Arabic-Indic digits: str.isdigit() takes them
        ("¹⁴⁰³", "ASCII digits"),  # superscripts: isdigit() again, int() refuses
    ],
)
def test_euroc_stamps_beyond_int64_or_in_other_digits_are_named_with_their_line(seq, tmp_path, stamp, why):
    root = seq("euroc")
    csv = root / "mav0/cam0/data.csv"
    n = data_lines(csv)[5]
    name = csv.read_text().splitlines()[n - 1].split(",")[1]
    set_line(csv, n, f"{stamp},{name}")
    refused(root, "euroc", tmp_path, f"data.csv:{n}", why)


@pytest.mark.parametrize(("stamp", "why"), [("9223372036854775808", "2^63"), ("١٤٠٣٦٣٦٥٧٩٧٦٣٥٥٥٥٨٤", "ASCII digits")])
def test_euroc_ground_truth_stamps_beyond_int64_or_in_other_digits_are_named_with_their_line(seq, tmp_path, stamp, why):
    root = seq("euroc")
    csv = root / "mav0/state_groundtruth_estimate0/data.csv"
    n = data_lines(csv)[-1]
    cells = csv.read_text().splitlines()[n - 1].split(",")
    set_line(csv, n, ",".join([stamp, *cells[1:]]))
    refused(root, "euroc", tmp_path, f"data.csv:{n}", why)

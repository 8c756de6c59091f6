"""Import and download bounded on hostile input, and imports that never half-happen (issue 37, items 4 and 5).

Every hostile archive is a real zip (or .tgz) written to tmp_path: members of gigabytes of zeros are deflated once
per MiB and repeated (a full flush makes every MiB's bytes the same), their CRC computed by the CRC register's
zero-byte operator, so a 3 GiB member costs a 3 MB file and milliseconds. Each hostile input is given to the real
`slamrun` CLI in a subprocess whose address space is limited, and must end within seconds with one line naming
the file or address, with nothing written or imported. Servers listen on 127.0.0.1 only.
"""

from __future__ import annotations

import http.server
import io
import os
import struct
import subprocess
import sys
import tarfile
import threading
import time
import zipfile
import zlib
from pathlib import Path

import pandas as pd
import pytest

from slamrun.cli import main
from tests.conftest import loopback_server
from tests.test_import import campaign, rows_of, split_archives  # noqa: F401 - the module's campaign fixture

MiB = 2**20
GiB = 2**30
M32 = 0xFFFFFFFF
ADDRESS_SPACE = 2 * GiB  # the CLI with numpy and pandas loaded needs well under this; a 3 GiB member cannot fit


# ------------------------------------------------------------------ real archives of any size, in milliseconds


def _zero_mib_operator() -> list[int]:
    """The CRC-32 register's map for one MiB of zero bytes (linear over GF(2)): its images of the 32 unit bits."""
    return [~zlib.crc32(bytes(MiB), ~(1 << i) & M32) & M32 for i in range(32)]


def zeros_crc(n: int, crc: int = 0) -> int:
    """zlib.crc32(bytes(n), crc), without making n bytes."""
    cols, reg = _zero_mib_operator(), ~crc & M32
    for _ in range(n // MiB):
        reg = _apply(cols, reg)
    return zlib.crc32(bytes(n % MiB), ~reg & M32)


def _apply(cols: list[int], reg: int) -> int:
    out = 0
    for i in range(32):
        if reg >> i & 1:
            out ^= cols[i]
    return out


def deflated_zeros(n: int, head: bytes = b"") -> bytes:
    """A raw deflate stream of `head` then n zero bytes."""
    co = zlib.compressobj(9, zlib.DEFLATED, -15)
    first = co.compress(head) + co.flush(zlib.Z_FULL_FLUSH) if head else b""
    mib = co.compress(bytes(MiB)) + co.flush(zlib.Z_FULL_FLUSH)  # the same bytes for every MiB after a full flush
    last = zlib.compressobj(9, zlib.DEFLATED, -15)
    return first + mib * (n // MiB) + last.compress(bytes(n % MiB)) + last.flush()


def zip_of(path: Path, members: list[tuple[str, bytes | int]], declared: dict[str, int] | None = None) -> Path:
    """A zip of deflated members: bytes, or an int for that many zero bytes; `declared` overrides a member's
    stated size (a zip that lies). Sizes below 4 GiB (no zip64)."""
    local, central = io.BytesIO(), io.BytesIO()
    for name, content in members:
        if isinstance(content, int):
            size, crc, data = content, zeros_crc(content), deflated_zeros(content)
        else:
            size, crc, data = len(content), zlib.crc32(content), deflated_zeros(0, content)
        size = (declared or {}).get(name, size)
        raw = name.encode()
        offset = local.tell()
        local.write(struct.pack("<4s5H3L2H", b"PK\x03\x04", 20, 0, 8, 0, 33, crc, len(data), size, len(raw), 0))
        local.write(raw + data)
        fields = (b"PK\x01\x02", 20, 20, 0, 8, 0, 33, crc, len(data), size, len(raw), 0, 0, 0, 0, 0, offset)
        central.write(struct.pack("<4s6H3L5H2L", *fields) + raw)
    cd = central.getvalue()
    n = len(members)
    path.write_bytes(
        local.getvalue() + cd + struct.pack("<4s4H2LH", b"PK\x05\x06", 0, 0, n, n, len(cd), local.tell(), 0)
    )
    return path


def tgz_of_zeros(path: Path, name: str, size: int) -> Path:
    """A real .tgz holding one member `name` of `size` zero bytes (a tar bomb when gzipped)."""
    info = tarfile.TarInfo(name)
    info.size = size
    header = info.tobuf(format=tarfile.GNU_FORMAT)
    body = size + (-size % 512) + 1024  # the data, its padding, the two end blocks: all zeros
    crc = zeros_crc(body, zlib.crc32(header))
    gz = b"\x1f\x8b\x08\x00\x00\x00\x00\x00\x02\xff" + deflated_zeros(body, header)
    path.write_bytes(gz + struct.pack("<2L", crc, (len(header) + body) & M32))
    return path


def test_the_archives_written_here_are_real(tmp_path):
    """The builders above against zipfile and tarfile themselves (small sizes)."""
    z = zip_of(tmp_path / "a.zip", [("a/x.txt", b"1 2 3\n"), ("a/zeros", 3 * MiB + 7)])
    with zipfile.ZipFile(z) as zf:
        assert zf.testzip() is None
        assert zf.read("a/x.txt") == b"1 2 3\n" and zf.read("a/zeros") == bytes(3 * MiB + 7)
    t = tgz_of_zeros(tmp_path / "b.tgz", "b/zeros", MiB + 3)
    with tarfile.open(t) as tar:
        (member,) = tar.getmembers()
        assert member.name == "b/zeros" and tar.extractfile(member).read() == bytes(MiB + 3)


# ------------------------------------------------------------------ the real CLI, in a limited address space

LIMITED = """
import resource, sys
resource.setrlimit(resource.RLIMIT_AS, (int(sys.argv[1]), resource.RLIM_INFINITY))
from slamrun.cli import main
sys.exit(main(sys.argv[2:]))
"""


def slamrun_limited(args: list[str], timeout: float = 60, **env: str) -> subprocess.CompletedProcess:
    """`slamrun ARGS` in a process of at most ADDRESS_SPACE bytes; fails the test if it runs past `timeout`."""
    t0 = time.monotonic()
    out = subprocess.run(
        [sys.executable, "-c", LIMITED, str(ADDRESS_SPACE), *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env={**os.environ, **env},
    )
    out.seconds = time.monotonic() - t0
    return out


def refused(out: subprocess.CompletedProcess, *names: str) -> str:
    """The one error line of a refused command (exit 1, no traceback), naming each of `names`."""
    assert out.returncode == 1, (out.returncode, out.stdout[-2000:], out.stderr[-4000:])
    assert "Traceback" not in out.stderr and "Error:" not in out.stderr.replace("slamrun: error:", ""), out.stderr
    assert out.stderr.startswith("slamrun: error: "), out.stderr
    for name in names:
        assert name in out.stderr, (name, out.stderr)
    return out.stderr


def nothing_imported(results: Path, label: str) -> None:
    assert [r for r in rows_of(results, label) if r["method_name"] == "imported"] == []
    assert not list((results / "runs").glob(f"{label}@imported-*")), list((results / "runs").glob(f"{label}@*"))
    assert not [p for p in results.iterdir() if p.name.startswith(".import")]


# ------------------------------------------------------------------ 4: import bounded


def test_an_import_of_a_zip_with_a_3_gib_member_ends_at_once_naming_it(campaign, shared_data, tmp_path):  # noqa: F811
    """The probe's 3 MB zip holding a 3 GiB member (was: inflated in memory, MemoryError traceback); a zip
    whose declared size lies; and members each small enough whose total is too much: each refused in seconds."""
    study = shared_data / "study_trajectories"
    good = (study / "dso_bw__sequence_48_0.txt").read_bytes()
    bomb = zip_of(tmp_path / "dso_bw.zip", [("dso_bw/sequence_48_0.txt", good), ("dso_bw/sequence_48_1.txt", 3 * GiB)])
    assert bomb.stat().st_size < 4 * MiB
    out = slamrun_limited(["import", str(bomb), "--campaign", str(campaign), "--as", "study:bomb"])
    err = refused(out, f"{bomb}:dso_bw/sequence_48_1.txt", "3,221,225,472 bytes")
    assert out.seconds < 30, out.seconds
    nothing_imported(campaign, "study:bomb")

    # a member that states 200 bytes and holds 512 MiB: never more than the stated size is inflated
    liar = zip_of(tmp_path / "liar.zip", [("dso_bw/sequence_48_0.txt", 512 * MiB)], {"dso_bw/sequence_48_0.txt": 200})
    out = slamrun_limited(["import", str(liar), "--campaign", str(campaign), "--as", "study:bomb"])
    refused(out, f"{liar}:dso_bw/sequence_48_0.txt")
    assert out.seconds < 30, out.seconds
    nothing_imported(campaign, "study:bomb")

    # forty members of 60 MiB each (2.3 GiB in all), each under the bound of one file
    many = zip_of(tmp_path / "many.zip", [(f"dso_bw/sequence_48_{i}.txt", 60 * MiB) for i in range(40)])
    out = slamrun_limited(["import", str(many), "--campaign", str(campaign), "--as", "study:bomb"])
    err = refused(out, str(many), "2,516,582,400 bytes")
    assert "in all" in err and out.seconds < 30, (err, out.seconds)
    nothing_imported(campaign, "study:bomb")


# ------------------------------------------------------------------ 4: download bounded


def test_a_downloaded_zip_bomb_is_refused_before_it_is_unpacked(tmp_path):
    """A 1 GiB zip bomb as a TUM-Mono sequence (was: unpacked whole), and a 1 GiB .tgz bomb as a TUM RGB-D
    one: refused at once, the archive deleted, nothing unpacked."""
    bomb = zip_of(
        tmp_path / "sequence_03.zip",
        [("sequence_03/times.txt", b"00000 0.0 0.03\n"), ("sequence_03/images.zip", GiB)],
    )
    tgz = tgz_of_zeros(tmp_path / "rgbd_dataset_freiburg1_xyz.tgz", "rgbd_dataset_freiburg1_xyz/rgb.txt", GiB)
    routes = {"/mono/sequence_03.zip": bomb, "/rgbd/freiburg1/rgbd_dataset_freiburg1_xyz.tgz": tgz}
    with loopback_server(routes) as (base, _):
        dest = tmp_path / "mono"
        out = slamrun_limited(
            ["dataset", "download", "tum-mono", str(dest), "--sequences", "3", "--url", f"{base}/mono"]
        )
        err = refused(out, str(dest / "sequence_03.zip"), "1,073,741,839 bytes")
        assert "zip bomb" in err and out.seconds < 30, (err, out.seconds)
        assert list(dest.iterdir()) == []
        dest = tmp_path / "rgbd"
        args = ["dataset", "download", "tum-rgbd", str(dest), "--sequences", "freiburg1_xyz", "--url", f"{base}/rgbd"]
        out = slamrun_limited(args)
        err = refused(out, str(dest / "rgbd_dataset_freiburg1_xyz.tgz"), "1,073,741,824 bytes")
        assert out.seconds < 30, out.seconds
        assert list(dest.iterdir()) == []


class SlowServer:
    """A server on 127.0.0.1 that misbehaves as `mode` says, then serves `data` honestly (with Range) once
    `mode` is set to "good"; records the Range headers asked for."""

    def __init__(self, data: bytes):
        self.data, self.mode, self.ranges = data, "good", []
        self.release = threading.Event()
        outer = self

        class Handler(http.server.BaseHTTPRequestHandler):
            protocol_version = "HTTP/1.1"

            def do_GET(self):  # noqa: N802
                outer.ranges.append(self.headers.get("Range"))
                try:
                    getattr(outer, outer.mode.replace("-", "_"))(self)
                except OSError:  # the client went away
                    pass

            def log_message(self, *a):
                pass

        self.httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.httpd.server_address[1]}/mono"
        threading.Thread(target=self.httpd.serve_forever, daemon=True).start()

    def good(self, h) -> None:
        rng = h.headers.get("Range")
        start = int(rng.split("=")[1].split("-")[0]) if rng else 0
        h.send_response(206 if rng else 200)
        h.send_header("Content-Length", str(len(self.data) - start))
        h.end_headers()
        h.wfile.write(self.data[start:])

    def drip(self, h) -> None:
        """Headers, then one byte every 0.2 s (the probe's: one every 20 s)."""
        h.send_response(200)
        h.send_header("Content-Length", str(len(self.data)))
        h.end_headers()
        for i in range(len(self.data)):
            if self.release.wait(0.2):
                return
            h.wfile.write(self.data[i : i + 1])
            h.wfile.flush()

    def stall_after_headers(self, h) -> None:
        h.send_response(200)
        h.send_header("Content-Length", str(len(self.data)))
        h.end_headers()
        h.wfile.flush()
        self.release.wait(60)

    def drip_headers(self, h) -> None:
        """The status line, then a header one byte every 0.2 s: never a whole response."""
        h.wfile.write(b"HTTP/1.1 200 OK\r\n")
        for _ in range(300):
            if self.release.wait(0.2):
                return
            h.wfile.write(b"X")
            h.wfile.flush()

    def close(self) -> None:
        self.release.set()
        self.httpd.shutdown()
        self.httpd.server_close()


@pytest.mark.parametrize("mode", ["drip", "stall-after-headers", "drip-headers"])
def test_a_server_that_stalls_is_left_within_seconds_and_the_download_resumes(tmp_path, tiny_dataset, mode):
    """A server that sends a byte now and then, one that stops after its headers, one that never finishes
    its headers (was: waited for ever, or a TimeoutError traceback): with SLAMRUN_DOWNLOAD_STALL_S=1 each ends
    within seconds naming the address and saying to run the command again, which resumes the part kept."""
    from tests.test_download import sequence_zip

    data = sequence_zip(tiny_dataset / "seq_a", "sequence_03")
    server = SlowServer(data)
    server.mode = mode
    try:
        args = ["dataset", "download", "tum-mono", str(tmp_path), "--sequences", "3", "--url", server.url]
        out = slamrun_limited(args, timeout=30, SLAMRUN_DOWNLOAD_STALL_S="1")
        err = refused(out, f"{server.url}/sequence_03.zip", "run the same command again")
        assert out.seconds < 15, out.seconds
        assert not (tmp_path / "sequence_03").exists()
        part = tmp_path / "sequence_03.zip.part"
        have = part.stat().st_size if part.exists() else 0
        if mode == "drip":
            assert have > 0 and "stalled" in err, err
        server.mode = "good"
        assert main(args) == 0
        assert (tmp_path / "sequence_03" / "times.txt").is_file() and not part.exists()
        assert server.ranges[-1] == (f"bytes={have}-" if have else None)
    finally:
        server.close()


# ------------------------------------------------------------------ 5: import integrity


def test_two_files_for_one_run_are_refused_naming_both_before_anything_is_written(
    campaign,  # noqa: F811
    shared_data,
    tmp_path,
    capsys,
):
    """`sequence_48_0` and `sequence_048_0` name one run, as does one member twice in a zip (was: a
    FileNotFoundError traceback after the ledger row was committed, the second file's poses kept)."""
    study = shared_data / "study_trajectories"
    real = (study / "dso_bw__sequence_48_0.txt").read_bytes()
    other = b"".join(real.splitlines(keepends=True)[:-5])
    folder = tmp_path / "db"
    folder.mkdir()
    (folder / "dso_bw__sequence_48_0.txt").write_bytes(real)
    (folder / "dso_bw__sequence_048_0.txt").write_bytes(other)
    (folder / "dso_bw__sequence_48_1.txt").write_bytes((study / "dso_bw__sequence_48_1.txt").read_bytes())
    before = (campaign / "results.csv").read_bytes()
    assert main(["import", str(folder), "--campaign", str(campaign), "--as", "study:twice"]) == 1
    err = capsys.readouterr().err
    assert "dso_bw__sequence_48_0.txt" in err and "dso_bw__sequence_048_0.txt" in err, err
    assert "sequence_48 backward trial 0" in err, err
    nothing_imported(campaign, "study:twice")
    assert (campaign / "results.csv").read_bytes() == before

    twice = tmp_path / "twice.zip"
    with zipfile.ZipFile(twice, "w") as zf, pytest.warns(UserWarning, match="Duplicate name"):
        zf.writestr("dso_bw/sequence_48_0.txt", real)
        zf.writestr("dso_bw/sequence_48_0.txt", other)
    assert main(["import", str(twice), "--campaign", str(campaign), "--as", "study:twice"]) == 1
    err = capsys.readouterr().err
    assert err.count(f"{twice}:dso_bw/sequence_48_0.txt") == 2, err
    nothing_imported(campaign, "study:twice")

    # without the duplicate the same folder imports, and again says unchanged
    (folder / "dso_bw__sequence_048_0.txt").unlink()
    assert main(["import", str(folder), "--campaign", str(campaign), "--as", "study:twice"]) == 0
    assert main(["import", str(folder), "--campaign", str(campaign), "--as", "study:twice"]) == 0
    assert "0 run(s) imported, 2 unchanged" in capsys.readouterr().out


def test_an_import_refreshes_the_results_tables_and_says_how_to_refresh_the_report(campaign, shared_data, capsys):  # noqa: F811
    """results.csv and results.parquet hold the imported runs; one line says to run `slamrun report` (was: not a
    word); the label is printed as written (`study:x:` was rich's emoji ❌)."""
    study = shared_data / "study_trajectories"
    first = split_archives(study, Path(str(campaign) + "-db"), "dyna", "fw")
    assert main(["import", str(first), "--campaign", str(campaign), "--as", "study:x"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("study:x: 3 run(s) imported"), out
    assert f"run `slamrun report {campaign}`" in out, out
    assert (pd.read_csv(campaign / "results.csv").method == "study:x").sum() == 3
    assert (pd.read_parquet(campaign / "results.parquet").method == "study:x").sum() == 3


def test_a_folder_of_the_studys_split_archives_as_its_repository_is_cloned_is_a_source(
    campaign,  # noqa: F811
    shared_data,
    tmp_path,
):
    """The study's repository as cloned: `<code>_<dir>.zip.001`, `.002`, ... beside a README and a .git
    folder (was: "file(s) whose name does not match")."""
    study = shared_data / "study_trajectories"
    clone = tmp_path / "clone"
    split_archives(study, clone, "dsm", "bw")
    split_archives(study, clone, "cnn-svo", "fw")
    (clone / "README.md").write_text("# The study's database\n")
    (clone / ".git" / "objects" / "ab").mkdir(parents=True)
    (clone / ".git" / "objects" / "ab" / "cdef").write_bytes(b"x")
    (clone / ".git" / "HEAD").write_text("ref: refs/heads/main\n")
    assert main(["import", str(clone), "--campaign", str(campaign), "--as", "study:clone"]) == 0
    runs = rows_of(campaign, "study:clone")
    assert sorted((r["sequence"], r["direction"], r["trial"]) for r in runs) == [
        ("sequence_47", "backward", 6),
        ("sequence_47", "backward", 7),
        ("sequence_47", "backward", 8),
        ("sequence_48", "forward", 7),
        ("sequence_48", "forward", 8),
        ("sequence_48", "forward", 9),
    ]
    sources = {json_source(r) for r in runs}
    assert f"{clone / 'dsm_bw.zip.001'}:dsm_bw/sequence_47_6.txt" in sources, sources


def json_source(row: dict) -> str:
    import json

    return json.loads((Path(row["run_dir"]) / "run.json").read_text())["imported"]["source"]


def test_imported_labels_never_meet_a_method_the_spec_runs(campaign, shared_data, tmp_path, capsys):  # noqa: F811
    """An imported label is SOURCE:NAME and a spec's label holds no ':', so an import and a spec never pool
    their runs in one row (was: `--as reference_vo` accepted, a spec label `study:dso` accepted)."""
    from slamrun.engine.spec_file import validate_spec
    from slamrun.errors import SpecError

    study = shared_data / "study_trajectories"
    files = tmp_path / "files"
    files.mkdir()
    (files / "dso_bw__sequence_48_0.txt").write_bytes((study / "dso_bw__sequence_48_0.txt").read_bytes())
    for label in ("reference_vo", "dso", ":dso", "study:"):
        assert main(["import", str(files), "--campaign", str(campaign), "--as", label]) == 1
        err = capsys.readouterr().err
        assert f"--as {label!r}" in err and "SOURCE:NAME" in err, err
        nothing_imported(campaign, label)
    raw = {
        "name": "x",
        "datasets": [{"name": "d", "path": str(tmp_path), "sequences": ["s"]}],
        "methods": [{"name": "reference_vo", "label": "study:dso"}],
    }
    with pytest.raises(SpecError, match=r"methods\[0\]\.label: 'study:dso' holds ':'"):
        validate_spec(raw, tmp_path, check_files=False)

"""Downloading against a local HTTP server on 127.0.0.1 that serves a small fake sequence, with Range support."""

from __future__ import annotations

import http.server
import io
import threading
import zipfile

import pytest

from slamrun.cli import main
from slamrun.datasets.download import fetch
from slamrun.datasets.tum_mono import open_sequence, parse_sequences
from slamrun.errors import DatasetError


class Server:
    """Serves files from a dict on 127.0.0.1, honouring Range; records the requests."""

    def __init__(self, files: dict[str, bytes]):
        self.files = files
        self.requests: list[tuple[str, str | None]] = []
        outer = self

        class Handler(http.server.BaseHTTPRequestHandler):
            def do_GET(self):  # noqa: N802
                rng = self.headers.get("Range")
                outer.requests.append((self.path, rng))
                data = outer.files.get(self.path.rsplit("/", 1)[-1])
                if data is None:
                    self.send_error(404)
                    return
                start = int(rng.split("=")[1].split("-")[0]) if rng else 0
                if start >= len(data):
                    self.send_error(416)
                    return
                self.send_response(206 if rng else 200)
                self.send_header("Content-Length", str(len(data) - start))
                self.end_headers()
                self.wfile.write(data[start:])

            def log_message(self, *a):
                pass

        self.httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.httpd.server_address[1]}/mono"
        threading.Thread(target=self.httpd.serve_forever, daemon=True).start()

    def close(self):
        self.httpd.shutdown()
        self.httpd.server_close()


def sequence_zip(folder, name: str) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        for f in folder.iterdir():
            zf.write(f, f"{name}/{f.name}")
    return buf.getvalue()


@pytest.fixture
def server(tiny_dataset):
    s = Server({"sequence_03.zip": sequence_zip(tiny_dataset / "seq_a", "sequence_03")})
    yield s
    s.close()


def test_download_unpacks_a_valid_sequence(tmp_path, server):
    assert main(["dataset", "download", "tum-mono", str(tmp_path), "--sequences", "3", "--url", server.url]) == 0
    seq = open_sequence(tmp_path / "sequence_03")
    assert seq.n_frames == 40
    assert not list(tmp_path.glob("*.zip")) and not list(tmp_path.glob(".*"))
    # present sequences are not fetched again
    n = len(server.requests)
    assert main(["dataset", "download", "tum-mono", str(tmp_path), "--sequences", "3", "--url", server.url]) == 0
    assert len(server.requests) == n


def test_download_resumes_a_partial_file(tmp_path, server):
    data = server.files["sequence_03.zip"]
    (tmp_path / "sequence_03.zip.part").write_bytes(data[:1000])
    fetch(f"{server.url}/sequence_03.zip", tmp_path / "sequence_03.zip")
    assert server.requests[-1][1] == "bytes=1000-"
    assert (tmp_path / "sequence_03.zip").read_bytes() == data


def test_download_errors_are_clear(tmp_path, server, capsys):
    assert main(["dataset", "download", "tum-mono", str(tmp_path), "--sequences", "4", "--url", server.url]) == 1
    assert "HTTP 404" in capsys.readouterr().err
    with pytest.raises(DatasetError, match="1 to 50"):
        parse_sequences("0-3")
    assert parse_sequences("1-3,7") == [1, 2, 3, 7]


# ---------------------------------------------------------------- EuRoC, TUM RGB-D, TUM-VI as their sites serve them


def archive_of(folder, kind: str, top: str | None) -> bytes:
    """A zip (members under `top/`, or at the top as EuRoC's), .tgz or .tar of a sequence folder."""
    import tarfile

    buf = io.BytesIO()
    files = sorted(p for p in folder.rglob("*") if p.is_file())
    prefix = f"{top}/" if top else ""
    if kind == "zip":
        with zipfile.ZipFile(buf, "w") as zf:
            for f in files:
                zf.write(f, prefix + str(f.relative_to(folder)))
    else:
        with tarfile.open(fileobj=buf, mode="w:gz" if kind == "tgz" else "w") as tar:
            for f in files:
                tar.add(f, prefix + str(f.relative_to(folder)))
    return buf.getvalue()


@pytest.fixture(scope="module")
def published(tmp_path_factory):
    """Synthetic EuRoC, TUM RGB-D and TUM-VI sequences packed as each dataset's site serves them."""
    from slamrun.datasets.make_synthetic import generate

    root = tmp_path_factory.mktemp("published")
    euroc = generate(root / "MH_01_easy", frames=30, seed=1, size=(160, 120), layout="euroc")
    rgbd = generate(root / "rgbd_dataset_freiburg1_xyz", frames=30, seed=2, layout="tum-rgbd")
    vi = generate(root / "dataset-room1_512_16", frames=30, seed=3, size=(128, 128), layout="tum-vi")
    files = {
        "MH_01_easy.zip": archive_of(euroc, "zip", None),
        "rgbd_dataset_freiburg1_xyz.tgz": archive_of(rgbd, "tgz", rgbd.name),
        "dataset-room1_512_16.tar": archive_of(vi, "tar", vi.name),
    }
    s = Server(files)
    yield s
    s.close()


@pytest.mark.parametrize(
    ("dataset", "sequence", "folder", "path"),
    [
        ("euroc", "MH_01_easy", "MH_01_easy", "/machine_hall/MH_01_easy/MH_01_easy.zip"),
        ("tum-rgbd", "freiburg1_xyz", "rgbd_dataset_freiburg1_xyz", "/freiburg1/rgbd_dataset_freiburg1_xyz.tgz"),
        ("tum-vi", "room1", "dataset-room1_512_16", "/dataset-room1_512_16.tar"),
    ],
)
def test_download_of_each_dataset_unpacks_a_sequence_of_its_layout(
    tmp_path, published, dataset, sequence, folder, path
):
    from slamrun.datasets.layouts import open_sequence as open_any

    args = ["dataset", "download", dataset, str(tmp_path), "--sequences", sequence, "--url", published.url]
    assert main(args) == 0
    assert published.requests[-1][0] == "/mono" + path  # the dataset's own folder structure under the base
    seq = open_any(tmp_path / folder)
    assert seq.layout == dataset and seq.n_frames == 30
    assert sorted(p.name for p in tmp_path.iterdir()) == [folder]  # no archive, no temporary folder left
    n = len(published.requests)
    assert main(args) == 0 and len(published.requests) == n  # present: not fetched again


def test_download_refuses_what_is_not_the_dataset(tmp_path, published, capsys):
    published.files["V1_01_easy.zip"] = published.files["rgbd_dataset_freiburg1_xyz.tgz"]
    assert (
        main(["dataset", "download", "euroc", str(tmp_path), "--sequences", "V1_01_easy", "--url", published.url]) == 1
    )
    assert "not a zip file" in capsys.readouterr().err
    published.files["dataset-room2_512_16.tar"] = published.files["MH_01_easy.zip"]
    assert main(["dataset", "download", "tum-vi", str(tmp_path), "--sequences", "room2", "--url", published.url]) == 1
    assert "not a readable archive" in capsys.readouterr().err
    published.files["dataset-room3_512_16.tar"] = published.files["rgbd_dataset_freiburg1_xyz.tgz"]
    assert main(["dataset", "download", "tum-vi", str(tmp_path), "--sequences", "room3", "--url", published.url]) == 1
    assert "holds no tum-vi sequence dataset-room3_512_16" in capsys.readouterr().err
    assert main(["dataset", "download", "tum-rgbd", str(tmp_path), "--sequences", "kinect_xyz"]) == 1
    assert "not tum-rgbd sequences" in capsys.readouterr().err
    assert main(["dataset", "download", "kitti", str(tmp_path)]) == 1
    assert "cvlibs.net" in capsys.readouterr().err
    assert not list(tmp_path.iterdir())  # nothing unpacked, no wrong archive kept to be reused

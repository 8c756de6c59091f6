"""Downloading against a local HTTP server on 127.0.0.1 that serves a small fake sequence, with Range support."""

from __future__ import annotations

import http.server
import io
import threading
import zipfile

import pytest

from runner.cli import main
from runner.datasets.download import fetch, parse_sequences
from runner.datasets.tum_mono import open_sequence
from runner.errors import DatasetError


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

"""Shared fixtures: a tiny synthetic sequence and spec builders around the fake method."""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from slamrun.datasets.make_synthetic import generate

FAKE = Path(__file__).parent / "fixtures" / "fake_method.py"
# shared/ lies beside the repository (CI clones main next to it); SLAMRUN_SHARED points elsewhere.
SHARED = Path(os.environ.get("SLAMRUN_SHARED", Path(__file__).resolve().parents[2] / "shared"))
SHARED_DATA = SHARED / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    if not SHARED_DATA.is_dir():
        pytest.skip(reason=f"{SHARED_DATA} not found: the real trajectory files live in shared/data beside the repo")
    return SHARED_DATA


@pytest.fixture(scope="session")
def tiny_dataset(tmp_path_factory) -> Path:
    """A dataset folder with two tiny synthetic sequences (40 frames, 160x120)."""
    root = tmp_path_factory.mktemp("data")
    generate(root / "seq_a", frames=40, seed=1, size=(160, 120))
    generate(root / "seq_b", frames=40, seed=2, size=(160, 120))
    return root


def fake_method(
    mode: str = "ok", sleep: float = 0.0, label: str | None = None, extra: list[str] | None = None, **kw
) -> dict:
    argv = [
        sys.executable,
        str(FAKE),
        "--times",
        "{times}",
        "--out",
        "{out}",
        "--view",
        "{view}",
        "--mode",
        mode,
        "--sleep",
        str(sleep),
        *(extra or []),
    ]
    m = {"name": "external", "params": {"argv": argv, **kw}}
    if label:
        m["label"] = label
    return m


def one_sequence(dataset: Path, sequence: str = "seq_a") -> list[dict]:
    """The `datasets` entry of a spec that runs a single sequence."""
    return [{"name": "s", "path": str(dataset), "sequences": [sequence]}]


def write_spec(tmp_path: Path, dataset: Path, methods: list[dict], **kw) -> Path:
    spec = {
        "name": "t",
        "results": str(tmp_path / "results"),
        "cache": str(tmp_path / "cache"),
        "datasets": [{"name": "synth", "path": str(dataset), "sequences": ["seq_a", "seq_b"]}],
        "methods": methods,
        "trials": 1,
        "timeout_s": 60,
        "lanes": 2,
        "retry_backoff_s": 0.01,
        "stop_grace_s": 5,
        "report": False,
    }
    spec.update(kw)
    path = tmp_path / "spec.yaml"
    path.write_text(yaml.safe_dump(spec))
    return path


UPSTREAM = SHARED / "upstream"


def require_upstream(path: Path = UPSTREAM) -> Path:
    """`path` (shared/upstream or an archive in it), or a skip saying why and how to provide it."""
    if not path.exists():
        why = f"{path} not found: these tests use the real upstream archives of shared/upstream, beside the repository"
        pytest.skip(reason=f"{why} (SLAMRUN_SHARED names another shared/ folder)")
    return path


def unpack_upstream(name: str, dest: Path) -> Path:
    """The real upstream tree of source `name` (slamrun/images/sources.py), unpacked from shared/upstream into `dest`;
    skips when shared/upstream is absent."""
    import tarfile

    from slamrun.images.sources import SOURCES

    archive = require_upstream(UPSTREAM / SOURCES[name].filename)
    with tarfile.open(archive, "r:gz") as tar:
        tar.extractall(dest, filter="data")
    return dest / SOURCES[name].top


@contextlib.contextmanager
def loopback_server(routes: dict[str, Path | bytes]):
    """An HTTP server on 127.0.0.1 serving `routes` (path -> file or bytes; other paths: 404). Yields its base
    address and the list of paths requested."""
    import http.server
    import threading

    hits: list[str] = []

    class Handler(http.server.BaseHTTPRequestHandler):
        def do_GET(self):  # noqa: N802
            hits.append(self.path)
            body = routes.get(self.path)
            if body is None:
                self.send_error(404)
                return
            data = body.read_bytes() if isinstance(body, Path) else body
            self.send_response(200)
            self.send_header("Content-Length", str(len(data)))
            self.end_headers()
            self.wfile.write(data)

        def log_message(self, *a):
            pass

    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    threading.Thread(target=httpd.serve_forever, daemon=True).start()
    try:
        yield f"http://127.0.0.1:{httpd.server_address[1]}", hits
    finally:
        httpd.shutdown()
        httpd.server_close()


def mount_tmpfs(mount: Path, size_mb: int, why: str) -> Path:
    """Mount a tmpfs of `size_mb` at `mount` (made); skips the test where mounting is not allowed (not root),
    fails it under CI (root there: the test must run). Unmount with `umount -l`."""
    mount.mkdir()
    cmd = ["mount", "-t", "tmpfs", "-o", f"size={size_mb}m", "tmpfs", str(mount)]
    if os.geteuid() != 0 or subprocess.run(cmd).returncode:
        if os.environ.get("CI"):
            pytest.fail(f"CI runs as root and must be able to mount a tmpfs ({why})")
        pytest.skip(reason=f"mounting a tmpfs ({why}) needs root")
    return mount


def recipe(name: str) -> Path:
    """The image recipe folder of method `name` (slamrun/methods/<name>/image), or a shared recipe part's
    (slamrun/methods/recipes/<name>: common, monodepth)."""
    methods = Path(__file__).resolve().parents[1] / "slamrun" / "methods"
    own = methods / name / "image"
    return own if own.is_dir() else methods / "recipes" / name

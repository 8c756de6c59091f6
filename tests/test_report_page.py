"""The report as a reader sees it: a real campaign over a synthetic EuRoC and a synthetic KITTI dataset (`slamrun
synth --layout`), the fake method at two noise levels and a third label planned for one forward trial only, its
report written by `slamrun report`, then opened in headless Chromium at 1400 px and inspected through the DevTools
protocol: the page does not overflow sideways, every image decodes, the interactive views draw from local files
only (a dead proxy stands in for the network), every table and figure file is linked, the provenance is on it."""

from __future__ import annotations

import base64
import contextlib
import html
import json
import os
import re
import signal
import socket
import struct
import subprocess
import sys
import time
import urllib.parse
import urllib.request
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd
import pytest

from tests.conftest import fake_method, write_spec
from tests.test_report import CHROMIUM_FLAGS, chromium_or_skip

SLAMRUN = [sys.executable, "-m", "slamrun.cli"]
WIDTH = 1400


def slamrun(*args) -> subprocess.CompletedProcess:
    return subprocess.run([*SLAMRUN, *map(str, args)], capture_output=True, text=True, timeout=600)


@dataclass(frozen=True)
class Report:
    results: Path
    index: Path
    df: pd.DataFrame = field(repr=False)


# what the docker backend writes beside the results: each label's image and its slamrun.* labels
IMAGES = {
    "steady": {
        "tag": "slamrun/steady:latest",
        "id": "sha256:0123abcd",
        "method": "steady",
        "march": "x86-64-v2",
        "sources": json.dumps({"steady": "example/steady@0123456789abcdef0123456789abcdef01234567"}),
        "vocabulary": "trained: 500 words from the synthetic frames",
        "weights": json.dumps({"net.pb": "net.pb sha256 89ab"}),
    }
}


@pytest.fixture(scope="module")
def report(tmp_path_factory) -> Report:
    root = tmp_path_factory.mktemp("page")
    for out, layout, extra in (
        (root / "euroc" / "V1_synth", "euroc", []),
        (root / "euroc" / "V2_synth", "euroc", []),
        (root / "kitti" / "sequences" / "00", "kitti", ["--scene", "outdoor"]),
    ):
        p = slamrun("synth", out, "--layout", layout, "--frames", 40, "--size", "160x120", *extra)
        assert p.returncode == 0, p.stderr
    datasets = [
        {"name": "euroc", "path": str(root / "euroc"), "sequences": ["V1_synth", "V2_synth"], "layout": "euroc"},
        {"name": "kitti", "path": str(root / "kitti" / "sequences"), "sequences": ["00"], "layout": "kitti"},
    ]
    methods = [
        fake_method(label="steady", extra=["--noise", "0.002", "--vary"]),
        fake_method(label="shaky", extra=["--noise", "0.02", "--vary"]),
        {**fake_method(label="once", extra=["--noise", "0.01"]), "trials": 1, "directions": ["forward"]},
    ]
    spec = write_spec(root, root, methods, datasets=datasets, trials=2)
    p = slamrun("campaign", spec)
    assert p.returncode == 0, p.stdout + p.stderr
    results = root / "results"
    (results / "images.json").write_text(json.dumps(IMAGES))
    p = slamrun("report", results)
    assert p.returncode == 0, p.stdout + p.stderr
    df = pd.read_csv(results / "results.csv", dtype={"sequence": str})
    assert len(df) == 3 * (4 + 4 + 1) and df.status.eq("done").all()
    return Report(results, results / "report" / "index.html", df)


# ---------------------------------------------------------------- a DevTools protocol client (stdlib only)


class DevTools:
    """One page target of a Chromium, over its WebSocket (RFC 6455, text frames): commands and their results, and
    the URL of every request the page made (Network.requestWillBeSent)."""

    def __init__(self, url: str):
        host, _, path = url.removeprefix("ws://").partition("/")
        self.sock = socket.create_connection(tuple(host.rsplit(":", 1)), timeout=60)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall(
            f"GET /{path} HTTP/1.1\r\nHost: {host}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
            f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n".encode()
        )
        head = b""
        while b"\r\n\r\n" not in head:
            head += self._read(1)
        assert head.split(b"\r\n")[0].split()[1] == b"101", head
        self.n = 0
        self.requests: list[str] = []

    def _read(self, n: int) -> bytes:
        data = b""
        while len(data) < n:
            chunk = self.sock.recv(n - len(data))
            if not chunk:
                raise ConnectionError("Chromium closed the DevTools connection")
            data += chunk
        return data

    def _send(self, text: str) -> None:
        data, mask = text.encode(), os.urandom(4)
        n = len(data)
        size = bytes([0x80 | n]) if n < 126 else bytes([0x80 | 126]) + struct.pack(">H", n)
        if n >= 1 << 16:
            size = bytes([0x80 | 127]) + struct.pack(">Q", n)
        self.sock.sendall(bytes([0x81]) + size + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(data)))

    def _message(self) -> dict:
        parts = []
        while True:
            b0, b1 = self._read(2)
            n = b1 & 0x7F
            if n == 126:
                n = struct.unpack(">H", self._read(2))[0]
            elif n == 127:
                n = struct.unpack(">Q", self._read(8))[0]
            payload, opcode = self._read(n), b0 & 0x0F
            if opcode == 8:
                raise ConnectionError("Chromium closed the DevTools connection")
            if opcode in (0, 1):
                parts.append(payload)
                if b0 & 0x80:
                    return json.loads(b"".join(parts))

    def call(self, method: str, **params) -> dict:
        self.n += 1
        self._send(json.dumps({"id": self.n, "method": method, "params": params}))
        while True:
            msg = self._message()
            if msg.get("method") == "Network.requestWillBeSent":
                self.requests.append(msg["params"]["request"]["url"])
            if msg.get("id") == self.n:
                assert "error" not in msg, msg
                return msg["result"]

    def evaluate(self, expression: str):
        result = self.call("Runtime.evaluate", expression=expression, returnByValue=True, awaitPromise=True)
        assert "exceptionDetails" not in result, result
        return result["result"].get("value")

    def until(self, expression: str, timeout_s: float = 60):
        """Evaluate until the value is truthy; returns it (fails after timeout_s)."""
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            if value := self.evaluate(expression):
                return value
            time.sleep(0.2)
        pytest.fail(f"not within {timeout_s} s: {expression}")


@contextlib.contextmanager
def chromium_page(url: str, profile: Path):
    """A page of headless Chromium, WIDTH px wide, opened at `url`; its network goes to a dead proxy."""
    chromium = chromium_or_skip()
    argv = [
        chromium,
        *CHROMIUM_FLAGS,
        f"--user-data-dir={profile}",
        "--remote-debugging-port=0",
        f"--window-size={WIDTH},1000",
        "--proxy-server=http://127.0.0.1:9",  # nothing listens: a page that needed the network would break
        "--hide-scrollbars",
        "about:blank",
    ]
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        active = profile / "DevToolsActivePort"
        end = time.monotonic() + 60
        while not (active.is_file() and active.read_text().strip()) and time.monotonic() < end:
            time.sleep(0.1)
        port = active.read_text().split()[0]
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=30) as r:
            target = next(t for t in json.load(r) if t["type"] == "page")
        page = DevTools(target["webSocketDebuggerUrl"])
        page.call("Network.enable")
        page.call("Page.navigate", url=url)
        page.until(f"location.href === {json.dumps(url)} && document.readyState === 'complete'")
        yield page
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGTERM)  # the browser and its helpers: the group this test started
        proc.wait(timeout=30)


@pytest.fixture(scope="module")
def page(report, tmp_path_factory):
    with chromium_page(report.index.as_uri(), tmp_path_factory.mktemp("profile")) as p:
        yield p


# ---------------------------------------------------------------- the page in the browser


def test_the_page_fits_1400_px_and_every_image_loads(report, page):
    assert page.evaluate("window.innerWidth") == WIDTH
    page.until("document.body.dataset.imagesLoaded")  # after the load event: laid out
    page_width, body_content, body_box = page.evaluate(
        "[document.documentElement.scrollWidth, document.body.scrollWidth, document.body.clientWidth]"
    )
    assert page_width <= WIDTH and body_content <= body_box, (page_width, body_content, body_box)  # none sideways
    sticking_out = page.evaluate(
        "(() => { const b = document.body.getBoundingClientRect().right - "
        "parseFloat(getComputedStyle(document.body).paddingRight) + 0.5;"
        "return [...document.body.querySelectorAll('*')]"
        ".filter(e => !e.parentElement.closest('.table-box, .js-plotly-plot, pre'))"
        ".filter(e => e.getBoundingClientRect().right > b).map(e => e.outerHTML.slice(0, 80)); })()"
    )
    assert sticking_out == []  # no element reaches past the page's column
    # a table wider than the page scrolls inside its own box, which fits the page
    boxes = page.evaluate(
        "[...document.querySelectorAll('.table-box')].map(b => [b.getBoundingClientRect().right, b.scrollWidth])"
    )
    assert boxes and all(right <= WIDTH for right, _ in boxes)
    images = page.evaluate("[...document.images].map(i => [i.getAttribute('src'), i.complete, i.naturalWidth])")
    assert len(images) == report.index.read_text().count("<img") >= 15
    assert all(complete and width > 0 for _, complete, width in images), images
    for src, _, _ in images:  # the report's own files, relative to the page: the folder can move
        assert not urllib.parse.urlparse(src).scheme and (report.index.parent / urllib.parse.unquote(src)).is_file()


def test_the_views_are_interactive_and_draw_from_local_files_only(report, page):
    folder = report.index.parent.resolve()
    # the first view of each dataset opens with the page: plotly draws it into its element
    page.until("document.querySelectorAll('details.view[open] .js-plotly-plot').length === 2")
    views = page.evaluate("[...document.querySelectorAll('details.view')].map(d => [d.dataset.src, d.open])")
    assert len(views) == 3  # one per sequence: V1_synth, V2_synth, 00
    assert [open_ for _, open_ in views] == [True, False, True]  # the first of each dataset opens with the page
    scripts = page.evaluate("[...document.scripts].filter(s => s.src).map(s => s.src)")
    assert any(s.endswith("/plotly.min.js") for s in scripts)
    assert page.evaluate("typeof Plotly.newPlot") == "function"  # the library ran: from its file beside the page
    # the closed view draws when it opens
    page.evaluate("document.querySelectorAll('details.view')[1].open = true")
    page.until("document.querySelectorAll('details.view')[1].querySelector('.js-plotly-plot canvas') !== null")
    for url in page.requests + page.evaluate("[...document.scripts].filter(s => s.src).map(s => s.src)"):
        if url.startswith("data:"):
            continue
        parsed = urllib.parse.urlparse(url)
        assert parsed.scheme == "file", url  # no network, no CDN
        assert Path(urllib.parse.unquote(parsed.path)).resolve().is_relative_to(folder), url
    assert any(u.endswith("/datasets/euroc/views/V2_synth.js") for u in page.requests)
    # what the view holds: the ground truth, its start, and each method's picks, in 3D with units
    traces = page.evaluate(
        "document.querySelectorAll('details.view')[1].querySelector('.js-plotly-plot').data"
        ".map(t => [t.type, t.name, t.legendgroup || ''])"
    )
    assert {t for t, _, _ in traces} == {"scatter3d"}
    names = [n for _, n, _ in traces]
    assert "ground truth" in names and "start (ground truth)" in names
    groups = {g for _, _, g in traces if g}
    assert groups == {"steady", "shaky", "once"}
    assert sum(n.startswith("best") for n in names) == 3 and sum(n.startswith("worst") for n in names) == 2
    title = page.evaluate(
        "document.querySelectorAll('details.view')[1].querySelector('.js-plotly-plot').layout.scene.xaxis.title.text"
    )
    assert title == "x (m)"


# ---------------------------------------------------------------- the page's content


def page_text(report) -> str:
    """The page's text as a reader sees it, tags out, spaces collapsed."""
    text = report.index.read_text().replace("<wbr>", "")  # a break opportunity, no space
    return " ".join(html.unescape(re.sub(r"<[^>]+>", " ", text)).split())


def test_every_table_and_figure_file_is_linked(report):
    page = report.index.read_text()
    folder = report.index.parent
    hrefs = {urllib.parse.unquote(h) for h in re.findall(r'href="([^"#][^"]*)"', page)}
    for h in hrefs:
        assert (folder / h).resolve().is_file(), h
    linked = {(folder / h).resolve() for h in hrefs}
    files = [p for p in folder.rglob("*") if p.suffix in (".csv", ".md", ".tex", ".png", ".svg")]
    assert len(files) > 60
    assert sorted(p for p in files if p.resolve() not in linked) == []
    assert (folder.parent / "results.csv").resolve() in linked and (
        folder.parent / "spec.resolved.yaml"
    ).resolve() in linked


def test_the_provenance_block(report):
    text = page_text(report)
    block = text.split("Provenance", 2)[2].split("All datasets (pooled)")[0]
    from importlib.metadata import version

    assert f"version {version('slamrun')}" in block
    assert "commit " in block and "backend local" in block
    assert "steady: example/steady@0123456789abcdef0123456789abcdef01234567" in block  # the image's sources
    assert "trained: 500 words from the synthetic frames" in block and "net.pb: net.pb sha256 89ab" in block
    assert f"runs {len(report.df)} (done {len(report.df)})" in block
    assert "total run time" in block and "first run started" in block and "UTC" in block
    assert "CPU" in block and "logical cores" in block and "GPU" in block
    spec = (report.results / "spec.resolved.yaml").read_text()
    assert " ".join(spec.split()) in block  # the spec as run, whole


def test_sections_say_what_they_hold(report):
    page = report.index.read_text()
    text = page_text(report)
    for name in ("euroc", "kitti"):
        assert f"<h2>Dataset {name}</h2>" in page
        tables = report.results / "report" / "datasets" / name / "tables"
        assert (tables / "trajectory_metrics_forward.csv").is_file()
        assert not list(tables.glob("table3_*"))  # no TUM-Mono drift here: no file says it holds drift
    # no KITTI metric (the synthetic drive is under 100 m): the heading names what the table holds
    assert "and KITTI's segment errors: medians" not in text and "ATE and RPE: medians with letter groups" in text
    stats = json.loads((report.results / "report" / "datasets" / "euroc" / "statistics.json").read_text())
    p = stats["metrics"]["ate_rmse"]["kruskal_p"]
    assert f"Kruskal-Wallis p - - {p:.4g}" in text  # the p-value on the page, not only in the CLI
    assert "their median coverage" in text and "median ate_rmse forward" in text
    assert "Levene" in text and "Lilliefors" in text and "p (holm)" in text


def test_the_views_draw_through_slamrun_serve(report, tmp_path):
    """The report served by `slamrun serve` (its security policy allows no inline script but the report's own two,
    by their hashes): the views draw as from the file, and no script the policy blocked is reported."""
    from tests.test_serve import serving

    with serving(report.results) as base:
        url = f"{base}/c/{report.results.name}/files/report/index.html"
        with chromium_page(url, tmp_path / "profile") as served:
            served.call("Runtime.enable")
            served.until("document.querySelectorAll('details.view[open] .js-plotly-plot').length === 2")
            served.evaluate(
                "window.blocked = []; document.addEventListener('securitypolicyviolation', "
                "e => blocked.push(e.violatedDirective + ' ' + e.blockedURI))"
            )
            served.evaluate("document.querySelectorAll('details.view')[1].open = true")  # a closed view opened
            served.until("(document.querySelectorAll('details.view')[1].querySelector('.js-plotly-plot') || {}).data")
            assert (
                served.evaluate(
                    "document.querySelectorAll('details.view')[1].querySelector('.js-plotly-plot').data.length"
                )
                > 1
            )  # the ground truth and the runs' paths
            assert served.evaluate("window.blocked") == []
            assert served.evaluate("document.body.dataset.imagesLoaded.split('/')[0] > 0")

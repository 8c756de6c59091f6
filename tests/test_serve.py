"""`slamrun serve` as a user meets it: a real campaign of the fake method, the real server as a process on
127.0.0.1, its page in headless Chromium following the campaign as runs finish; the results folder byte for byte
unchanged by serving it; paths out of the folder (`..`, encoded separators, symbolic links) refused; a token
beyond loopback; a folder of several campaigns listed."""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import http.client
import json
import os
import re
import selectors
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.conftest import fake_method, one_sequence, write_spec
from tests.test_report_page import chromium_page

ROOT = Path(__file__).resolve().parents[1]

SLAMRUN = [sys.executable, "-m", "slamrun.cli"]


def slamrun(*args, timeout: float = 600) -> subprocess.CompletedProcess:
    return subprocess.run([*SLAMRUN, *map(str, args)], capture_output=True, text=True, timeout=timeout)


@contextlib.contextmanager
def serving(folder: Path, *extra: str, stderr: Path | None = None, nofile: int | None = None):
    """`slamrun serve FOLDER --port 0` as a process; yields its base URL (http://127.0.0.1:PORT); ended by SIGTERM,
    which must end it cleanly (exit 0). `stderr`: a file for its stderr (else a pipe); `nofile`: its limit of open
    files (ulimit -n)."""

    def limit_files() -> None:
        import resource

        resource.setrlimit(resource.RLIMIT_NOFILE, (nofile, resource.getrlimit(resource.RLIMIT_NOFILE)[1]))

    err = open(stderr, "w") if stderr is not None else subprocess.PIPE  # noqa: SIM115 - closed below
    proc = subprocess.Popen(
        [*SLAMRUN, "serve", str(folder), "--port", "0", "--interval", "0.3", *extra],
        stdout=subprocess.PIPE,
        stderr=err,
        text=True,
        start_new_session=True,
        preexec_fn=limit_files if nofile else None,
    )
    try:
        sel = selectors.DefaultSelector()
        sel.register(proc.stdout, selectors.EVENT_READ)
        assert sel.select(timeout=60), "slamrun serve printed no address within 60 s"
        line = proc.stdout.readline()
        match = re.search(r"http://127\.0\.0\.1:(\d+)/", line)
        assert match, f"no address in {line!r}; stderr: {proc.stderr.read() if proc.poll() is not None else ''}"
        yield f"http://127.0.0.1:{match.group(1)}"
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
        try:
            code = proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
            pytest.fail("slamrun serve did not end within 30 s of SIGTERM")
        if stderr is not None:
            err.close()
        assert code == 0, f"slamrun serve ended with {code}: {proc.stderr.read() if stderr is None else ''}"


def get(base: str, path: str, headers: dict | None = None, method: str = "GET") -> tuple[int, bytes, dict]:
    """One request with `path` sent exactly as written (no normalisation of `..` or of %-escapes)."""
    host, port = base.removeprefix("http://").split(":")
    conn = http.client.HTTPConnection(host, int(port), timeout=30)
    try:
        conn.putrequest(method, path, skip_host="Host" in (headers or {}), skip_accept_encoding=True)
        for k, v in (headers or {}).items():
            conn.putheader(k, v)
        conn.endheaders()
        r = conn.getresponse()
        return r.status, r.read(), dict(r.getheaders())
    finally:
        conn.close()


def events(base: str, path: str, seconds: float) -> list[dict]:
    """The `state` events a server-sent-event stream delivers within `seconds`."""
    host, port = base.removeprefix("http://").split(":")
    sock = socket.create_connection((host, int(port)), timeout=seconds)
    sock.sendall(f"GET {path} HTTP/1.1\r\nHost: {host}:{port}\r\nAccept: text/event-stream\r\n\r\n".encode())
    data, end = b"", time.monotonic() + seconds
    with contextlib.suppress(TimeoutError, socket.timeout):
        while time.monotonic() < end:
            sock.settimeout(max(end - time.monotonic(), 0.01))
            chunk = sock.recv(65536)
            if not chunk:
                break
            data += chunk
    sock.close()
    return [json.loads(m.group(1)) for m in re.finditer(rb"event: state\ndata: (.*)\n\n", data)]


def folder_state(root: Path) -> dict[str, tuple]:
    """Every entry under `root` (hidden ones too, links not followed): its kind, and for a file its size, mtime
    and SHA-256."""
    state = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in dirnames + filenames:
            path = Path(dirpath) / name
            st = path.lstat()
            if path.is_symlink():
                state[str(path.relative_to(root))] = ("link", os.readlink(path))
            elif path.is_file():
                digest = hashlib.sha256(path.read_bytes()).hexdigest()
                state[str(path.relative_to(root))] = ("file", st.st_size, st.st_mtime_ns, digest)
            else:
                state[str(path.relative_to(root))] = ("dir", st.st_mode)
    return state


@pytest.fixture(scope="module")
def finished(tmp_path_factory, tiny_dataset) -> Path:
    """A finished campaign with done and failed runs and its report: tmp/results."""
    root = tmp_path_factory.mktemp("served")
    methods = [fake_method(label="steady", extra=["--noise", "0.002", "--vary"]), fake_method("crash", label="broken")]
    spec = write_spec(root, tiny_dataset, methods, datasets=one_sequence(tiny_dataset), trials=2)
    p = slamrun("campaign", spec)
    assert p.returncode == 0, p.stdout + p.stderr
    p = slamrun("report", root / "results")
    assert p.returncode == 0, p.stdout + p.stderr
    return root / "results"


# ---------------------------------------------------------------- the live page in a browser


def test_the_page_follows_a_running_campaign_in_chromium(tmp_path, tiny_dataset):
    release = tmp_path / "release"
    methods = [
        fake_method(label="quick", extra=["--noise", "0.002", "--vary"]),
        fake_method(label="held", extra=["--wait-for", str(release)]),
        fake_method("crash", label="broken"),
    ]
    # three lanes: the two held runs (forward, backward) leave one for the others
    spec = write_spec(
        tmp_path, tiny_dataset, methods, datasets=one_sequence(tiny_dataset), trials=1, lanes=3, timeout_s=600
    )
    results = tmp_path / "results"
    campaign = subprocess.Popen([*SLAMRUN, "campaign", str(spec)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        end = time.monotonic() + 120
        while not (results / "ledger.sqlite").is_file() and time.monotonic() < end and campaign.poll() is None:
            time.sleep(0.1)
        with serving(results) as base, chromium_page(f"{base}/c/results/", tmp_path / "profile") as page:
            progress = "document.getElementById('progress')"
            assert page.until(f"{progress} && {progress}.dataset.total", timeout_s=180) == "6"
            # the held runs are on the lanes, the others finish around them: what the page shows moves
            page.until(
                "[...document.querySelectorAll('#lanes td')].some(td => td.textContent === 'held')", timeout_s=180
            )
            seen = {int(page.evaluate(f"{progress}.dataset.finished"))}
            assert page.evaluate(f"{progress}.dataset.state") == "running"
            assert max(seen) < 6  # nothing can be finished while the held runs wait
            page.until(
                f"+{progress}.dataset.finished >= 4", timeout_s=180
            )  # quick and broken, each forward and backward
            seen.add(int(page.evaluate(f"{progress}.dataset.finished")))
            release.write_text("go")
            page.until(f"{progress}.dataset.state === 'finished'", timeout_s=180)
            seen.add(int(page.evaluate(f"{progress}.dataset.finished")))
            assert len(seen) >= 2 and max(seen) == 6, seen
            text = page.evaluate("document.body.innerText")
            assert "6 of 6 runs finished" in text and "done 4" in text and "failed 2" in text
            # the failures by kind, each with its log tail
            assert "by kind: crashed 2" in text
            page.evaluate("document.querySelector('#failures details').open = true")
            tail = page.until(
                "document.querySelector('#failures pre.log').dataset.loaded && "
                "document.querySelector('#failures pre.log').textContent"
            )
            assert "Segmentation fault" in tail
            # medians per dataset, with the live box plot drawn
            assert page.until(
                "document.querySelector('#medians table') && "
                "document.querySelectorAll('#medians .box .main-svg').length > 0"
            )
            # a done run's path over its ground truth
            page.evaluate("document.querySelector('#path button').click()")
            page.until("document.querySelectorAll('#run-select option').length === 5")  # a prompt and 4 done runs
            page.evaluate(
                "(() => { const s = document.getElementById('run-select');"
                " s.value = [...s.options].find(o => o.text.startsWith('quick')).value;"
                " s.dispatchEvent(new Event('change')); })()"
            )
            traces = page.until(
                "document.getElementById('run-path').data && document.getElementById('run-path').data.map(t => t.name)"
            )
            assert any(t.startswith("ground truth") for t in traces) and any(t.startswith("quick (") for t in traces)
            # everything the page loaded came from the server itself
            assert page.requests and all(u.startswith(base) for u in page.requests), page.requests
        assert campaign.wait(timeout=120) == 0, campaign.stderr.read()
    finally:
        release.write_text("go")
        if campaign.poll() is None:
            campaign.kill()
            campaign.wait()


def in_own_group(argv: list[str], timeout_s: float) -> str:
    """`argv`'s stdout; past `timeout_s` its whole process group (a browser and its helpers) is killed and the test
    fails."""
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, start_new_session=True)
    try:
        return proc.communicate(timeout=timeout_s)[0]
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        pytest.fail(f"{argv[0]} did not end within {timeout_s} s: {' '.join(argv[-2:])}")


def test_the_page_comes_with_its_first_state_and_a_headless_browser_settles_on_it(finished, tmp_path):
    """The page was JavaScript only: curl and text browsers saw "loading...", a headless screenshot showed the page
    on some tries and "loading..." on others, and with a virtual time budget the browser never finished (the event
    stream stayed open). Now the server renders the first state; on a campaign that is not running the page closes
    its stream between states: ten screenshots in a row under a virtual time budget each end, each of the page."""
    import html as html_

    import cv2

    from tests.test_report import CHROMIUM_FLAGS, chromium_or_skip

    with serving(finished) as base:
        status, body, _ = get(base, "/c/results/")
        page = body.decode()
        state = json.loads(get(base, "/c/results/api/state")[1])
        text = html_.unescape(re.sub(r"<[^>]+>", " ", page.split('<script type="application/json"')[0]))
        assert status == 200 and "loading..." not in text  # what curl and a text browser show
        assert "8 of 8 runs finished (100 %) · done 4 · failed 4" in text and " · ".join(state["facts"]) in text
        assert "by kind: crashed 4" in text and "Per method and direction" in text
        assert "alignment error e_align (GT units)" in text and " steady " in text  # the medians table, with units
        for figure in state["figures"]:
            assert f'src="/c/results/files/{figure["path"]}?v=' in page
        chromium = chromium_or_skip()
        for i in range(10):
            shot = tmp_path / f"shot-{i}.png"
            argv = [chromium, *CHROMIUM_FLAGS, f"--user-data-dir={tmp_path / 'profile'}", "--window-size=1400,1000"]
            argv += ["--virtual-time-budget=3000", f"--screenshot={shot}", f"{base}/c/results/"]
            in_own_group(argv, 90)  # never ended with the stream open
            grey = cv2.imread(str(shot), cv2.IMREAD_GRAYSCALE)
            inked = int((grey < 160).any(axis=1).sum())  # rows holding text, tables or figures
            assert inked > 300, (i, inked)  # "loading..." alone inks under 20
        dom = in_own_group(
            [chromium, *CHROMIUM_FLAGS, f"--user-data-dir={tmp_path / 'profile'}", "--virtual-time-budget=3000"]
            + ["--dump-dom", f"{base}/c/results/"],
            90,
        )
        assert 'class="main-svg"' in dom and "first-state" not in dom  # the script's render, with the box plot


def test_the_first_state_escapes_every_text_it_shows():
    from slamrun.serve.sections import campaign_body, embedded

    hostile = "</script><script>alert(1)</script>"
    progress = {"total": 1, "finished": 1, "done": 0, "failed": 1, "infra": 0, "active": False, "per_group": []}
    snap = {
        "name": "c&d", "campaign": "<b>c</b>", "generated_at": 0.0, "progress": progress, "state": "finished",
        "facts": ["1 of 1 runs finished (100 %)"], "labels": {}, "lanes": [], "medians": {}, "figures": [],
        "report": None,
        "failed": {"total": 1, "kinds": {"crashed": 1}, "runs": [
            {"failure": "crashed", "method": hostile, "dataset": "d", "sequence": "s", "direction": "forward",
             "trial": 0, "message": hostile, "key": '"><img src=x onerror=alert(1)>'}
        ]},
    }  # fmt: skip
    body = campaign_body(snap)
    assert "<script" not in body and "<b>" not in body and "&lt;/script&gt;&lt;script&gt;alert(1)" in body
    assert "<img" not in body and 'data-key="&quot;&gt;&lt;img' in body  # the log tail's key, escaped
    block = embedded(json.dumps(snap).encode())
    assert block.count("</script>") == 1 and block.endswith("</script>")  # no text in it ends the block
    assert json.loads(block.split(">", 1)[1].removesuffix("</script>")) == snap


def test_the_sections_are_rendered_once_on_the_server_for_the_page_and_its_stream(finished):
    """The page's first paint and every state it follows carry the same sections, rendered by the server; the script
    renders none of them (it places them, and draws the plots, log tails and path viewer)."""
    from slamrun.serve.sections import SECTIONS

    with serving(finished) as base:
        state = json.loads(get(base, "/c/results/api/state")[1])
        page = get(base, "/c/results/")[1].decode()
    assert list(state["sections"]) == list(SECTIONS)
    for name, html in state["sections"].items():
        assert html.startswith(("<section", "<header")) and f'id="{name}"' in html.split(">", 1)[0]
        if name != "progress":  # the header says when it was read
            assert html in page, name
    script = (ROOT / "slamrun" / "serve" / "static" / "page.js").read_text()
    for title in (
        "What each lane runs",
        "Failures",
        "Medians per dataset",
        "Per method and direction",
        "Report figures",
    ):
        assert title not in script


def test_the_box_plot_keeps_each_methods_colour_and_labels_its_log_axis_with_whole_values(finished, tmp_path):
    """A method's colour on the page came from the order its first result arrived (it changed when another method's
    first result came), and the log axis labelled one decade only ("3 4 5 ... 0.01 2 3": "3" meant 0.003 on the left
    and 0.03 on the right), with no unit. Now: the campaign's colours (the report's), whole values, units."""
    from slamrun.analysis.colours import TAB10, method_colours
    from slamrun.core.ticks import log_ticks

    with serving(finished) as base:
        state = json.loads(get(base, "/c/results/api/state")[1])
        # `broken` has no result to plot: `steady` still has the second colour of the campaign's two methods
        assert state["colours"] == method_colours(["steady", "broken"]) == {"broken": TAB10[0], "steady": TAB10[1]}
        with chromium_page(f"{base}/c/results/", tmp_path / "profile") as page:
            box = "document.querySelector('#medians .box')"
            drawn = f"{box} && {box}.data && {box}.querySelectorAll('.xtick text').length > 0"
            end = time.monotonic() + 60
            while not page.evaluate(drawn) and time.monotonic() < end:
                time.sleep(0.2)
            diag = f"[!!{box}, {box} && !!{box}.data, {box} && {box}.querySelectorAll('text').length].join()"
            shown = "document.getElementById('app').innerText"
            assert page.evaluate(drawn), (page.evaluate(diag), page.evaluate(shown))  # what it shows if not drawn
            assert page.evaluate(f"{box}.data.map(t => t.name + ' ' + t.marker.color).join()") == f"steady {TAB10[1]}"
            ticks = page.evaluate(f"[...{box}.querySelectorAll('.xtick text')].map(t => t.textContent).join(' ')")
            assert len(ticks.split()) >= 2, ticks  # a labelled tick at each end, however close the values
            # the server's ticks (the report's rule), whole values; values between two ticks (this test's plot had
            # none labelled one try in three): the axis widens to them
            shown = page.evaluate(f"JSON.stringify({box}.layout.xaxis.tickvals)")
            assert json.loads(shown) == next(iter(state["medians"].values()))["ticks"]
            assert log_ticks([0.030, 0.043]) == [0.02, 0.05]
            for tick in ticks.split():
                value = float(tick)  # a whole value, never a digit whose decade is written elsewhere
                assert value >= 1 or tick.startswith("0.") or "e-" in tick, ticks
            title = page.evaluate(f"{box}.querySelector('.xtitle').textContent")
            assert title == "alignment error e_align (GT units)", title


def test_the_reports_curves_take_the_campaigns_colours():
    """A dataset where only one of the campaign's two methods has results draws it in its campaign colour."""
    import pandas as pd

    from slamrun.analysis import figures
    from slamrun.analysis.colours import TAB10, TAB20, method_colours

    df = pd.DataFrame({"method": ["steady"] * 3, "e_align": [0.01, 0.02, 0.03]})
    fig = figures.cumulative_figure(df, "e_align", colours=method_colours(["broken", "steady"]))
    assert [line.get_color() for line in fig.axes[0].lines] == [TAB10[1]]
    import matplotlib.pyplot as plt

    plt.close(fig)
    for n, palette in ((10, TAB10), (20, TAB20)):  # the page's palette is matplotlib's, as the figures draw it
        cmap = plt.get_cmap("tab10" if n == 10 else "tab20")
        assert [plt.matplotlib.colors.to_hex(cmap(i)) for i in range(n)] == list(palette)


# ---------------------------------------------------------------- read-only, and nothing outside the folder


def test_serving_leaves_the_results_folder_byte_for_byte_unchanged(finished):
    before = folder_state(finished)
    with serving(finished) as base:
        assert get(base, "/")[0] == 302
        status, body, _ = get(base, "/c/results/api/state")
        assert status == 200
        state = json.loads(body)
        assert state["progress"]["finished"] == 8 and state["failed"]["kinds"] == {"crashed": 4}
        assert state["figures"] and state["report"] == "report/index.html"
        for figure in state["figures"][:5]:
            assert get(base, f"/c/results/files/{figure['path']}")[0] == 200
        assert get(base, "/c/results/files/report/index.html")[0] == 200
        assert get(base, "/c/results/files/results.csv")[0] == 200
        runs = json.loads(get(base, "/c/results/api/runs")[1])["runs"]
        assert len(runs) == 4
        for run in runs:
            status, body, _ = get(base, f"/c/results/api/path?key={run['key']}")
            assert status == 200 and json.loads(body)["data"]
        failed = state["failed"]["runs"][0]["key"]
        assert b"Segmentation fault" in get(base, f"/c/results/api/log?key={failed}")[1]
        assert get(base, f"/c/results/api/path?key={failed}")[0] == 404  # a failed run has no path to draw
        streamed = events(base, "/c/results/events", 2.0)
        assert streamed and streamed[0]["progress"]["finished"] == 8
        for static in ("/static/page.js", "/static/page.css", "/static/plotly.min.js"):
            assert get(base, static)[0] == 200
    assert folder_state(finished) == before


SECRET = "the-secret-outside-the-results-folder"


@pytest.fixture()
def planted(finished, tmp_path) -> Path:
    """A copy of the finished campaign with links out of it planted in its report folder, and a secret beside it."""
    copy = tmp_path / "results"
    shutil.copytree(finished, copy, symlinks=True)
    (tmp_path / "secret.txt").write_text(SECRET)
    (tmp_path / "outside").mkdir()
    (tmp_path / "outside" / "secret.txt").write_text(SECRET)
    (copy / "report" / "link.txt").symlink_to(tmp_path / "secret.txt")
    (copy / "report" / "linkdir").symlink_to(tmp_path / "outside")
    (copy / "runs" / "escape").symlink_to(tmp_path / "outside")
    return copy


@pytest.mark.parametrize(
    "path",
    [
        "/c/results/files/report/../../secret.txt",
        "/c/results/files/../../secret.txt",
        "/c/results/files/report/%2e%2e/%2e%2e/secret.txt",
        "/c/results/files/report%2f..%2f..%2fsecret.txt",
        "/c/results/files/report/..%2f..%2fsecret.txt",
        "/c/results/files/report/..%5c..%5csecret.txt",
        "/c/results/files/report/%252e%252e/%252e%252e/secret.txt",
        "/c/results/files/report/link.txt",
        "/c/results/files/report/linkdir/secret.txt",
        "/c/results/files/runs/escape/secret.txt",
        "/c/results/files//" + "etc/passwd",
        "/c/results/files/%2fetc%2fpasswd",
        "/c/results/files/ledger.sqlite",
        "/c/results/files/runs/../../secret.txt",
        "/c/..%2f..%2fsecret.txt/api/state",
        "/c/results/api/log?key=escape",
        "/c/results/api/log?key=../../secret.txt",
        "/c/results/api/log?key=..%2F..%2Fsecret.txt",
        "/c/results/api/path?key=escape",
        "/static/..%2fapp.py",
        "/static/../../secret.txt",
    ],
)
def test_paths_out_of_the_folder_are_refused(planted, path):
    with serving(planted) as base:
        status, body, _ = get(base, path)
        assert status in (400, 403, 404), (status, body[:200])
        assert SECRET.encode() not in body and b"root:" not in body
        assert get(base, "/c/results/files/report/index.html")[0] == 200  # the same server serves what it should


SWAPPER = """
import ctypes, os, sys, time
libc = ctypes.CDLL(None, use_errno=True)
a, b, until = sys.argv[1].encode(), sys.argv[2].encode(), time.monotonic() + float(sys.argv[3])
n = 0
while time.monotonic() < until:
    if libc.renameat2(-100, a, -100, b, 2) != 0:  # AT_FDCWD, RENAME_EXCHANGE: one atomic swap
        sys.exit("renameat2: errno %d" % ctypes.get_errno())
    n += 1
print(n)
"""


def test_a_folder_swapped_for_a_link_while_served_never_serves_what_is_outside(finished, tmp_path):
    """Another process swaps a run's folder for a link out of the results folder and back, atomically, as fast as it
    can (renameat2 RENAME_EXCHANGE) while files of that folder are asked for: the old check-then-open served the
    file outside in 15-20 % of requests. Now each part is opened without following a link: the run's own file, or a
    404, never the other."""
    copy = tmp_path / "results"
    shutil.copytree(finished, copy, symlinks=True)
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "trajectory.txt").write_text(SECRET)
    run = next(p.parent for p in sorted((copy / "runs").rglob("trajectory.txt")))
    (run.parent / "swap").symlink_to(outside)
    served = f"/c/results/files/{run.relative_to(copy)}/trajectory.txt"
    own = (run / "trajectory.txt").read_bytes()
    with serving(copy) as base:
        swapper = subprocess.Popen(
            [sys.executable, "-c", SWAPPER, str(run), str(run.parent / "swap"), "20"],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        try:
            answers = [get(base, served) for _ in range(300)]
        finally:
            swapper.kill()
            out, err = swapper.communicate(timeout=30)
        assert not err, err
    statuses = [status for status, _, _ in answers]
    assert all(SECRET.encode() not in body for _, body, _ in answers), statuses.count(200)
    assert set(statuses) <= {200, 404}
    assert any(body == own for status, body, _ in answers if status == 200)  # the folder was served in between


def test_a_runs_files_are_text_or_downloads_never_pages(finished, tmp_path):
    """A method's `raw/notes.html` ran as a page in the server's origin; now a run's files are plain text (its
    trajectory, log, run.json) or downloads, each under a sandbox; the report's own pages stay pages."""
    copy = tmp_path / "results"
    shutil.copytree(finished, copy, symlinks=True)
    run = next(p.parent for p in sorted((copy / "runs").rglob("trajectory.txt")))
    raw = run / "raw"
    raw.mkdir(exist_ok=True)
    (raw / "notes.html").write_text("<script>fetch('/c/results/api/state')</script>")
    (raw / "map.bin").write_bytes(b"\x00\x01")
    (raw / "ledger-link").symlink_to(copy / "ledger.sqlite")
    (raw / ".hidden.txt").write_text("hidden")
    rel = run.relative_to(copy)
    with serving(copy) as base:
        status, body, headers = get(base, f"/c/results/files/{rel}/raw/notes.html")
        assert status == 200 and headers["Content-Type"].startswith("text/plain")
        assert "sandbox" in headers["Content-Security-Policy"] and headers["X-Content-Type-Options"] == "nosniff"
        status, body, headers = get(base, f"/c/results/files/{rel}/raw/map.bin")
        assert status == 200 and body == b"\x00\x01" and headers["Content-Type"] == "application/octet-stream"
        assert headers["Content-Disposition"].startswith("attachment;")
        status, _, headers = get(base, f"/c/results/files/{rel}/trajectory.txt", method="HEAD")
        assert status == 200 and headers["Content-Type"].startswith("text/plain")
        assert int(headers["Content-Length"]) == (run / "trajectory.txt").stat().st_size
        for refused in ("raw/ledger-link", "raw/.hidden.txt"):  # a link to the ledger, a hidden file
            assert get(base, f"/c/results/files/{rel}/{refused}")[0] == 404
        status, body, headers = get(base, "/c/results/files/report/index.html")
        assert status == 200 and headers["Content-Type"].startswith("text/html") and b"<html" in body.lower()
        assert "sandbox" not in headers["Content-Security-Policy"]


def test_slow_and_idle_connections_are_closed_and_never_starve_the_server(finished, tmp_path):
    """600 connections that send half a request line and stop, at `ulimit -n 256`: once nothing was answered for
    45 s, none closed, and stderr grew by 116 MB of EMFILE tracebacks. Now a connection past the cap (64 here: a
    quarter of the file limit) closes the oldest idle one, those without a whole request within 10 s are closed, the
    server answers again within seconds, and stderr holds a few lines."""
    log = tmp_path / "serve.err"
    with serving(finished, stderr=log, nofile=256) as base:
        host, port = base.removeprefix("http://").split(":")
        slow = []
        for _ in range(600):
            with contextlib.suppress(OSError):
                s = socket.create_connection((host, int(port)), timeout=5)
                s.sendall(b"GET /c/results/api/state HTTP/1.1\r\nHost: 127")
                slow.append(s)
        start = time.monotonic()
        answered = None
        while time.monotonic() - start < 30:
            with contextlib.suppress(OSError, http.client.HTTPException):
                if get(base, "/c/results/api/state")[0] == 200:
                    answered = time.monotonic() - start
                    break
            time.sleep(0.5)
        assert answered is not None and answered < 20, answered
        hanging = 0
        for s in slow:  # every slow connection is closed by the server (or was refused): none hangs
            s.settimeout(max(1.0, 25 - (time.monotonic() - start)))
            try:
                hanging += s.recv(1024) != b""
            except (ConnectionResetError, BrokenPipeError):
                pass  # refused at the cap
            except TimeoutError:
                hanging += 1
            s.close()
        assert hanging == 0, f"{hanging} of {len(slow)} slow connections still open"
        assert get(base, "/c/results/files/report/index.html")[0] == 200
    text = log.read_text()
    assert "Traceback" not in text and len(text.splitlines()) <= 12, text[:3000]
    assert "closed the oldest idle connections at the cap of 64 open" in text
    assert "closed connections idle or without a whole request for 10 s" in text


def test_one_client_holding_slow_connections_never_keeps_another_out(finished, tmp_path):
    """Under the cap, 1,100 slow connections from one client still refused a normal request for about 10 s (issue
    63: a newcomer at the cap was refused). Now a connection arriving at the cap closes the oldest one that answers
    no request (of the client holding the most): the normal request is answered at once, every time."""
    log = tmp_path / "serve.err"
    with serving(finished, stderr=log, nofile=256) as base:
        host, port = base.removeprefix("http://").split(":")
        slow = []
        for _ in range(300):
            with contextlib.suppress(OSError):
                s = socket.create_connection((host, int(port)), timeout=5)
                s.sendall(b"GET /c/results/api/state HTTP/1.1\r\nHost: 127")
                slow.append(s)
        took = []
        for _ in range(5):
            t0 = time.monotonic()
            assert get(base, "/c/results/api/state")[0] == 200
            took.append(time.monotonic() - t0)
        for s in slow:
            s.close()
    assert max(took) < 2.0, took
    text = log.read_text()
    assert "Traceback" not in text and "closed the oldest idle connections at the cap of 64 open" in text, text


def test_only_loopback_names_and_reads(finished):
    with serving(finished) as base:
        assert get(base, "/c/results/api/state", headers={"Host": "attacker.example:80"})[0] == 403
        assert get(base, "/c/results/api/state", headers={"Host": base.removeprefix("http://")})[0] == 200
        assert get(base, "/c/results/api/state", method="POST")[0] == 405
        assert get(base, "/c/results/api/state", method="DELETE")[0] == 405
        status, _, headers = get(base, "/c/results/")
        assert status == 200 and "default-src 'self'" in headers["Content-Security-Policy"]
        assert get(base, "/c/nosuch/api/state")[0] == 404


def test_a_token_is_asked_of_every_request_when_one_is_set(finished):
    from aiohttp.test_utils import TestClient, TestServer

    from slamrun.serve.app import make_app

    token = "t" * 24

    async def check() -> None:
        async with TestClient(TestServer(make_app(finished, token=token), host="127.0.0.1")) as client:
            assert (await client.get("/c/results/api/state")).status == 401
            assert (await client.get("/c/results/api/state?token=wrong-token-of-24-chars")).status == 401
            first = await client.get(f"/c/results/?token={token}")
            assert first.status == 200 and "slamrun_token" in first.cookies
            assert (await client.get("/c/results/api/state")).status == 200  # the cookie it set

    asyncio.run(check())


def test_a_spec_is_served_as_its_results_folder(finished):
    """`slamrun serve SPEC.yaml` (it said "no such folder" about the file) serves the spec's results folder."""
    with serving(finished.parent / "spec.yaml") as base:
        status, body, _ = get(base, "/api/campaigns")
        assert status == 200 and b'"results"' in body, body


@pytest.mark.parametrize("made", ["later", "empty"])
def test_a_folder_that_holds_no_campaign_yet_is_waited_for(tmp_path, finished, made):
    """`serve` started before the campaign has made its folder (it said "no such folder"), or on a folder with no
    campaign yet: it says once on stderr what it waits for, and serves the campaign once there."""
    import shutil

    folder = tmp_path / "results"
    if made == "empty":
        folder.mkdir()
    proc = subprocess.Popen(
        [*SLAMRUN, "serve", str(folder), "--port", "0"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        waiting = proc.stderr.readline()
        why = "holds no campaign yet" if made == "empty" else "does not exist yet"
        assert waiting.startswith(f"slamrun serve: {folder} {why}; waiting for a campaign there"), waiting
        assert proc.poll() is None
        if made == "empty":
            folder.rmdir()
        shutil.copytree(finished, folder)
        sel = selectors.DefaultSelector()
        sel.register(proc.stdout, selectors.EVENT_READ)
        assert sel.select(timeout=60), "no address printed within 60 s of the campaign's folder appearing"
        match = re.search(r"http://127\.0\.0\.1:(\d+)/", proc.stdout.readline())
        assert match and get(f"http://127.0.0.1:{match.group(1)}", "/api/campaigns")[0] == 200
    finally:
        proc.terminate()
        proc.wait(timeout=30)


def test_a_wildcard_host_prints_the_machines_names_not_the_wildcard():
    """`--host 0.0.0.0` printed http://0.0.0.0:PORT, which opens nothing on a colleague's machine: it prints this
    machine's name and each address beyond loopback (computed here; no test listens beyond loopback)."""
    import socket as sockets

    from slamrun.serve.server import machine_names, urls

    names = machine_names("0.0.0.0")
    assert names[0] == sockets.gethostname() and "0.0.0.0" not in names and "127.0.0.1" not in names
    assert all(":" not in n for n in names[1:])  # IPv4 only for 0.0.0.0
    assert urls("0.0.0.0", 8765, "tok", ["lab-pc", "10.0.0.5"]) == [
        "http://lab-pc:8765/?token=tok",
        "http://10.0.0.5:8765/?token=tok",
    ]
    assert urls("::", 80, None, ["lab-pc", "fd00::5"]) == ["http://lab-pc:80/", "http://[fd00::5]:80/"]
    assert urls("127.0.0.2", 80, None, ["lab-pc"]) == ["http://127.0.0.2:80/"]


def test_bad_arguments_are_one_line_before_anything_listens(tmp_path, finished):
    p = slamrun("serve", finished, "--port", "70000")
    assert p.returncode == 2 and "0 to 65535" in p.stderr
    p = slamrun("serve", finished, "--host", "0.0.0.0", "--token", "short")
    assert p.returncode == 1 and "at least 16 characters" in p.stderr  # refused before binding any address
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen(1)
        p = slamrun("serve", finished, "--port", busy.getsockname()[1], timeout=60)
    assert p.returncode == 1 and "cannot listen on 127.0.0.1" in p.stderr and "Traceback" not in p.stderr


def test_a_folder_of_several_campaigns_is_listed(finished, tmp_path):
    root = tmp_path / "all"
    for name in ("first", "second"):
        shutil.copytree(finished, root / name, symlinks=True)
    (root / "not-a-campaign").mkdir()
    with serving(root) as base:
        status, body, _ = get(base, "/")
        assert status == 200 and b"data-view=campaigns" in body
        listed = json.loads(get(base, "/api/campaigns")[1])["campaigns"]
        assert [c["name"] for c in listed] == ["first", "second"]
        assert all(c["finished"] == 8 and not c["active"] for c in listed)
        assert get(base, "/c/second/api/state")[0] == 200
        assert get(base, "/c/not-a-campaign/api/state")[0] == 404


def test_the_65th_viewer_polls_instead_of_waiting(finished, tmp_path):
    """64 viewers stream (server-sent events); the 65th's stream is refused (503) and its page stayed "loading...".
    Now its page polls api/state and shows the campaign, saying why it polls."""
    with serving(finished) as base:
        host, port = base.removeprefix("http://").split(":")
        streams = []
        try:
            for _ in range(64):
                s = socket.create_connection((host, int(port)), timeout=10)
                s.sendall(f"GET /c/results/events HTTP/1.1\r\nHost: {host}:{port}\r\n\r\n".encode())
                assert s.recv(64).startswith(b"HTTP/1.1 200")
                streams.append(s)
            assert get(base, "/c/results/events")[0] == 503
            with chromium_page(f"{base}/c/results/", tmp_path / "profile") as page:
                progress = "document.getElementById('progress')"
                assert page.until(f"{progress} && {progress}.dataset.total", timeout_s=60) == "8"
                assert "polls" in page.until("document.querySelector('.polling')?.textContent", timeout_s=30)
        finally:
            for s in streams:
                s.close()


def test_a_ledger_damaged_while_served_is_one_line_not_a_crash(finished, tmp_path):
    copy = tmp_path / "results"
    shutil.copytree(finished, copy, symlinks=True)
    with serving(copy) as base:
        assert get(base, "/c/results/api/state")[0] == 200
        (copy / "ledger.sqlite").write_bytes(b"not a database at all " * 100)
        time.sleep(1.2)  # past the snapshot's shortest age
        status, body, _ = get(base, "/c/results/api/state")
        assert status == 503 and b"ledger" in body and b"Traceback" not in body, body
        assert get(base, "/c/results/files/report/index.html")[0] == 200  # the server goes on


def test_a_folder_moved_away_while_served_is_one_line_not_a_crash(finished, tmp_path):
    """The served campaign's folder moved (or deleted) while served: each request is one line (503 for the
    campaign's state, 404 for its files), never a 500 with a traceback; the server goes on."""
    copy = tmp_path / "results"
    shutil.copytree(finished, copy, symlinks=True)
    log = tmp_path / "serve.err"
    with serving(copy, stderr=log) as base:
        assert get(base, "/c/results/api/state")[0] == 200
        copy.rename(tmp_path / "moved")
        time.sleep(1.2)  # past the snapshot's shortest age
        for path in ("/c/results/api/state", "/c/results/api/runs", "/c/results/", "/c/results/files/results.csv"):
            status, body, _ = get(base, path)
            assert status in (404, 503) and b"Traceback" not in body, (path, status, body[:300])
        status, body, _ = get(base, "/c/results/api/state")
        assert status == 503 and b"results" in body, body
        status, body, _ = get(base, "/api/campaigns")  # the served folder itself is gone: said, not a crash
        assert status == 503 and b"no such folder" in body, body
        copy.parent.joinpath("moved").rename(copy)  # back: served again
        assert get(base, "/c/results/api/state")[0] == 200
    assert "Traceback" not in log.read_text(), log.read_text()[-3000:]


def _printed_address(*args: str) -> tuple[subprocess.Popen, str]:
    """`slamrun serve ARGS` as a process, and the address it printed (stdout's first line)."""
    proc = subprocess.Popen(
        [*SLAMRUN, "serve", *args, "--port", "0"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    sel = selectors.DefaultSelector()
    sel.register(proc.stdout, selectors.EVENT_READ)
    assert sel.select(timeout=60), "no address printed within 60 s"
    match = re.search(r"(http://\S+)", proc.stdout.readline())
    assert match, proc.stderr.read() if proc.poll() is not None else "no address"
    return proc, match.group(1)


def _follow(url: str) -> int:
    """The status the printed address ends at, following redirects with the cookies they set (as a browser)."""
    import http.cookiejar
    import urllib.error
    import urllib.request

    opener = urllib.request.build_opener(urllib.request.HTTPCookieProcessor(http.cookiejar.CookieJar()))
    try:
        with opener.open(url, timeout=30) as response:
            return response.status
    except urllib.error.HTTPError as exc:
        return exc.code


@pytest.mark.parametrize("host", ["127.0.0.2", "127.0.0.3"])
def test_the_printed_address_opens_the_page(finished, host):
    """Another loopback address than 127.0.0.1: the address printed opens the page (it answered 403: only
    127.0.0.1, localhost and [::1] were accepted as the Host)."""
    proc, url = _printed_address(str(finished), "--host", host)
    try:
        assert url.startswith(f"http://{host}:")
        assert _follow(url) == 200
    finally:
        proc.terminate()
        proc.wait(timeout=30)


def test_a_token_mode_redirect_keeps_the_token(finished):
    """The one-campaign folder's / redirects to /c/NAME/: with the token in the query, the redirect sets the cookie
    (the next page is answered), as the page itself does."""
    from aiohttp.test_utils import TestClient, TestServer

    from slamrun.serve.app import make_app

    token = "r" * 24

    async def check() -> None:
        async with TestClient(TestServer(make_app(finished, token=token), host="127.0.0.1")) as client:
            first = await client.get(f"/?token={token}", allow_redirects=False)
            assert first.status == 302 and "slamrun_token" in first.cookies
            assert (await client.get(first.headers["Location"])).status == 200

    asyncio.run(check())

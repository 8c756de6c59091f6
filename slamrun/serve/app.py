"""The live page's server (aiohttp): read-only, GET only, loopback by default.

Routes: `/` (the campaigns; one campaign's folder goes straight to its page), `/static/<file>` (the page's script,
style and plotly.js, from slamrun's own files), and per campaign `/c/<name>/` (the page), `api/state` (the
snapshot), `events` (server-sent events: a new snapshot when the ledger or the report changes), `api/runs`,
`api/path`, `api/log` (a done run's path over its ground truth, a run's log tail) and `files/<path>` (the report's
files, the runs' files, results.csv: each resolved inside the campaign's folder).

One Hub per server keeps each campaign's last snapshot with the signature it was read at: every viewer gets the
same bytes, and the ledger is read again only when it changed (or, while the campaign runs, every few seconds for
the clock-driven figures: elapsed, ETA)."""

from __future__ import annotations

import asyncio
import base64
import contextlib
import hashlib
import hmac
import html
import json
import mimetypes
import os
import re
import time
import urllib.parse
from collections import OrderedDict
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

from aiohttp import web

from slamrun.analysis.page import INLINE_SCRIPTS
from slamrun.core import jsonio
from slamrun.engine.paths import RunPaths
from slamrun.errors import SlamRunError
from slamrun.results import files as campaign_files
from slamrun.results.catalogue import MAIN_METRICS
from slamrun.results.files import CampaignFiles
from slamrun.serve import runview, sections
from slamrun.serve.connections import Watch
from slamrun.serve.folders import campaigns, open_served
from slamrun.serve.snapshot import Signature, snapshot

REFRESH_S = 5.0  # a running campaign's snapshot is read again at least this often (elapsed, ETA, lanes' times)
HEARTBEAT_S = 15.0
MAX_STREAMS = 64  # viewers streaming at once; one more is told to come back later
MAX_PATHS = 32  # path figures kept in memory
MAX_RUNS_LISTED = 2000
CHUNK_BYTES = 256 * 1024  # a served file is read and sent in pieces of this size
SERVED_TOP = (
    campaign_files.REPORT,
    campaign_files.RUNS,
    campaign_files.RESULTS_CSV,
    campaign_files.RESULTS_PARQUET,
    campaign_files.SPEC,
)
STATIC = {"page.js": "application/javascript", "page.css": "text/css"}
_BAD_RAW = re.compile(r"%(2f|5c|00|2e)|\\|\x00", re.IGNORECASE)
TOKEN_COOKIE = "slamrun_token"


@dataclass
class Cached:
    signature: Signature | None = None
    read_at: float = 0.0
    body: bytes = b""
    version: int = 0
    active: bool = False  # the campaign was running at the last read
    cost_s: float = 0.0  # how long the last read took
    lock: asyncio.Lock = field(default_factory=asyncio.Lock)


class Hub:
    """Each campaign's latest snapshot as JSON bytes with a version number that changes when the bytes do."""

    def __init__(self, root: Path, interval_s: float):
        self.root = root
        self.interval_s = interval_s
        self.cached: dict[str, Cached] = {}
        self.paths: OrderedDict[tuple, dict] = OrderedDict()
        self._listed: tuple[float, dict[str, Path]] = (0.0, {})

    def campaigns(self) -> dict[str, Path]:
        """The campaigns, listed again at most once a second."""
        at, found = self._listed
        if time.monotonic() - at > 1.0:
            found = campaigns(self.root)
            self._listed = (time.monotonic(), found)
        return found

    def folder(self, name: str) -> Path:
        folder = self.campaigns().get(name)
        if folder is None:
            raise web.HTTPNotFound(text=f"no campaign {name!r} here\n")
        return folder

    async def state(self, name: str) -> tuple[bytes, int]:
        """The campaign's snapshot: read again when the ledger or the report changed, but never sooner than
        `interval_s`, nor than 4x the last read's own time after it (a 10,000-run ledger that changes all the time
        costs at most a fifth of a core, whatever the number of viewers)."""
        folder = self.folder(name)
        entry = self.cached.setdefault(name, Cached())
        async with entry.lock:
            if entry.body and time.monotonic() - entry.read_at < max(self.interval_s, 4 * entry.cost_s):
                return entry.body, entry.version
            signature = Signature.of(folder)
            stale = signature != entry.signature
            if not stale and entry.body:
                stale = entry.active and time.monotonic() - entry.read_at >= REFRESH_S
            if stale or not entry.body:
                started = time.monotonic()
                data = await asyncio.to_thread(snapshot, folder, name)
                data["sections"] = sections.sections(data)  # the page's sections, rendered once per change
                body = jsonio.dumps(data).encode()
                entry.signature, entry.read_at = signature, time.monotonic()
                entry.cost_s = entry.read_at - started
                entry.active = bool(data["progress"]["active"])
                if body != entry.body:
                    entry.body, entry.version = body, entry.version + 1
        return entry.body, entry.version

    async def path(self, name: str, key: str) -> dict:
        folder = self.folder(name)
        run = runview.run_folder(folder, key)
        traj = RunPaths.trajectory(run) if run else None
        stamp = traj.stat().st_mtime_ns if traj and traj.is_file() else None
        cache_key = (name, key, stamp)
        if cache_key in self.paths:
            self.paths.move_to_end(cache_key)
            return self.paths[cache_key]
        figure = await asyncio.to_thread(runview.path_figure, folder, key)
        self.paths[cache_key] = figure
        while len(self.paths) > MAX_PATHS:
            self.paths.popitem(last=False)
        return figure


HUB = web.AppKey("hub", Hub)  # the application's state, typed (aiohttp's AppKey)
STREAMS = web.AppKey("streams", int)  # event streams open now
CLOSING = web.AppKey("closing", asyncio.Event)  # set at shutdown: every event stream ends at once


def make_app(
    root: Path,
    token: str | None = None,
    port: int | None = None,
    interval_s: float = 1.0,
    host: str | None = None,
    watch: Watch | None = None,
) -> web.Application:
    """The server's application for the folder `root`; `token` (when serving beyond loopback) is asked of every
    request; `port` (when bound to loopback) limits the Host header to loopback names (no DNS rebinding); `watch`
    (the server's connections) learns which connection is answering a request."""
    hub = Hub(Path(root), interval_s)
    middlewares = [_guard(token, port, host), _one_line_errors] + ([_answering(watch)] if watch is not None else [])
    app = web.Application(middlewares=middlewares, client_max_size=1024)
    app[HUB] = hub
    app[STREAMS] = 0
    app[CLOSING] = asyncio.Event()

    async def closing(app: web.Application) -> None:
        app[CLOSING].set()

    app.on_shutdown.append(closing)
    app.on_response_prepare.append(_secure)
    app.router.add_get("/", index)
    app.router.add_get("/api/campaigns", list_campaigns)
    app.router.add_get("/static/{name}", static)
    app.router.add_get("/c/{name}/", page)
    app.router.add_get("/c/{name}/api/state", state)
    app.router.add_get("/c/{name}/events", events)
    app.router.add_get("/c/{name}/api/runs", runs)
    app.router.add_get("/c/{name}/api/path", path)
    app.router.add_get("/c/{name}/api/log", log)
    app.router.add_get("/c/{name}/files/{tail:.+}", files)
    return app


def _guard(token: str | None, port: int | None, host: str | None = None):
    """GET and HEAD only; no encoded separator, backslash or NUL in the raw path; on loopback, a loopback Host
    header (127.0.0.1, localhost, [::1], or the loopback address it listens on); beyond it, the token (query
    `token=` once, then a cookie, set on a redirect too); headers that keep the page to itself."""
    named = ("127.0.0.1", "localhost", "[::1]", *([f"[{host}]" if ":" in host else host] if host else []))
    hosts = {f"{h}:{port}" for h in named} if port is not None else None

    @web.middleware
    async def guard(request: web.Request, handler):
        if request.method not in ("GET", "HEAD"):
            raise web.HTTPMethodNotAllowed(request.method, ["GET", "HEAD"])
        if _BAD_RAW.search(request.raw_path.split("?", 1)[0]) or "/../" in f"{request.raw_path}/":
            raise web.HTTPNotFound(text="no such file here\n")
        if hosts is not None and request.host not in hosts:
            raise web.HTTPForbidden(text="this server answers to 127.0.0.1 and localhost only\n")
        set_cookie = False
        if token is not None:
            given = request.query.get("token") or request.cookies.get(TOKEN_COOKIE) or ""
            if not hmac.compare_digest(given.encode(), token.encode()):
                raise web.HTTPUnauthorized(text="a token is needed: open the address `slamrun serve` printed\n")
            set_cookie = "token" in request.query
        try:
            response = await handler(request)
        except web.HTTPRedirection as exc:  # the one-campaign folder's / leads on: the token goes with it
            if set_cookie:
                exc.set_cookie(TOKEN_COOKIE, token, httponly=True, samesite="Strict")
            raise
        if set_cookie and not response.prepared:
            response.set_cookie(TOKEN_COOKIE, token, httponly=True, samesite="Strict")
        return response

    return guard


@web.middleware
async def _one_line_errors(request: web.Request, handler):
    """What goes wrong with the folder served (a damaged ledger, a folder moved or deleted while served) is a 503
    with one line, never a 500 with a traceback; the server goes on."""
    try:
        return await handler(request)
    except SlamRunError as exc:
        raise web.HTTPServiceUnavailable(text=f"{' '.join(str(exc).split())[:500]}\n") from None
    except (FileNotFoundError, NotADirectoryError) as exc:
        raise web.HTTPServiceUnavailable(text=f"{exc.filename}: gone (moved or deleted while served)\n") from None


def _answering(watch: Watch):
    """Tells `watch` that a request's connection is busy while its handler runs (an event stream: all along)."""

    @web.middleware
    async def answering(request: web.Request, handler):
        watch.begin(request.protocol)
        try:
            return await handler(request)
        finally:
            watch.end(request.protocol)

    return answering


SECURITY_HEADERS = {
    "X-Content-Type-Options": "nosniff",
    "X-Frame-Options": "DENY",
    "Referrer-Policy": "no-referrer",
    "Content-Security-Policy": "default-src 'self'; img-src 'self' data:; style-src 'self' 'unsafe-inline'; "
    "connect-src 'self'; object-src 'none'; base-uri 'none'",
}

# The report's pages run its two inline scripts (allowed by their SHA-256, nothing else inline) and plotly.js and the
# views' scripts from the report's folder
REPORT_CSP = (
    SECURITY_HEADERS["Content-Security-Policy"]
    + "; script-src 'self' "
    + " ".join(
        f"'sha256-{base64.b64encode(hashlib.sha256(script.encode()).digest()).decode()}'" for script in INLINE_SCRIPTS
    )
)


async def _secure(request: web.Request, response: web.StreamResponse) -> None:
    """Every response's headers that keep the page to itself, set as it is sent (streamed ones too); a handler's
    own stricter policy (a method's file: a sandbox) stays."""
    for name, value in SECURITY_HEADERS.items():
        response.headers.setdefault(name, value)


def _html(title: str, body_attrs: str, main: str = "<p>loading...</p>", data: str = "") -> str:
    """A page: its `main` as the server renders it (the script takes over from there), `data` blocks after it."""
    return (
        "<!doctype html>\n<html lang=en><head><meta charset=utf-8>"
        '<meta name=viewport content="width=device-width, initial-scale=1">'
        f"<title>{html.escape(title)}</title>"
        '<link rel=stylesheet href="/static/page.css">'
        '<script src="/static/plotly.min.js" defer></script>'
        '<script src="/static/page.js" defer></script>'
        f"</head><body {body_attrs}><main id=app>{main}</main>{data}</body></html>\n"
    )


async def index(request: web.Request) -> web.Response:
    found = request.app[HUB].campaigns()
    if len(found) == 1 and CampaignFiles(request.app[HUB].root).ledger.is_file():
        raise web.HTTPFound(f"/c/{next(iter(found))}/")
    return web.Response(text=_html("slamrun: campaigns", "data-view=campaigns"), content_type="text/html")


async def list_campaigns(request: web.Request) -> web.Response:
    hub: Hub = request.app[HUB]
    listed = []
    for name in hub.campaigns():
        try:
            body, _ = await hub.state(name)
        except (SlamRunError, OSError) as exc:
            listed.append({"name": name, "error": str(exc)[:300]})
            continue
        progress = json.loads(body)["progress"]
        keep = ("total", "finished", "done", "failed", "infra", "active", "eta_s", "elapsed_s")
        listed.append({"name": name, **{k: progress[k] for k in keep}})
    return web.json_response({"campaigns": listed}, dumps=jsonio.dumps)


async def static(request: web.Request) -> web.Response:
    name = request.match_info["name"]
    if name == "plotly.min.js":
        return web.Response(body=_plotly_js(), content_type="application/javascript", headers=_cache_for(3600))
    if name not in STATIC:
        raise web.HTTPNotFound()
    body = resources.files("slamrun.serve").joinpath("static", name).read_bytes()
    return web.Response(body=body, content_type=STATIC[name])


_PLOTLY: list[bytes] = []


def _plotly_js() -> bytes:
    """plotly.js as the installed plotly package ships it (the report's own), read once."""
    if not _PLOTLY:
        from plotly.offline import get_plotlyjs

        _PLOTLY.append(get_plotlyjs().encode())
    return _PLOTLY[0]


def _cache_for(seconds: int) -> dict:
    return {"Cache-Control": f"max-age={seconds}"}


async def page(request: web.Request) -> web.Response:
    """The campaign's page with its state rendered on the server (curl and a screenshot see it) and embedded for
    the script, whose first render then needs no request."""
    name = request.match_info["name"]
    request.app[HUB].folder(name)
    attrs = f'data-view=campaign data-campaign="{html.escape(name)}"'
    try:
        body, _ = await request.app[HUB].state(name)
    except SlamRunError as exc:  # a damaged ledger, one being replaced: said, and the script tries again
        main = f'<p class="problem">{html.escape(str(exc))}</p><p>loading...</p>'
        return web.Response(text=_html(f"slamrun: {name}", attrs, main), content_type="text/html")
    snap = json.loads(body)
    title = f"{snap['progress']['finished']}/{snap['progress']['total']} · {snap['campaign']} · slamrun"
    page_html = _html(title, attrs, "".join(snap["sections"].values()), sections.embedded(body))
    return web.Response(text=page_html, content_type="text/html")


async def state(request: web.Request) -> web.Response:
    body, version = await _state_or_error(request)
    return web.Response(body=body, content_type="application/json", headers={"X-Version": str(version)})


async def _state_or_error(request: web.Request) -> tuple[bytes, int]:
    try:
        return await request.app[HUB].state(request.match_info["name"])
    except SlamRunError as exc:  # a damaged ledger, one being replaced
        raise web.HTTPServiceUnavailable(text=f"{exc}\n") from None


async def events(request: web.Request) -> web.StreamResponse:
    """Server-sent events: `state` with the snapshot whenever it changes, a comment line as a heartbeat."""
    app = request.app
    if app[STREAMS] >= MAX_STREAMS:
        raise web.HTTPServiceUnavailable(text=f"over {MAX_STREAMS} viewers stream now; poll api/state instead\n")
    hub: Hub = app[HUB]
    hub.folder(request.match_info["name"])
    response = web.StreamResponse(headers={"Content-Type": "text/event-stream", "Cache-Control": "no-cache"})
    app[STREAMS] += 1
    try:
        await response.prepare(request)
        sent, quiet_since = -1, time.monotonic()
        while True:
            try:
                body, version = await hub.state(request.match_info["name"])
            except (SlamRunError, web.HTTPException) as exc:
                await response.write(f"event: problem\ndata: {json.dumps(str(exc)[:300])}\n\n".encode())
                body, version = b"", sent
            if version != sent:
                await response.write(b"event: state\ndata: " + body + b"\n\n")
                sent, quiet_since = version, time.monotonic()
            elif time.monotonic() - quiet_since > HEARTBEAT_S:
                await response.write(b": still here\n\n")
                quiet_since = time.monotonic()
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(app[CLOSING].wait(), timeout=hub.interval_s)
            if app[CLOSING].is_set():
                break
    except ConnectionResetError:  # the viewer went away
        pass
    finally:
        app[STREAMS] -= 1
    return response


async def runs(request: web.Request) -> web.Response:
    """The done runs (key, method, dataset, sequence, direction, trial, main metrics), optionally of one
    sequence; at most MAX_RUNS_LISTED."""
    from slamrun.engine.ledger import Ledger

    folder = request.app[HUB].folder(request.match_info["name"])
    sequence = request.query.get("sequence")
    cols = ("key", "method", "dataset", "sequence", "direction", "trial", *MAIN_METRICS)

    def read() -> list[dict]:
        ledger = Ledger(CampaignFiles(folder).ledger, read_only=True)
        try:
            rows = ledger.rows(status="done", columns=cols)
        finally:
            ledger.close()
        return [r for r in rows if sequence is None or r["sequence"] == sequence]

    rows = await asyncio.to_thread(read)
    listed = rows[:MAX_RUNS_LISTED]
    sequences = sorted({f"{r['sequence']}" for r in rows})
    return web.json_response(
        {"total": len(rows), "runs": listed, "sequences": sequences}, dumps=lambda o: jsonio.dumps(o)
    )


async def path(request: web.Request) -> web.Response:
    key = request.query.get("key", "")
    try:
        figure = await request.app[HUB].path(request.match_info["name"], key)
    except (SlamRunError, OSError, ValueError) as exc:
        raise web.HTTPNotFound(text=f"{exc}\n") from None
    return web.json_response(figure, dumps=jsonio.dumps)


async def log(request: web.Request) -> web.Response:
    folder = request.app[HUB].folder(request.match_info["name"])
    key = request.query.get("key", "")
    text = await asyncio.to_thread(runview.log_tail, folder, key)
    if text is None:
        raise web.HTTPNotFound(text=f"no log of a run {key!r} here\n")
    return web.Response(text=text, content_type="text/plain")


async def files(request: web.Request) -> web.StreamResponse:
    """A file of the campaign's folder, opened without a check-then-open gap (folders.open_served). What slamrun
    wrote (report/, results, the resolved spec) is served with its type; what a method wrote (anything under
    runs/) as plain text when it is text and as a download otherwise, never as a page of this server's origin."""
    folder = request.app[HUB].folder(request.match_info["name"])
    tail = request.match_info["tail"]
    if tail.split("/", 1)[0] not in SERVED_TOP:
        raise web.HTTPNotFound(text="no such file here\n")
    f = await asyncio.to_thread(open_served, folder, tail)
    if f is None:
        raise web.HTTPNotFound(text="no such file here\n")
    try:
        size = os.fstat(f.fileno()).st_size
        name = tail.rsplit("/", 1)[-1]
        headers = {"Cache-Control": "no-cache", "Content-Length": str(size)}
        if tail.startswith("runs/"):
            headers |= _method_file_headers(name)
        else:
            headers["Content-Type"] = mimetypes.guess_type(name)[0] or "application/octet-stream"
            if tail.startswith("report/") and headers["Content-Type"] == "text/html":
                headers["Content-Security-Policy"] = REPORT_CSP
        response = web.StreamResponse(headers=headers)
        await response.prepare(request)
        if request.method != "HEAD":
            while chunk := await asyncio.to_thread(f.read, CHUNK_BYTES):
                await response.write(chunk)
        await response.write_eof()
        return response
    finally:
        f.close()


def _method_file_headers(name: str) -> dict[str, str]:
    """A run's file as plain text (what a browser shows, never runs: its trajectory, log, run.json) or, for any
    other kind, a download; a sandbox in either case, so nothing it holds acts in this server's origin."""
    kind = mimetypes.guess_type(name)[0] or ""
    text = kind.startswith("text/") or kind in ("application/json", "application/x-yaml") or "." not in name
    shown = (
        {"Content-Type": "text/plain; charset=utf-8"}
        if text
        else {
            "Content-Type": "application/octet-stream",
            "Content-Disposition": f"attachment; filename*=UTF-8''{urllib.parse.quote(name)}",
        }
    )
    return shown | {"Content-Security-Policy": "sandbox; default-src 'none'"}

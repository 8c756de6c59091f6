"""Starting and stopping `slamrun serve`: the address rules (loopback by default; any other address only with a
warning and a token), the listening socket, and a clean end on Ctrl-C or SIGTERM."""

from __future__ import annotations

import asyncio
import ipaddress
import secrets
import signal
import socket
import sys
import time
from pathlib import Path

from slamrun.errors import SlamRunError
from slamrun.serve import connections
from slamrun.serve.folders import LEDGER, campaigns

MIN_TOKEN = 16


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def check_folder(root: Path) -> dict[str, Path]:
    found = campaigns(root)
    if not found:
        raise SlamRunError(
            f"{root}: holds no campaign (no {LEDGER} in it or in a folder directly under it); "
            "expected a results folder of `slamrun campaign`"
        )
    return found


WAIT_POLL_S = 0.5


def wait_for_campaign(root: Path, poll_s: float = WAIT_POLL_S) -> None:
    """Return once `root` holds a campaign; until then say once what it waits for (a campaign started a moment
    before creates its folder and ledger a moment later). Ctrl-C ends the wait."""
    said = False
    while True:
        try:
            if campaigns(root):
                return
            why = "holds no campaign yet"
        except SlamRunError:
            why = "does not exist yet"
        if not said:
            print(
                f"slamrun serve: {root} {why}; waiting for a campaign there (`slamrun campaign` creates its "
                f"results folder and {LEDGER}; Ctrl-C to stop)",
                file=sys.stderr,
                flush=True,
            )
            said = True
        time.sleep(poll_s)


def serve(root: Path, host: str, port: int, token: str | None, interval_s: float) -> int:
    """Serve `root` until interrupted; 0 when stopped by Ctrl-C or SIGTERM."""
    loopback = is_loopback(host)
    if loopback:
        token = None
    else:
        if token is not None and len(token) < MIN_TOKEN:
            raise SlamRunError(f"--token: at least {MIN_TOKEN} characters (a random one is made when none is given)")
        token = token or secrets.token_urlsafe(24)
    wait_for_campaign(root)
    check_folder(root)
    return asyncio.run(_serve(root, host, port, token, interval_s, loopback))


def urls(host: str, port: int, token: str | None, names: list[str]) -> list[str]:
    """The addresses to print: `host`'s, or for a wildcard host (0.0.0.0, ::), one per name of this machine (`names`:
    its host name, then its addresses), since 0.0.0.0 opens nothing on a colleague's machine."""
    wildcard = host in ("0.0.0.0", "::", "[::]", "")
    query = f"?token={token}" if token else ""
    return [f"http://{f'[{h}]' if ':' in h else h}:{port}/{query}" for h in (names if wildcard else [host])]


def machine_names(host: str) -> list[str]:
    """This machine's host name and its addresses beyond loopback (IPv4 for 0.0.0.0; IPv6 too for ::)."""
    import psutil

    families = (socket.AF_INET,) if host == "0.0.0.0" else (socket.AF_INET, socket.AF_INET6)
    found = [socket.gethostname()]
    for addrs in psutil.net_if_addrs().values():
        for a in addrs:
            address = a.address.split("%")[0]
            if a.family in families and not ipaddress.ip_address(address).is_loopback:
                if not ipaddress.ip_address(address).is_link_local:
                    found.append(address)
    return list(dict.fromkeys(found))


async def _serve(root: Path, host: str, port: int, token: str | None, interval_s: float, loopback: bool) -> int:
    from aiohttp import web

    from slamrun.serve.app import make_app

    sock = _listen(host, port)
    bound = sock.getsockname()[1]
    watch = connections.Watch()
    app = make_app(root, token=token, port=bound if loopback else None, interval_s=interval_s, host=host, watch=watch)
    runner = web.AppRunner(
        app, access_log=None, handle_signals=False, shutdown_timeout=1.0, keepalive_timeout=2 * connections.IDLE_S
    )
    await runner.setup()
    loop = asyncio.get_running_loop()
    loop.set_exception_handler(lambda _loop, context: watch.refusals.note(_loop_error(context)))
    listening = await loop.create_server(watch.factory(runner.server), sock=sock)
    sweeper = asyncio.create_task(watch.sweeping())
    addresses = urls(host, bound, token, machine_names(host))
    if not loopback:
        print(
            f"slamrun serve: WARNING: listening on {host}, not this machine alone: anyone who can reach it and has "
            "the token sees the campaign (its logs, paths and figures). The traffic is not encrypted.",
            file=sys.stderr,
        )
    print(f"slamrun serve: {root} at {addresses[0]} (Ctrl-C to stop)", flush=True)
    for other in addresses[1:]:
        print(f"slamrun serve: also at {other}", flush=True)
    stop = asyncio.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    try:
        await stop.wait()
    finally:
        sweeper.cancel()
        listening.close()
        await runner.cleanup()
    return 0


def _loop_error(context: dict) -> str:
    """What went wrong in the event loop (accept() out of file descriptors, a protocol's error), as one line's
    kind: printed once per LOG_EVERY_S with its count, never a traceback per connection."""
    exc = context.get("exception")
    what = context.get("message", "an error in the server's event loop")
    return f"{what}: {type(exc).__name__}: {exc}"[:300] if exc is not None else what[:300]


def _listen(host: str, port: int) -> socket.socket:
    """The listening socket, or one line saying why there is none."""
    try:
        infos = socket.getaddrinfo(host.strip("[]"), port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    except socket.gaierror as exc:
        raise SlamRunError(f"--host {host}: not an address of this machine ({exc.strerror})") from None
    family, kind, proto, _, address = infos[0]
    sock = socket.socket(family, kind, proto)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind(address)
        sock.listen(128)
    except OSError as exc:
        sock.close()
        raise SlamRunError(f"cannot listen on {host}:{port}: {exc.strerror}; choose another --port") from None
    sock.setblocking(False)
    return sock

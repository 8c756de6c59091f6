"""The one plug-in registry: the entry points of a group (`slamrun.methods`, `slamrun.datasets`) found, each imported
once and checked by its kind, with one guard for a broken plug-in: a name a built-in has, a name two installed
distributions register, a module that raises (or calls sys.exit) at import or whose import does not return (given up
after SLAMRUN_PLUGIN_IMPORT_S seconds), an object of the wrong kind: each is named with why, and never stops slamrun
or the other plug-ins."""

from __future__ import annotations

import math
import os
import threading
from collections.abc import Callable, Collection
from dataclasses import dataclass
from typing import TypeVar

from slamrun.errors import one_line

T = TypeVar("T")

# How long a plug-in's import may take (s; importing torch with its CUDA libraries takes seconds), unless the variable
# says otherwise
IMPORT_LIMIT_S = 60.0
IMPORT_LIMIT_VARIABLE = "SLAMRUN_PLUGIN_IMPORT_S"
_HUNG: dict[str, float] = {}  # module -> the limit its import did not return within (its thread may still wait)


@dataclass(frozen=True)
class Provider:
    """The installed distribution a plug-in comes from."""

    distribution: str
    version: str

    def __str__(self) -> str:
        return f"{self.distribution} {self.version}"


@dataclass
class Found:
    """What a group's discovery gives: the plug-ins accepted (name -> object), why the others are not registered,
    and the distribution behind each accepted one."""

    loaded: dict
    errors: dict[str, str]
    providers: dict[str, Provider]


def provider_of(ep) -> Provider:
    dist = ep.dist
    if dist is None:
        return Provider("an unknown distribution", "?")
    return Provider(dist.name or "an unnamed distribution", dist.version or "?")


def discover(
    group: str, built_in: Collection[str], kind: str, accept: Callable[[str, object, Provider, str], T | str]
) -> Found:
    """Every entry point of `group`: refused when its name is a built-in `kind`'s or two distributions register it;
    else imported (whatever it raises is named) and handed to `accept(name, obj, provider, where)`, which returns
    what is registered, or why not (a string). Each import is given import_limit() seconds."""
    from importlib.metadata import entry_points

    limit = import_limit()
    found: dict[str, dict[tuple[Provider, str], object]] = {}
    for ep in entry_points(group=group):
        found.setdefault(ep.name, {})[(provider_of(ep), ep.value)] = ep
    out = Found({}, {}, {})
    for name, eps in sorted(found.items()):
        where = ", ".join(f"{value} from {provider}" for provider, value in eps)
        if name in built_in:
            out.errors[name] = f"plug-in {where}: {name!r} is a built-in {kind}"
        elif len(eps) > 1:
            out.errors[name] = (
                f"{name!r} is registered by {len(eps)} installed plug-ins ({where}), so slamrun cannot tell which "
                f"one to use: uninstall all but one (pip uninstall {' or '.join(p.distribution for p, _ in eps)})"
            )
        else:
            (provider, _value), ep = next(iter(eps.items()))
            obj, why = load(ep, where, limit)
            if why is not None:
                out.errors[name] = why
                continue
            got = accept(name, obj, provider, where)
            if isinstance(got, str):
                out.errors[name] = got
            else:
                out.loaded[name] = got
                out.providers[name] = provider
    return out


def import_limit() -> float | str:
    """The seconds a plug-in's import may take: SLAMRUN_PLUGIN_IMPORT_S, or IMPORT_LIMIT_S; or why the variable's
    value is none (then no plug-in is imported, each named with that line)."""
    raw = os.environ.get(IMPORT_LIMIT_VARIABLE)
    if raw is None:
        return IMPORT_LIMIT_S
    try:
        value = float(raw)
    except ValueError:
        value = math.nan
    if math.isfinite(value) and value > 0:
        return value
    return f"{IMPORT_LIMIT_VARIABLE}={raw!r}: expected a number of seconds above 0 (default {IMPORT_LIMIT_S:g})"


def load(ep, where: str, limit: float | str) -> tuple[object, str | None]:
    """(the object entry point `ep` names, None), or (None, why not): its import raised (sys.exit() included), or
    did not return within `limit` seconds. The import runs in a thread of its own, which a hung import leaves
    waiting (a daemon: it ends with the process; Python cannot stop it); another entry point of that module is then
    named at once, never waited for again."""
    if isinstance(limit, str):
        return None, f"plug-in {where} was not imported: {limit}"
    module = ep.value.split(":", 1)[0].strip()
    if module in _HUNG:
        return None, _hung(where, _HUNG[module])
    box: dict = {}

    def target() -> None:
        try:
            box["obj"] = ep.load()
        except BaseException as exc:  # noqa: BLE001 - sys.exit() or any error of someone else's package
            box["error"] = exc

    worker = threading.Thread(target=target, name=f"plug-in import {ep.name}", daemon=True)
    worker.start()
    worker.join(limit)
    if worker.is_alive():
        _HUNG[module] = limit
        return None, _hung(where, limit)
    if "error" in box:
        return None, f"plug-in {where} cannot be imported: {one_line(box['error'])}"
    return box["obj"], None


def _hung(where: str, limit: float) -> str:
    return (
        f"plug-in {where} cannot be imported: its import did not return within {limit:g} s and was given up "
        f"({IMPORT_LIMIT_VARIABLE} sets the limit, default {IMPORT_LIMIT_S:g} s)"
    )

"""The one plug-in registry: the entry points of a group (`slamrun.methods`, `slamrun.datasets`) found, each imported
once and checked by its kind, with one guard for a broken plug-in: a name a built-in has, a name two installed
distributions register, a module that raises (or calls sys.exit) at import, an object of the wrong kind: each is named
with why, and never stops slamrun or the other plug-ins."""

from __future__ import annotations

from collections.abc import Callable, Collection
from dataclasses import dataclass
from typing import TypeVar

from slamrun.errors import one_line

T = TypeVar("T")


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
    what is registered, or why not (a string)."""
    from importlib.metadata import entry_points

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
            try:
                obj = ep.load()
            except KeyboardInterrupt:
                raise
            except BaseException as exc:  # noqa: BLE001 - sys.exit() or any error of someone else's package
                out.errors[name] = f"plug-in {where} cannot be imported: {one_line(exc)}"
                continue
            got = accept(name, obj, provider, where)
            if isinstance(got, str):
                out.errors[name] = got
            else:
                out.loaded[name] = got
                out.providers[name] = provider
    return out

"""The method registry (the one source of truth for method names) and the plug-in API for a method.

A plug-in's adapter imports what it needs from here: `from slamrun.methods import Method, PreparedView, Profile`
(and NoParams, PythonProcess, read_tum_output, require_poses, executable_problem, Direction); what a dataset
layout needs comes from `slamrun.datasets`. Everything else under slamrun/ may move between releases.

The spec validator, the CLI's method list, the image build targets and the tests all read REGISTRY. Methods from
other Python packages join it through the entry-point group `slamrun.methods` (`name = "package.module:Class"`, a
subclass of slamrun.methods.Method with the same contract as the built-in ones); a plug-in that cannot be loaded,
or a name two installed packages register, is named with its reason when a spec asks for it (PLUGIN_ERRORS), and
never breaks the others. A registered plug-in's calls are guarded (slamrun.methods.base.guarded): whatever it raises
is its own failure, never slamrun's; its distribution and version (PLUGINS) key its runs and are recorded in run.json.
"""

from __future__ import annotations

import functools
import importlib
from pathlib import Path

from slamrun.core.suggest import did_you_mean
from slamrun.datasets.view import Direction, PreparedView, Profile
from slamrun.errors import one_line
from slamrun.methods.base import (
    Method,
    NoParams,
    Provider,
    PythonProcess,
    executable_problem,
    guarded,
    read_tum_output,
    require_poses,
)

__all__ = [  # the plug-in API, then the registry
    "Method",
    "NoParams",
    "PythonProcess",
    "read_tum_output",
    "require_poses",
    "executable_problem",
    "PreparedView",
    "Profile",
    "Direction",
    "REGISTRY",
    "STUDY_METHODS",
    "PLUGINS",
    "PLUGIN_ERRORS",
    "get",
    "describe",
    "provider_record",
]

STUDY_METHODS = ("orb_slam2", "df_orb_slam", "lsd_slam", "dso", "svo", "ldso", "dsm", "dynaslam", "cnn_dso", "cnn_svo")

HERE = Path(__file__).parent


def _built_in() -> dict[str, type[Method]]:
    """The built-in methods: each folder of slamrun/methods/ with an __init__.py is one, named by the folder, and
    declares its class there (the study's ten first, in the study's order, then the others by name)."""
    found = {}
    for folder in sorted(p.parent for p in HERE.glob("*/__init__.py")):
        module = importlib.import_module(f"{__name__}.{folder.name}")
        classes = [
            c
            for c in vars(module).values()
            if isinstance(c, type) and issubclass(c, Method) and c.__module__ == module.__name__
            and getattr(c, "name", None) == folder.name
        ]  # fmt: skip
        if len(classes) != 1:
            raise ImportError(f"{folder}: declares {len(classes)} Method classes named {folder.name!r}, not one")
        found[folder.name] = classes[0]
    order = [n for n in STUDY_METHODS if n in found] + sorted(set(found) - set(STUDY_METHODS))
    return {n: found[n] for n in order}


REGISTRY: dict[str, type[Method]] = _built_in()


PLUGIN_GROUP = "slamrun.methods"
PLUGIN_ERRORS: dict[str, str] = {}  # entry-point name -> why it could not be registered
PLUGINS: dict[str, Provider] = {}  # method name -> the installed distribution that provides it


def _load_plugins() -> None:
    """Register the group's entry points: a name two distributions register is refused (naming both), as is one a
    built-in has; each other one is imported, checked and registered, or named with why not. Nothing a plug-in does
    at import (an exception, sys.exit) stops slamrun."""
    from importlib.metadata import entry_points

    found: dict[str, dict[tuple[Provider, str], object]] = {}
    for ep in entry_points(group=PLUGIN_GROUP):
        found.setdefault(ep.name, {})[(_provider(ep), ep.value)] = ep
    for name, eps in found.items():
        where = ", ".join(f"{value} from {provider}" for provider, value in eps)
        if name in REGISTRY:
            PLUGIN_ERRORS[name] = f"plug-in {where}: {name!r} is taken by a built-in method"
        elif len(eps) > 1:
            PLUGIN_ERRORS[name] = (
                f"{name!r} is registered by {len(eps)} installed plug-ins ({where}), so slamrun cannot tell which "
                f"one to run: uninstall all but one (pip uninstall {' or '.join(p.distribution for p, _ in eps)})"
            )
        else:
            (provider, _value), ep = next(iter(eps.items()))
            _register(name, ep, provider, where)


def _provider(ep) -> Provider:
    dist = ep.dist
    if dist is None:
        return Provider("an unknown distribution", "?")
    return Provider(dist.name or "an unnamed distribution", dist.version or "?")


def _register(name: str, ep, provider: Provider, where: str) -> None:
    try:
        cls = ep.load()
    except KeyboardInterrupt:
        raise
    except BaseException as exc:  # noqa: BLE001 - sys.exit() or any error of someone else's package: named, not raised
        PLUGIN_ERRORS[name] = f"plug-in {where} cannot be imported: {one_line(exc)}"
        return
    if not (isinstance(cls, type) and issubclass(cls, Method)):
        PLUGIN_ERRORS[name] = f"plug-in {where} is not a subclass of slamrun.methods.Method"
    elif getattr(cls, "name", None) != name:
        PLUGIN_ERRORS[name] = f"plug-in {where}: its class's name is {getattr(cls, 'name', None)!r}, not {name!r}"
    elif missing := sorted(getattr(cls, "__abstractmethods__", ())):
        PLUGIN_ERRORS[name] = f"plug-in {where}: {cls.__name__} does not implement {', '.join(missing)}"
    else:
        REGISTRY[name] = guarded(cls, f"plug-in {name} ({provider})")
        PLUGINS[name] = provider


_load_plugins()


def get(name: str) -> type[Method]:
    try:
        return REGISTRY[name]
    except KeyError:
        if name in PLUGIN_ERRORS:
            raise KeyError(PLUGIN_ERRORS[name]) from None
        hint = did_you_mean(name, REGISTRY)
        raise KeyError(f"unknown method {name!r}{hint} (known: {', '.join(sorted(REGISTRY))})") from None


def describe(name: str) -> str:
    """A method as messages name it: the plug-in with its distribution, or the built-in's name."""
    provider = PLUGINS.get(name)
    return f"plug-in {name} ({provider})" if provider else name


def provider_record(name: str) -> dict[str, str]:
    """The distribution that provides method `name` (run.json): the plug-in's package, or slamrun itself."""
    provider = PLUGINS.get(name) or _slamrun()
    return {"distribution": provider.distribution, "version": provider.version}


@functools.cache
def _slamrun() -> Provider:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return Provider("slamrun", version("slamrun"))
    except PackageNotFoundError:
        return Provider("slamrun", "?")

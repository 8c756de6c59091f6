"""The method registry (the one source of truth for method names) and the plug-in API for a method.

A plug-in's adapter imports what it needs from here: `from slamrun.methods import Method, PreparedView, Profile`
(and NoParams, PythonProcess, read_tum_output, require_poses, executable_problem, Direction); what a dataset
layout needs comes from `slamrun.datasets`. Everything else under slamrun/ may move between releases.

The spec validator, the CLI's method list, the image build targets and the tests all read REGISTRY. Methods from
other Python packages join it through the entry-point group `slamrun.methods` (`name = "package.module:Class"`, a
subclass of slamrun.methods.Method with the same contract as the built-in ones); a plug-in that cannot be loaded
(its import raises, or does not return within SLAMRUN_PLUGIN_IMPORT_S seconds; its `threads` is no int >= 1 nor
None), a name two installed packages register, or a folder here that declares no Method class, is named with its
reason by list-methods and when a spec asks for it (PLUGIN_ERRORS), and never breaks the others. A registered
plug-in's calls are guarded (slamrun.methods.base.guarded): whatever it raises, or a value slamrun cannot use, is its
own failure, never slamrun's; its distribution and version (PLUGINS) key its runs and are recorded in run.json.
"""

from __future__ import annotations

import functools
import importlib
import threading
from pathlib import Path

from slamrun.core.suggest import did_you_mean
from slamrun.datasets.view import Direction, PreparedView, Profile
from slamrun.errors import one_line
from slamrun.methods.base import (
    Method,
    NoParams,
    PythonProcess,
    executable_problem,
    guarded,
    read_tum_output,
    require_poses,
    threads_problem,
)
from slamrun.plugins import Provider, discover

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


def _built_in() -> tuple[dict[str, type[Method]], dict[str, str]]:
    """The built-in methods: each folder of slamrun/methods/ with an __init__.py is one, named by the folder, and
    declares its class there (the study's ten first, in the study's order, then the others by name); and the folders
    that are none (no Method class named by the folder, or an __init__.py that raises), each with why: named, never
    in the way of the others."""
    found, errors = {}, {}
    for folder in sorted(p.parent for p in HERE.glob("*/__init__.py")):
        got = _folder_method(folder)
        if isinstance(got, str):
            errors[folder.name] = f"slamrun/methods/{folder.name}/: {got}; not a method"
        else:
            found[folder.name] = got
    order = [n for n in STUDY_METHODS if n in found] + sorted(set(found) - set(STUDY_METHODS))
    return {n: found[n] for n in order}, errors


def _folder_method(folder: Path) -> type[Method] | str:
    """The one Method class a built-in folder's __init__.py declares, named by the folder; or why not."""
    try:
        module = importlib.import_module(f"{__name__}.{folder.name}")
    except Exception as exc:  # noqa: BLE001 - a half-written folder is named, the other methods stay
        return f"its __init__.py cannot be imported: {one_line(exc)}"
    classes = [
        c
        for c in vars(module).values()
        if isinstance(c, type) and issubclass(c, Method) and c.__module__ == module.__name__
        and getattr(c, "name", None) == folder.name
    ]  # fmt: skip
    if len(classes) != 1:
        return f"its __init__.py declares {len(classes)} Method classes named {folder.name!r}, not one"
    return classes[0]


class _WithPlugins(dict):
    """A dict of the registry that takes in the plug-ins on its first read (`_load_plugins`): their imports run once
    this module is whole, so a plug-in's `from slamrun.methods import Method` never waits for it."""

    def _loaded(self):
        _load_plugins()
        return self

    def __getitem__(self, key):
        return dict.__getitem__(self._loaded(), key)

    def __contains__(self, key) -> bool:
        return dict.__contains__(self._loaded(), key)

    def __iter__(self):
        return dict.__iter__(self._loaded())

    def __len__(self) -> int:
        return dict.__len__(self._loaded())

    def get(self, key, default=None):
        return dict.get(self._loaded(), key, default)

    def keys(self):
        return dict.keys(self._loaded())

    def values(self):
        return dict.values(self._loaded())

    def items(self):
        return dict.items(self._loaded())


_found, _errors = _built_in()
REGISTRY: dict[str, type[Method]] = _WithPlugins(_found)
# method name -> why it could not be registered: a plug-in's entry point, or a folder of slamrun/methods/
PLUGIN_ERRORS: dict[str, str] = _WithPlugins(_errors)


PLUGIN_GROUP = "slamrun.methods"
PLUGINS: dict[str, Provider] = _WithPlugins()  # method name -> the installed distribution that provides it
_PLUGINS_LOCK = threading.RLock()  # another thread's first read waits for the whole load
_PLUGINS_STATE = {"done": False, "loading": False}


def _accept(name: str, cls, provider: Provider, where: str) -> type[Method] | str:
    """A plug-in's class, checked as a built-in's is (a Method subclass, its name, its calls implemented), with its
    calls guarded; or why not."""
    if not (isinstance(cls, type) and issubclass(cls, Method)):
        return f"plug-in {where} is not a subclass of slamrun.methods.Method"
    if getattr(cls, "name", None) != name:
        return f"plug-in {where}: its class's name is {getattr(cls, 'name', None)!r}, not {name!r}"
    if missing := sorted(getattr(cls, "__abstractmethods__", ())):
        return f"plug-in {where}: {cls.__name__} does not implement {', '.join(missing)}"
    if why := threads_problem(getattr(cls, "threads", None)):
        return f"plug-in {where}: method {name!r} declares threads = {why}"
    return guarded(cls, f"plug-in {name} ({provider})")


def _load_plugins() -> None:
    """Register the group's entry points once, on the registry's first read (slamrun/plugins.py: one guard for a
    broken plug-in of any kind; each import bounded in time)."""
    if _PLUGINS_STATE["done"]:
        return
    with _PLUGINS_LOCK:
        if _PLUGINS_STATE["done"] or _PLUGINS_STATE["loading"]:
            return  # loaded, or a read of this thread's own during the load (_accept's)
        _PLUGINS_STATE["loading"] = True
        try:
            found = discover(PLUGIN_GROUP, dict(dict.items(REGISTRY)), "method", _accept)
            dict.update(REGISTRY, found.loaded)
            dict.update(PLUGIN_ERRORS, found.errors)
            dict.update(PLUGINS, found.providers)
        finally:
            _PLUGINS_STATE.update(done=True, loading=False)


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

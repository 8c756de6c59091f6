"""The method registry: the one source of truth for method names.

The spec validator, the CLI's method list, the image build targets and the tests all read REGISTRY.
"""

from __future__ import annotations

from methods.base import Method
from methods.external import External

REGISTRY: dict[str, type[Method]] = {cls.name: cls for cls in (External,)}


def get(name: str) -> type[Method]:
    try:
        return REGISTRY[name]
    except KeyError:
        raise KeyError(f"unknown method {name!r} (known: {', '.join(sorted(REGISTRY))})") from None

"""The method registry: the one source of truth for method names.

The spec validator, the CLI's method list, the image build targets and the tests all read REGISTRY.
"""

from __future__ import annotations

from methods.base import Method
from methods.colmap import Colmap
from methods.external import External
from methods.reference_vo.adapter import ReferenceVO

REGISTRY: dict[str, type[Method]] = {cls.name: cls for cls in (Colmap, External, ReferenceVO)}


def get(name: str) -> type[Method]:
    try:
        return REGISTRY[name]
    except KeyError:
        raise KeyError(f"unknown method {name!r} (known: {', '.join(sorted(REGISTRY))})") from None

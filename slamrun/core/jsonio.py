"""JSON as RFC 8259 defines it, for every JSON slamrun writes: NaN and the infinities become null (bare `NaN` is
not JSON: strict parsers and browsers refuse it), numpy scalars and arrays become numbers and lists, paths
strings."""

from __future__ import annotations

import json
import math
from pathlib import PurePath
from typing import Any


def plain(value: Any) -> Any:
    """`value` with every non-finite float replaced by None and numpy/Path values made plain, recursively
    (numpy is not imported: a command that prints JSON starts without it)."""
    if type(value).__module__ == "numpy" and hasattr(value, "tolist"):  # a numpy scalar or array
        return plain(value.tolist())
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, bool | int | str) or value is None:
        return value
    if isinstance(value, dict):
        return {str(k) if not isinstance(k, str) else k: plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple | set | frozenset):
        return [plain(v) for v in value]
    if isinstance(value, PurePath):
        return str(value)
    return value


def dumps(value: Any, **kw) -> str:
    """json.dumps of `plain(value)`, refusing anything that would not be RFC 8259 JSON."""
    return json.dumps(plain(value), allow_nan=False, **kw)

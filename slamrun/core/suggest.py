"""did-you-mean: the known name closest to one that is not known, for messages."""

from __future__ import annotations

from collections.abc import Iterable


def closest(name: str, known: Iterable[str]) -> str | None:
    """The known name `name` was meant to be: the same name in another case, else the closest by difflib (ratio at
    least 0.6, compared case-insensitively), else None."""
    by_lower: dict[str, str] = {}
    for k in known:
        by_lower.setdefault(k.lower(), k)
    key = name.lower()
    if key in by_lower:
        return by_lower[key]
    import difflib  # only when a name is not known

    hits = difflib.get_close_matches(key, list(by_lower), n=1, cutoff=0.6)
    return by_lower[hits[0]] if hits else None


def did_you_mean(name: str, known: Iterable[str]) -> str:
    """ "; did you mean 'x'?" for the closest known name, or "" where none is close."""
    hit = closest(name, known)
    return f"; did you mean {hit!r}?" if hit is not None and hit != name else ""

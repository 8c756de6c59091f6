"""One colour per method for the whole campaign, shared by the report's figures and `slamrun serve`'s page (which
does not import matplotlib): matplotlib's tab10 (tab20 beyond ten methods) over the methods sorted by name."""

from __future__ import annotations

from collections.abc import Iterable

TAB10 = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22", "#17becf")
TAB20 = (
    "#1f77b4", "#aec7e8", "#ff7f0e", "#ffbb78", "#2ca02c", "#98df8a", "#d62728", "#ff9896", "#9467bd", "#c5b0d5",
    "#8c564b", "#c49c94", "#e377c2", "#f7b6d2", "#7f7f7f", "#c7c7c7", "#bcbd22", "#dbdb8d", "#17becf", "#9edae5",
)  # fmt: skip


def method_colours(methods: Iterable[str]) -> dict[str, str]:
    """'#rrggbb' per method: a method keeps its colour from figure to figure, dataset to dataset, and on the live
    page while results arrive (the order is the names', not that of the first results)."""
    names = sorted({str(m) for m in methods})
    palette = TAB10 if len(names) <= 10 else TAB20
    return {m: palette[i % len(palette)] for i, m in enumerate(names)}

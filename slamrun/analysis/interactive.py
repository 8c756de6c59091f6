"""The report's interactive views: per sequence, the runs' paths over the ground truth in 3D (rotate, zoom, a run
shown or hidden by its legend entry), drawn by plotly.js. The library is the plotly package's own bundle, written
once beside the report (plotly.min.js): the views work offline, without a network or a CDN. Each view's data is a
small script of its own that the page loads when the view is opened, so a campaign of many sequences keeps a light
page and few WebGL contexts."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from slamrun.analysis.paths import SequencePaths

PLOTLY_JS = "plotly.min.js"
MAX_POINTS = 3000  # per path: a view of a long sequence stays small; the static figures draw every pose
DASH = {"best": "solid", "median": "dash", "worst": "dot"}
COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22")


def write_library(folder: Path) -> Path:
    """plotly.js, as the installed plotly package ships it, into `folder` (rewritten only when it differs)."""
    from plotly.offline import get_plotlyjs

    js = get_plotlyjs()
    path = folder / PLOTLY_JS
    folder.mkdir(parents=True, exist_ok=True)
    if not path.is_file() or path.read_text() != js:
        path.write_text(js)
    return path


def thinned(points: np.ndarray, limit: int = MAX_POINTS) -> np.ndarray:
    """At most `limit` rows, evenly spaced, the first and the last kept."""
    if len(points) <= limit:
        return points
    return points[np.unique(np.linspace(0, len(points) - 1, limit).round().astype(int))]


def _xyz(points: np.ndarray) -> dict[str, list]:
    """Plotly's x, y, z lists; null where a coordinate is missing (a gap in the line)."""
    p = thinned(points)
    scale = float(np.nanmax(np.abs(p))) if np.isfinite(p).any() else 1.0
    decimals = max(1, 4 - int(np.floor(np.log10(scale or 1.0))))  # about 1e-4 of the extent: under a pixel
    return {
        k: [None if not np.isfinite(v) else round(float(v), decimals) for v in p[:, i]] for i, k in enumerate("xyz")
    }


def view_figure(paths: SequencePaths, title: str, names: dict[str, str] | None = None) -> dict:
    """The plotly figure (data, layout) of one sequence: the ground truth, its start and end, and each method's best,
    median and worst run (a colour per method, a dash per pick), grouped by method in the legend (`names`: a method's
    name as shown, with its marks)."""
    data = []
    if paths.full is not None:
        line = {"color": "#cccccc", "width": 7}
        data.append(
            {"type": "scatter3d", "mode": "lines", "name": "ground truth, whole path", "line": line, **_xyz(paths.full)}
        )
    data.append(
        {
            "type": "scatter3d",
            "mode": "lines",
            "name": paths.gt_label(),
            "line": {"color": "black", "width": 3},
            **_xyz(paths.gt),
        }
    )
    start, end = paths.ends()
    for name, point, symbol in (("start (ground truth)", start, "diamond"), ("end (ground truth)", end, "square-open")):
        marker = {"symbol": symbol, "size": 6, "color": "black"}
        data.append({"type": "scatter3d", "mode": "markers", "name": name, "marker": marker, **_xyz(point[None, :])})
    methods = list(dict.fromkeys(r.method for r in paths.runs))
    for run in paths.runs:
        colour = COLOURS[methods.index(run.method) % len(COLOURS)]
        data.append(
            {
                "type": "scatter3d",
                "mode": "lines",
                "name": f"{run.which} ({paths.metric} {run.value:.4g}; {run.direction} trial {run.trial})",
                "legendgroup": run.method,
                "legendgrouptitle": {"text": (names or {}).get(run.method, run.method)},
                "line": {"color": colour, "width": 4 if run.which == "best" else 3, "dash": DASH[run.which]},
                **_xyz(run.positions),
            }
        )
    axes = {f"{k}axis": {"title": {"text": f"{k} ({paths.units})"}} for k in "xyz"}
    layout = {
        "title": {"text": title, "font": {"size": 13}},
        "height": 620,
        "margin": {"l": 0, "r": 0, "t": 40, "b": 0},
        "scene": {"aspectmode": "data", "camera": camera(paths), **axes},
        "legend": {"groupclick": "toggleitem"},
    }
    return {"data": data, "layout": layout}


def camera(paths: SequencePaths) -> dict:
    """A view from above and aside, far enough for a flat path drawn to scale (aspect "data") to fit."""
    a, b = paths.plane()
    up, sign = paths.up()
    eye, vertical = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
    eye[a], eye[b], eye[up] = 1.2, -2.3, 1.9 * sign
    vertical[up] = float(sign)
    return {"eye": dict(zip("xyz", eye, strict=True)), "up": dict(zip("xyz", vertical, strict=True))}


def write_view(paths: SequencePaths, path: Path, element: str, title: str, names: dict[str, str] | None = None) -> Path:
    """The script that draws one sequence's view into the page's element `element`."""
    figure = json.dumps(view_figure(paths, title, names), separators=(",", ":"), allow_nan=False)
    config = {"responsive": True, "displaylogo": False}
    path.parent.mkdir(parents=True, exist_ok=True)
    call = f"Plotly.newPlot({json.dumps(element)}, f.data, f.layout, {json.dumps(config)});"
    path.write_text(f"(function () {{\nconst f = {figure};\n{call}\n}})();\n")
    return path

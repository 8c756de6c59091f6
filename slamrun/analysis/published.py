"""Published figures beside a campaign's own medians: the report's table and `slamrun stats`' lines. The
campaign's figures are its evaluated runs on ordinary views, per method (its registry name), sequence and metric;
a published figure is matched by method, the settings it was made with (DPV-SLAM's loop closure), sequence
(slamrun.results.published.same_sequence) and metric, shown with its protocol and where it differs from the
campaign's, and never enters a test."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from slamrun.analysis.load import evaluated
from slamrun.analysis.paths import run_alignment
from slamrun.analysis.robustness import baseline
from slamrun.errors import SlamRunError
from slamrun.results.published import Beside, Published, built_in, read_table, same_sequence


def figures(files: list[Path] | list[str] = ()) -> tuple[list[Published], list[str]]:
    """The built-in published figures and those of `files` (a lab's CSVs), and why a file could not be read (a
    file named by the spec when it ran and moved since: the rest are still shown)."""
    out, problems = built_in(), []
    for f in files:
        try:
            out += read_table(Path(f))
        except SlamRunError as exc:
            problems.append(str(exc))
    return out, problems


def beside(df: pd.DataFrame, published: list[Published], params: dict[str, dict] | None = None) -> pd.DataFrame:
    """One row per published figure a method of the campaign has runs for (same method, settings, sequence, metric):
    the campaign's median over its evaluated runs and their count beside the published value, its protocol and what
    differs (the alignment). `params`: each method label's parameters with their defaults (method_params); a label
    it lacks runs with its method's defaults. Empty where nothing matches."""
    if df.empty or "sequence" not in df.columns:
        return pd.DataFrame()
    runs = evaluated(baseline(df), [])
    if runs.empty:
        return pd.DataFrame()
    names = runs["method_name"] if "method_name" in runs.columns else runs["method"]
    labels = dict(zip(runs["method"].astype(str), names.astype(str), strict=False))
    settings = {lab: (params or {}).get(lab) or default_params(name) for lab, name in labels.items()}
    rows = []
    for p in published:
        if p.metric not in runs.columns:
            continue
        same = np.array([same_sequence(str(s), p.sequence) for s in runs["sequence"]], dtype=bool)
        made = np.array([p.made_with(settings[lab]) for lab in runs["method"].astype(str)], dtype=bool)
        hit = runs[(names == p.method).to_numpy(bool) & same & made]
        for (method, sequence), g in hit.groupby(["method", "sequence"], sort=True):
            values = pd.to_numeric(g[p.metric], errors="coerce").to_numpy(float)
            values = values[np.isfinite(values)]
            if not values.size:
                continue
            alignment = run_alignment(g["eval_settings"].iloc[0]) if "eval_settings" in g.columns else "sim3"
            rows.append(Beside(str(method), str(sequence), p.metric, float(np.median(values)), values.size,
                               alignment, p).row())  # fmt: skip
    return pd.DataFrame(rows)


def default_params(name: str) -> dict | None:
    """A registered method's parameters with their defaults; None for a name not registered (or whose parameters
    have no defaults)."""
    from pydantic import ValidationError

    import slamrun.methods

    cls = slamrun.methods.REGISTRY.get(name)
    try:
        return cls.Params().model_dump(mode="json") if cls else None
    except ValidationError:
        return None


def method_params(results: Path) -> dict[str, dict]:
    """Each method label's parameters with their defaults, from the spec a results folder (or the folder of its
    results table) ran; {} where none is recorded or a method is no longer registered."""
    from pydantic import ValidationError

    import slamrun.methods
    from slamrun.analysis.provenance import recorded_spec

    spec = recorded_spec(Path(results) if Path(results).is_dir() else Path(results).parent)
    out = {}
    for m in spec.methods if spec else []:
        cls = slamrun.methods.REGISTRY.get(m.name)
        try:
            out[m.run_label] = cls.Params.model_validate(m.params or {}).model_dump(mode="json")
        except (AttributeError, ValidationError):  # not registered here, or parameters of another version
            continue
    return out


def spec_files(results: Path) -> list[str]:
    """The `published:` files the spec a results folder (or the folder of its results table) ran had."""
    from slamrun.analysis.provenance import recorded_spec

    spec = recorded_spec(Path(results) if Path(results).is_dir() else Path(results).parent)
    return list(spec.published) if spec else []

"""A campaign's state as the live page shows it, read from its ledger without writing or locking anything (as
`slamrun status` reads it): progress and ETA, what each lane runs, failures by kind, medians so far per dataset
and method, the values behind the live box plots, and the report's figures with their times.

`snapshot(results)` is what the server sends; `Signature` says cheaply whether the ledger or the report changed
since the last one, so many viewers of a 10,000-run campaign cost one read per change, not one per viewer."""

from __future__ import annotations

import math
import os
import statistics
import time
from dataclasses import dataclass
from pathlib import Path

from slamrun.analysis.colours import method_colours
from slamrun.core.ticks import log_ticks
from slamrun.engine.ledger import Ledger
from slamrun.engine.progress import Tracker, duration
from slamrun.engine.session import current_session, measurement_conditions
from slamrun.results.catalogue import COVERAGE, FLAG_COLUMNS, MAIN_METRICS, SUMMARY_METRICS
from slamrun.results.catalogue import label as column_label
from slamrun.results.marks import flags, marked, notes
from slamrun.results.vocabulary import NONE
from slamrun.serve.folders import LEDGER

MAX_FAILED = 100  # the newest failed runs listed (every failure is counted by kind)
MAX_VALUES = 500  # per dataset and method: the live box plot's values (evenly taken from the runs, in key order)
MAX_FIGURES = 200
MESSAGE_CHARS = 300
FIGURE_SUFFIXES = (".png", ".svg")
RUN_COLUMNS = ("key", "method", "dataset", "sequence", "direction", "trial", "attempts", "started_at", "ended_at")
# a metric's name on the page, with its unit, as the report names it (TUM-Mono's lengths are in its ground truth's
# units: the benchmark's ground truth has no metric scale)
LABELS = {COVERAGE: "coverage (median, share of frames)"} | {m: column_label(m) for m in SUMMARY_METRICS}


@dataclass(frozen=True)
class Signature:
    """What changes when a campaign writes its ledger or its report: sizes and times of the ledger, its WAL and
    the report's folder of figures."""

    stamps: tuple

    @classmethod
    def of(cls, results: Path) -> Signature:
        stamps = []
        folders = [results / "report" / "figures", results / "report", *_dataset_figure_folders(results).values()]
        for path in (results / LEDGER, results / f"{LEDGER}-wal", *folders):
            try:
                st = os.stat(path)
                stamps.append((st.st_mtime_ns, st.st_size, st.st_ino))
            except OSError:
                stamps.append(None)
        return cls(tuple(stamps))


def snapshot(results: Path, name: str, now: float | None = None) -> dict:
    """The page's data for the campaign in `results` (written through slamrun.core.jsonio: NaN as null)."""
    now = time.time() if now is None else now
    ledger = Ledger(results / LEDGER, read_only=True)
    try:
        session = current_session(ledger)
        campaign = ledger.meta("campaign", name)
        measurement = measurement_conditions(ledger.meta("spec"))
        rows = ledger.progress_rows()
        progress = Tracker(rows, session, campaign).figures(now)
        running = ledger.rows(status="running", columns=RUN_COLUMNS)
        failed = ledger.rows(status="failed", columns=(*RUN_COLUMNS, "failure", "message"))
        done = ledger.rows(status="done", columns=MEDIAN_COLUMNS)
    finally:
        ledger.close()
    counts = progress.to_dict()
    return {
        "campaign": campaign,
        "name": name,
        "generated_at": now,
        "progress": counts,
        "state": state_of(counts),
        "facts": facts(counts) + ([f"measurement {measurement}"] if measurement else []),
        "labels": LABELS,
        "lanes": [_lane(r, now) for r in sorted(running, key=lambda r: r.get("started_at") or 0.0)],
        "failed": _failed(failed),
        "medians": medians(done),
        "colours": method_colours(r["method"] for r in rows),
        "figures": report_figures(results),
        "report": "report/index.html" if (results / "report" / "index.html").is_file() else None,
    }


def state_of(progress: dict) -> str:
    """running (a campaign process runs now), finished (every run finished), or stopped."""
    return "running" if progress["active"] else "finished" if progress["finished"] >= progress["total"] else "stopped"


def facts(p: dict) -> list[str]:
    """The progress line of the page's header, one fact per item."""
    share = 100 * p["finished"] / p["total"] if p["total"] else 0
    shown = [
        f"{p['finished']} of {p['total']} runs finished ({share:.0f} %)",
        f"done {p['done']}",
        f"failed {p['failed']}",
    ]
    if p["infra"]:
        shown.append(f"infrastructure {p['infra']} (retried at the next start)")
    shown.append(f"running {p['running']} on {p['lanes']} lane(s)")
    if p["elapsed_s"] is not None:
        shown.append(f"elapsed {duration(p['elapsed_s'])}")
    if p["finished"] < p["total"]:
        basis = p["eta_basis"] if p["eta_basis"] not in ("measured", "-") else ""
        shown.append(f"ETA {duration(p['eta_s'])}" + (f" ({basis})" if basis else ""))
    if p["occupancy"] is not None:
        shown.append(f"lanes busy {100 * p['occupancy']:.0f} %")
    return shown


def _lane(row: dict, now: float) -> dict:
    started = row.get("started_at")
    return {**_run(row), "running_s": max(now - started, 0.0) if started else None}


def _run(row: dict) -> dict:
    return {k: row.get(k) for k in RUN_COLUMNS}


def _failed(rows: list[dict]) -> dict:
    """Every failed run counted by kind (`infra`, the machine's fault, apart from the method's own kinds); the
    newest MAX_FAILED listed with their messages."""
    rows = sorted(rows, key=lambda r: r.get("ended_at") or 0.0, reverse=True)
    kinds: dict[str, int] = {}
    for r in rows:
        kinds[r.get("failure") or "unknown"] = kinds.get(r.get("failure") or "unknown", 0) + 1
    listed = [
        {**_run(r), "failure": r.get("failure"), "message": (r.get("message") or "")[:MESSAGE_CHARS]}
        for r in rows[:MAX_FAILED]
    ]
    return {"total": len(rows), "kinds": kinds, "runs": listed}


MEDIAN_COLUMNS = (
    "method", "dataset", "sequence", "direction", "perturbation", COVERAGE, *SUMMARY_METRICS, *FLAG_COLUMNS,
    "eval_settings",
)  # fmt: skip


def medians(done: list[dict]) -> dict:
    """Per dataset (never pooled: metres of one dataset are not a population with another's), per method: the
    runs done, their median coverage (the share of the frames the method was given with a pose: an ATE over 31 poses
    is not one over 150), the median of each summary metric that has values, and up to MAX_VALUES values of the
    dataset's main metric (e_align where the runs have it, else ATE RMSE) for the live box plot, with its log axis's
    ticks. As every other view: the runs on ordinary views only (perturbed ones are the report's Robustness
    section), copies of a run (a method's equal figures on one sequence and direction) once, a method's name with
    its marks (low coverage, diverged) and what they mean in `notes`."""
    out: dict[str, dict] = {}
    by_dataset: dict[str, list[dict]] = {}
    perturbed: dict[str, int] = {}
    for r in done:
        dataset = r.get("dataset") or ""
        if (r.get("perturbation") or NONE) == NONE:
            by_dataset.setdefault(dataset, []).append(r)
        else:
            perturbed[dataset] = perturbed.get(dataset, 0) + 1
    for dataset, rows in sorted(by_dataset.items()):
        metrics = [m for m in (COVERAGE, *SUMMARY_METRICS) if any(_finite(r.get(m)) for r in rows)]
        main = next((m for m in MAIN_METRICS if m in metrics), None)
        found = flags({**r, "done": True} for r in rows)
        methods, values = [], {}
        for label in sorted({r["method"] for r in rows}):
            mine = [r for r in rows if r["method"] == label]
            row = {"method": marked(label, found), "done": len(mine)}
            for m in metrics:
                finite = _distinct(mine, m)
                row[m] = statistics.median(finite) if finite else None
            methods.append(row)
            if main:
                values[label] = _spread(_distinct(mine, main), MAX_VALUES)
        ticks = log_ticks(v for vs in values.values() for v in vs)  # the box plot's log axis
        out[dataset] = {
            "metrics": metrics,
            "main": main,
            "methods": methods,
            "values": values,
            "ticks": ticks,
            "notes": notes(found) + _perturbed_note(perturbed.get(dataset, 0)),
        }
    return out


def _perturbed_note(n: int) -> list[str]:
    """Where the runs on perturbed views are, when there are any (never in the baseline's figures)."""
    if not n:
        return []
    return [f"{n} done run(s) on perturbed views are not in these figures: the report's Robustness section has them"]


def _distinct(rows: list[dict], metric: str) -> list[float]:
    """The finite values of `metric`, each of a sequence and direction once (copies count once, as in the
    statistics: analysis.load.counted)."""
    seen = set()
    out = []
    for r in rows:
        v = r.get(metric)
        key = (r.get("sequence"), r.get("direction"), v)
        if _finite(v) and key not in seen:
            seen.add(key)
            out.append(v)
    return out


def _dataset_figure_folders(results: Path) -> dict[str, Path]:
    """A multi-dataset report's folders of figures by dataset (report/datasets/NAME/figures), sorted by name."""
    try:
        with os.scandir(results / "report" / "datasets") as entries:
            names = sorted(e.name for e in entries if e.is_dir(follow_symlinks=False) and not e.name.startswith("."))
    except OSError:
        return {}
    return {name: results / "report" / "datasets" / name / "figures" for name in names}


def report_figures(results: Path) -> list[dict]:
    """The report's figures (PNG, SVG when there is no PNG of the name) with their times (the page reloads one when
    its time changes): those of the whole campaign, newest first, then each dataset's of a multi-dataset report
    (`dataset` names it), datasets by name."""
    found = _figures_in(results / "report" / "figures", "report/figures", None)
    for name, folder in _dataset_figure_folders(results).items():
        found += _figures_in(folder, f"report/datasets/{name}/figures", name)
    return found[:MAX_FIGURES]


def _figures_in(folder: Path, served: str, dataset: str | None) -> list[dict]:
    try:
        entries = [e for e in os.scandir(folder) if e.is_file(follow_symlinks=False)]
    except OSError:
        return []
    names = {e.name for e in entries}
    found = []
    for e in entries:
        stem, suffix = os.path.splitext(e.name)
        if suffix not in FIGURE_SUFFIXES or e.name.startswith(".") or (suffix == ".svg" and f"{stem}.png" in names):
            continue
        found.append({"path": f"{served}/{e.name}", "name": stem, "mtime": e.stat().st_mtime, "dataset": dataset})
    found.sort(key=lambda f: (-f["mtime"], f["name"]))
    return found


def _finite(v) -> bool:
    return isinstance(v, int | float) and math.isfinite(v)


def _spread(values: list[float], limit: int) -> list[float]:
    """At most `limit` of `values`, evenly taken (every value when there are fewer), to 4 significant digits (a
    box plot's resolution: the page's data stays small)."""
    if len(values) > limit:
        step = len(values) / limit
        values = [values[int(i * step)] for i in range(limit)]
    return [float(f"{v:.4g}") for v in values]

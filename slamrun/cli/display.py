"""What the CLI shows of a campaign: the live view while it runs, `slamrun status`, the end summary.

Every number comes from slamrun.engine.progress.figures over the ledger, so the live view, the status of a second
terminal and the summary agree. Only the CLI uses this module.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING

from rich.console import Console, Group
from rich.progress_bar import ProgressBar
from rich.table import Table
from rich.text import Text

from slamrun.engine.paths import RunPaths
from slamrun.engine.progress import Figures, Tracker, duration, one_line
from slamrun.engine.session import read_tracker
from slamrun.results.catalogue import CPU_WAIT_PCT, PROGRESS_METRICS, SUMMARY_METRICS, WALL_S, column
from slamrun.results.marks import marked
from slamrun.results.marks import notes as mark_notes
from slamrun.results.vocabulary import INFRA_FAILURES, played

if TYPE_CHECKING:
    import pandas as pd

    from slamrun.analysis.stats import StudyStats


def headline(f: Figures, width: int = 40) -> Table:
    """Bar, counts, failures by kind, elapsed and ETA on one line."""
    grid = Table.grid(padding=(0, 1))
    for _ in range(4):
        grid.add_column()
    kinds = ", ".join(f"{k} {n}" for k, n in f.failures.items())
    counts = Text(f"{f.finished}/{f.total}", style="bold")
    detail = f"done {f.done}  failed {f.failed}" + (f" ({kinds})" if kinds else "")
    if f.infra:
        detail += f"  infra {f.infra}"
    timing = f"elapsed {duration(f.elapsed_s)}" if f.elapsed_s is not None else ""
    if f.finished < f.total:
        timing += f"  ETA {duration(f.eta_s)}" + (f" ({f.eta_basis})" if f.eta_basis not in ("measured", "-") else "")
    if f.occupancy is not None:
        timing += f"  lanes busy {100 * f.occupancy:.0f} %"
    grid.add_row(ProgressBar(total=max(f.total, 1), completed=f.finished, width=width), counts, detail, timing)
    return grid


def group_table(f: Figures) -> Table:
    t = Table(title=f"{f.campaign}: runs per method and direction")
    for c in ("method", "direction", "pending", "running", "done", "failed", "infra", "success %", "CPU wait %"):
        t.add_column(c, justify="left" if c in ("method", "direction") else "right")
    for g in f.per_group:
        rate = "-" if g["success_pct"] is None else f"{g['success_pct']:.0f}"
        wait = "-" if g.get(CPU_WAIT_PCT) is None else f"{g[CPU_WAIT_PCT]:.0f}"
        t.add_row(
            g["method"],
            g["direction"],
            *(str(g[k]) for k in ("pending", "running", "done", "failed", "infra")),
            rate,
            wait,
        )
    return t


def status_view(f: Figures) -> Group:
    state = "running" if f.active else "not running"
    return Group(group_table(f), headline(f), Text(f"campaign {state}, {f.lanes} lane(s)"))


def finished_line(lane: int, run_id: str, info: dict) -> str:
    """A finished run's plain line: its state, failure, and its main figure, whatever its dataset's metrics
    (TUM-Mono's e_align, else ATE's RMSE, else RPE's, else KITTI's segment error)."""
    line = f"[lane {lane}] {run_id}: {info.get('status')} ({info.get('failure') or 'ok'})"
    for name in PROGRESS_METRICS:
        value, unit = info.get(name), column(name).unit
        if isinstance(value, float) and value == value:
            return f"{line} {name}={value:.4g}" + (f" {unit}" if unit else "")
    return line


class LiveProgress:
    """The campaign's live view: a headline over the whole plan and what each lane runs now, refreshed from
    the ledger; plain lines (each finished run, and the headline every `every` runs) when not on a terminal."""

    def __init__(self, results: Path, console: Console, tty: bool, every: int | None = None):
        self.results = results
        self.console = console
        self.tty = tty
        self.every = every
        self.lanes: dict[int, tuple[str, str, float]] = {}  # lane -> (run key, what, started)
        self._lock = threading.Lock()  # events come from the lanes and the finishing threads
        self.finished_here = 0
        self._tracker: Tracker | None = None
        self._last_read = 0.0
        self._live = None
        if tty:
            from rich.live import Live

            self._live = Live(console=console, refresh_per_second=2, get_renderable=self.render, transient=False)
            self._live.start()

    RESYNC_S = 30.0  # the ledger is read whole this often (and until a session is recorded); events in between

    def figures(self) -> Figures | None:
        """The figures, kept current from the runs' events at a constant cost per run; the ledger is read whole
        only every RESYNC_S seconds (what no event reports: another process's changes, a recovered run)."""
        now = time.monotonic()
        t = self._tracker
        # this campaign's own session not read yet (none, or an earlier one that ended), a run the tracker does
        # not know (the plan grew), or time for the periodic read
        stale = (
            t is None
            or not t.session
            or t.session.get("ended_at")
            or t.unknown
            or now - self._last_read > self.RESYNC_S
        )
        if stale and now - self._last_read > 1.0:
            try:
                self._tracker = read_tracker(self.results) or self._tracker
            except Exception:  # noqa: BLE001 - the ledger is being created or replaced: keep the last figures
                pass
            self._last_read = now
        return None if self._tracker is None else self._tracker.figures(time.time())

    def _track(self, kind: str, run, info: dict) -> None:
        if self._tracker is None:
            return
        if kind == "started":
            self._tracker.update(run.key.id, status="running", started_at=time.time())
        elif kind == "finished":
            self._tracker.update(
                run.key.id, status=info.get("status"), failure=info.get("failure"), wall_s=info.get(WALL_S)
            )
        elif kind in ("retry", "requeued"):
            self._tracker.update(run.key.id, status="pending")

    def render(self):
        f = self.figures()
        if f is None:
            return Text("preparing ...")
        now = time.monotonic()
        lanes = [
            Text(f"  lane {i}: {what} ({duration(now - t0)})", style="dim")
            for i, (what, t0) in sorted(self.lanes.items())
        ]
        return Group(Text(f.campaign, style="bold"), headline(f), *lanes)

    def note(self, msg: str) -> None:
        self.console.print(msg)

    def event(self, kind: str, run, lane, info: dict) -> None:
        with self._lock:
            self._event(kind, run, lane, info)

    def _event(self, kind: str, run, lane, info: dict) -> None:
        self._track(kind, run, info)
        if kind == "started":
            self.lanes[lane.index] = (
                f"{run.key.label} {run.key.sequence} {run.key.direction.value} {run.key.trial}",
                time.monotonic(),
            )
        elif kind == "finished":
            if self.lanes.get(lane.index, ("",))[0] == run.key.id:  # the lane may run the next one already
                self.lanes.pop(lane.index, None)
            self.finished_here += 1
            f = self.figures()
            if not self.tty:
                self.console.print(finished_line(lane.index, run.key.id, info), markup=False, highlight=False)
                every = self.every or max(1, min(10, (f.total if f else 20) // 20))
                if f is not None and self.finished_here % every == 0:
                    self.console.print(f"progress: {one_line(f)}")
        elif kind in ("retry", "requeued", "view"):
            self.console.print(f"[lane {lane.index}] {run.key.id}: {kind} {info.get('message', '')}", markup=False)

    def close(self) -> None:
        if self._live is not None:
            self._live.stop()


def failed_runs_table(rows: list[dict], campaign: str, limit: int = 20) -> tuple[Table | None, int]:
    """The failed runs (method failures and infrastructure), at most `limit`, with their dataset where the runs
    have several; returns the table and how many more there are."""
    failed = sorted((r for r in rows if r["status"] == "failed"), key=lambda r: r["key"])
    if not failed:
        return None, 0
    several = len({r.get("dataset") for r in rows}) > 1
    t = Table(title=f"{campaign}: failed runs ({len(failed)})")
    for c in ("method", *(("dataset",) if several else ()), "sequence", "direction", "trial", "kind", "log"):
        t.add_column(c)
    for r in failed[:limit]:
        log = (
            str(RunPaths.log(Path(r["run_dir"])))
            if r.get("run_dir") and r.get("failure") not in INFRA_FAILURES
            else (r.get("message") or "")[:80]
        )
        where = (str(r.get("dataset")),) if several else ()
        how = played(r["direction"], r.get("perturbation"), r.get("level"))
        t.add_row(r["method"], *where, r["sequence"], how, str(r["trial"]), r.get("failure") or "?", log)
    return t, max(len(failed) - limit, 0)


def method_table(summary: pd.DataFrame, title: str, marks: dict | None = None) -> Table:
    """The end-of-campaign table of one dataset's per-method summary (slamrun.analysis.summary.method_summary):
    counts, success rate, the medians of the metrics its runs have, fps and the failure kinds that occurred; a
    method marked (`marks`: low coverage, diverged) carries its mark, said under the table."""
    from slamrun.results.vocabulary import FAILURES

    medians = [f"median_{m}" for m in SUMMARY_METRICS]
    medians = [c for c in medians if summary[c].notna().any()] or medians[:4]  # the metrics the dataset has
    cols = ["method", "runs", "done", "failed", "success_pct", *medians, "median_fps"]
    fails = [k for k in (*FAILURES, "infra") if k in summary and summary[k].sum() > 0 and k not in cols]
    t = Table(title=title, caption=_mark_caption(marks, summary["method"]), caption_justify="left")
    for c in cols + fails:
        t.add_column(c.replace("median_", "med "), justify="right" if c != "method" else "left")
    for _, r in summary.iterrows():
        t.add_row(marked(str(r["method"]), marks or {}), *[_cell(r[c]) for c in cols[1:] + fails])
    return t


def pooled_table(pooled: pd.DataFrame, title: str, marks: dict | None = None) -> Table:
    """The pooled view over every dataset (slamrun.analysis.summary.pooled_summary): counts, success rate and the
    mean rank within sequences; no median in metres; marked methods as in method_table."""
    cols = ["method", "runs", "done", "failed", "infra", "success_pct", "mean_rank", "sequences_ranked"]
    t = Table(title=title, caption=_mark_caption(marks, pooled["method"]), caption_justify="left")
    for c in cols:
        t.add_column(c.replace("_", " "), justify="right" if c != "method" else "left")
    for _, r in pooled.iterrows():
        t.add_row(marked(str(r["method"]), marks or {}), *[_cell(r[c]) for c in cols[1:]])
    return t


def _mark_caption(marks: dict | None, shown) -> str | None:
    names = {str(m) for m in shown}
    said = mark_notes({m: f for m, f in (marks or {}).items() if m in names})
    return "\n".join(said) or None


def _cell(v) -> str:
    if isinstance(v, float):
        return "-" if v != v else f"{v:.4g}"
    return str(v)


def _num(v: float, digits: int = 4) -> str:
    return "-" if v is None or v != v else f"{v:.{digits}g}"


def stats_lines(dataset: str, st: StudyStats, adjust: str, alpha: float) -> list[str]:
    """`slamrun stats`' text of one dataset: every test the procedure computed (outliers, Lilliefors, Levene,
    Kruskal-Wallis, pairwise Wilcoxon rank-sum tests adjusted and not), with the medians and letters."""
    n = len(st.kept) + st.n_outliers
    lines = [f"dataset {dataset}: {n} evaluated runs (copies once), {len(st.kept)} kept; {st.outlier_text()}"]
    lines += [f"  {line}" for line in st.excluded_lines()]
    if note := st.counting_note():
        lines.append(f"  {note}")
    if st.coverage:
        shares = ", ".join(f"{g} {_num(v, 3)}" for g, v in st.coverage.items())
        lines.append(
            f"  median coverage (share of the frames each method was given with a pose) of the runs tested: {shares}"
        )
    lines += [f"  {note}" for note in mark_notes(st.marks)]
    if not st.metrics:
        lines.append("  no metric with values: no test")
    for name, m in st.metrics.items():
        order = sorted(m.medians, key=lambda g: m.medians[g])
        lines.append(
            f"  {name}: median and letters (pairwise tests, {adjust} adjustment, alpha {alpha}): "
            + (
                ", ".join(
                    f"{marked(g, st.marks)} {_num(m.medians[g])} {m.letters.get(g, '')} (n={m.runs.get(g)})"
                    for g in order
                )
                or "no run"
            )
        )
        if gone := st.left_out.get(name):
            lines.append("    not in this metric's tests: " + "; ".join(f"{g} ({why})" for g, why in gone.items()))
        lines.append(
            "    Lilliefors normality p: "
            + (", ".join(f"{g} {_num(m.lilliefors_p[g], 3)}" for g in order) or "-")
            + ("  (-: under 5 runs, or no spread)" if any(v != v for v in m.lilliefors_p.values()) else "")
        )
        levene = f"F {_num(m.levene_F)}, p {_num(m.levene_p, 3)}" if "levene" not in m.notes else m.notes["levene"]
        lines.append(f"    Levene (median-centred): {levene}")
        kw = f"chi2 {_num(m.kruskal_chi2)}, df {m.kruskal_df}, p {_num(m.kruskal_p, 3)}"
        lines.append(f"    Kruskal-Wallis: {m.notes.get('kruskal', kw)}")
        if "pairwise" in m.notes:
            lines.append(f"    pairwise Wilcoxon rank-sum: {m.notes['pairwise']}")
        raw = {frozenset((r["a"], r["b"])): r["p"] for r in m.pairwise_none}
        pairs = [
            f"{r['a']} vs {r['b']} {_num(r['p'], 3)}; {_num(raw[frozenset((r['a'], r['b']))], 3)}"
            for r in m.pairwise_adjusted
        ]
        if pairs:
            lines.append(f"    pairwise Wilcoxon rank-sum p ({adjust}; unadjusted): " + ", ".join(pairs))
    return lines


def pooled_lines(pooled: dict) -> list[str]:
    """The pooled view's text: counts, success rates and mean ranks within sequences over every dataset."""
    by = ", ".join(f"{d} by {m}" for d, m in pooled["ranked_by"].items())
    lines = [
        f"all datasets, pooled ({', '.join(pooled['datasets'])}): success rates and ranks within sequences "
        f"({by}); no value in metres is pooled"
    ]
    for method, r in pooled["methods"].items():
        success = "-" if r["success_pct"] != r["success_pct"] else f"{r['success_pct']:.0f} %"
        lines.append(
            f"  {method}: {r['runs']} runs, {r['done']} done, {r['failed']} failed, success {success}, "
            f"mean rank {_num(r['mean_rank'], 3)} over {r['sequences_ranked']} sequence(s)"
        )
    return lines

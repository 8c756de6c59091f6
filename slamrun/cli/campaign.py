"""slamrun campaign, plan, status, validate, schema, prepare: running a campaign and looking at it."""

from __future__ import annotations

import signal
import sys
import time
from pathlib import Path

from slamrun.cli.console import console
from slamrun.core import jsonio
from slamrun.errors import SlamRunError
from slamrun.results.files import CampaignFiles


def add_commands(sub) -> None:
    c = sub.add_parser("campaign", help="run a campaign (resumes where it stopped)")
    c.add_argument("spec", type=Path, help="the campaign's YAML spec")
    c.add_argument("--results", type=Path, help="results directory (overrides the spec)")
    c.add_argument("--lanes", type=int, help="parallel runs (overrides the spec)")
    c.add_argument("--no-report", action="store_true", help="skip the report at the end")
    c.add_argument(
        "--dry-run", action="store_true", help="say what would run, prepare and take; run nothing, write nothing"
    )
    c.set_defaults(func=cmd_campaign)
    pl = sub.add_parser("plan", help="the same as `campaign SPEC --dry-run`")
    pl.add_argument("spec", type=Path, help="the campaign's YAML spec")
    pl.add_argument("--results", type=Path, help="results directory (overrides the spec)")
    pl.set_defaults(func=cmd_plan)
    s = sub.add_parser("status", help="states per method and direction, failures, ETA (read-only, no lock)")
    s.add_argument("results", type=Path, help="a campaign's results directory")
    s.add_argument("--watch", action="store_true", help="refresh in place until the campaign ends")
    s.add_argument("--interval", type=float, default=2.0, help="seconds between refreshes with --watch")
    s.add_argument("--json", action="store_true", help="print the figures as one JSON object")
    s.set_defaults(func=cmd_status)
    v = sub.add_parser("validate", help="check a spec and its sequences; list every problem")
    v.add_argument("spec", type=Path, help="the campaign's YAML spec")
    v.set_defaults(func=cmd_validate)
    sc = sub.add_parser("schema", help="print the spec's JSON Schema")
    sc.set_defaults(func=cmd_schema)
    pr = sub.add_parser("prepare", help="build the prepared views a spec needs")
    pr.add_argument("spec", type=Path, help="the campaign's YAML spec")
    pr.set_defaults(func=cmd_prepare)


def cmd_campaign(args) -> int:
    from slamrun.cli.display import LiveProgress
    from slamrun.engine.campaign import run_campaign
    from slamrun.engine.spec_file import load_spec

    spec = load_spec(args.spec, results=args.results)  # the flag is checked as the spec's key is
    updates = {}
    if args.lanes:
        updates["lanes"] = args.lanes
    if args.no_report:
        updates["report"] = False
    spec = spec.model_copy(update=updates)
    if args.dry_run:
        return _print_dry_run(spec)
    progress = LiveProgress(spec.results, console.real(), sys.stdout.isatty())
    sched_ref = {}

    def on_signal(signum, _frame):
        sched_ref.setdefault("signal", signal.Signals(signum).name)
        sched = sched_ref.get("s")
        if sched is None:
            raise KeyboardInterrupt
        again = sched.stop.is_set()
        sched.request_stop(now=again)
        progress.note(
            f"{signal.Signals(signum).name}: "
            + (
                "stopping the runs in flight"
                if again
                else f"no new runs; in-flight runs get {spec.stop_grace_s:.0f} s (signal again to stop them now)"
            )
        )

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    t0 = time.monotonic()
    try:
        result = run_campaign(
            spec, on_event=progress.event, scheduler_hook=lambda s: sched_ref.update(s=s), log=progress.note
        )
    finally:
        progress.close()
    _print_summary(spec.name, result.results, result.results_csv)
    from slamrun.engine.session import read_figures

    figures = read_figures(result.results)
    busy = f", lanes busy {100 * figures.occupancy:.0f} %" if figures and figures.occupancy is not None else ""
    console.print(
        f"{sum(result.counts.values())} runs: "
        + ", ".join(f"{k} {v}" for k, v in result.counts.items())
        + f" ({time.monotonic() - t0:.0f} s{busy})"
    )
    if result.stop_requested and not result.interrupted:
        console.print(
            f"{sched_ref.get('signal', 'The stop')} came after the last runs had started; they finished within the "
            "grace period: the campaign is complete"
        )
    if spec.report and not result.interrupted:
        from slamrun.analysis.report import write_report

        console.print(f"report: {write_report(result.results)}")
    console.print(f"results: {result.results_csv}")
    if result.interrupted:
        console.print("stopped before the end: run the same command again to resume")
        return 130
    if result.infra_failures:
        console.print(
            f"{result.infra_failures} run(s) failed for infrastructure reasons (see message column); "
            "run again to retry them"
        )
        return 3
    return 0


def cmd_plan(args) -> int:
    from slamrun.engine.spec_file import load_spec

    return _print_dry_run(load_spec(args.spec, results=args.results))


def _print_dry_run(spec) -> int:
    from rich.table import Table

    from slamrun.engine.dryrun import dry_run
    from slamrun.engine.plan import seed_warnings
    from slamrun.engine.progress import duration
    from slamrun.engine.spec_file import cpu_warnings

    d = dry_run(spec)

    t = Table(title=f"{spec.name}: what `slamrun campaign` would run (nothing was run or written)")
    for c in ("method", "direction", "runs", "new", "pending", "done", "failed"):
        t.add_column(c, justify="left" if c in ("method", "direction") else "right")
    for g in d.groups:
        t.add_row(g["method"], g["direction"], *(str(g[k]) for k in ("runs", "new", "pending", "done", "failed")))
    console.print(t)
    console.print(
        f"{d.to_run} run(s) to run of {d.total} ({d.done} done, {d.failed} failed as the method's result)"
        + (f"; {d.infra} infrastructure failure(s) to retry" if d.infra else "")
    )
    if d.to_reevaluate:
        console.print(
            f"{d.to_reevaluate} run(s) to re-evaluate: finished with other evaluation settings than their dataset's "
            "now (metrics, alignment, rpe, min_coverage, coverage_mark, max_ate_rel, or the evaluation code); their "
            "stored trajectories are evaluated again, no method runs again"
        )
    if d.views_to_prepare or d.views_unknown:
        console.print(
            f"{d.views_to_prepare} view(s) to prepare in {spec.cache}, about {d.view_bytes / 2**30:.2f} GB"
            + (
                f", and {d.views_unknown} view(s) of {d.sequences_unknown} synthetic sequence(s) generated on first "
                "use (their size is known once generated)"
                if d.views_unknown
                else ""
            )
        )
    else:
        console.print("every view it needs is prepared")
    if d.perturbed_runs:
        console.print(
            f"robustness: {d.perturbed_runs} of the {d.total} runs are on perturbed views (README, Robustness); "
            f"{d.perturbed_views} of the views to prepare, about {d.perturbed_bytes / 2**30:.2f} GB"
            + (f", about {d.perturbed_cpu_s / 60:.1f} CPU-minutes to corrupt their frames" if d.perturbed_cpu_s else "")
        )
    for warning in cpu_warnings(spec) + seed_warnings(spec):
        console.print(f"warning: {warning}", markup=False, highlight=False)
    if d.to_run:
        basis = f" ({d.eta_basis}, from this results folder's timings)" if d.eta_s is not None else ""
        console.print(
            f"estimated duration: {duration(d.eta_s) if d.eta_s is not None else 'unknown (no timing yet)'}"
            f" on {d.lanes} lane(s){basis}"
        )
    return 0


def _print_summary(campaign: str, results: Path, csv: Path) -> None:
    """The end-of-campaign tables: per method within each dataset (medians in metres are never pooled across
    datasets), the pooled counts, rates and ranks when there are several datasets, and the failed runs."""
    from slamrun.analysis.left_out import section_flags
    from slamrun.analysis.load import by_dataset, read_csv
    from slamrun.analysis.robustness import baseline, perturbed
    from slamrun.analysis.summary import method_summary, pooled_summary
    from slamrun.cli.display import failed_runs_table, method_table, pooled_table
    from slamrun.engine.ledger import Ledger

    everything = read_csv(csv)
    if everything.empty:
        return
    df = baseline(everything)  # the runs on perturbed views: the report's Robustness section
    if perturbed(everything):
        console.print(f"{len(everything) - len(df)} run(s) on perturbed views: the report's Robustness section")
    groups = by_dataset(df)
    for name, part in groups.items():
        table = method_table(method_summary(part), f"{campaign}: per method, dataset {name}", section_flags(part))
        console.print(table)
    if len(groups) > 1:
        console.print(
            pooled_table(pooled_summary(df), f"{campaign}: per method, all datasets (pooled)", section_flags(df))
        )
    ledger = Ledger(CampaignFiles(results).ledger, read_only=True)
    try:
        failed, more = failed_runs_table(ledger.rows(), campaign)
    finally:
        ledger.close()
    if failed is not None:
        console.print(failed)
        if more:
            console.print(f"... and {more} more failed run(s): `slamrun status {results}` or results.csv")


def cmd_status(args) -> int:
    from slamrun.engine.session import read_figures

    f = read_figures(args.results)
    if f is None:
        raise SlamRunError(f"{args.results}: no ledger.sqlite; is this a results directory of `slamrun campaign`?")
    if args.json:
        print(jsonio.dumps(f.to_dict()))
        return 0
    from slamrun.cli.display import status_view

    if not args.watch:
        console.print(status_view(f))
        return 0
    from rich.live import Live

    with Live(status_view(f), console=console.real(), refresh_per_second=1) as live:
        while True:
            time.sleep(args.interval)
            f = read_figures(args.results) or f
            live.update(status_view(f))
            if not f.active:
                break
    console.print("the campaign is not running")
    return 0


def cmd_validate(args) -> int:
    from slamrun.engine.campaign import check_sequences
    from slamrun.engine.plan import plan, seed_warnings
    from slamrun.engine.spec_file import cpu_warnings, load_spec

    spec = load_spec(args.spec)
    for warning in check_sequences(spec, skip_ungenerated=True) + cpu_warnings(spec) + seed_warnings(spec):
        console.print(f"warning: {warning}")
    from slamrun.datasets.layouts import holds_sequence

    todo = sum(1 for d in spec.datasets if d.synthetic for s in d.sequences if not holds_sequence(d.path / s))
    later = f" ({todo} synthetic sequence(s) generated on first use)" if todo else ""
    console.print(f"{args.spec}: valid, {len(plan(spec))} runs{later}")
    return 0


def cmd_schema(args) -> int:
    from slamrun.engine.spec import json_schema

    print(jsonio.dumps(json_schema(), indent=2))
    return 0


def cmd_prepare(args) -> int:
    from slamrun.datasets.cache import disk_usage
    from slamrun.engine.campaign import ensure_datasets, prepare_views
    from slamrun.engine.plan import plan
    from slamrun.engine.spec_file import load_spec

    spec = load_spec(args.spec)
    ensure_datasets(spec)
    runs = plan(spec)
    views = prepare_views(spec, runs, {r.key.id for r in runs})
    total, seen = 0, set()
    for v in views.values():
        size = disk_usage(v.root, seen)  # frames shared with the other direction's view count once
        total += size
        console.print(f"{v.root} ({v.n_frames} frames, {size / 2**20:.1f} MiB)")
    console.print(f"{len(views)} views, {total / 2**20:.1f} MiB in {spec.cache}")
    return 0

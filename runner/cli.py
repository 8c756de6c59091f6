"""slamrun: the command line. Thin: each subcommand calls library functions; errors become one line."""

from __future__ import annotations

import argparse
import json
import signal
import sys
import time
from pathlib import Path

from rich.console import Console
from rich.table import Table

from runner.errors import SlamRunError

console = Console(stderr=False, width=None if sys.stdout.isatty() else 160)


def main(argv: list[str] | None = None) -> int:
    parser = _parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return args.func(args) or 0
    except SlamRunError as exc:
        print(f"slamrun: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("slamrun: interrupted", file=sys.stderr)
        return 130


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("slamrun")
    except PackageNotFoundError:
        return "unknown (not installed)"


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="slamrun", description="Run and compare monocular SLAM/VO methods.")
    p.add_argument("--version", action="version", version=f"slamrun {_version()}")
    sub = p.add_subparsers()

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

    lm = sub.add_parser("list-methods", help="the registered methods")
    lm.set_defaults(func=cmd_list_methods)

    e = sub.add_parser("evaluate", help="TUM-Mono metrics of trajectory files against a ground truth")
    e.add_argument("--gt", type=Path, required=True, help="the sequence's groundtruthSync.txt")
    e.add_argument("--json", action="store_true", help="one JSON object per line")
    e.add_argument("traj", type=Path, nargs="+", help="TUM trajectory files")
    e.add_argument("--jobs", type=int, help="worker processes (default: every core); output stays in input order")
    e.set_defaults(func=cmd_evaluate)

    pr = sub.add_parser("prepare", help="build the prepared views a spec needs")
    pr.add_argument("spec", type=Path, help="the campaign's YAML spec")
    pr.set_defaults(func=cmd_prepare)

    st = sub.add_parser("stats", help="the study's statistics of a results table")
    st.add_argument("results", type=Path, help="results.csv, results.parquet or a results directory")
    st.add_argument("--json", action="store_true", help="print the statistics as JSON")
    st.add_argument("--level", type=float, default=0.999, help="chi-square quantile of the outlier cut-off")
    st.add_argument("--adjust", default="holm", choices=["holm", "bonferroni", "BH", "none"], help="p-value adjustment")
    st.add_argument("--alpha", type=float, default=0.05, help="significance level of the letters")
    st.add_argument("--metrics", nargs="+", help="metric columns (default: the study's six)")
    st.set_defaults(func=cmd_stats)

    rp = sub.add_parser("report", help="write report/index.html with tables and figures")
    rp.add_argument("results", type=Path, help="a results directory")
    rp.set_defaults(func=cmd_report)

    im = sub.add_parser("images", help="build (and verify) the methods' Docker images")
    im.add_argument("--method", action="append", help="only this method (repeatable)")
    im.add_argument("--list", action="store_true", help="list the buildable images and exit")
    im.add_argument("--sources", type=Path, help="folder of upstream source archives (no network needed)")
    im.add_argument("--source-url", help="base address of the source archives (default https://github.com)")
    im.add_argument("--march", default="x86-64-v2", help="-march target the methods are compiled for")
    im.add_argument("--jobs", type=int, help="parallel compile jobs (default: all cores)")
    im.add_argument(
        "--vocabulary", action="append", default=[], metavar="[METHOD=]FILE", help="a vocabulary file for the build"
    )
    im.add_argument(
        "--weights",
        action="append",
        default=[],
        metavar="NAME=FILE",
        help="weights for the build: a file, or URL#sha256=HEX",
    )
    im.add_argument(
        "--no-train-vocabulary", action="store_true", help="fail instead of training a vocabulary the source lacks"
    )
    im.add_argument(
        "--standin-model",
        action="store_true",
        help="without --weights: an untrained stand-in network (CNN-DSO, CNN-SVO), for plumbing tests only",
    )
    im.add_argument("--build-arg", action="append", default=[], metavar="KEY=VALUE", help="extra Docker build argument")
    im.add_argument("--log-dir", type=Path, help="where build logs and records go (default .cache/images)")
    im.add_argument("--missing", action="store_true", help="build only the images that do not exist yet")
    im.add_argument("--no-cache", action="store_true", help="rebuild every step (a from-scratch build time)")
    im.add_argument(
        "--verify",
        action="store_true",
        help="build what is missing, run a short Docker campaign per image, print a table of results",
    )
    im.add_argument("--results", type=Path, help="results folder of --verify (default .cache/verify)")
    im.set_defaults(func=cmd_images)

    ds = sub.add_parser("dataset", help="dataset tools")
    dsub = ds.add_subparsers()
    dl = dsub.add_parser("download", help="download TUM-Mono sequences (resumable)")
    dl.add_argument("name", choices=["tum-mono"], help="the dataset")
    dl.add_argument("dest", type=Path, help="folder to download into")
    dl.add_argument("--sequences", default="1-50", help="numbers and ranges, e.g. 1-5,7")
    dl.add_argument("--url", help="base address of the sequence zips (default: the dataset's site)")
    dl.set_defaults(func=cmd_download)

    sy = sub.add_parser("synth", help="write a synthetic sequence in the TUM-Mono layout")
    sy.add_argument("out", type=Path, help="the sequence folder to write")
    sy.add_argument("--frames", type=int, default=300, help="number of frames")
    sy.add_argument("--seed", type=int, default=0, help="random seed of the scene and its texture")
    sy.add_argument("--size", default="640x480", help="image size WIDTHxHEIGHT")
    sy.add_argument("--scene", choices=["indoor", "outdoor"], default="indoor", help="room or courtyard scale")
    sy.set_defaults(func=cmd_synth)
    return p


# ---------------------------------------------------------------- campaign


def cmd_campaign(args) -> int:
    from runner.campaign import run_campaign
    from runner.display import LiveProgress
    from runner.spec import load_spec

    spec = load_spec(args.spec)
    updates = {}
    if args.results:
        updates["results"] = args.results.resolve()
    if args.lanes:
        updates["lanes"] = args.lanes
    if args.no_report:
        updates["report"] = False
    spec = spec.model_copy(update=updates)
    if args.dry_run:
        return _print_dry_run(spec)
    progress = LiveProgress(spec.results, console, sys.stdout.isatty())
    sched_ref = {}

    def on_signal(signum, _frame):
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
    from runner.display import read_figures

    figures = read_figures(result.results)
    busy = f", lanes busy {100 * figures.occupancy:.0f} %" if figures and figures.occupancy is not None else ""
    console.print(
        f"{sum(result.counts.values())} runs: "
        + ", ".join(f"{k} {v}" for k, v in result.counts.items())
        + f" ({time.monotonic() - t0:.0f} s{busy})"
    )
    if spec.report and not result.interrupted:
        from runner.analysis.report import write_report

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
    from runner.spec import load_spec

    spec = load_spec(args.spec)
    if args.results:
        spec = spec.model_copy(update={"results": args.results.resolve()})
    return _print_dry_run(spec)


def _print_dry_run(spec) -> int:
    from runner.dryrun import dry_run
    from runner.progress import duration

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
    if d.views_to_prepare or d.views_unknown:
        console.print(
            f"{d.views_to_prepare} view(s) to prepare in {spec.cache}, about {d.view_bytes / 2**30:.2f} GB"
            + (f", and {d.views_unknown} of synthetic sequences generated on first use" if d.views_unknown else "")
        )
    else:
        console.print("every view it needs is prepared")
    if d.to_run:
        basis = f" ({d.eta_basis}, from this results folder's timings)" if d.eta_s is not None else ""
        console.print(
            f"estimated duration: {duration(d.eta_s) if d.eta_s is not None else 'unknown (no timing yet)'}"
            f" on {d.lanes} lane(s){basis}"
        )
    return 0


def _print_summary(campaign: str, results: Path, csv: Path) -> None:
    import pandas as pd

    from runner.display import failed_runs_table
    from runner.ledger import Ledger
    from runner.results import method_summary

    df = pd.read_csv(csv)
    if df.empty:
        return
    summ = method_summary(df)
    t = Table(title=f"{campaign}: per method")
    cols = [
        "method",
        "runs",
        "done",
        "failed",
        "success_pct",
        "median_e_t",
        "median_e_r",
        "median_e_s_sym",
        "median_e_align",
        "median_fps",
    ]
    fails = [
        k for k in ("not_initialized", "lost", "no_output", "crashed", "timeout", "oom", "infra") if summ[k].sum() > 0
    ]
    for c in cols + fails:
        t.add_column(c.replace("median_", "med "), justify="right" if c != "method" else "left")
    for _, r in summ.iterrows():
        t.add_row(*[_fmt(r[c]) for c in cols + fails])
    console.print(t)
    ledger = Ledger(results / "ledger.sqlite", read_only=True)
    try:
        failed, more = failed_runs_table(ledger.rows(), campaign)
    finally:
        ledger.close()
    if failed is not None:
        console.print(failed)
        if more:
            console.print(f"... and {more} more failed run(s): `slamrun status {results}` or results.csv")


def _fmt(v) -> str:
    if isinstance(v, float):
        return "-" if v != v else f"{v:.4g}"
    return str(v)


# ---------------------------------------------------------------- status


def cmd_status(args) -> int:
    from runner.display import read_figures, status_view

    f = read_figures(args.results)
    if f is None:
        raise SlamRunError(f"{args.results}: no ledger.sqlite; is this a results directory of `slamrun campaign`?")
    if args.json:
        print(json.dumps(f.to_dict()))
        return 0
    if not args.watch:
        console.print(status_view(f))
        return 0
    from rich.live import Live

    with Live(status_view(f), console=console, refresh_per_second=1) as live:
        while True:
            time.sleep(args.interval)
            f = read_figures(args.results) or f
            live.update(status_view(f))
            if not f.active:
                break
    console.print("the campaign is not running")
    return 0


# ---------------------------------------------------------------- small commands


def cmd_validate(args) -> int:
    from runner.campaign import check_sequences
    from runner.plan import plan
    from runner.spec import load_spec

    spec = load_spec(args.spec)
    for warning in check_sequences(spec, skip_ungenerated=True):
        console.print(f"warning: {warning}")
    todo = sum(1 for d in spec.datasets if d.synthetic for s in d.sequences if not (d.path / s / "times.txt").exists())
    later = f" ({todo} synthetic sequence(s) generated on first use)" if todo else ""
    console.print(f"{args.spec}: valid, {len(plan(spec))} runs{later}")
    return 0


def cmd_schema(args) -> int:
    from runner.spec import json_schema

    print(json.dumps(json_schema(), indent=2))
    return 0


def cmd_list_methods(args) -> int:
    import methods

    t = Table(title="methods")
    for c in ("name", "view", "image", "gpu", "native", "loop closure switch"):
        t.add_column(c)
    for name, cls in sorted(methods.REGISTRY.items()):
        prof = cls.profile if isinstance(cls.profile, str) else getattr(cls.profile, "value", "per spec")
        t.add_row(
            name,
            str(prof),
            cls.image if isinstance(cls.image, str) else "-" if cls.image is None else "from the spec",
            "optional" if cls.gpu_capable else "no",
            "yes" if cls.native else "no",
            cls.loop_closure_switch or "-",
        )
    console.print(t)
    return 0


def cmd_evaluate(args) -> int:
    import numpy as np

    from runner.batch_eval import evaluate_files
    from runner.trajectory import Trajectory

    data = np.loadtxt(args.gt, comments="#", ndmin=2) if args.gt.exists() else None
    if data is None or data.shape[1] != 8:
        raise SlamRunError(f"{args.gt}: expected a groundtruthSync file of 'timestamp tx ty tz qx qy qz qw' rows")
    gt = Trajectory(data[:, 0], data[:, 1:4], data[:, 4:8])
    for d in evaluate_files(gt, args.traj, args.jobs):
        if args.json:
            print(json.dumps(d))
        else:
            vals = " ".join(f"{k}={v:.6g}" for k, v in d.items() if isinstance(v, float))
            detail = d.get("detail")
            print(f"{d['file']}: {d['status']} {vals}" + (f"({detail})" if detail else ""))
    return 0


def cmd_prepare(args) -> int:
    from runner.campaign import ensure_datasets, prepare_views
    from runner.datasets.views import disk_usage
    from runner.plan import plan
    from runner.spec import load_spec

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


def cmd_stats(args) -> int:
    from runner.analysis.load import evaluated, load_results, metrics_for
    from runner.analysis.stats import study_statistics

    df = load_results(args.results)
    metrics = args.metrics or metrics_for(df)
    missing = [m for m in metrics if m not in df.columns]
    if missing:
        raise SlamRunError(f"{args.results}: no column(s) {', '.join(missing)}; have {', '.join(df.columns)}")
    st = study_statistics(evaluated(df, metrics), metrics, level=args.level, adjust=args.adjust, alpha=args.alpha)
    if args.json:
        print(json.dumps(st.to_json()))
        return 0
    console.print(f"{len(st.kept)} runs kept, {st.n_outliers} outliers above {st.cutoff:.4f}")
    for name, m in st.metrics.items():
        meds = ", ".join(f"{g} {v:.4g} {m.letters[g]}" for g, v in sorted(m.medians.items(), key=lambda x: x[1]))
        console.print(f"{name}: Kruskal-Wallis chi2 {m.kruskal_chi2:.4g} (p {m.kruskal_p:.3g}); {meds}")
    return 0


def cmd_report(args) -> int:
    from runner.analysis.report import write_report

    console.print(f"report: {write_report(args.results)}")
    return 0


def cmd_images(args) -> int:
    import methods
    from runner.images import BuildOptions, build, buildable

    if args.list:
        for name, (tag, dockerfile) in buildable().items():
            gpu = " (GPU optional, CPU by default)" if methods.REGISTRY[name].gpu_capable else ""
            console.print(f"{name}: {tag} <- {dockerfile.parent.name}/Dockerfile{gpu}")
        return 0
    opts = BuildOptions(
        sources_dir=args.sources,
        source_url=args.source_url,
        march=args.march,
        vocabulary=dict(_pair(v, "*") for v in args.vocabulary),
        weights=dict(_pair(w) for w in args.weights),
        train_vocabulary=not args.no_train_vocabulary,
        standin_model=args.standin_model,
        build_args=dict(_pair(b) for b in args.build_arg),
        no_cache=args.no_cache,
    )
    if args.jobs:
        opts.jobs = args.jobs
    if args.log_dir:
        opts.log_dir = args.log_dir
    if args.verify:
        from runner.verify_images import print_table, verify

        rows = verify(args.method, opts, args.results, log=lambda m: print(m, flush=True))
        print_table(rows, console)
        return 0 if all(r.passed for r in rows) else 1
    records = build(args.method, log=lambda m: print(m, flush=True), opts=opts, only_missing=args.missing)
    console.print(f"built {len(records)} image(s): {', '.join(r.tag for r in records) or '-'}")
    return 0


def _pair(text: str, default_key: str | None = None) -> tuple[str, Path | str]:
    """KEY=VALUE (or VALUE alone when a default key is allowed)."""
    if "=" in text:
        key, value = text.split("=", 1)
        return key, value
    if default_key is None:
        raise SlamRunError(f"{text!r}: expected KEY=VALUE")
    return default_key, text


def cmd_download(args) -> int:
    from rich.progress import BarColumn, DownloadColumn, Progress, TextColumn, TransferSpeedColumn

    from runner.datasets.download import TUM_MONO_URL, download_tum_mono, parse_sequences

    numbers = parse_sequences(args.sequences)
    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        DownloadColumn(),
        TransferSpeedColumn(),
        console=console,
        disable=not sys.stdout.isatty(),
    ) as progress:

        def factory(name):
            task = progress.add_task(name, total=None)
            return lambda done, total: progress.update(task, completed=done, total=total or None)

        folders = download_tum_mono(args.dest, numbers, args.url or TUM_MONO_URL, factory, log=progress.console.print)
    console.print(f"{len(folders)} sequence(s) in {args.dest}")
    return 0


def cmd_synth(args) -> int:
    from runner.datasets.synth import generate

    w, h = (int(v) for v in args.size.lower().split("x"))
    t0 = time.monotonic()
    out = generate(args.out, frames=args.frames, seed=args.seed, size=(w, h), scene_kind=args.scene)
    console.print(f"{out}: {args.frames} frames in {time.monotonic() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())

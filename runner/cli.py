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


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="slamrun", description="Run and compare monocular SLAM/VO methods.")
    sub = p.add_subparsers()

    c = sub.add_parser("campaign", help="run a campaign (resumes where it stopped)")
    c.add_argument("spec", type=Path)
    c.add_argument("--results", type=Path, help="results directory (overrides the spec)")
    c.add_argument("--lanes", type=int, help="parallel runs (overrides the spec)")
    c.add_argument("--no-report", action="store_true", help="skip the report at the end")
    c.set_defaults(func=cmd_campaign)

    s = sub.add_parser("status", help="states per method and direction, with an ETA")
    s.add_argument("results", type=Path)
    s.set_defaults(func=cmd_status)

    v = sub.add_parser("validate", help="check a spec and list every problem")
    v.add_argument("spec", type=Path)
    v.set_defaults(func=cmd_validate)

    sc = sub.add_parser("schema", help="print the spec's JSON Schema")
    sc.set_defaults(func=cmd_schema)

    lm = sub.add_parser("list-methods", help="the registered methods")
    lm.set_defaults(func=cmd_list_methods)

    e = sub.add_parser("evaluate", help="TUM-Mono metrics of trajectory files against a ground truth")
    e.add_argument("--gt", type=Path, required=True)
    e.add_argument("--json", action="store_true", help="one JSON object per line")
    e.add_argument("traj", type=Path, nargs="+")
    e.set_defaults(func=cmd_evaluate)

    pr = sub.add_parser("prepare", help="build the prepared views a spec needs")
    pr.add_argument("spec", type=Path)
    pr.set_defaults(func=cmd_prepare)

    st = sub.add_parser("stats", help="the study's statistics of a results table")
    st.add_argument("results", type=Path, help="results.csv, results.parquet or a results directory")
    st.add_argument("--json", action="store_true", help="print the statistics as JSON")
    st.add_argument("--level", type=float, default=0.999, help="chi-square quantile of the outlier cut-off")
    st.add_argument("--adjust", default="holm", choices=["holm", "bonferroni", "BH", "none"])
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
    im.add_argument("--weights", action="append", default=[], metavar="NAME=FILE", help="a weights file for the build")
    im.add_argument(
        "--no-train-vocabulary", action="store_true", help="fail instead of training a vocabulary the source lacks"
    )
    im.add_argument("--build-arg", action="append", default=[], metavar="KEY=VALUE", help="extra Docker build argument")
    im.add_argument("--log-dir", type=Path, help="where build logs and records go (default .cache/images)")
    im.add_argument("--missing", action="store_true", help="build only the images that do not exist yet")
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
    dl.add_argument("name", choices=["tum-mono"])
    dl.add_argument("dest", type=Path)
    dl.add_argument("--sequences", default="1-50", help="numbers and ranges, e.g. 1-5,7")
    dl.add_argument("--url", help="base address of the sequence zips (default: the dataset's site)")
    dl.set_defaults(func=cmd_download)

    sy = sub.add_parser("synth", help="write a synthetic sequence in the TUM-Mono layout")
    sy.add_argument("out", type=Path)
    sy.add_argument("--frames", type=int, default=300)
    sy.add_argument("--seed", type=int, default=0)
    sy.add_argument("--size", default="640x480")
    sy.add_argument("--scene", choices=["indoor", "outdoor"], default="indoor")
    sy.set_defaults(func=cmd_synth)
    return p


# ---------------------------------------------------------------- campaign


def cmd_campaign(args) -> int:
    from runner.campaign import run_campaign
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
    progress = _Progress(sys.stdout.isatty())
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
    result = run_campaign(
        spec, on_event=progress.event, scheduler_hook=lambda s: sched_ref.update(s=s), log=progress.note
    )
    progress.close()
    _print_summary(result.results, result.results_csv)
    console.print(
        f"{sum(result.counts.values())} runs: "
        + ", ".join(f"{k} {v}" for k, v in result.counts.items())
        + f" ({time.monotonic() - t0:.0f} s)"
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


class _Progress:
    """A rich progress display on a terminal; plain lines otherwise."""

    def __init__(self, tty: bool):
        self.tty = tty
        self.done = self.failed = 0
        self.total = None
        self.lanes: dict[int, str] = {}
        self.t0 = time.monotonic()
        self._progress = None
        if tty:
            from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

            self._progress = Progress(
                TextColumn("{task.description}"),
                BarColumn(),
                MofNCompleteColumn(),
                TextColumn("failed {task.fields[failed]}"),
                TimeRemainingColumn(),
                console=console,
            )
            self._task = self._progress.add_task("runs", total=None, failed=0)
            self._progress.start()

    def note(self, msg: str) -> None:
        (self._progress.console if self._progress else console).print(msg)

    def event(self, kind: str, run, lane, info: dict) -> None:
        if kind == "started":
            self.lanes[lane.index] = f"{run.key.label}/{run.key.sequence}/{run.key.direction.value}/{run.key.trial}"
        elif kind == "finished":
            self.done += 1
            self.failed += info.get("state") == "failed"
            self.lanes.pop(lane.index, None)
            what = info.get("failure") or "ok"
            metric = info.get("e_align")
            extra = f" e_align={metric:.4g}" if isinstance(metric, float) else ""
            line = f"[lane {lane.index}] {run.key.id}: {info.get('state')} ({what}){extra}"
            if not self.tty:
                print(line, flush=True)
        elif kind in ("retry", "requeued"):
            self.note(f"[lane {lane.index}] {run.key.id}: {kind} {info.get('message', '')}")
        if self._progress:
            lanes = " | ".join(f"L{i}: {v}" for i, v in sorted(self.lanes.items()))
            self._progress.update(
                self._task, completed=self.done, failed=self.failed, description=f"runs [{lanes}]" if lanes else "runs"
            )

    def close(self) -> None:
        if self._progress:
            self._progress.stop()


def _print_summary(results: Path, csv: Path) -> None:
    import pandas as pd

    from runner.results import method_summary

    df = pd.read_csv(csv)
    if df.empty:
        return
    summ = method_summary(df)
    t = Table(title=f"per method ({results.name})")
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


def _fmt(v) -> str:
    if isinstance(v, float):
        return "-" if v != v else f"{v:.4g}"
    return str(v)


# ---------------------------------------------------------------- status


def cmd_status(args) -> int:
    from runner.ledger import Ledger
    from runner.results import method_summary, results_frame

    path = args.results / "ledger.sqlite"
    if not path.exists():
        raise SlamRunError(f"{args.results}: no ledger.sqlite; is this a results directory of `slamrun campaign`?")
    ledger = Ledger(path)
    df = results_frame(ledger)
    t = Table(title=f"{ledger.meta('campaign', args.results.name)}: states per method and direction")
    for c in ("method", "direction", "pending", "running", "done", "failed", "infra", "success %"):
        t.add_column(c)
    for (m, d), g in df.groupby(["method", "direction"], sort=True):
        s = method_summary(g).iloc[0]
        running = int((g.status == "running").sum())
        t.add_row(
            m, d, str(s.pending - running), str(running), str(s.done), str(s.failed), str(s.infra), _fmt(s.success_pct)
        )
    console.print(t)
    summ = method_summary(df)
    for _, r in summ.iterrows():
        console.print(f"{r['method']}: success {_fmt(r['success_pct'])} % of {r['done'] + r['failed']} method results")
    left = int(df.status.isin(["pending", "running"]).sum())
    walls = df.wall_s.dropna()
    lanes = (ledger.meta("eta") or {}).get("lanes", 1)
    if left and len(walls):
        eta = walls.mean() * left / max(lanes, 1)
        console.print(f"{left} runs left, ETA ~{eta / 60:.1f} min at {lanes} lane(s)")
    else:
        console.print(f"{left} runs left")
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
            cls.image or "-",
            "optional" if cls.gpu_capable else "no",
            "yes" if cls.native else "no",
            cls.loop_closure_switch or "-",
        )
    console.print(t)
    return 0


def cmd_evaluate(args) -> int:
    import numpy as np

    from runner.errors import TrajectoryFormatError
    from runner.evaluation import tum_mono_file
    from runner.trajectory import Trajectory, read_tum_many

    data = np.loadtxt(args.gt, comments="#", ndmin=2) if args.gt.exists() else None
    if data is None or data.shape[1] != 8:
        raise SlamRunError(f"{args.gt}: expected a groundtruthSync file of 'timestamp tx ty tz qx qy qz qw' rows")
    gt = Trajectory(data[:, 0], data[:, 1:4], data[:, 4:8])
    for f, traj in zip(args.traj, read_tum_many(args.traj), strict=True):
        if isinstance(traj, TrajectoryFormatError):
            d = {"status": "unreadable", "detail": str(traj)}
        else:
            d = tum_mono_file(gt, traj).to_dict()
        detail = d.get("detail") if d["status"] != "ok" else None
        d = {
            "file": str(f),
            **{
                k: d.get(k) for k in ("status", "e_t", "e_r", "e_s", "e_align", "e_start", "e_end", "e_rmse", "n_poses")
            },
            **({"detail": detail} if detail else {}),
        }
        if args.json:
            print(json.dumps(d))
        else:
            vals = " ".join(f"{k}={v:.6g}" for k, v in d.items() if isinstance(v, float))
            print(f"{f}: {d['status']} {vals}" + (f"({detail})" if detail else ""))
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
    total = 0
    for v in views.values():
        size = disk_usage(v.root)
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
        build_args=dict(_pair(b) for b in args.build_arg),
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

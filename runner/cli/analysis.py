"""slamrun stats, report and import: the study's statistics, the report of a results table, and published
trajectories imported into a campaign's results."""

from __future__ import annotations

from pathlib import Path

from runner.cli.console import console
from runner.core import jsonio
from runner.errors import SlamRunError


def add_commands(sub) -> None:
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
    im = sub.add_parser("import", help="import published trajectories into a campaign as runs of a method label")
    im.add_argument("sources", type=Path, nargs="+", help="folders, zips, or the first part of split zips (.zip.001)")
    im.add_argument("--campaign", type=Path, required=True, help="the campaign's results directory")
    im.add_argument("--as", dest="label", required=True, help="the method label of the imported runs, e.g. study:dso")
    im.add_argument(
        "--pattern",
        help="regular expression with the named groups sequence, direction (fw|bw|forward|backward) and trial, "
        "searched in each file's path (default: the study's <code>_<fw|bw>/sequence_SS_R.txt)",
    )
    im.add_argument("--format", default="tum", choices=["tum", "kitti", "euroc"], help="the files' trajectory format")
    im.set_defaults(func=cmd_import)


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
        print(jsonio.dumps(st.to_json()))
        return 0
    console.print(f"{len(st.kept)} runs kept, {st.n_outliers} outliers above {st.cutoff:.4f}")
    for name, m in st.metrics.items():
        meds = ", ".join(f"{g} {v:.4g} {m.letters[g]}" for g, v in sorted(m.medians.items(), key=lambda x: x[1]))
        console.print(f"{name}: Kruskal-Wallis chi2 {m.kruskal_chi2:.4g} (p {m.kruskal_p:.3g}); {meds}")
    return 0


def cmd_report(args) -> int:
    from runner.analysis.report import write_report
    from runner.engine.folders import REPORT, claim_output_folder, require_output_folder

    folder = args.results / "report"
    require_output_folder(folder, REPORT)  # never over a report/ of someone else's
    path = write_report(args.results)
    claim_output_folder(folder, REPORT)
    console.print(f"report: {path}")
    return 0


def cmd_import(args) -> int:
    from runner.engine.export import export
    from runner.engine.importer import check_campaign_folder, import_trajectories
    from runner.engine.ledger import Ledger, ResultsLock

    check_campaign_folder(args.campaign)  # before the lock file: never write into a folder that is not a campaign's
    with ResultsLock(args.campaign):  # not while a campaign writes the same ledger
        report = import_trajectories(args.campaign, args.sources, args.label, args.pattern, args.format)
        ledger = Ledger(args.campaign / "ledger.sqlite")
        try:
            export(ledger, args.campaign)
        finally:
            ledger.close()
    console.print(
        f"{args.label}: {len(report.imported)} run(s) imported, {len(report.unchanged)} unchanged (imported before), "
        f"{len(report.kept)} kept (a run of that key exists from another file: not overwritten), "
        f"{len(report.skipped)} skipped"
    )
    for line in report.skipped[:10]:
        console.print(f"  skipped: {line}")
    for line in report.kept[:10]:
        console.print(f"  kept: {line}")
    return 0

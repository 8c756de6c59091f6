"""slamrun stats, report and import: the study's statistics, the report of a results table, and published
trajectories imported into a campaign's results."""

from __future__ import annotations

from pathlib import Path

from slamrun.cli.console import console
from slamrun.core import jsonio
from slamrun.core.formats import FORMATS, RECOGNISED
from slamrun.results.files import CampaignFiles


def add_commands(sub) -> None:
    st = sub.add_parser("stats", help="the study's statistics of a results table")
    st.add_argument("results", type=Path, help="results.csv, results.parquet or a results directory")
    st.add_argument("--json", action="store_true", help="print the statistics as JSON")
    st.add_argument("--level", type=float, default=0.999, help="chi-square quantile of the outlier cut-off")
    st.add_argument("--adjust", default="holm", choices=["holm", "bonferroni", "BH", "none"], help="p-value adjustment")
    st.add_argument("--alpha", type=float, default=0.05, help="significance level of the letters")
    st.add_argument(
        "--metrics",
        nargs="+",
        help="metric columns (default: per dataset, the metrics its runs have: TUM-Mono's six where it has them, "
        "then ATE RMSE, RPE and KITTI's errors)",
    )
    st.add_argument(
        "--dataset", help="only this dataset's runs (the spec's dataset name; default: each dataset on its own)"
    )
    st.add_argument(
        "--published",
        type=Path,
        action="append",
        default=[],
        help="a CSV of published figures to print beside the medians (README, Published figures; repeatable; the "
        "built-in ones and the spec's `published:` are always read)",
    )
    st.set_defaults(func=cmd_stats)
    rp = sub.add_parser("report", help="write report/index.html with tables and figures")
    rp.add_argument("results", type=Path, help="a results directory")
    rp.set_defaults(func=cmd_report)
    im = sub.add_parser("import", help="import published trajectories into a campaign as runs of a method label")
    im.add_argument("sources", type=Path, nargs="+", help="folders, zips, or the first part of split zips (.zip.001)")
    im.add_argument("--campaign", type=Path, required=True, help="the campaign's results directory")
    im.add_argument(
        "--as",
        dest="label",
        required=True,
        help="the label of the imported runs, SOURCE:NAME (e.g. study:dso; a spec's labels never hold ':')",
    )
    im.add_argument(
        "--pattern",
        help="regular expression with the named groups sequence, direction (fw|bw|forward|backward) and trial, "
        "searched in each file's path (default: the study's <code>_<fw|bw>/sequence_SS_R.txt)",
    )
    im.add_argument(
        "--format",
        default="tum",
        choices=[*FORMATS, RECOGNISED],
        help="the files' trajectory format (auto: each file's first row tells)",
    )
    im.set_defaults(func=cmd_import)


def cmd_stats(args) -> int:
    from slamrun.analysis.datasets import dataset_rows, per_dataset_statistics, pooled_json, statistics_json
    from slamrun.analysis.load import load_results
    from slamrun.analysis.robustness import baseline
    from slamrun.results.published import read_table

    for f in args.published:  # a file named on the command line is an error, checked before anything is computed
        read_table(f)
    df = dataset_rows(baseline(load_results(args.results)), args.dataset, args.results)  # perturbed: in the report
    per = per_dataset_statistics(df, args.results, args.metrics, level=args.level, adjust=args.adjust, alpha=args.alpha)
    pooled = pooled_json(df)
    if args.json:
        print(jsonio.dumps(statistics_json(per, pooled)))
        return 0
    from slamrun.cli.display import pooled_lines, stats_lines

    for name, st in per.items():
        for line in stats_lines(name, st, args.adjust, args.alpha):
            console.print(line, markup=False, highlight=False)
    if len(per) > 1:
        for line in pooled_lines(pooled):
            console.print(line, markup=False, highlight=False)
    for line in _published_lines(df, args.results, args.published):
        console.print(line, markup=False, highlight=False)
    return 0


def _published_lines(df, results: Path, extra: list[Path]) -> list[str]:
    """Published figures beside the campaign's medians, one line each: never part of the statistics above."""
    from slamrun.analysis.load import by_dataset
    from slamrun.analysis.published import beside, figures, method_params, spec_files

    published, unread = figures([*spec_files(results), *extra])
    params = method_params(results)
    lines = [f"published figures left out: {why}" for why in unread]
    for name, part in by_dataset(df).items():
        table = beside(part, published, params)
        if table.empty:
            continue
        lines.append(f"published figures beside this campaign's ({name}; shown, never tested):")
        for r in table.to_dict("records"):
            lines.append(
                f"  {r['method']} {r['sequence']} {r['metric']}: median {r['this campaign, median']:.4g} over "
                f"{r['runs']} run(s); {r['published as']}: {r['published']:.4g} [{r['source']}]"
                + ("" if r["protocol differs"] == "-" else f"; differs: {r['protocol differs']}")
            )
    return lines


def cmd_report(args) -> int:
    from slamrun.analysis.report import write_report
    from slamrun.engine.folders import REPORT, claim_output_folder, require_output_folder
    from slamrun.engine.reevaluate import reevaluate_folder

    folder = args.results / "report"
    require_output_folder(folder, REPORT)  # never over a report/ of someone else's
    reevaluate_folder(args.results, log=lambda line: console.print(line, markup=False, highlight=False))
    path = write_report(args.results)
    claim_output_folder(folder, REPORT)
    console.print(f"report: {path}")
    return 0


def cmd_import(args) -> int:
    from slamrun.engine.export import export
    from slamrun.engine.importer import check_campaign_folder, import_trajectories
    from slamrun.engine.ledger import Ledger, ResultsLock

    check_campaign_folder(args.campaign)  # before the lock file: never write into a folder that is not a campaign's
    with ResultsLock(args.campaign):  # not while a campaign writes the same ledger
        report = import_trajectories(args.campaign, args.sources, args.label, args.pattern, args.format)
        ledger = Ledger(CampaignFiles(args.campaign).ledger)
        try:
            export(ledger, args.campaign)
        finally:
            ledger.close()
    lines = [
        f"{args.label}: {len(report.imported)} run(s) imported, {len(report.unchanged)} unchanged (imported before), "
        f"{len(report.kept)} kept (a run of that key exists from another file: not overwritten), "
        f"{len(report.skipped)} skipped",
        *(f"  skipped: {line}" for line in report.skipped[:10]),
        *(f"  kept: {line}" for line in report.kept[:10]),
    ]
    if report.imported:
        lines.append(f"results.csv and results.parquet updated, the report not: run `slamrun report {args.campaign}`")
    for line in lines:  # as written: a label's `:x:` is no emoji, a path's `[...]` no markup
        console.print(line, soft_wrap=True, markup=False, emoji=False, highlight=False)
    return 0

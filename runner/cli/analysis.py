"""slamrun stats and report: the study's statistics and the report of a results table."""

from __future__ import annotations

import json
from pathlib import Path

from runner.cli.console import console
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

"""The study's statistics, following R: Mahalanobis outliers, Lilliefors, Levene, Kruskal-Wallis, pairwise
Wilcoxon rank-sum tests with p-value adjustment, and compact letter displays. Pure functions.

Two guards keep a test from saying more than its data can: runs whose figures are copies of another run of the same
method, sequence and direction (a deterministic method's trials) count once (`distinct_runs`), and a test whose
input cannot support it (no spread within any group to rounding, every value tied, fewer runs than metrics) gives
no figure but a reason (`MetricStats.notes`, `StudyStats.outlier_note`). A figure that is no measurement (infinite,
a negative error, a magnitude above LIMIT) is named and left out of its metric's tests (`screen`)."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from scipy import stats

from slamrun.results.catalogue import COVERAGE, DIVERGED, LOW_COVERAGE, NON_NEGATIVE

ROUNDING = 1e-9  # a spread at most this, relative to the values' magnitude, is rounding: no spread
# A figure whose magnitude is above LIMIT is no measurement but a numerical blow-up: in metres 7 astronomical units,
# in %, degrees or a scale factor nothing a trajectory gives; below it every sum of squares the tests form stays
# finite (1e24 a square) however many runs a table has.
LIMIT = 1e12
# the figures that are errors or spreads, so never below 0 (e_s, e_s' are scale factors: positive)


def _no_spread(values: np.ndarray, scale: float) -> bool:
    """Whether `values` differ from their median by rounding at most (relative to `scale`)."""
    return len(values) == 0 or float(np.max(np.abs(values - np.median(values)))) <= ROUNDING * scale


def _scale(groups) -> float:
    """The magnitude of the values of `groups` (1 where all are 0)."""
    peak = max((float(np.max(np.abs(v))) for v in groups if len(v)), default=0.0)
    return peak if peak > 0 else 1.0


# ---------------------------------------------------------------- figures that are no measurement


def why_not_a_figure(metric: str, value: float) -> str:
    """Why `value` of `metric` is no measurement (empty where it is one, or a NaN: no figure)."""
    if value != value:
        return ""
    if math.isinf(value):
        return "not finite"
    if abs(value) > LIMIT:
        return f"magnitude above {LIMIT:g}: a numerical blow-up, no measurement"
    if value < 0 and metric in NON_NEGATIVE:
        return "negative: an error is never below 0"
    return ""


def run_name(row: dict) -> str:
    """A run as a line names it: method, sequence, direction and trial (the columns the table has)."""
    parts = [str(row[c]) for c in ("method", "sequence", "direction") if c in row]
    trial = row.get("trial")
    if isinstance(trial, float) and trial.is_integer():  # a column with a blank reads as floats
        trial = int(trial)
    return " ".join(parts + ([f"trial {trial}"] if "trial" in row else []))


def screen(df: pd.DataFrame, metrics: list[str]) -> tuple[pd.DataFrame, list[dict]]:
    """`df` with every figure of `metrics` that is no measurement (`why_not_a_figure`) made NaN (no figure: the run
    stays in the other metrics' tests), and each named: run, metric, value (as text: JSON has no infinity), reason.
    Only done runs are screened (the others are in no test)."""
    present = [m for m in metrics if m in df.columns]
    done = df["status"].eq("done").to_numpy() if "status" in df.columns else np.ones(len(df), bool)
    out, found = df, []
    for m in present:
        values = pd.to_numeric(df[m], errors="coerce").to_numpy(float)
        suspect = np.flatnonzero(done & (~(np.abs(values) <= LIMIT) | (values < 0)))
        bad = [(i, m, float(values[i]), why) for i in suspect if (why := why_not_a_figure(m, float(values[i])))]
        if bad:
            out = out.copy() if out is df else out
            out[m] = np.where(np.isin(np.arange(len(df)), [b[0] for b in bad]), math.nan, values)
            found += bad
    found.sort(key=lambda f: (f[0], present.index(f[1])))
    return out, [_named(df.iloc[i].to_dict(), m, value, why) for i, m, value, why in found]


def _named(row: dict, metric: str, value: float, why: str) -> dict:
    """One left-out figure as `StudyStats.excluded` lists it."""
    keys = {c: _plain(row[c]) for c in ("method", "sequence", "direction", "trial", "key") if c in row}
    return {"run": run_name(row), **keys, "metric": metric, "value": repr(value), "reason": why}


def _plain(v):
    """A cell as JSON writes it: numpy scalars plain, a missing cell None."""
    if v is None or (not isinstance(v, str) and bool(pd.isna(v))):
        return None
    return v.item() if isinstance(v, np.generic) else v


# ---------------------------------------------------------------- copies


def distinct_runs(
    df: pd.DataFrame, metrics: list[str], group: str = "method", within: tuple[str, ...] = ("sequence", "direction")
) -> tuple[pd.DataFrame, dict[str, dict]]:
    """The runs of `df` with every run whose figures (all of `metrics`) equal those of an earlier run of the same
    `group`, sequence and direction dropped: a copy adds no information, and counted as a sample it would shrink
    every p-value (a deterministic method's identical trials). Per group: runs, distinct runs, and whether it is
    deterministic (every sequence and direction with two runs or more gave one result). Without the `within`
    columns (a table of plain observations) nothing is dropped."""
    if df.empty or any(c not in df.columns for c in within):
        return df, {}
    keep = ~df.duplicated(subset=[group, *within, *metrics], keep="first")
    out = df[keep]
    counted = {}
    for g, part in df.groupby(group, sort=True):
        kept = out[out[group] == g]
        cells = part.groupby(list(within)).size()
        distinct = kept.groupby(list(within)).size()
        repeated = cells[cells > 1].index
        counted[str(g)] = {
            "runs": len(part),
            "distinct": len(kept),
            "deterministic": bool(len(repeated)) and bool((distinct.reindex(repeated) == 1).all()),
        }
    return out, counted


# ---------------------------------------------------------------- outliers


def mahalanobis_sq(x: np.ndarray) -> np.ndarray:
    """Squared Mahalanobis distance of every row to the mean (pooled rows, sample covariance). The distance is the
    same in any unit, so each column is first brought to magnitude 1 by a power of two (exact): no square overflows
    however large the figures. A covariance that is still not finite (a non-finite figure) or an SVD that does not
    converge gives no distance (NaN): LAPACK's SVD can loop forever on an infinite matrix, so it never sees one."""
    x = np.asarray(x, float)
    peak = np.max(np.abs(x), axis=0, initial=0.0)
    x = np.ldexp(x, -np.frexp(np.where(np.isfinite(peak), peak, 1.0))[1])
    centred = x - x.mean(axis=0)
    cov = np.atleast_2d(np.cov(x, rowvar=False, ddof=1))  # one metric: np.cov gives a scalar
    if not np.isfinite(cov).all():
        return np.full(len(x), np.nan)
    try:
        inverse = np.linalg.pinv(cov)
    except np.linalg.LinAlgError:
        return np.full(len(x), np.nan)
    return np.einsum("ij,ij->i", centred @ inverse, centred)


def chi2_cutoff(level: float, df: int) -> float:
    return float(stats.chi2.ppf(level, df))


# ---------------------------------------------------------------- normality and variance


def lilliefors_p(x: np.ndarray) -> float:
    """Lilliefors (Kolmogorov-Smirnov) normality test p-value, as nortest::lillie.test computes it
    (Dallal-Wilkinson approximation, Stephens' formulas above 0.1); NaN under 5 values or without spread."""
    x = np.sort(np.asarray(x, float)[np.isfinite(x)])
    n = len(x)
    if n < 5 or not x.std(ddof=1) > 0:  # too few values, or no spread (a deterministic method's trials)
        return math.nan
    p = stats.norm.cdf((x - x.mean()) / x.std(ddof=1))
    i = np.arange(1, n + 1)
    k = max(np.max(i / n - p), np.max(p - (i - 1) / n))
    kd, nd = (k, n) if n <= 100 else (k * (n / 100) ** 0.49, 100)
    pvalue = math.exp(
        -7.01256 * kd**2 * (nd + 2.78019)
        + 2.99587 * kd * math.sqrt(nd + 2.78019)
        - 0.122119
        + 0.974598 / math.sqrt(nd)
        + 1.67997 / nd
    )
    if pvalue > 0.1:
        kk = (math.sqrt(n) - 0.01 + 0.85 / math.sqrt(n)) * k
        if kk <= 0.302:
            pvalue = 1.0
        elif kk <= 0.5:
            pvalue = 2.76773 - 19.828315 * kk + 80.709644 * kk**2 - 138.55152 * kk**3 + 81.218052 * kk**4
        elif kk <= 0.9:
            pvalue = -4.901232 + 40.662806 * kk - 97.490286 * kk**2 + 94.029866 * kk**3 - 32.355711 * kk**4
        elif kk <= 1.31:
            pvalue = 6.198765 - 19.558097 * kk + 23.186922 * kk**2 - 10.733477 * kk**3 + 1.43963 * kk**4
        else:
            pvalue = 0.0
    return float(pvalue)


def levene(groups: list[np.ndarray]) -> tuple[float, float]:
    """Levene's test centred on the median (car::leveneTest's default, i.e. Brown-Forsythe): F and p.

    Groups without spread (a deterministic method's identical trials) give NaN, as in R, without a warning; so do
    groups whose spread is rounding alone (R would give F 1e34 from it: see `levene_problem`).
    """
    if levene_problem(groups):
        return math.nan, math.nan
    with np.errstate(divide="ignore", invalid="ignore"):
        res = stats.levene(*groups, center="median")
    return float(res.statistic), float(res.pvalue)


def levene_problem(groups: list[np.ndarray]) -> str | None:
    """Why Levene's test means nothing on `groups`, or None. The test is an analysis of variance of each value's
    absolute deviation from its group's median: where those deviations have no spread within any group (to rounding:
    every group without spread, or of two values, each as far from the median as the other) its F divides by
    rounding or by zero (1e30, inf) and means nothing."""
    if len(groups) < 2:
        return "fewer than two methods with two runs or more"
    scale = _scale(groups)
    if all(_no_spread(np.asarray(v, float), scale) for v in groups):
        return "no spread within any method's runs (identical to rounding): variances cannot be compared"
    deviations = [np.abs(np.asarray(v, float) - np.median(v)) for v in groups]
    if all(_no_spread(d, scale) for d in deviations):
        return (
            "the absolute deviations from each method's median, which the test compares, have no spread within any "
            "method (to rounding; e.g. two runs each, equally far from their median): its F would divide by zero"
        )
    return None


def kruskal_problem(groups: list[np.ndarray]) -> str | None:
    """Why a rank test means nothing on `groups` (fewer than two, or every value tied), or None."""
    if len(groups) < 2:
        return "fewer than two methods with runs"
    values = np.concatenate([np.asarray(v, float) for v in groups])
    if _no_spread(values, _scale(groups)):
        return "every value is the same (to rounding): nothing to rank"
    return None


def kruskal(groups: list[np.ndarray]) -> tuple[float, int, float]:
    """Kruskal-Wallis rank-sum test with the tie correction, as kruskal.test: chi-square, df, p."""
    res = stats.kruskal(*groups)
    return float(res.statistic), len(groups) - 1, float(res.pvalue)


# ---------------------------------------------------------------- pairwise tests


def wilcoxon_rank_sum_p(x: np.ndarray, y: np.ndarray) -> float:
    """Two-sided Wilcoxon rank-sum p-value with R's defaults: exact when both samples have fewer than 50
    values and there are no ties, otherwise the normal approximation with continuity correction. NaN where every
    value of both is the same (to rounding: nothing to rank)."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    if kruskal_problem([x, y]):
        return math.nan
    ties = len(np.unique(np.concatenate([x, y]))) < len(x) + len(y)
    exact = len(x) < 50 and len(y) < 50 and not ties
    res = stats.mannwhitneyu(
        x, y, alternative="two-sided", method="exact" if exact else "asymptotic", use_continuity=True
    )
    return float(res.pvalue)


def adjust_p(p: np.ndarray, method: str = "holm") -> np.ndarray:
    """R's p.adjust for holm, bonferroni, BH (fdr) and none; NaN p-values (tests not made) stay NaN and are not
    counted among the tests (R's p.adjust with its default n = the non-NA p-values)."""
    p = np.asarray(p, float)
    known = np.isfinite(p)
    if not known.all():
        out = np.full(len(p), np.nan)
        out[known] = adjust_p(p[known], method)
        return out
    m = len(p)
    if method == "none" or m == 0:
        return p.copy()
    if method == "bonferroni":
        return np.minimum(p * m, 1.0)
    order = np.argsort(p, kind="stable")
    out = np.empty(m)
    if method == "holm":
        adj = np.maximum.accumulate((m - np.arange(m)) * p[order])
        out[order] = np.minimum(adj, 1.0)
        return out
    if method in ("BH", "fdr"):
        rev = order[::-1]
        adj = np.minimum.accumulate(m / np.arange(m, 0, -1) * p[rev])
        out[rev] = np.minimum(adj, 1.0)
        return out
    raise ValueError(f"unknown p-value adjustment {method!r}; expected holm, bonferroni, BH or none")


def pairwise_wilcoxon(groups: dict[str, np.ndarray], adjust: str = "holm") -> list[dict]:
    """pairwise.wilcox.test: every pair of groups in R's lower-triangle order, with adjusted p-values."""
    names = sorted(groups)
    pairs = [(names[j], names[i]) for j in range(len(names)) for i in range(j + 1, len(names))]
    pairs.sort(key=lambda ab: (names.index(ab[1]), names.index(ab[0])))
    raw = np.array([wilcoxon_rank_sum_p(groups[a], groups[b]) for a, b in pairs])
    adj = adjust_p(raw, adjust)
    return [{"a": a, "b": b, "p": float(p)} for (a, b), p in zip(pairs, adj, strict=True)]


# ---------------------------------------------------------------- letters


def compact_letters(groups: list[str], pvalues: dict[frozenset, float], alpha: float = 0.05) -> dict[str, str]:
    """Compact letter display by insert-and-absorb (Piepho 2004, as multcompView::multcompLetters):
    two groups share a letter exactly when their difference is not significant at `alpha`."""
    if not groups:
        return {}
    columns: list[set[str]] = [set(groups)]
    for a, b in itertools.combinations(groups, 2):
        if pvalues.get(frozenset((a, b)), 1.0) > alpha:
            continue
        new_columns = []
        for col in columns:
            if a in col and b in col:
                new_columns += [col - {a}, col - {b}]
            else:
                new_columns.append(col)
        # absorb: drop columns contained in another
        uniq = []
        for c in new_columns:
            if c and c not in uniq:
                uniq.append(c)
        columns = [c for c in uniq if not any(c < other for other in uniq)]
    # letters in the order the groups are listed
    columns.sort(key=lambda c: min(groups.index(g) for g in c))
    letters = {g: "" for g in groups}
    for k, col in enumerate(columns):
        letter = _letter(k)
        for g in groups:
            if g in col:
                letters[g] += letter
    return letters


def _letter(k: int) -> str:
    alphabet = "abcdefghijklmnopqrstuvwxyz"
    return alphabet[k] if k < 26 else alphabet[k // 26 - 1] + alphabet[k % 26]


# ---------------------------------------------------------------- the whole procedure


@dataclass
class MetricStats:
    medians: dict[str, float]
    lilliefors_p: dict[str, float]
    levene_F: float
    levene_p: float
    kruskal_chi2: float
    kruskal_df: int
    kruskal_p: float
    pairwise_holm: list[dict]
    pairwise_none: list[dict]
    letters: dict[str, str]
    adjust: str = "holm"
    pairwise_adjusted: list[dict] = field(default_factory=list)
    notes: dict[str, str] = field(default_factory=dict)  # test -> why it gave no figure
    runs: dict[str, int] = field(default_factory=dict)  # per method: the runs this metric's tests took


@dataclass
class StudyStats:
    mahalanobis: list[float]
    cutoff: float
    n_outliers: int
    metrics: dict[str, MetricStats]
    kept: pd.DataFrame
    counted: dict[str, dict] = field(default_factory=dict)  # per method: runs, distinct runs, deterministic
    outlier_note: str = ""  # why no outlier test was made
    coverage: dict[str, float] = field(default_factory=dict)  # per method: the median coverage of its kept runs
    outlier_tests: list[dict] = field(default_factory=list)  # per set of metrics the runs had: outlier_tests
    left_out: dict[str, dict[str, str]] = field(default_factory=dict)  # per metric: method -> why it has no figure
    marks: dict = field(default_factory=dict)  # per method: its done runs' flags (results.marks.Flags)
    excluded: list[dict] = field(default_factory=list)  # each figure that is no measurement: `screen`

    @property
    def deterministic(self) -> list[str]:
        """The methods every sequence and direction of which gave identical figures over its trials."""
        return [g for g, c in self.counted.items() if c["deterministic"]]

    def outlier_text(self) -> str:
        """What the outlier tests did, in one sentence: the study's test over every metric, and where some runs lack a
        metric, the test of those runs on the metrics they have."""
        if self.outlier_note:
            return self.outlier_note
        parts = []
        for t in self.outlier_tests:
            which = ", ".join(t["metrics"])
            if t["cutoff"] is None:
                parts.append(
                    f"{t['runs']} run(s) with figures of {which} only not tested (too few runs for a covariance)"
                )
                continue
            over = f"over {len(t['metrics'])} metric(s)" + ("" if t is self.outlier_tests[0] else f" ({which})")
            parts.append(
                f"{t['outliers']} of {t['runs']} run(s) removed {over} (squared Mahalanobis distance above "
                f"{t['cutoff']:.4f}, the chi-square quantile, against the {t['population']} runs with those metrics)"
            )
        return "multivariate outliers: " + "; ".join(parts) if parts else "no run to test for outliers"

    def counting_note(self) -> str:
        """How copies were counted, in one sentence (empty where no run was a copy of another)."""
        copied = {g: c for g, c in self.counted.items() if c["distinct"] < c["runs"]}
        if not copied:
            return ""
        parts = [
            f"{g} {c['distinct']} of {c['runs']}" + (" (deterministic: identical trials)" if c["deterministic"] else "")
            for g, c in copied.items()
        ]
        return (
            "runs whose figures equal another run's of the same method, sequence and direction are counted once: "
            + ", ".join(parts)
        )

    def excluded_lines(self) -> list[str]:
        """Each figure left out of its metric's tests as no measurement, one line each (`screen`)."""
        return [
            f"left out of {e['metric']}'s tests: {e['run']}: {e['metric']} = {e['value']} ({e['reason']})"
            for e in self.excluded
        ]

    def to_json(self) -> dict:
        out = {
            "mahalanobis": self.mahalanobis,
            "cutoff": self.cutoff,
            "n_outliers": self.n_outliers,
            "outlier_note": self.outlier_note or None,
            "counted": self.counted,
            "counting_note": self.counting_note() or None,
            COVERAGE: self.coverage,
            "outlier_tests": self.outlier_tests,
            "marks": {
                m: {"mark": f.symbol, "done": f.done, LOW_COVERAGE: f.low_coverage, DIVERGED: f.diverged}
                for m, f in self.marks.items()
                if f.symbol
            },
            "metrics": {},
        }
        if self.excluded:  # the figures left out as no measurement (`screen`); absent where there is none
            out["excluded"] = self.excluded
        for name, m in self.metrics.items():
            out["metrics"][name] = {
                "medians": m.medians,
                "lilliefors_p": m.lilliefors_p,
                "levene_F": m.levene_F,
                "levene_p": m.levene_p,
                "kruskal_chi2": m.kruskal_chi2,
                "kruskal_df": m.kruskal_df,
                "kruskal_p": m.kruskal_p,
                "pairwise_holm": m.pairwise_holm,
                "pairwise_none": m.pairwise_none,
                "letters": m.letters,
                "runs": m.runs,
                "left_out": self.left_out.get(name, {}),
                "notes": m.notes,
            }
            if m.adjust not in ("holm", "none"):
                out["metrics"][name][f"pairwise_{m.adjust}"] = m.pairwise_adjusted
        return out


def outlier_tests(data: pd.DataFrame, metrics: list[str], level: float) -> tuple[np.ndarray, np.ndarray, list[dict]]:
    """The multivariate outlier test of each run on the metrics it has figures of: the squared Mahalanobis distance
    of every run, against the other runs that have those metrics, over those metrics, and the chi-square `level`
    quantile it is cut at (inf where untested). A run with every metric is tested as the study tests it; a run
    without one metric (KITTI's segments on a short track) is tested on the others, never dropped. Also, per set of
    metrics, what was tested: its metrics, runs, the population they were tested against, cut-off and outliers."""
    finite = np.isfinite(data[metrics].to_numpy(float)) if len(data) else np.zeros((0, len(metrics)), bool)
    d2, cutoff, tests = np.zeros(len(data)), np.full(len(data), np.inf), []
    for pattern in sorted({tuple(row) for row in finite if row.any()}, key=lambda r: (-sum(r), r)):
        cols = [m for m, has in zip(metrics, pattern, strict=True) if has]
        rows = (finite == pattern).all(axis=1)
        population = finite[:, list(pattern)].all(axis=1)
        test = {"metrics": cols, "runs": int(rows.sum()), "population": int(population.sum())}
        if population.sum() > len(cols):
            dist = mahalanobis_sq(data.loc[population, cols].to_numpy(float))
            d2[rows] = dist[rows[population]]
            cutoff[rows] = chi2_cutoff(level, len(cols))
            test |= {"cutoff": float(cutoff[rows][0]), "outliers": int((d2[rows] > cutoff[rows]).sum())}
        else:
            test |= {"cutoff": None, "outliers": 0}
        tests.append(test)
    return d2, cutoff, tests


def study_statistics(
    df: pd.DataFrame,
    metrics: list[str],
    group: str = "method",
    level: float = 0.999,
    adjust: str = "holm",
    alpha: float = 0.05,
) -> StudyStats:
    """The study's procedure on evaluated runs, each distinct result of a method, sequence and direction counted once
    (`distinct_runs`). Each metric's tests take every run with a figure for that metric: a run without one metric
    (KITTI's segments on a track under 100 m) stays in the others' (the outlier test takes each run on the metrics it
    has: `outlier_tests`). No metric or no run gives no figure (empty medians and tests), not an error, and a test
    its data cannot support gives none, with the reason. A figure that is no measurement (`screen`: infinite, a
    negative error, a magnitude above LIMIT) is left out of its metric's tests and named (`StudyStats.excluded`)."""
    df, excluded = screen(df, metrics)
    have = np.isfinite(df[metrics].to_numpy(float)).any(axis=1) if metrics else np.zeros(len(df), bool)
    data, counted = distinct_runs(df[have], metrics, group)
    data = data.reset_index(drop=True)
    d2, cutoffs, tests = outlier_tests(data, metrics, level)
    outlier_note = ""
    if tests and all(t["cutoff"] is None for t in tests):
        outlier_note = (
            f"no outlier test: {len(data)} run(s) for {len(metrics)} metric(s); a covariance needs more runs than "
            "metrics"
        )
    outlier = d2 > cutoffs
    kept = data[~outlier].reset_index(drop=True)
    out = {metric: metric_statistics(kept, metric, group, adjust, alpha) for metric in metrics}
    d2_list = [] if outlier_note else [float(v) if np.isfinite(c) else None for v, c in zip(d2, cutoffs, strict=True)]
    coverage = {}
    if COVERAGE in kept.columns:
        coverage = {str(g): float(v) for g, v in kept.groupby(group, sort=True)[COVERAGE].median().items() if v == v}
    cutoff = chi2_cutoff(level, len(metrics)) if metrics else math.nan
    st = StudyStats(d2_list, cutoff, int(outlier.sum()), out, kept, counted, outlier_note, coverage)
    st.outlier_tests, st.excluded = tests, excluded
    return st


def metric_statistics(kept: pd.DataFrame, metric: str, group: str, adjust: str, alpha: float) -> MetricStats:
    """One metric's tests on the runs of `kept` with a figure for it: medians, Lilliefors, Levene, Kruskal-Wallis,
    the pairwise tests and letters, and per method the runs counted."""
    rows = kept[np.isfinite(kept[metric].to_numpy(float))]
    usable = {g: part[metric].to_numpy(float) for g, part in rows.groupby(group, sort=True)}
    medians = {g: float(np.median(v)) for g, v in usable.items()}
    lillie = {g: lilliefors_p(v) for g, v in usable.items()}
    multi = [v for v in usable.values() if len(v) > 1]
    notes = {}
    if why := levene_problem(multi):
        notes["levene"] = why
    lev_f, lev_p = levene(multi) if len(multi) > 1 else (math.nan, math.nan)
    if why := kruskal_problem(list(usable.values())):
        notes["kruskal"] = notes["pairwise"] = why
        kw = (math.nan, max(len(usable) - 1, 0), math.nan)
    else:
        kw = kruskal(list(usable.values()))
    if any(v != v for v in lillie.values()):
        notes["lilliefors"] = "a method with fewer than 5 runs, or without spread, has none"
    holm = pairwise_wilcoxon(usable, "holm")
    none = pairwise_wilcoxon(usable, "none")
    chosen = {"holm": holm, "none": none}.get(adjust) or pairwise_wilcoxon(usable, adjust)
    pmap = {frozenset((r["a"], r["b"])): r["p"] for r in chosen if r["p"] == r["p"]}  # no test: no difference
    if "pairwise" not in notes and len(pmap) < len(chosen):
        notes["pairwise"] = "no test between two methods whose values are all the same (to rounding)"
    letters = compact_letters(sorted(usable, key=lambda g: medians[g]), pmap, alpha)
    return MetricStats(
        medians,
        lillie,
        lev_f,
        lev_p,
        *kw,
        holm,
        none,
        {g: letters[g] for g in usable},
        adjust,
        chosen,
        notes,
        {str(g): len(v) for g, v in usable.items()},
    )

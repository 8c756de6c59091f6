"""The study's statistics, following R: Mahalanobis outliers, Lilliefors, Levene, Kruskal-Wallis, pairwise
Wilcoxon rank-sum tests with p-value adjustment, and compact letter displays. Pure functions."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from scipy import stats

# ---------------------------------------------------------------- outliers


def mahalanobis_sq(x: np.ndarray) -> np.ndarray:
    """Squared Mahalanobis distance of every row to the mean (pooled rows, sample covariance)."""
    centred = x - x.mean(axis=0)
    cov = np.atleast_2d(np.cov(x, rowvar=False, ddof=1))  # one metric: np.cov gives a scalar
    return np.einsum("ij,ij->i", centred @ np.linalg.pinv(cov), centred)


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

    Groups without spread (a deterministic method's identical trials) give NaN, as in R, without a warning.
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        res = stats.levene(*groups, center="median")
    return float(res.statistic), float(res.pvalue)


def kruskal(groups: list[np.ndarray]) -> tuple[float, int, float]:
    """Kruskal-Wallis rank-sum test with the tie correction, as kruskal.test: chi-square, df, p."""
    res = stats.kruskal(*groups)
    return float(res.statistic), len(groups) - 1, float(res.pvalue)


# ---------------------------------------------------------------- pairwise tests


def wilcoxon_rank_sum_p(x: np.ndarray, y: np.ndarray) -> float:
    """Two-sided Wilcoxon rank-sum p-value with R's defaults: exact when both samples have fewer than 50
    values and there are no ties, otherwise the normal approximation with continuity correction."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    ties = len(np.unique(np.concatenate([x, y]))) < len(x) + len(y)
    exact = len(x) < 50 and len(y) < 50 and not ties
    res = stats.mannwhitneyu(
        x, y, alternative="two-sided", method="exact" if exact else "asymptotic", use_continuity=True
    )
    return float(res.pvalue)


def adjust_p(p: np.ndarray, method: str = "holm") -> np.ndarray:
    """R's p.adjust for holm, bonferroni, BH (fdr) and none."""
    p = np.asarray(p, float)
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


@dataclass
class StudyStats:
    mahalanobis: list[float]
    cutoff: float
    n_outliers: int
    metrics: dict[str, MetricStats]
    kept: pd.DataFrame

    def to_json(self) -> dict:
        out = {"mahalanobis": self.mahalanobis, "cutoff": self.cutoff, "n_outliers": self.n_outliers, "metrics": {}}
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
            }
            if m.adjust not in ("holm", "none"):
                out["metrics"][name][f"pairwise_{m.adjust}"] = m.pairwise_adjusted
        return out


def study_statistics(
    df: pd.DataFrame,
    metrics: list[str],
    group: str = "method",
    level: float = 0.999,
    adjust: str = "holm",
    alpha: float = 0.05,
) -> StudyStats:
    """The study's procedure on evaluated runs (rows with every metric finite); no metric or no run gives no
    figure (empty medians and tests), not an error."""
    data = df.dropna(subset=metrics).reset_index(drop=True)
    x = data[metrics].to_numpy(float)
    d2 = mahalanobis_sq(x) if metrics and len(data) > len(metrics) else np.zeros(len(data))
    cutoff = chi2_cutoff(level, len(metrics)) if metrics else math.nan
    kept = data[~(d2 > cutoff)].reset_index(drop=True)
    order = list(kept.groupby(group, sort=True).groups)
    out = {}
    for metric in metrics:
        groups = {g: kept.loc[kept[group] == g, metric].to_numpy(float) for g in order}
        usable = {g: v for g, v in groups.items() if len(v) > 0}
        medians = {g: float(np.median(v)) for g, v in usable.items()}
        lillie = {g: lilliefors_p(v) for g, v in usable.items()}
        multi = [v for v in usable.values() if len(v) > 1]
        lev_f, lev_p = levene(multi) if len(multi) > 1 else (math.nan, math.nan)
        kw = kruskal(list(usable.values())) if len(usable) > 1 else (math.nan, 0, math.nan)
        holm = pairwise_wilcoxon(usable, "holm")
        none = pairwise_wilcoxon(usable, "none")
        chosen = {"holm": holm, "none": none}.get(adjust) or pairwise_wilcoxon(usable, adjust)
        pmap = {frozenset((r["a"], r["b"])): r["p"] for r in chosen}
        by_median = sorted(usable, key=lambda g: medians[g])
        letters = compact_letters(by_median, pmap, alpha)
        out[metric] = MetricStats(
            medians,
            lillie,
            lev_f,
            lev_p,
            kw[0],
            kw[1],
            kw[2],
            holm,
            none,
            {g: letters[g] for g in usable},
            adjust,
            chosen,
        )
    return StudyStats([float(v) for v in d2], cutoff, int(np.sum(d2 > cutoff)), out, kept)

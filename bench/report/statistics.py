"""Statistics of a benchmark: fixed-budget and fixed-target views and pairwise rank tests.

All functions work on improvement traces ``[(evaluations, best gap), ...]`` (the gap being
``f - f_ref``, f_ref the problem's known minimum or the best any run reached) and plain
DataFrames; nothing here knows what the problems are.

* :func:`gap_at` / :func:`evals_to` read a trace at a budget / for a target;
* :func:`fixed_budget`: the median gap per method and problem at fractions of the budget;
* :func:`fixed_target`: per method and target, the runs that reach it, the ERT (all evaluations
  of all runs over the number of runs that reached it, COCO's expected running time) and the
  median evaluations of the runs that reached it;
* :func:`pairwise_tests`: every pair of methods compared by a two-sided rank test on the final
  gaps: Wilcoxon signed-rank over the problems (paired by problem, the median of a method's runs
  on each), and Mann-Whitney U within each problem when both methods have >= 3 runs there; the
  p-values Holm-corrected over the method pairs of each scope (:func:`holm`).
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pandas as pd

#: fractions of a run's budget at which the fixed-budget view reads the traces
BUDGET_FRACTIONS = (0.02, 0.1, 0.5, 1.0)
#: f-gap targets of the fixed-target view (same units as f)
GAP_TARGETS = (1e2, 1e0, 1e-2, 1e-4, 1e-6, 1e-8)
#: significance level of the pairwise tests (after Holm's correction)
ALPHA = 0.05


def gap_at(trace, n: float) -> float:
    """The best gap a run had reached after ``n`` evaluations (``inf`` before its first usable
    one)."""
    best = math.inf
    for k, g in trace:
        if k > n:
            break
        best = g
    return best


def evals_to(trace, target: float) -> float:
    """Evaluations a run needed to reach a gap <= ``target`` (``inf`` if it never did)."""
    for k, g in trace:
        if g <= target:
            return float(k)
    return math.inf


def holm(pvalues) -> np.ndarray:
    """Holm's step-down adjusted p-values (family-wise error), in the input order."""
    p = np.asarray(pvalues, dtype=float)
    m = p.size
    order = np.argsort(p, kind="stable")
    adj = np.empty(m)
    running = 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (m - rank) * p[i]))
        adj[i] = running
    return adj


def fixed_budget(runs: pd.DataFrame, fractions=BUDGET_FRACTIONS) -> pd.DataFrame:
    """Median gap per (method, problem) at each fraction of the budget: columns method, problem,
    budget, ``gap@<fraction>``; ``runs`` has method, problem, budget, trace."""
    rows = []
    for (method, problem, budget), g in runs.groupby(["method", "problem", "budget"], sort=True):
        row = {"method": method, "problem": problem, "budget": int(budget), "runs": len(g)}
        for q in fractions:
            row[f"gap@{q:g}"] = float(np.median([gap_at(t, q * budget) for t in g["trace"]]))
        rows.append(row)
    return pd.DataFrame(rows)


def fixed_target(runs: pd.DataFrame, targets=GAP_TARGETS) -> pd.DataFrame:
    """Per method and target over all its runs: ``reached`` (runs whose gap got to the target),
    ``runs``, ``ert`` (evaluations of all runs, a run counting those to the target when it reached
    it and all of its own otherwise, over ``reached``; ``inf`` when none) and ``median_evals`` of
    the runs that reached it."""
    rows = []
    for method, g in runs.groupby("method", sort=True):
        for t in targets:
            hit = np.array([evals_to(tr, t) for tr in g["trace"]])
            ok = np.isfinite(hit)
            spent = np.where(ok, hit, g["n_evals"].to_numpy(float)).sum()
            rows.append(
                {
                    "method": method,
                    "target": t,
                    "reached": int(ok.sum()),
                    "runs": len(g),
                    "ert": spent / ok.sum() if ok.any() else math.inf,
                    "median_evals": float(np.median(hit[ok])) if ok.any() else math.nan,
                }
            )
    return pd.DataFrame(rows)


def _log_gap(v):
    """Gaps compared on a log scale (ties at the floor 1e-12: both reached the optimum)."""
    return np.log10(np.maximum(np.asarray(v, float), 1e-12))


def pairwise_tests(runs: pd.DataFrame, value: str = "gap", alpha: float = ALPHA) -> pd.DataFrame:
    """Every pair of methods, two-sided tests of their final ``value`` (smaller is better):

    * ``scope = "all problems"``: Wilcoxon signed-rank over the problems both ran (the median of
      each method's runs per problem; zero differences split between the ranks), when there are
      >= 5 such problems;
    * ``scope = <problem>``: Mann-Whitney U of the runs on that problem, when both methods have
      >= 3 runs there.

    Columns: scope, a, b, n (problems or runs a/b), median_a, median_b, p, p_holm (Holm over the
    method pairs of the same scope: one family over the problems, one per problem), verdict
    (``a better``, ``b better`` or ``no difference`` at ``alpha``)."""
    from scipy.stats import mannwhitneyu, wilcoxon

    rows = []
    methods = sorted(runs["method"].unique())
    med = runs.groupby(["method", "problem"])[value].median().unstack("problem")
    for a, b in itertools.combinations(methods, 2):
        both = med.loc[[a, b]].dropna(axis=1)
        if both.shape[1] >= 5:
            xa, xb = _log_gap(both.loc[a]), _log_gap(both.loc[b])
            p = 1.0 if np.all(xa == xb) else float(wilcoxon(xa, xb, zero_method="zsplit").pvalue)
            rows.append(
                dict(
                    scope="all problems",
                    a=a,
                    b=b,
                    n=str(both.shape[1]),
                    median_a=float(np.median(both.loc[a])),
                    median_b=float(np.median(both.loc[b])),
                    p=p,
                    diff=float(np.median(xa - xb)),
                )
            )
        for problem, g in runs.groupby("problem", sort=True):
            va = g.loc[g["method"] == a, value].to_numpy(float)
            vb = g.loc[g["method"] == b, value].to_numpy(float)
            if len(va) >= 3 and len(vb) >= 3:
                la, lb = _log_gap(va), _log_gap(vb)
                same = np.all(la == la[0]) and np.all(lb == la[0])
                p = 1.0 if same else float(mannwhitneyu(la, lb, alternative="two-sided").pvalue)
                rows.append(
                    dict(
                        scope=problem,
                        a=a,
                        b=b,
                        n=f"{len(va)}/{len(vb)}",
                        median_a=float(np.median(va)),
                        median_b=float(np.median(vb)),
                        p=p,
                        diff=float(np.median(la) - np.median(lb)),
                    )
                )
    out = pd.DataFrame(rows, columns=["scope", "a", "b", "n", "median_a", "median_b", "p", "diff"])
    out["p_holm"] = np.nan
    for _, idx in out.groupby("scope").groups.items():  # one family per scope
        out.loc[idx, "p_holm"] = holm(out.loc[idx, "p"])
    out["verdict"] = [
        "no difference" if ph > alpha else ("a better" if d < 0 else "b better")
        for ph, d in zip(out["p_holm"], out["diff"])
    ]
    return out.drop(columns="diff")

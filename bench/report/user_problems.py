"""The report of user problems (suites with ``[problems.<name>]``, e.g. BBOB or NIST StRD).

Its wording follows the problem, not the FE cases: budgets and running times are in
*evaluations* (every call of the objective), success is each problem's own rule as stored in the
record (``result.extra.problem``: ``f − f_min ≤ target``, correct digits against a certified
answer, or the solver's verdict), and there is no Table 1. Sections: overview, success rates, ERT
to success with the pairwise rank tests next to it, fixed-target and fixed-budget views
(:mod:`bench.report.statistics`). Reads records only.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from bench.report import statistics as S
from bench.report import tables as T


def is_user_record(rec) -> bool:
    """Whether a record is a run of a user problem (its config names an entry point)."""
    return bool((rec.get("config") or {}).get("problem"))


def user_frame(records) -> pd.DataFrame:
    """One row per user-problem record: problem, method, seed, start, budget, n_evals, status,
    crashed, message, kind, rule (in words), success (by the problem's rule), evals_success
    (evaluations to success: to the target for an ``f-target`` rule, else the run's), f_ref,
    gap (final best f − f_ref), digits, trace (gaps)."""
    from bench.report.export import _trace_of

    rows = []
    for rec in records:
        if not is_user_record(rec):
            continue
        cfg, res = rec["config"], rec["result"]
        prob = (res.get("extra") or {}).get("problem") or {}
        rows.append(
            {
                "problem": cfg["case"],
                "method": cfg["method"],
                "seed": int(cfg["seed"]),
                "start": f"{cfg['start']}{cfg['start_index']}",
                "budget": int(cfg["budget"]),
                "n_evals": int(res.get("n_evals") or 0),
                "n_cache_hits": int(res.get("n_cache_hits") or 0),
                "status": res.get("status"),
                "crashed": bool(rec.get("error")),
                "message": str(res.get("message") or "").splitlines()[0:1],
                "kind": prob.get("kind", ""),
                "rule": prob.get("success_text", ""),
                "rule_kind": (prob.get("success_rule") or {}).get("kind", "solver"),
                "target": (prob.get("success_rule") or {}).get("target", math.nan),
                "success": bool(prob.get("success", False)),
                "f_min": prob.get("f_min"),
                "cost": float(res.get("cost") if res.get("cost") is not None else math.nan),
                "digits": prob.get("digits", math.nan),
                "raw_trace": _trace_of(rec),
            }
        )
    df = pd.DataFrame(rows)
    if not len(df):
        return df
    df["message"] = [m[0] if m else "" for m in df["message"]]
    best = df.groupby("problem")["cost"].min()
    df["f_ref"] = [
        float(fm) if fm is not None else float(best[p]) for p, fm in zip(df["problem"], df["f_min"])
    ]
    df["gap"] = [c - r if math.isfinite(c) else math.inf for c, r in zip(df["cost"], df["f_ref"])]
    df["trace"] = [[(n, f - r) for n, f in t] for t, r in zip(df["raw_trace"], df["f_ref"])]
    df["evals_success"] = [
        (S.evals_to(t, tg) if k == "f-target" else float(n)) if ok else math.nan
        for t, tg, k, n, ok in zip(
            df["trace"], df["target"], df["rule_kind"], df["n_evals"], df["success"]
        )
    ]
    return df.sort_values(["problem", "method", "seed", "start"], kind="stable").reset_index(
        drop=True
    )


def ert_frame(df: pd.DataFrame) -> pd.DataFrame:
    """ERT to success per (method, problem) in evaluations: the evaluations of all runs (to
    success for a successful run, all of them otherwise) over the number of successes (``inf``
    when none); with success rate and run count."""
    rows = []
    for (method, problem), g in df.groupby(["method", "problem"], sort=True):
        ok = g["success"].to_numpy(bool)
        spent = np.where(ok, g["evals_success"], g["n_evals"]).astype(float).sum()
        rows.append(
            {
                "method": method,
                "problem": problem,
                "runs": len(g),
                "successes": int(ok.sum()),
                "success_pct": 100.0 * ok.mean(),
                "ert": spent / ok.sum() if ok.any() else math.inf,
            }
        )
    return pd.DataFrame(rows)


def _fmt(v) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return T.DASH
    if isinstance(v, float) and math.isinf(v):
        return "∞"
    return f"{v:.3g}"


class _Tables:
    """Writes tables into ``dest/tables`` and collects their markdown in ``md``."""

    def __init__(self, dest: Path, tfmt):
        self.dest, self.tfmt, self.md = Path(dest), list(tfmt), []

    def __call__(self, stem, display, raw, caption, index_label="method"):
        paths = T.write_table(
            self.dest / "tables" / stem,
            self.tfmt,
            display=display,
            raw=raw,
            caption=caption,
            label=f"tab:{stem}",
            index_label=index_label,
        )
        links = ", ".join(f"[{p.suffix[1:]}]({p.relative_to(self.dest)})" for p in paths)
        self.md.extend([caption + "\n", T.to_markdown(display, index_label=index_label)])
        if links:
            self.md.append(f"Files: {links}\n")


def section(records, dest: Path, tfmt, source: Path | None = None) -> list[str]:
    """The markdown blocks of the user-problem report (tables written into ``dest/tables``);
    ``[]`` when there are no user-problem records."""
    df = user_frame(records)
    if not len(df):
        return []
    table = _Tables(dest, tfmt)
    md = table.md

    problems = sorted(df["problem"].unique())
    methods = sorted(df["method"].unique())
    md.append("## User problems\n")
    kinds = ", ".join(f"{n} {k}" for k, n in df.groupby("kind")["problem"].nunique().items())
    md.append(
        f"{len(df)} runs of {len(problems)} problems ({kinds}) with {len(methods)} methods; "
        f"budgets {', '.join(map(str, sorted(df['budget'].unique())))} evaluations (every call "
        "of the objective counts). Success is each problem's own rule:\n"
    )
    for rule, g in df.groupby("rule", sort=True):
        names = sorted(g["problem"].unique())
        shown = ", ".join(names[:6]) + (f" … ({len(names)} problems)" if len(names) > 6 else "")
        md.append(f"- {rule}: {shown}")
    md.append("")
    crashed = df[df["crashed"]]
    if len(crashed):
        md.append(
            f"{len(crashed)} run(s) did not run (counted as unsuccessful), e.g. "
            f"{crashed['problem'].iloc[0]} / {crashed['method'].iloc[0]}: "
            f"{crashed['message'].iloc[0]}\n"
        )

    ert = ert_frame(df)
    succ = ert.pivot(index="method", columns="problem", values="success_pct")
    table(
        "user_success",
        succ.map(lambda v: f"{v:.0f}"),
        succ,
        "Success rate in percent per method and problem (each problem's own rule).",
    )
    agg = (
        df.assign(spent=np.where(df["success"], df["evals_success"], df["n_evals"]).astype(float))
        .groupby("method")
        .agg(runs=("success", "size"), successes=("success", "sum"), spent=("spent", "sum"))
    )
    agg["ert"] = [s / k if k else math.inf for s, k in zip(agg["spent"], agg["successes"])]
    ert_disp = ert.pivot(index="method", columns="problem", values="ert").map(_fmt)
    ert_disp["all problems"] = [
        f"{_fmt(agg.loc[m, 'ert'])} ({int(agg.loc[m, 'successes'])}/{int(agg.loc[m, 'runs'])})"
        for m in ert_disp.index
    ]
    table(
        "user_ert",
        ert_disp,
        ert.set_index("method"),
        "ERT to success in evaluations (all evaluations of a method's runs on a problem, to "
        "success for a successful run, over its successes; ∞ = none); last column over all "
        "problems, with successes/runs.",
    )
    statistics_blocks(df, table, "user")
    fig = ecdf_figure(df, dest / "figures" / "user_ecdf.png")
    md.append(
        "Runtime ECDF (COCO style): fraction of (run, target) pairs with f − f_ref ≤ 10^k, "
        f"k = {', '.join(f'{math.log10(t):g}' for t in S.GAP_TARGETS)}, reached within a number "
        "of evaluations, one line per method over all problems.\n"
    )
    md.append(f"![runtime ECDF of the user problems]({fig.relative_to(dest).as_posix()})\n")
    return md


#: more method pairs than this: the rank-test table shows only those that differ
MAX_PAIRS_SHOWN = 30

#: what the gap of the user problems is, in the captions
USER_GAP = "f − f_ref (f_ref = f_min, or the best any run reached)"


def statistics_blocks(df: pd.DataFrame, table, prefix: str, gap: str = USER_GAP, unit="") -> None:
    """Pairwise rank tests, fixed-target and fixed-budget tables of the frame ``df`` (columns
    problem, method, budget, n_evals, gap, trace), written by ``table`` (a :class:`_Tables`) as
    ``<prefix>_rank_tests``, ``<prefix>_fixed_target``, ``<prefix>_fixed_budget``; ``gap`` says
    in words what the gap is, ``unit`` what the budgets count (default evaluations)."""
    unit = unit or "evaluations"
    short = gap.split(" (")[0]
    tests = S.pairwise_tests(df)
    if len(tests):
        overall = tests[tests["scope"] == "all problems"]
        per = tests[tests["scope"] != "all problems"]
        disp = overall[["a", "b", "n", "median_a", "median_b", "p", "p_holm", "verdict"]].copy()
        if len(per):
            counts = per.groupby(["a", "b"])["verdict"].value_counts().unstack(fill_value=0)
            disp = disp.merge(
                counts.reset_index().rename(
                    columns={"a better": "problems a better", "b better": "problems b better"}
                ),
                on=["a", "b"],
                how="outer",
            )
        for c in ("median_a", "median_b", "p", "p_holm"):
            if c in disp:
                disp[c] = disp[c].map(_fmt)
        disp = disp.drop(columns=["no difference"], errors="ignore").fillna(T.DASH)
        n_pairs, note = len(disp), ""
        if n_pairs > MAX_PAIRS_SHOWN:  # many methods: the pairs that differ
            differ = disp["verdict"].ne("no difference")
            for c in ("problems a better", "problems b better"):
                if c in disp:
                    differ |= disp[c].ne(T.DASH) & disp[c].astype(str).ne("0")
            disp = disp[differ]
            note = f" Of the {n_pairs} pairs, the {len(disp)} with a difference are shown."
        table(
            f"{prefix}_rank_tests",
            disp.set_index("a"),
            tests.set_index("scope"),
            f"Pairwise rank tests of the final {gap} on a log scale: Wilcoxon signed-rank over "
            "the problems (median of each method's "
            f"runs per problem; n problems), Holm-corrected, α = {S.ALPHA:g}; 'problems a/b "
            "better': problems where a Mann–Whitney U test of the runs (>= 3 per method) finds "
            "a difference after Holm's correction (every test in the CSV)." + note,
            index_label="a",
        )

    ft = S.fixed_target(df)
    ft_disp = ft.pivot(index="method", columns="target", values="ert").map(_fmt)
    reached = ft.pivot(index="method", columns="target", values="reached")
    runs = ft.pivot(index="method", columns="target", values="runs")
    ft_disp = ft_disp.astype(str) + " (" + reached.astype(str) + "/" + runs.astype(str) + ")"
    ft_disp = ft_disp[sorted(ft_disp.columns, reverse=True)]  # easy to hard
    ft_disp.columns = [f"≤ {t:g}" for t in ft_disp.columns]
    table(
        f"{prefix}_fixed_target",
        ft_disp,
        ft.set_index("method"),
        f"Fixed target: ERT in {unit} to reach {gap} ≤ target over all runs of a method "
        "(runs that reached it / runs).",
    )
    fb = S.fixed_budget(df)
    cols = [c for c in fb.columns if c.startswith("gap@")]
    fb_disp = fb.groupby("method")[cols].median().map(_fmt)
    fb_disp.columns = [f"{float(c[4:]):g} × budget" for c in cols]
    table(
        f"{prefix}_fixed_budget",
        fb_disp,
        fb.set_index("method"),
        f"Fixed budget: {short} reached after a fraction of the budget, median over the "
        "problems of the median over a method's runs (per problem in the CSV).",
    )


def fe_frame(records) -> pd.DataFrame:
    """The FE (and analytic) runs as :func:`statistics_blocks` reads them: a problem is a case
    with its data tier and treatment, a method the solver with its track and Jacobian; the gap is
    the relative cost ``(J − J_best) / (J_init − J_best)`` (J_best the best final cost any run of
    the problem reached, J_init the median first cost of its runs; the FE report's cost-target
    scale), the trace from the record's exact trace or its history rows."""
    from bench.report.export import _method_key, _problem_key, _trace_of

    rows = []
    for rec in records:
        if is_user_record(rec):
            continue
        cfg, res = rec["config"], rec["result"]
        trace = _trace_of(rec)
        if not trace:
            continue
        rows.append(
            {
                "problem": _problem_key(cfg),
                "method": _method_key(cfg),
                "budget": int(cfg["budget"]),
                "n_evals": max(int(res.get("n_evals") or 0), trace[-1][0]),
                "raw_trace": trace,
            }
        )
    df = pd.DataFrame(rows)
    if not len(df):
        return df
    best = df.groupby("problem")["raw_trace"].agg(lambda ts: min(t[-1][1] for t in ts))
    init = df.groupby("problem")["raw_trace"].agg(
        lambda ts: float(np.median([t[0][1] for t in ts]))
    )
    scale = {p: max(init[p] - best[p], 1e-300) for p in best.index}
    df["trace"] = [
        [(n, (f - best[p]) / scale[p]) for n, f in t]
        for t, p in zip(df["raw_trace"], df["problem"])
    ]
    df["gap"] = [t[-1][1] for t in df["trace"]]
    return df


def fe_statistics(records, dest: Path, tfmt) -> list[str]:
    """The statistics section of the FE runs (``femubench report --format stats``)."""
    df = fe_frame(records)
    if not len(df):
        return []
    table = _Tables(dest, tfmt)
    table.md.append("## Statistics of the FE runs\n")
    table.md.append(
        "Rank tests, fixed-target and fixed-budget views of the runs above (a problem: a case with "
        "its data tier and treatment; budgets in the solvers' evaluations, charges not "
        "included).\n"
    )
    statistics_blocks(
        df,
        table,
        "fe",
        gap="(J − J_best)/(J_init − J_best) (J_best the best final cost of the case, J_init its "
        "median first cost)",
    )
    return table.md


def ecdf_figure(df: pd.DataFrame, path: Path, targets=S.GAP_TARGETS) -> Path:
    """Runtime ECDF of the frame's runs: per method, the fraction of (run, target) pairs reached
    within n evaluations (log axis, up to the largest budget); black-and-white line styles."""
    from bench.plotting import SINGLE, line_style, pyplot, save

    plt = pyplot()
    fig, ax = plt.subplots(figsize=SINGLE)
    xmax = float(max(df["budget"].max(), df["n_evals"].max(), 2))
    for i, (method, g) in enumerate(df.groupby("method", sort=True)):
        hits = np.array([S.evals_to(t, tg) for t in g["trace"] for tg in targets], float)
        done = np.sort(hits[np.isfinite(hits)])
        x = np.concatenate([[1.0], np.maximum(done, 1.0), [xmax]])
        y = np.concatenate(
            [[0.0], np.arange(1, done.size + 1) / hits.size, [done.size / hits.size]]
        )
        style = line_style(i)
        ax.step(x, y, where="post", label=method, markevery=max(1, x.size // 8), **style)
    ax.set_xscale("log")
    ax.set_xlim(1, xmax)
    ax.set_ylim(0, 1)
    ax.set_xlabel("evaluations")
    ax.set_ylabel("fraction of (run, target) pairs")
    ax.legend(loc="center left", bbox_to_anchor=(1.02, 0.5), frameon=False)
    return save(fig, path)

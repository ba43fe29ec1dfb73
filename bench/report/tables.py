"""Report tables computed from the tidy run DataFrame of :func:`bench.experiment.store.to_frames`.

* :func:`table1` — the paper's Table 1 for one method: signed residual error of every
  identified parameter with respect to its reference, in percent (median over seeds and
  starts), rows = parameters, columns = cases, NaN (printed ``–``) where a parameter is not
  active in a case. A cell whose final parameter lies on a bound of the case's box (within
  :data:`BOUND_TOL` of the box width, in at least one of its runs) is flagged with
  :data:`BOUND_MARK`: its error then measures the box, not the identification.
* :func:`comparison` — per case x method: runs, success rate (every |error| <= tol), median
  and interquartile range of forward evaluations, median final cost, median wall time.
* :func:`success_matrix` — success rate (%) per method (rows) and case (columns).

Writers render a DataFrame as Markdown, CSV (full precision, ``–`` for inactive) or LaTeX
(booktabs) without extra dependencies.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from bench.experiment.store import PARAMETER_ORDER, parameter_order
from bench.plotting import LABELS
from bench.report.catalogue import CASE_ORDER, METHOD_FAMILIES, case_info

DASH = "–"  # en dash: inactive parameter
BOUND_MARK = "†"  # a final parameter on a bound of its box
BOUND_TOL = 1e-6  # "on a bound": within this fraction of the box width (upper - lower)


def case_box(case: str) -> dict[str, tuple[float, float, float]]:
    """``{parameter: (lower, upper, reference)}`` of a case (physical units); empty for an unknown
    case."""
    c = case_info(case)
    return {} if c is None else {name: (lo, hi, ref) for name, lo, hi, ref in c.parameters}


def normalised_box(case: str) -> dict[str, tuple[float, float]]:
    """``{parameter: (lower, upper)}`` of a case divided by the reference (as x / x_REF; sorted)."""
    out = {}
    for name, (lo, hi, ref) in case_box(case).items():
        if ref != 0:
            a, b = sorted((lo / ref, hi / ref))
            out[name] = (a, b)
    return out


def bound_side(x: float, lower: float, upper: float, tol: float = BOUND_TOL) -> int:
    """-1 when ``x`` lies on the lower bound, +1 on the upper (within ``tol`` of the box width),
    else 0
    (also for NaN or a degenerate box)."""
    width = upper - lower
    if not (math.isfinite(x) and width > 0):
        return 0
    if x - lower <= tol * width:
        return -1
    if upper - x <= tol * width:
        return 1
    return 0


def bound_hits(runs: pd.DataFrame) -> pd.DataFrame:
    """Per run (rows as ``runs``) and parameter (columns): -1 final value on the lower bound of the
    case's box, +1 on the upper, 0 inside, NaN where inactive or the case is unknown."""
    params = runs.attrs.get("parameters") or parameter_order(
        c[2:] for c in runs.columns if c.startswith("x.")
    )
    out = pd.DataFrame(np.nan, index=runs.index, columns=list(params))
    if not len(runs):
        return out
    for case, g in runs.groupby("case", sort=False):
        box = case_box(case)
        for p in params:
            col = f"x.{p}"
            if p not in box or col not in g:
                continue
            x = pd.to_numeric(g[col], errors="coerce").to_numpy(float)
            lo, hi = box[p][0], box[p][1]
            side = np.array([bound_side(float(v), lo, hi) for v in x], float)
            out.loc[g.index, p] = np.where(np.isfinite(x), side, np.nan)
    return out


def case_order(cases) -> list[str]:
    """The nine FE cases in the study's order, then the others alphabetically."""
    canon = list(CASE_ORDER)
    cases = list(dict.fromkeys(cases))
    return [c for c in canon if c in cases] + sorted(c for c in cases if c not in canon)


def base_method(label: str) -> str:
    """The solver name of a method label (``"lm (consistent) [surrogate]"`` -> ``"lm"``)."""
    return str(label).split(" (")[0].split(" [")[0]


def method_order(methods) -> list[str]:
    """Methods by family (local, global, sampling), then in the order of the study's list."""
    rank = {"local": 0, "global": 1, "sampling": 2}
    canon = list(METHOD_FAMILIES)  # registration order

    def key(m):
        base = base_method(m)  # labels carry the data tier and track: "lm (consistent) [FD]"
        fam = rank.get(METHOD_FAMILIES.get(base), 3)
        return fam, canon.index(base) if base in canon else len(canon), m

    return sorted(dict.fromkeys(methods), key=key)


def identified(runs: pd.DataFrame) -> pd.DataFrame:
    """Runs that returned an identification (crashed runs excluded)."""
    if "crashed" not in runs:
        return runs
    return runs[~runs["crashed"].astype(bool)]


#: The success criterion of the comparison (issue 16), defined here once: every identified
#: parameter within SUCCESS_TOL percent of its reference and every derived parameter (the exponent
#: cases' ``a``, see :mod:`bench.report.derived`) within DERIVED_TOL[name] percent.
SUCCESS_TOL = 2.0
DERIVED_TOL = {"a": 20.0}


def success_rule(tol: float = SUCCESS_TOL, derived_tol: dict | None = None) -> str:
    """The success criterion in words (for captions and report.md)."""
    dt = DERIVED_TOL if derived_tol is None else derived_tol
    extra = "".join(f", and {p} within {v:g} %" for p, v in dt.items())
    return f"every identified parameter within {tol:g} % of its reference{extra}"


def success(runs: pd.DataFrame, tol: float = SUCCESS_TOL, derived_tol: dict | None = None):
    """True where every active identified parameter is within ``tol`` percent of its reference and
    every derived parameter (``derived_tol``, default :data:`DERIVED_TOL`) within its own
    tolerance; crashed runs and runs without any active parameter fail."""
    dt = DERIVED_TOL if derived_tol is None else derived_tol
    params = runs.attrs.get("parameters") or parameter_order(
        c[4:] for c in runs.columns if c.startswith("err.")
    )
    params = [p for p in params if f"err.{p}" in runs]
    ok = pd.Series(True, index=runs.index)
    n_active = pd.Series(0, index=runs.index)
    for p in params:
        err = runs[f"err.{p}"].astype(float).abs()
        active = err.notna()
        n_active += (active & (p not in dt)).astype(int)
        ok &= (err <= dt.get(p, tol)) | ~active
    ok &= n_active > 0
    if "crashed" in runs:
        ok &= ~runs["crashed"].fillna(False).astype(bool)
    return ok


def groups_key(runs: pd.DataFrame) -> list[str]:
    """Grouping beyond case x method: the budget when the suite used several."""
    return ["budget"] if "budget" in runs and runs["budget"].nunique() > 1 else []


def table1(runs: pd.DataFrame, method: str, *, budget: int | None = None) -> pd.DataFrame:
    """Rows = parameters, columns = cases; median signed error in percent (NaN = inactive)."""
    sel = runs[runs["method"] == method]
    if budget is not None:
        sel = sel[sel["budget"] == budget]
    cases = case_order(runs["case"].unique())
    params = runs.attrs.get("parameters") or parameter_order(
        c[4:] for c in runs.columns if c.startswith("err.")
    )
    # canonical study parameters always appear (the paper's rows), others only when used
    rows = [p for p in PARAMETER_ORDER if p in params] + [
        p for p in params if p not in PARAMETER_ORDER
    ]
    ok = identified(sel)
    hits = bound_hits(ok) if len(ok) else pd.DataFrame()
    vals = np.full((len(rows), len(cases)), math.nan)
    on_bound: dict[tuple[str, str], tuple[int, int]] = {}
    by_case = dict(tuple(ok.groupby("case", sort=False))) if len(ok) else {}
    for j, case in enumerate(cases):
        part = by_case.get(case)
        if part is None:
            continue
        for i, p in enumerate(rows):
            if f"err.{p}" not in part:
                continue
            col = part[f"err.{p}"].to_numpy(float)
            if not np.isfinite(col).any():
                continue
            vals[i, j] = float(np.nanmedian(col))
            if p in hits:
                h = hits.loc[part.index, p].to_numpy(float)
                h = h[np.isfinite(h) & np.isfinite(col)]
                if (h != 0).any():
                    on_bound[(p, case)] = (int((h != 0).sum()), int(len(h)))
    out = pd.DataFrame(vals, index=pd.Index(rows, name="parameter"), columns=cases)
    out.attrs["n_runs"] = {c: int((sel["case"] == c).sum()) for c in cases}
    out.attrs["n_identified"] = {c: int((ok["case"] == c).sum()) for c in cases}
    out.attrs["on_bound"] = on_bound  # (parameter, case) -> (runs on a bound, runs)
    return out


def comparison(
    runs: pd.DataFrame, tol: float = SUCCESS_TOL, derived_tol: dict | None = None
) -> pd.DataFrame:
    """One row per case x method (x budget when there are several)."""
    extra = groups_key(runs)
    ok = success(runs, tol, derived_tol)
    rows = []
    for (case, method, *rest), g in runs.groupby(["case", "method", *extra], sort=False):
        ev = g["n_evals"].astype(float)
        gi = identified(g)
        row = {"case": case, "method": method}
        row.update(dict(zip(extra, rest)))
        row.update(
            {
                "runs": len(g),
                "success_pct": 100.0 * float(ok.loc[g.index].mean()),
                "evals_median": float(ev.median()),
                "evals_q25": float(ev.quantile(0.25)),
                "evals_q75": float(ev.quantile(0.75)),
                "fe_median": float(g["total_equivalents"].median())
                if "total_equivalents" in g
                else math.nan,
                "cost_median": float(gi["cost"].median()) if len(gi) else math.nan,
                "max_err_median_pct": float(gi["max_abs_err"].median()) if len(gi) else math.nan,
                "wall_median_s": float(g["wall_s"].median()),
                "crashed": int(g["crashed"].sum()),
            }
        )
        rows.append(row)
    df = pd.DataFrame(rows)
    if len(df):
        cases, methods = case_order(df["case"]), method_order(df["method"])
        df["_c"] = df["case"].map(cases.index)
        df["_m"] = df["method"].map(methods.index)
        df = df.sort_values(["_c", "_m", *extra]).drop(columns=["_c", "_m"]).reset_index(drop=True)
    df.attrs["tol"] = tol
    return df


def success_matrix(
    runs: pd.DataFrame, tol: float = SUCCESS_TOL, derived_tol: dict | None = None
) -> pd.DataFrame:
    """Success rate in percent, rows = methods, columns = cases (all budgets pooled)."""
    ok = success(runs, tol, derived_tol)
    tab = (
        pd.DataFrame(
            {"method": runs["method"], "case": runs["case"], "ok": ok.astype(float)}
        ).pivot_table(index="method", columns="case", values="ok", aggfunc="mean")
        * 100.0
    )
    tab = tab.reindex(index=method_order(tab.index), columns=case_order(tab.columns))
    tab.index.name, tab.columns.name = "method", None
    return tab


# --- formatting ------------------------------------------------------------------------------


def fmt_pct(v: float) -> str:
    """A percentage for Table 1: ``–`` if inactive, 3 significant digits, scientific if tiny."""
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return DASH
    if v == 0:
        return "0"
    a = abs(v)
    if a >= 1e-2 and a < 1e4:
        return f"{v:.3g}" if a < 100 else f"{v:.0f}"
    return f"{v:.2e}"


def fmt_num(v: float, digits: int = 3) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return DASH
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if v == 0:
        return "0"
    a = abs(v)
    if 1e-2 <= a < 1e5:
        return f"{v:.{digits}g}"
    return f"{v:.{max(digits - 1, 1)}e}"


def table1_display(t: pd.DataFrame) -> pd.DataFrame:
    """Table 1 as strings; cells with a final parameter on a bound carry :data:`BOUND_MARK`
    (followed by ``k/n`` when only k of the n runs of the cell ended there)."""
    out = t.apply(lambda col: col.map(fmt_pct)).astype(str)
    for (p, case), (k, n) in t.attrs.get("on_bound", {}).items():
        if p in out.index and case in out.columns:
            out.loc[p, case] = f"{out.loc[p, case]} {BOUND_MARK}" + (f"{k}/{n}" if k < n else "")
    return out


def bound_note(t: pd.DataFrame) -> str:
    """The footnote of the bound marks of a Table 1 (empty when no cell is marked)."""
    if not t.attrs.get("on_bound"):
        return ""
    return (
        f"{BOUND_MARK} the identified parameter ended on a bound of the case's box (within "
        f"{BOUND_TOL:g} of the box width; {BOUND_MARK}k/n: in k of the n runs): the error then "
        "measures the box, not the identification."
    )


def comparison_display(df: pd.DataFrame) -> pd.DataFrame:
    tol = df.attrs.get("tol", 1.0)
    out = pd.DataFrame({"case": df["case"], "method": df["method"]})
    if "budget" in df:
        out["budget"] = df["budget"].astype(int).astype(str)
    out["runs"] = df["runs"].astype(int).astype(str)
    out[f"success (|err| ≤ {tol:g} %)"] = df["success_pct"].map(lambda v: f"{v:.0f} %")
    out["evals median"] = df["evals_median"].map(lambda v: f"{v:.0f}")
    out["evals IQR"] = [f"{a:.0f}–{b:.0f}" for a, b in zip(df["evals_q25"], df["evals_q75"])]
    out["forward-equivalents median"] = df["fe_median"].map(lambda v: fmt_num(v))
    out["final cost median"] = df["cost_median"].map(lambda v: fmt_num(v))
    out["max |err| median (%)"] = df["max_err_median_pct"].map(fmt_pct)
    out["wall median (s)"] = df["wall_median_s"].map(lambda v: fmt_num(v, 2))
    out["crashed"] = df["crashed"].astype(int).astype(str)
    return out


def success_display(t: pd.DataFrame) -> pd.DataFrame:
    return t.apply(lambda col: col.map(lambda v: DASH if pd.isna(v) else f"{v:.0f}")).astype(str)


def to_markdown(df: pd.DataFrame, *, index: bool = True, index_label: str | None = None) -> str:
    """A GitHub-flavoured Markdown table of the (string) cells of ``df``."""
    cols = [str(c) for c in df.columns]
    body = [[str(v) for v in row] for row in df.itertuples(index=False)]
    if index:
        cols = [index_label or str(df.index.name or "")] + cols
        body = [[str(i)] + r for i, r in zip(df.index, body)]
    esc = lambda s: s.replace("|", "\\|")  # noqa: E731
    lines = [
        "| " + " | ".join(map(esc, cols)) + " |",
        "|" + "|".join([":---"] + ["---:"] * (len(cols) - 1)) + "|",
    ]
    lines += ["| " + " | ".join(map(esc, r)) + " |" for r in body]
    return "\n".join(lines) + "\n"


_TEX_ESC = {
    "&": r"\&",
    "%": r"\%",
    "$": r"\$",
    "#": r"\#",
    "_": r"\_",
    "{": r"\{",
    "}": r"\}",
    "~": r"\textasciitilde{}",
    "^": r"\textasciicircum{}",
    "\\": r"\textbackslash{}",
    "–": "--",
    "≤": r"$\leq$",
    "|": r"$|$",
    BOUND_MARK: r"\textsuperscript{\dag}",
}


def tex_escape(s: str) -> str:
    return "".join(_TEX_ESC.get(ch, ch) for ch in str(s))


def to_latex(
    df: pd.DataFrame,
    *,
    caption: str,
    label: str,
    index: bool = True,
    index_label: str | None = None,
    raw_index: bool = False,
) -> str:
    """A booktabs ``table`` environment; cells are escaped, ``–`` becomes ``--``."""
    cols = [tex_escape(c) for c in df.columns]
    body = [[tex_escape(v) for v in row] for row in df.itertuples(index=False)]
    if index:
        cols = [tex_escape(index_label or df.index.name or "")] + cols
        idx = [str(i) if raw_index else tex_escape(i) for i in df.index]
        body = [[i] + r for i, r in zip(idx, body)]
    spec = "l" + "r" * (len(cols) - 1)
    lines = [
        r"\begin{table}[htbp]",
        r"\centering",
        rf"\caption{{{tex_escape(caption)}}}",
        rf"\label{{{label}}}",
        r"\small",
        rf"\begin{{tabular}}{{{spec}}}",
        r"\toprule",
        " & ".join(cols) + r" \\",
        r"\midrule",
    ]
    lines += [" & ".join(r) + r" \\" for r in body]
    lines += [r"\bottomrule", r"\end{tabular}", r"\end{table}"]
    return "\n".join(lines) + "\n"


def write_table(
    stem: Path,
    formats,
    *,
    display: pd.DataFrame,
    raw: pd.DataFrame,
    caption: str,
    label: str,
    index: bool = True,
    index_label: str | None = None,
    tex_display: pd.DataFrame | None = None,
    raw_index_tex: bool = False,
    raw_index: bool | None = None,
) -> list[Path]:
    """Write ``stem.{md,csv,tex}`` for the requested formats; return the paths written.
    ``raw_index``: whether the CSV (``raw``) has an index column (default: ``index``)."""
    raw_index = index if raw_index is None else raw_index
    stem.parent.mkdir(parents=True, exist_ok=True)
    paths = []
    if "md" in formats:
        p = stem.with_suffix(".md")
        p.write_text(
            f"{caption}\n\n" + to_markdown(display, index=index, index_label=index_label),
            encoding="utf-8",
        )
        paths.append(p)
    if "csv" in formats:
        p = stem.with_suffix(".csv")
        raw.to_csv(
            p,
            index=raw_index,
            index_label=index_label if raw_index else None,
            na_rep=DASH,
            float_format="%.10g",
        )
        paths.append(p)
    if "tex" in formats:
        p = stem.with_suffix(".tex")
        p.write_text(
            to_latex(
                tex_display if tex_display is not None else display,
                caption=caption,
                label=label,
                index=index,
                index_label=index_label,
                raw_index=raw_index_tex,
            ),
            encoding="utf-8",
        )
        paths.append(p)
    return paths


def tex_param_index(t: pd.DataFrame) -> pd.DataFrame:
    """Table 1 with LaTeX parameter symbols as index (unescaped)."""
    t = t.copy()
    t.index = [LABELS.get(p, tex_escape(p)) for p in t.index]
    return t


# --- comparison tables of issue 16 -----------------------------------------------------------


def a_table(runs: pd.DataFrame) -> pd.DataFrame:
    """The exponent cases' coefficient a (derived from pt0, sigma0 and b, see
    :mod:`bench.report.derived`): rows = methods, per case ``<case>`` the median identified a and
    ``<case> err`` its median signed error in percent; ``reference`` row first. Empty without
    ``x.a``."""
    if "x.a" not in runs or not runs["x.a"].notna().any():
        return pd.DataFrame()
    ok = identified(runs[runs["x.a"].notna()])
    cases = case_order(ok["case"].unique())
    methods = method_order(ok["method"].unique())
    out = pd.DataFrame(index=pd.Index(["reference"] + methods, name="method"), dtype=float)
    for c in cases:
        part = ok[ok["case"] == c]
        ref = float(part["ref.a"].dropna().iloc[0]) if "ref.a" in part else math.nan
        out.loc["reference", c] = ref
        out.loc["reference", f"{c} err"] = 0.0
        for m, g in part.groupby("method"):
            out.loc[m, c] = float(g["x.a"].median())
            out.loc[m, f"{c} err"] = float(g["err.a"].median())
    return out


def a_display(t: pd.DataFrame) -> pd.DataFrame:
    """:func:`a_table` as strings: ``a (error %)`` per case."""
    cases = [c for c in t.columns if not str(c).endswith(" err")]
    out = pd.DataFrame(index=t.index)
    for c in cases:
        cells = []
        for m in t.index:
            v, e = t.loc[m, c], t.loc[m, f"{c} err"]
            if pd.isna(v):
                cells.append(DASH)
            elif m == "reference":
                cells.append(f"{v:.4g}")
            else:
                cells.append(f"{v:.4g} ({fmt_pct(float(e))} %)")
        out[c] = cells
    return out


def pivot(df: pd.DataFrame, value, *, index: str = "method", columns: str = "case") -> pd.DataFrame:
    """``df`` (long) as a method x case matrix of ``value`` (a column name, or a function of a
    row giving a string), in the study's orders; missing cells ``–``."""
    if not len(df):
        return pd.DataFrame()
    vals = df.apply(value, axis=1) if callable(value) else df[value]
    tab = pd.DataFrame({index: df[index], columns: df[columns], "v": vals}).pivot_table(
        index=index, columns=columns, values="v", aggfunc="first"
    )
    rows = method_order(tab.index) if index == "method" else list(tab.index)
    cols = case_order(tab.columns) if columns == "case" else list(tab.columns)
    tab = tab.reindex(index=rows, columns=cols)
    tab.index.name, tab.columns.name = index, None
    return tab.fillna(DASH) if callable(value) else tab


def fmt_ert(v: float, lo: float, hi: float) -> str:
    """``ERT [lo, hi]`` in forward-equivalents; ∞ for no success."""

    def f(x):
        if x is None or (isinstance(x, float) and math.isnan(x)):
            return DASH
        return "∞" if math.isinf(x) else (f"{x:.0f}" if x >= 10 else f"{x:.2g}")

    if math.isinf(v):
        return "∞"
    return f"{f(v)} [{f(lo)}, {f(hi)}]"

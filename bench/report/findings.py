"""The *Findings* section of report.md, computed from the frames (no number is typed in here except
the paper's Table-1 range for a, :data:`bench.report.catalogue.PAPER_A_ERROR`).

Each finding quotes the numbers it rests on:

1. which method wins each case (highest success rate, then lowest ERT), at what cost, per track
   and data tier;
2. what the global methods buy over Levenberg–Marquardt from the default start and from random
   starts (success, median max error, median forward-equivalents, pooled over the cases);
3. the worst-identified parameters (median |error| over the runs; a and pt0 for the exponent
   cases) next to the posterior's 95 % width and the paper's Table-1 error of a;
4. what finite-difference Jacobians cost against exact ones (when such pairs exist).
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from bench.report.tables import DASH, case_order, fmt_ert, fmt_num, fmt_pct, method_order

LM = "lm"


def _pct(k: int, n: int) -> str:
    return f"{k}/{n} ({100.0 * k / n:.0f} %)" if n else DASH


def findings(
    runs: pd.DataFrame,
    ert_df: pd.DataFrame,
    ok: pd.Series,
    *,
    post: pd.DataFrame | None = None,
    jac: pd.DataFrame | None = None,
    rule: str = "",
    tol: float = 2.0,
) -> list[str]:
    """Markdown lines of the findings (see the module docstring); ``tol`` (%) is the success
    tolerance of the identified parameters."""
    from bench.report.metrics import rank, winners

    md = ["## Findings\n"]
    md.append(
        "Computed from the records of this folder when the report was written"
        + (f"; success = {rule}" if rule else "")
        + ". ERT = expected running time to success in forward-equivalents (all runs' "
        "forward-equivalents over the successes) with its bootstrap 95 % interval.\n"
    )
    # 1. winners ---------------------------------------------------------------------------------
    w = winners(ert_df)
    md.append("### Which method wins where, at what cost\n")
    for (track, tier), g in w.groupby(["track", "tier"], sort=False):
        sub = ert_df[(ert_df["track"] == track) & (ert_df["tier"] == tier)]
        g = g.assign(_c=g["case"].map(case_order(g["case"]).index)).sort_values("_c")
        solved = g[g["successes"] > 0]
        first = list(dict.fromkeys(solved["method"]))
        counts = sorted(
            ((m, int((solved["method"] == m).sum())) for m in first), key=lambda t: -t[1]
        )
        lead = ", ".join(f"{m} on {n}" for m, n in counts) if counts else "no method"
        charge = float(sub["charged_median"].median()) if "charged_median" in sub else 0.0
        shared = float(sub["shared_median"].median()) if "shared_median" in sub else 0.0
        ctext = (
            f" The ERTs include the charges recorded with each run (median {fmt_num(charge)} "
            "fe per run: high-fidelity corrections, BAE statistics, surrogate training"
            + (
                f"; of which {fmt_num(shared)} fe shared by the runs, left out in "
                "`ert_amortised` of the ERT CSV"
                if shared > 0
                else ""
            )
            + ")."
            if charge > 0
            else ""
        )
        md.append(
            f"- **{track} track, {tier} data** ({len(sub)} method × case cells, "
            f"{int(sub['runs'].sum())} runs): a method succeeds on {len(solved)} of {len(g)} "
            f"cases; the winners: {lead}.{ctext}"
        )
        lines = ["| case | winner | success | ERT [95 % CI] (fe) | runner-up (success, ERT) |"]
        lines.append("|:---|:---|---:|---:|:---|")
        for _, r in g.iterrows():
            rest = rank(sub[(sub["case"] == r["case"]) & (sub["method"] != r["method"])])
            ru = DASH
            if len(rest):
                q = rest.iloc[0]
                ru = (
                    f"{q['method']} ({_pct(int(q['successes']), int(q['runs']))}, "
                    f"{fmt_ert(q['ert'], q['ert_lo'], q['ert_hi'])})"
                )
            win = (
                r["method"]
                if r["successes"] > 0
                else f"none; closest: {r['method']} (median largest error "
                f"{fmt_pct(float(r['max_err_median']))} %)"
            )
            lines.append(
                f"| {r['case']} | {win} | {_pct(int(r['successes']), int(r['runs']))} | "
                f"{fmt_ert(r['ert'], r['ert_lo'], r['ert_hi'])} | {ru} |"
            )
        md.append("\n" + "\n".join(lines) + "\n")

    # 2. global methods versus LM ----------------------------------------------------------------
    md.append("### What the global methods buy over Levenberg–Marquardt\n")
    md += _global_vs_lm(runs, ok)

    # 3. the surrogate alone -------------------------------------------------------------------
    md += _surrogate_alone(runs, tol)

    # 4. worst-identified parameters -----------------------------------------------------------
    md.append("### The worst-identified parameters\n")
    md += _worst_parameters(runs, ok, post)

    # 5. FD versus exact ------------------------------------------------------------------------
    if jac is not None and len(jac):
        md.append("### Finite-difference against exact Jacobians\n")
        md += _jacobian_finding(jac)
    return md


def _global_vs_lm(runs: pd.DataFrame, ok: pd.Series) -> list[str]:
    """Per data tier and treatment, from the default and from random starts: lm on the FE track
    (exact Jacobians when there are such runs) against each global method on each track (a
    surrogate-track result counts after its FE polish)."""
    out = []
    fam = runs["family"] if "family" in runs else pd.Series("other", index=runs.index)
    glob = fam == "global"
    lm = runs["solver"] == LM
    if not glob.any():
        return [
            "No global method ran in these records: nothing to compare with "
            f"Levenberg–Marquardt ({int(lm.sum())} lm runs).\n"
        ]
    if not lm.any():
        return ["No Levenberg–Marquardt run in these records: nothing to compare with.\n"]
    for (tier, treatment), g in runs.groupby(["tier", "treatment"], sort=False):
        for start in ("default", "random"):
            gs = g[g["start"] == start]
            gl = gs[(gs["solver"] == LM) & (gs["track"] == "fe")]
            if (gl["jacobian"] == "exact").any():
                gl = gl[gl["jacobian"] == "exact"]
            gg = gs[fam.loc[gs.index] == "global"]
            if not len(gl) and not len(gg):
                continue
            groups = [(f"{LM} (FE)", gl)] + [
                (f"{solver} ({'FE' if track == 'fe' else track})", gr)
                for (solver, track), gr in sorted(
                    gg.groupby(["solver", "track"]),
                    key=lambda kv: (method_order([kv[0][0]]), kv[0][1] != "fe"),
                )
            ]
            parts = []
            for name, gr in groups:
                if not len(gr):
                    parts.append(f"{name}: no run")
                    continue
                k = int(ok.loc[gr.index].sum())
                am = ""
                if "fe_shared" in gr and (gr["fe_shared"] > 0).any():
                    am = f" ({fmt_num(float(gr['fe_amortised'].median()))} amortised)"
                parts.append(
                    f"{name} {_pct(k, len(gr))}, median max |error| "
                    f"{fmt_pct(float(gr['max_abs_err'].median()))} %, median "
                    f"{fmt_num(float(gr['fe_total'].median()))} fe{am}"
                )
            verdict = _verdict(gl, groups[1:], ok)
            tr = "" if treatment == "none" else f", {treatment} treatment"
            out.append(
                f"- **{tier} data{tr}, {start} start(s)** (pooled over "
                f"{gs['case'].nunique()} case(s)): " + "; ".join(parts) + f". {verdict}"
            )
    return out + [""] if out else ["No run from the default or random starts.\n"]


def _surrogate_alone(runs: pd.DataFrame, tol: float) -> list[str]:
    """Per case: how far the surrogate search's own optimum is from the reference, and what the
    FE polish adds (surrogate-track runs whose records keep that optimum)."""
    if "sur_max_err" not in runs:
        return []
    sub = runs[(runs["track"] == "surrogate") & runs["sur_max_err"].notna()]
    if not len(sub):
        return []
    md = ["### The surrogate alone, before the FE polish\n"]
    k = int((sub["sur_max_err"] <= tol).sum())
    md.append(
        f"Largest error over the identified parameters of the optimum the search found on the "
        f"surrogate, against the same run after its FE polish ({len(sub)} surrogate-track runs): "
        f"the surrogate's optimum is within {fmt_num(tol)} % in {_pct(k, len(sub))} of them.\n"
    )
    lines = [
        f"| case | runs | surrogate optimum: median largest error (%) | within {fmt_num(tol)} % "
        "| after the polish: median largest error (%) | polish FE evaluations (median) |",
        "|:---|---:|---:|---:|---:|---:|",
    ]
    order = case_order(sub["case"].unique())
    for case in order:
        g = sub[sub["case"] == case]
        kk = int((g["sur_max_err"] <= tol).sum())
        lines.append(
            f"| {case} | {len(g)} | {fmt_pct(float(g['sur_max_err'].median()))} | "
            f"{_pct(kk, len(g))} | {fmt_pct(float(g['max_abs_err'].median()))} | "
            f"{fmt_num(float(g['polish_evals'].median()))} |"
        )
    md.append("\n".join(lines) + "\n")
    return md


def _verdict(gl: pd.DataFrame, groups: list, ok: pd.Series) -> str:
    groups = [(n, g) for n, g in groups if len(g)]
    if not len(gl) or not groups:
        return ""
    s_l = float(ok.loc[gl.index].mean())
    name, s_g, g = max(
        ((n, float(ok.loc[g.index].mean()), g) for n, g in groups),
        key=lambda t: (t[1], -float(t[2]["fe_total"].median())),
    )
    fe_l, fe_g = float(gl["fe_total"].median()), float(g["fe_total"].median())
    ratio = fe_g / fe_l if fe_l > 0 else math.inf
    own = ""
    if "fe_shared" in gl and (gl["fe_shared"] > 0).any() and (g["fe_shared"] > 0).any():
        # both pay the same shared charge (e.g. a case's BAE statistics): their own costs too
        am_l, am_g = float(gl["fe_amortised"].median()), float(g["fe_amortised"].median())
        own = f"; {fmt_num(am_g / am_l if am_l > 0 else math.inf, 2)} × without the shared charges"
    if s_g > s_l:
        return (
            f"The best global method, {name}, succeeds more often than lm "
            f"({100 * s_g:.0f} % against {100 * s_l:.0f} %) at {fmt_num(ratio, 2)} × its median "
            f"cost{own}."
        )
    if s_g == s_l:
        return (
            f"No global method succeeds more often than lm ({100 * s_l:.0f} %); the best, "
            f"{name}, costs {fmt_num(ratio, 2)} × as much (median fe{own})."
        )
    return (
        f"lm succeeds more often ({100 * s_l:.0f} %) than every global method (best: {name}, "
        f"{100 * s_g:.0f} %), which costs {fmt_num(ratio, 2)} × as much (median fe{own})."
    )


def _worst_parameters(runs: pd.DataFrame, ok: pd.Series, post: pd.DataFrame | None) -> list[str]:
    from bench.report.catalogue import PAPER_A_ERROR

    params = runs.attrs.get("parameters") or [c[4:] for c in runs.columns if c.startswith("err.")]
    params = [p for p in params if f"err.{p}" in runs and runs[f"err.{p}"].notna().any()]
    out = []
    for (track, tier), g in runs.groupby(["track", "tier"], sort=False):
        g = g[~g["crashed"].astype(bool)]
        med = {
            p: float(g[f"err.{p}"].abs().median()) for p in params if g[f"err.{p}"].notna().any()
        }
        med = {p: v for p, v in med.items() if math.isfinite(v)}
        if not med:
            continue
        rank = sorted(med.items(), key=lambda kv: -kv[1])
        worst = ", ".join(f"{p} {fmt_pct(v)} %" for p, v in rank[:3])
        line = (
            f"- **{track} track, {tier} data**: median |error| over all {len(g)} runs, worst "
            f"first: {worst} (best identified: {rank[-1][0]} {fmt_pct(rank[-1][1])} %)."
        )
        exp = g[g["err.a"].notna()] if "err.a" in g else g.iloc[0:0]
        if len(exp):
            a_med = float(exp["err.a"].abs().median())
            a_ok = exp[ok.loc[exp.index]]
            pt = float(exp["err.pt0"].abs().median()) if "err.pt0" in exp else math.nan
            line += (
                f" On the exponent cases ({len(exp)} runs) |error of a| has median "
                f"{fmt_pct(a_med)} % (range {fmt_pct(float(exp['err.a'].abs().min()))}–"
                f"{fmt_pct(float(exp['err.a'].abs().max()))} %; the paper's Table 1: "
                f"{PAPER_A_ERROR[0]:g}–{PAPER_A_ERROR[1]:g} %), |error of pt0| median "
                f"{fmt_pct(pt)} %; {len(a_ok)} of these runs meet the success criterion."
            )
        out.append(line)
    if post is not None and len(post):
        lines = _posterior_lines(post)
        out += lines or [
            f"- posteriors of {', '.join(case_order(post['case'].unique()))}: none of these "
            "cases identifies a or pt0 (see the posterior table for their widths)."
        ]
        out += _coverage_lines(post)
    else:
        out.append("- no posterior (no MCMC record and no posterior study summary) to compare.")
    return out + [""]


def _posterior_lines(post: pd.DataFrame) -> list[str]:
    """Per data tier, for a and pt0: the range of the 95 % posterior widths over the cases and
    sources, and in how many of them the interval contains the reference."""
    out = []
    rows = post[post["parameter"].isin(["a", "pt0"]) & np.isfinite(post["width95_pct"])]
    for tier, g in rows.groupby("tier", sort=True):
        parts = []
        for p in ("a", "pt0"):
            gp = g[g["parameter"] == p]
            if not len(gp):
                continue
            w = gp["width95_pct"].astype(float)
            inside = int(((gp["q025_n"] <= 1.0) & (gp["q975_n"] >= 1.0)).sum())
            lap = gp["laplace_width_pct"].astype(float).dropna()
            lap_txt = (
                f", Laplace ±2 sd {fmt_num(float(lap.min()), 2)}–{fmt_num(float(lap.max()), 2)} %"
                if len(lap)
                else ""
            )
            parts.append(
                f"{p} 95 % width {fmt_num(float(w.min()), 2)}–{fmt_num(float(w.max()), 2)} % of "
                f"the reference{lap_txt}, the interval contains the reference in {inside} of "
                f"{len(gp)}"
            )
        if parts:
            n_cases = g["case"].nunique()
            n_src = g.groupby(["case", "source"]).ngroups
            out.append(
                f"- **posterior, {tier} data** ({n_src} posterior(s) over {n_cases} case(s), "
                "see the posterior table): " + "; ".join(parts) + "."
            )
    return out


def _coverage_lines(post: pd.DataFrame) -> list[str]:
    """Per data tier: how many posterior 95 % intervals (all parameters, cases and sources)
    contain the reference value."""
    out = []
    ok = post[np.isfinite(post["q025_n"]) & np.isfinite(post["q975_n"])]
    for tier, g in ok.groupby("tier", sort=True):
        inside = (g["q025_n"] <= 1.0) & (g["q975_n"] >= 1.0)
        miss = g[~inside]
        worst = ""
        if len(miss):
            off = (miss["mean_n"] - 1.0).abs() * 100.0
            r = miss.loc[off.idxmax()]
            worst = (
                f"; farthest: {r['parameter']} of {r['case']}, posterior mean "
                f"{fmt_num(float(r['mean_n']), 3)} × reference"
            )
        out.append(
            f"- **posterior coverage, {tier} data**: {int(inside.sum())} of {len(g)} 95 % "
            f"intervals (parameters × cases × sources) contain the reference value{worst}."
        )
    return out


def _jacobian_finding(jac: pd.DataFrame) -> list[str]:
    js = sorted({c.split(".", 1)[1] for c in jac.columns if c.startswith("fe.")})
    if "exact" not in js:
        return ["No exact-Jacobian run to compare with.\n"]
    out = []
    for j in [j for j in js if j != "exact"]:
        sub = jac[jac[f"fe.{j}"].notna() & jac["fe.exact"].notna()]
        if not len(sub):
            continue
        ratio = (sub[f"fe.{j}"] / sub["fe.exact"]).replace([np.inf, -np.inf], np.nan).dropna()
        it = (sub[f"iterations.{j}"] - sub["iterations.exact"]).astype(float)
        derr = (sub[f"max_err.{j}"] - sub["max_err.exact"]).abs().astype(float)
        out.append(
            f"- {j} differences against exact Jacobians ({len(sub)} pairs of runs): "
            f"forward-equivalents × {fmt_num(float(ratio.median()), 3)} (median; range "
            f"{fmt_num(float(ratio.min()), 3)}–{fmt_num(float(ratio.max()), 3)}), iterations "
            f"{float(it.median()):+.0f} (median), final max |error| differing by "
            f"{fmt_pct(float(derr.median()))} percentage points (median)."
        )
    return out + [""]

"""The report of a results directory: tables, figures and ``report.md`` in ``DIR/report/``.

The report reads only the records on disk (through :func:`bench.store.to_frames`); it knows
nothing of how the runs were executed. Record files it cannot read (and those ``femubench run``
moved into ``DIR/runs/corrupt/``) are listed in report.md and on stderr. It is rebuilt from scratch
each time in a temporary directory that then replaces ``DIR/report`` (so no stale table or figure
survives).

Layout (see docs/reports.md)::

    DIR/report/report.md                              overview, findings, tables, figures
    DIR/report/tables/table1__<method>.{md,csv,tex}   Table 1 per method (label: tier, track, ...)
    DIR/report/tables/a_exponent.*                    the exponent cases' derived a
    DIR/report/tables/success.*                       success rate, every method x case
    DIR/report/tables/{success,ert,targets}__<track>__<tier>.*
    DIR/report/tables/comparison.*, jacobian.*, posterior_widths.*
    DIR/report/figures/convergence/<case>__<family>.png   like the paper's Figs 6-14
    DIR/report/figures/<case>__ecdf.png, all__ecdf.png    runtime ECDFs per track and tier
    DIR/report/figures/posterior/<case>.png               MCMC intervals and Laplace
    DIR/report/runs.parquet, history.parquet              with --format parquet
"""

from __future__ import annotations

import math
import os
import shutil
import sys
import tempfile
from pathlib import Path

TABLE_FORMATS = ("md", "csv", "tex")


def study_dirs(out_dir: Path, study: str, *, direct: bool = True) -> list[Path]:
    """The existing folders of a study's results for the report of ``out_dir``: ``DIR/<study>``
    (with ``direct``), ``DIR/studies/<study>`` and the sibling ``DIR/../studies/<study>`` (the
    results root's studies, for ``results/<suite>``)."""
    out_dir = Path(out_dir)
    cands = [out_dir / study] if direct else []
    cands += [out_dir / "studies" / study, out_dir.resolve().parent / "studies" / study]
    return [p for p in dict.fromkeys(cands) if p.is_dir()]


def default_posterior_dirs(out_dir: Path) -> list[Path]:
    """Where the posterior study's ``<case>/summary.json`` files are looked for
    (:func:`study_dirs` of ``posterior``)."""
    return study_dirs(out_dir, "posterior")


def write_report(
    out_dir: str | Path,
    formats=("md", "csv", "tex"),
    *,
    tol: float | None = None,
    figures: bool = True,
    progress: bool = False,
    tol_a: float | None = None,
    dest: str | Path | None = None,
    posterior_dirs=None,
    model_error_dirs=None,
) -> Path:
    """Write the report of ``out_dir`` into ``dest`` (default ``out_dir/report``); return the path
    of report.md.

    ``formats``: any of md, csv, tex (tables), pdf (figures also as PDF), parquet (the tidy
    DataFrames ``runs.parquet`` and ``history.parquet``). ``tol``: success tolerance of the
    identified parameters in percent (default :data:`bench.report.tables.SUCCESS_TOL`), ``tol_a``
    that of the derived a (default :data:`bench.report.tables.DERIVED_TOL`). ``posterior_dirs``:
    folders with the posterior study's ``<case>/summary.json`` (default
    :func:`default_posterior_dirs`); ``model_error_dirs``: folders with the model-error study's
    ``<case>/*.json`` rows, quoted in the note under each model-error Table 1 (default
    :func:`bench.report.model_error_note.default_model_error_dirs`). Every record file that
    could not be read is named on stderr and in report.md. ``progress``: a progress bar (stderr)
    over the figures.
    """
    from bench import store
    from bench.report.tables import SUCCESS_TOL

    out_dir = Path(out_dir)
    tol = SUCCESS_TOL if tol is None else tol
    formats = [f.lower() for f in formats]
    records, unreadable = store.scan_records(out_dir)
    set_aside = store.set_aside_files(out_dir)
    for line in unreadable_lines(unreadable, set_aside):
        print(f"femubench report: {line}", file=sys.stderr)
    runs, history = store.to_frames(out_dir, records)
    if not len(runs):
        raise ValueError(
            f"no run records in {store.runs_dir(out_dir)}"
            + (f" that could be read ({len(unreadable)} unreadable)" if unreadable else "")
            + f"; run 'femubench run SUITE --out {out_dir}' first"
        )
    final = out_dir / "report" if dest is None else Path(dest)
    final.parent.mkdir(parents=True, exist_ok=True)
    if posterior_dirs is None:
        posterior_dirs = default_posterior_dirs(out_dir)
    if model_error_dirs is None:
        from bench.report.model_error_note import default_model_error_dirs

        model_error_dirs = default_model_error_dirs(out_dir)
    tmp = Path(tempfile.mkdtemp(dir=final.parent, prefix=".report-"))
    try:
        build_report(
            runs,
            history,
            tmp,
            formats,
            tol=tol,
            tol_a=tol_a,
            figures=figures,
            source=out_dir,
            unreadable=unreadable,
            set_aside=set_aside,
            progress=progress,
            records=records,
            posterior_dirs=posterior_dirs,
            model_error_dirs=model_error_dirs,
        )
        old = None
        if final.exists():
            old = final.parent / f".report-old-{os.getpid()}"
            os.replace(final, old)
        os.replace(tmp, final)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return final / "report.md"


def unreadable_lines(unreadable, set_aside, base: Path | None = None) -> list[str]:
    """One line per record file the report could not use: unreadable ones (left out of every
    table) and those ``femubench run`` moved aside for inspection; paths relative to ``base`` if
    given."""

    def show(p):
        return _rel(p, base) if base is not None else str(p)

    lines = [f"unreadable record {show(p)} left out: {why}" for p, why in unreadable]
    lines += [
        f"unreadable record kept aside by 'femubench run' (its run was run again): {show(p)}"
        for p in set_aside
    ]
    return lines


def build_report(
    runs,
    history,
    dest: Path,
    formats,
    *,
    tol: float,
    figures: bool,
    source: Path,
    unreadable=(),
    set_aside=(),
    progress: bool = False,
    tol_a: float | None = None,
    records=(),
    posterior_dirs=(),
    model_error_dirs=(),
) -> Path:
    """Write the tables, figures and report.md of ``runs``/``history`` into ``dest``.

    ``unreadable``: ``(path, reason)`` of the record files that could not be read; ``set_aside``:
    the files moved into ``runs/corrupt/``; both are listed in report.md. ``records``: the records
    themselves (MCMC posteriors); ``posterior_dirs``: folders holding the posterior study's
    ``<case>/summary.json``; ``model_error_dirs``: folders holding the model-error study's
    ``<case>/*.json`` (none found: the notes under the model-error Tables 1 say so)."""
    import pandas as pd

    from bench.report import metrics as M
    from bench.report import tables as T
    from bench.report.findings import findings
    from bench.report.posterior import posterior_frame, width_table

    runs, history = M.prepare(runs, history)
    runs = M.add_shared_charges(runs, records)
    runs = M.add_surrogate_optimum(runs, records)
    dtol = dict(T.DERIVED_TOL) if tol_a is None else {**T.DERIVED_TOL, "a": float(tol_a)}
    rule = T.success_rule(tol, dtol)
    ok = T.success(runs, tol, dtol)
    dest.mkdir(parents=True, exist_ok=True)
    tdir = dest / "tables"
    tfmt = [f for f in formats if f in TABLE_FORMATS]
    methods = T.method_order(runs["method"].unique())
    cases = T.case_order(runs["case"].unique())
    budgets = sorted(int(b) for b in runs["budget"].unique())
    ert_df = M.ert_table(runs, tol, dtol)
    post = posterior_frame(records, posterior_dirs)
    if len(post):
        post = post[post["case"].isin(cases)].reset_index(drop=True)
    jac = M.jacobian_table(runs)

    md: list[str] = []
    md.append(f"# femubench report: `{source.resolve().name}`\n")
    md += _overview(runs, history, cases, methods, budgets, rule)
    if unreadable or set_aside:
        md.append("## Unreadable records\n")
        md.append(
            "Record files that could not be read as records (truncated, empty, not JSON or of the "
            "wrong shape). Unreadable records in `runs/` are left out of every table below; rerun "
            "the suite to redo their runs (`femubench run` moves them to `runs/corrupt/` first).\n"
        )
        lines = unreadable_lines(unreadable, set_aside, base=source)
        md.append("".join(f"- {line}\n" for line in lines))
    md += findings(runs, ert_df, ok, post=post, jac=jac, rule=rule, tol=tol)

    def table(stem, display, raw, caption, label, raw_kw=None, **kw):
        ri = (raw_kw or {}).get("index")
        paths = T.write_table(
            tdir / stem,
            tfmt,
            display=display,
            raw=raw,
            caption=caption,
            label=label,
            raw_index=ri,
            **kw,
        )
        md.append(caption + "\n")
        md.append(
            T.to_markdown(display, index=kw.get("index", True), index_label=kw.get("index_label"))
        )
        md.append(_links(paths, dest) + "\n")

    # --- success, targets, ERT per track and tier ------------------------------------------------
    from bench.report.figures import COST_KS, ERR_TARGETS, facets

    tgt = M.target_table(runs, history)
    md.append("## Success rates, cost targets and expected running time\n")
    md.append(
        f"Success: {rule}. Cost targets (COCO style, relative to the best known cost of the "
        "objective: case, data tier and model-error treatment): J_best + 10^−k (J_init − J_best) "
        f"for k = {', '.join(map(str, COST_KS))}, J_best the best final cost any run reached, "
        "J_init the median cost at the start points. ERT: the forward-equivalents of all runs of "
        "a method on a case (successful or not; charges such as high-fidelity corrections, BAE "
        "statistics or surrogate training included) over its number of successes, ∞ when none; "
        "in brackets the 95 % percentile-bootstrap interval (runs resampled 1000 times, seeded).\n"
    )
    sm_all = T.success_matrix(runs, tol, dtol)
    paths = T.write_table(
        tdir / "success",
        tfmt,
        display=T.success_display(sm_all),
        raw=sm_all,
        caption=f"Success rate in percent, every method (all tracks and tiers): {rule}.",
        label="tab:success",
        index_label="method",
    )
    md.append("All methods in one table: " + _links(paths, dest) + "\n")
    for track, tier in facets(runs):
        key = f"{_safe(track)}__{_safe(tier)}"
        sel = ert_df[(ert_df["track"] == track) & (ert_df["tier"] == tier)]
        if not len(sel):
            continue
        md.append(f"### {track} track, {tier} data\n")
        sm = T.pivot(sel, "success_pct")
        table(
            f"success__{key}",
            T.success_display(sm),
            sm,
            f"Success rate in percent ({track} track, {tier} data): {rule}.",
            f"tab:success-{key}",
            index_label="method",
        )
        shared = bool((sel.get("shared_median", pd.Series(dtype=float)) > 0).any())

        def ert_cell(r, shared=shared):
            cell = T.fmt_ert(r["ert"], r["ert_lo"], r["ert_hi"])
            if shared and math.isfinite(r["ert"]):
                cell += f"; {T.fmt_num(float(r['ert_amortised']))} amortised"
            return cell

        disp = T.pivot(sel, ert_cell)
        table(
            f"ert__{key}",
            disp,
            sel.reset_index(drop=True),
            f"ERT to success in forward-equivalents [bootstrap 95 % interval] ({track} track, "
            f"{tier} data); ∞ = no success."
            + (
                " 'amortised': the ERT without the charges shared by the runs (surrogate "
                "training, BAE statistics)."
                if shared
                else ""
            ),
            f"tab:ert-{key}",
            index_label="method",
            raw_kw={"index": False},
        )
        ts = tgt[(tgt["track"] == track) & (tgt["tier"] == tier)]
        if len(ts):
            kcols = [f"k{k}" for k in COST_KS]
            ts = ts.assign(reached=ts[kcols].mean(axis=1))
            disp = T.pivot(ts, lambda r: DASH_IF_NAN(r["reached"], lambda v: f"{v:.0f}"))
            table(
                f"targets__{key}",
                disp,
                ts.reset_index(drop=True),
                f"Cost targets reached ({track} track, {tier} data): percentage of (run, target) "
                f"pairs whose final cost reaches the target, over k = "
                f"{', '.join(map(str, COST_KS))} (per k in the CSV).",
                f"tab:targets-{key}",
                index_label="method",
                raw_kw={"index": False},
            )

    # --- Table 1 per method (x budget) ----------------------------------------------------------
    md.append("## Table 1: residual error of the identified parameters\n")
    md.append(
        "Signed error of each identified parameter with respect to its reference value, "
        "100 (x/x_REF − 1) in percent; median over seeds and starts where a case has several "
        f"runs; `{T.DASH}` marks a parameter that is not active in the case. The row `a` of the "
        "exponent cases is derived from the identified pt0, sigma0 and b through the case's "
        "exponent surface (the cases identify pt0 in place of a); the success criterion allows it "
        f"{dtol.get('a', math.nan):g} %. Crashed runs are left out (see the comparison table).\n"
    )
    at = T.a_table(runs)
    if len(at):
        table(
            "a_exponent",
            T.a_display(at),
            at,
            "The exponent coefficient a (MPa^(1−b)) derived from each method's identified "
            "parameters, median over runs, with its signed error against the reference a in "
            "percent.",
            "tab:a-exponent",
            index_label="method",
        )
    for method in methods:
        for budget in budgets if len(budgets) > 1 else [None]:
            t = T.table1(runs, method, budget=budget)
            if not any(t.attrs["n_runs"].values()):
                continue
            suffix = f"__b{budget}" if budget is not None else ""
            stem = tdir / f"table1__{_safe(method)}{suffix}"
            nrun = sorted(set(t.attrs["n_identified"].values()))
            per = f"{nrun[0]}" if len(nrun) == 1 else f"{min(nrun)}–{max(nrun)}"
            btxt = f", budget {budget}" if budget is not None else ""
            note = T.bound_note(t)
            caption = (
                f"Table 1 ({method}{btxt}): residual error of the identified parameters in "
                f"percent, median over {per} run(s) per case; {T.DASH} = inactive parameter."
                + (f" {note}" if note else "")
            )
            disp = T.table1_display(t)
            paths = T.write_table(
                stem,
                tfmt,
                display=disp,
                raw=t,
                caption=caption,
                label=f"tab:table1-{_safe(method)}{suffix}",
                index_label="parameter",
                tex_display=T.tex_param_index(disp),
                raw_index_tex=True,
            )
            md.append(f"### {method}{btxt}\n")
            md.append(T.to_markdown(disp, index_label="parameter"))
            if note:
                md.append(note + "\n")
            sel = runs[runs["method"] == method]
            if budget is not None:
                sel = sel[sel["budget"] == budget]
            if len(sel) and (sel["tier"] == "model-error").all():
                md.append(_model_error_note(t, sel, records, model_error_dirs, tol, dtol, dest))
            md.append(_links(paths, dest) + "\n")

    # --- comparison -------------------------------------------------------------------------
    comp = T.comparison(runs, tol, dtol)
    cdisp = T.comparison_display(comp)
    md.append("## Comparison per case and method\n")
    table(
        "comparison",
        cdisp,
        comp,
        "Comparison per case and method (with its data tier, model-error treatment and, when not "
        f"the defaults, track and Jacobian): success = {rule}; forward evaluations (median and "
        "interquartile range) and forward-equivalents (measured; charges included), median "
        "final cost, median max |error| of the identified parameters, median wall time per run.",
        "tab:comparison",
        index=False,
    )

    # --- FD versus exact Jacobians ------------------------------------------------------------
    if len(jac):
        md.append("## Finite-difference against exact Jacobians\n")
        table(
            "jacobian",
            _jacobian_display(jac),
            jac,
            "Runs that differ only in their Jacobian, side by side: iterations, forward "
            "evaluations, forward-equivalents (measured) and final max |parameter error| (%).",
            "tab:jacobian",
            index=False,
        )

    # --- posterior ------------------------------------------------------------------------------
    if len(post):
        md.append("## Posterior (MCMC)\n")
        wt = width_table(post)
        table(
            "posterior_widths",
            wt,
            post,
            "Posterior 95 % interval width in percent of the reference per parameter (in "
            "brackets the Laplace approximation's mean ± 2 sd width), the chain length in "
            "autocorrelation times (smallest over the parameters), and the paper's Table-1 error "
            "of a for comparison.",
            "tab:posterior",
            index=False,
            raw_kw={"index": False},
        )

    # --- figures ----------------------------------------------------------------------------
    if figures:
        from bench.report.figures import write_figures

        figs = write_figures(
            runs,
            history,
            dest / "figures",
            pdf="pdf" in formats,
            progress=progress,
            posterior=post,
        )
        md.append("## Figures\n")
        md.append(
            "Line styles and markers distinguish methods and parameters (greys only)."
            + (" PDF versions sit next to the PNGs." if "pdf" in formats else "")
            + "\n"
        )
        md.append("### Runtime ECDFs and best cost\n")
        md.append(
            "*Runtime ECDF* (COCO style), one column per track and data tier: fraction of (run, "
            "target) pairs reached within a number of forward-equivalents; (a) the cost targets "
            f"above (k = {', '.join(map(str, COST_KS))}), (b) parameter targets max_i "
            f"|x_i/x_i^REF − 1| ≤ {', '.join(f'{t:g}' for t in ERR_TARGETS)} %. Per case, the same "
            "figure over that case's runs.\n"
        )
        if figs["ecdf_all"] is not None:
            md.append(f"![runtime ECDF, all cases]({_rel(figs['ecdf_all'], dest)})\n")
        kinds = [k for k in ("ecdf", "convergence") if figs[k]]
        head = {"ecdf": "runtime ECDF", "convergence": "best cost"}
        rows = []
        for c in cases:
            cells = [f"[fig]({_rel(figs[k][c], dest)})" if c in figs[k] else T.DASH for k in kinds]
            rows.append(f"| {c} | " + " | ".join(cells) + " |")
        if kinds:
            md.append(
                "| case | "
                + " | ".join(head[k] for k in kinds)
                + " |\n|"
                + "|".join([":---"] * (1 + len(kinds)))
                + "|\n"
                + "\n".join(rows)
                + "\n"
            )
        md.append("### Convergence per method family (like the paper's Figs 6–14)\n")
        md.append(
            "For each case and method family (local, global, sampling), one row per method: (a) "
            "normalised parameters x_i/x_i^REF against iteration of the run with the median "
            "final cost (a, derived, as a thin line), a ring and a note "
            f"({T.BOUND_MARK}) at every final value on a bound of the case's box; (b) cost "
            "against iteration (dots: iterates; line: best so far; band: range of the best cost "
            "over all runs of the method).\n"
        )
        fams = [f for f in M.FAMILIES if any(k[1] == f for k in figs["family"])]
        fams += sorted({k[1] for k in figs["family"]} - set(fams))
        if fams:
            lines = [
                "| case | " + " | ".join(fams) + " |",
                "|" + "|".join([":---"] * (1 + len(fams))) + "|",
            ]
            for c in cases:
                cells = []
                for f in fams:
                    ps = figs["family"].get((c, f), [])
                    cells.append(
                        ", ".join(
                            f"[{'fig' if i == 0 else f'p{i + 1}'}]({_rel(p, dest)})"
                            for i, p in enumerate(ps)
                        )
                        or T.DASH
                    )
                lines.append(f"| {c} | " + " | ".join(cells) + " |")
            md.append("\n".join(lines) + "\n")
            first = next(iter(figs["family"].values()))[0]
            md.append(f"![convergence, first case and family]({_rel(first, dest)})\n")
        if figs["posterior"]:
            md.append("### Posterior panels\n")
            md.append(
                "Per parameter: the posterior 95 % interval (line) and mean (marker) divided by "
                "the reference, for each source; dashed beside it the Laplace approximation's "
                "mean ± 2 sd where known.\n"
            )
            for c, p in figs["posterior"].items():
                md.append(f"![{c}: posterior]({_rel(p, dest)})\n")

    if "parquet" in formats:
        store_paths = _parquet(runs, history, dest)
        md.append("## Data\n")
        md.append(
            "The tidy DataFrames (one row per run; one row per history row): "
            + ", ".join(f"[{p.name}]({_rel(p, dest)})" for p in store_paths)
            + ".\n"
        )

    text = "\n".join(md)
    (dest / "report.md").write_text(text, encoding="utf-8")
    return dest / "report.md"


def DASH_IF_NAN(v, fmt):  # noqa: N802
    from bench.report.tables import DASH

    return DASH if v is None or (isinstance(v, float) and math.isnan(v)) else fmt(v)


def _jacobian_display(jac):
    import pandas as pd

    from bench.report.tables import fmt_num, fmt_pct

    js = sorted({c.split(".", 1)[1] for c in jac.columns if c.startswith("fe.")})
    js = (["exact"] if "exact" in js else []) + [j for j in js if j != "exact"]
    out = pd.DataFrame(
        {
            "case": jac["case"],
            "method": jac["method"],
            "seed": jac["seed"].astype(str) if "seed" in jac else "",
            "start": jac["start"] if "start" in jac else "",
        }
    )
    for what, col, f in (
        ("iterations", "iterations", lambda v: DASH_IF_NAN(v, lambda x: f"{x:.0f}")),
        ("evaluations", "evals", lambda v: DASH_IF_NAN(v, lambda x: f"{x:.0f}")),
        ("forward-equivalents", "fe", lambda v: DASH_IF_NAN(v, fmt_num)),
        ("max |err| (%)", "max_err", lambda v: DASH_IF_NAN(v, fmt_pct)),
    ):
        for j in js:
            c = f"{col}.{j}"
            out[f"{what} {j}"] = jac[c].map(f) if c in jac else "–"
    return out


def _overview(runs, history, cases, methods, budgets, rule) -> list[str]:
    from bench.report import tables as T

    n_crashed = int(runs["crashed"].sum())
    seeds = sorted(int(s) for s in runs["seed"].unique())
    suites = sorted(s for s in runs["suite"].dropna().unique()) if "suite" in runs else []
    hashes = (
        sorted(str(h) for h in runs["data_hash"].dropna().unique()) if "data_hash" in runs else []
    )
    meshes = sorted(str(m) for m in runs["mesh"].dropna().unique()) if "mesh" in runs else []

    def counts(col):
        if col not in runs:
            return T.DASH
        vc = runs[col].astype(str).value_counts()
        return ", ".join(f"{k} ({v})" for k, v in vc.items())

    if "budget_unit" in runs:
        tracks = runs["track"].fillna("fe") if "track" in runs else ["fe"] * len(runs)
        units = runs["budget_unit"].fillna("evaluations")
        pairs = sorted(
            {
                # on the surrogate track the budget counts surrogate evaluations (its FE polish
                # has its own budget)
                (int(b), "surrogate evaluations" if t == "surrogate" else str(u))
                for b, u, t in zip(runs["budget"], units, tracks)
            }
        )
        budget_text = ", ".join(f"{b} {u}" for b, u in pairs)
    else:
        budget_text = ", ".join(map(str, budgets)) + " evaluations"
    hshow = ", ".join(f"`{h[:16]}`" for h in hashes[:6]) + (
        f" and {len(hashes) - 6} more" if len(hashes) > 6 else ""
    )
    wall = runs["wall_s"].sum() / 3600.0 if "wall_s" in runs else math.nan
    lines = [
        f"- **{len(runs)} runs** ({n_crashed} crashed) from suite(s) "
        f"{', '.join(f'`{s}`' for s in suites) or T.DASH}",
        f"- cases ({len(cases)}): {', '.join(cases)}",
        f"- methods ({len(methods)}): {', '.join(methods)}",
        f"- tracks: {counts('track')}; data tiers: {counts('tier')}; Jacobians: "
        f"{counts('jacobian')}; starts: {counts('start')}",
        f"- budgets: {budget_text}; seeds: "
        f"{', '.join(map(str, seeds))}; mesh: {', '.join(meshes) or T.DASH}",
        f"- data file hash(es): {hshow or T.DASH}",
        f"- success criterion: **{rule}**",
        f"- total cost of the runs: {runs['fe_total'].sum():.0f} forward-equivalents; wall time "
        f"{wall:.2f} h",
        "",
    ]
    return lines


def _model_error_note(t, sel, records, dirs, tol, dtol, dest: Path) -> str:
    """The note under a model-error Table 1 (:mod:`bench.report.model_error_note`), its links
    relative to ``dest``."""
    from bench.paths import results_root
    from bench.report import model_error_note as N

    settings = N.run_settings(sel, records)
    study = N.load_study(dirs, settings)
    doc = Path(__file__).resolve().parents[2] / "docs" / "objective.md"
    name = "`results/studies/model_error`"
    found = [Path(d) for d in dirs or () if Path(d).is_dir()]
    if found:
        d = found[0]
        shown = (
            "results/studies/model_error"
            if d.resolve() == (results_root() / "studies" / "model_error").resolve()
            else _rel(d, dest)
        )
        target = d / "overview.md" if (d / "overview.md").is_file() else d
        name = f"[`{shown}`]({_rel(target, dest)})"
    return N.model_error_note(
        t,
        settings,
        study,
        tol=tol,
        derived_tol=dtol,
        doc=_rel(doc, dest) if doc.is_file() else None,
        study_name=name,
    )


def _parquet(runs, history, dest: Path) -> list[Path]:
    paths = []
    for df, name in ((runs, "runs.parquet"), (history, "history.parquet")):
        df = df.copy()
        df.attrs = {}
        p = dest / name
        df.to_parquet(p, index=False)
        paths.append(p)
    return paths


def _safe(name: str) -> str:
    from bench.report.figures import safe

    return safe(name)


def _rel(path: Path, base: Path) -> str:
    return Path(os.path.relpath(path, base)).as_posix()


def _links(paths, base: Path) -> str:
    return (
        ("Files: " + ", ".join(f"[{p.suffix[1:]}]({_rel(p, base)})" for p in paths))
        if paths
        else ""
    )

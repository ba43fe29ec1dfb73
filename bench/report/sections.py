"""The sections of report.md, one function each (see :func:`bench.report.build_report`).

:func:`prepare` computes once what several sections share (the prepared run table, the success
rule, the ERT table, the posterior and Jacobian tables) into a :class:`Report`; each section is a
function ``section(rep) -> list[str]`` that writes its tables and figures into ``rep.dest`` and
returns its markdown blocks (joined with blank lines into report.md). :data:`SECTIONS` is their
order in report.md; a new section is a function added there.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

from bench.report.completeness import section_completeness

TABLE_FORMATS = ("md", "csv", "tex")


@dataclass
class Report:
    """What the sections of one report share. ``runs``/``history``: the prepared tidy frames
    (:func:`bench.report.metrics.prepare`); ``records``: the run records (MCMC posteriors, shared
    charges); ``dest``: the report folder; ``formats``: the requested formats (``tfmt`` those of
    the tables); ``tol``: success tolerance in percent, ``dtol`` that of the derived parameters;
    ``rule``: the success criterion in words; ``ok``: success per run; ``ert_df``: the ERT table;
    ``post``: the posterior frame; ``jac``: the FD-against-exact table."""

    runs: object
    history: object
    records: object
    dest: Path
    source: Path
    formats: list
    tfmt: list
    tol: float
    dtol: dict
    rule: str
    ok: object
    methods: list
    cases: list
    budgets: list
    ert_df: object
    post: object
    jac: object
    figures: bool = True
    progress: bool = False
    unreadable: tuple = ()
    set_aside: tuple = ()
    model_error_dirs: tuple = ()

    @property
    def tdir(self) -> Path:
        """The folder of the tables."""
        return self.dest / "tables"

    def table(self, stem, display, raw, caption, label, raw_kw=None, **kw) -> list[str]:
        """Write table ``stem`` in the table formats; return its caption, markdown and links."""
        from bench.report import tables as T

        ri = (raw_kw or {}).get("index")
        paths = T.write_table(
            self.tdir / stem,
            self.tfmt,
            display=display,
            raw=raw,
            caption=caption,
            label=label,
            raw_index=ri,
            **kw,
        )
        return [
            caption + "\n",
            T.to_markdown(display, index=kw.get("index", True), index_label=kw.get("index_label")),
            _links(paths, self.dest) + "\n",
        ]


def prepare(
    runs,
    history,
    dest: Path,
    formats,
    *,
    tol: float,
    tol_a: float | None,
    source: Path,
    records=(),
    posterior_dirs=(),
    **kw,
) -> Report:
    """The :class:`Report` of the tidy frames ``runs``/``history`` (``kw``: the remaining
    :class:`Report` fields: figures, progress, unreadable, set_aside, model_error_dirs)."""
    from bench.report import metrics as M
    from bench.report import tables as T
    from bench.report.posterior import posterior_frame

    runs, history = M.prepare(runs, history)
    runs = M.add_shared_charges(runs, records)
    runs = M.add_surrogate_optimum(runs, records)
    dtol = dict(T.DERIVED_TOL) if tol_a is None else {**T.DERIVED_TOL, "a": float(tol_a)}
    cases = T.case_order(runs["case"].unique())
    post = posterior_frame(records, posterior_dirs)
    if len(post):
        post = post[post["case"].isin(cases)].reset_index(drop=True)
    return Report(
        runs=runs,
        history=history,
        records=records,
        dest=dest,
        source=source,
        formats=list(formats),
        tfmt=[f for f in formats if f in TABLE_FORMATS],
        tol=tol,
        dtol=dtol,
        rule=T.success_rule(tol, dtol),
        ok=T.success(runs, tol, dtol),
        methods=T.method_order(runs["method"].unique()),
        cases=cases,
        budgets=sorted(int(b) for b in runs["budget"].unique()),
        ert_df=M.ert_table(runs, tol, dtol),
        post=post,
        jac=M.jacobian_table(runs),
        **kw,
    )


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


def section_overview(rep: Report) -> list[str]:
    """The title and the overview: runs, cases, methods, tracks, budgets, data, success rule,
    total cost."""
    from bench.report import tables as T

    runs = rep.runs
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
        budget_text = ", ".join(map(str, rep.budgets)) + " evaluations"
    hshow = ", ".join(f"`{h[:16]}`" for h in hashes[:6]) + (
        f" and {len(hashes) - 6} more" if len(hashes) > 6 else ""
    )
    wall = runs["wall_s"].sum() / 3600.0 if "wall_s" in runs else math.nan
    return [
        f"# femubench report: `{rep.source.resolve().name}`\n",
        f"- **{len(runs)} runs** ({n_crashed} crashed) from suite(s) "
        f"{', '.join(f'`{s}`' for s in suites) or T.DASH}",
        f"- cases ({len(rep.cases)}): {', '.join(rep.cases)}",
        f"- methods ({len(rep.methods)}): {', '.join(rep.methods)}",
        f"- tracks: {counts('track')}; data tiers: {counts('tier')}; Jacobians: "
        f"{counts('jacobian')}; starts: {counts('start')}",
        f"- budgets: {budget_text}; seeds: "
        f"{', '.join(map(str, seeds))}; mesh: {', '.join(meshes) or T.DASH}",
        f"- data file hash(es): {hshow or T.DASH}",
        f"- success criterion: **{rep.rule}**",
        f"- total cost of the runs: {runs['fe_total'].sum():.0f} forward-equivalents; wall time "
        f"{wall:.2f} h",
        "",
    ]


def section_unreadable(rep: Report) -> list[str]:
    """The record files that could not be read (none: no section)."""
    if not (rep.unreadable or rep.set_aside):
        return []
    lines = unreadable_lines(rep.unreadable, rep.set_aside, base=rep.source)
    return [
        "## Unreadable records\n",
        "Record files that could not be read as records (truncated, empty, not JSON or of the "
        "wrong shape). Unreadable records in `runs/` are left out of every table below; rerun "
        "the suite to redo their runs (`femubench run` moves them to `runs/corrupt/` first).\n",
        "".join(f"- {line}\n" for line in lines),
    ]


def section_findings(rep: Report) -> list[str]:
    """The findings in words (:func:`bench.report.findings.findings`)."""
    from bench.report.findings import findings

    return findings(
        rep.runs, rep.ert_df, rep.ok, post=rep.post, jac=rep.jac, rule=rep.rule, tol=rep.tol
    )


def section_success(rep: Report) -> list[str]:
    """Success rates, cost targets and ERT: one table of every method, then per track and tier
    the success, ERT and cost-target tables."""
    import pandas as pd

    from bench.report import metrics as M
    from bench.report import tables as T
    from bench.report.figures import facets
    from bench.report.metrics import COST_KS

    runs, ert_df, rule = rep.runs, rep.ert_df, rep.rule
    tgt = M.target_table(runs, rep.history)
    md = ["## Success rates, cost targets and expected running time\n"]
    md.append(
        f"Success: {rule}. Cost targets (COCO style, relative to the best known cost of the "
        "objective: case, data tier and model-error treatment): J_best + 10^−k (J_init − J_best) "
        f"for k = {', '.join(map(str, COST_KS))}, J_best the best final cost any run reached, "
        "J_init the median cost at the start points. ERT: the forward-equivalents of all runs of "
        "a method on a case (successful or not; charges such as high-fidelity corrections, BAE "
        "statistics or surrogate training included) over its number of successes, ∞ when none; "
        "in brackets the 95 % percentile-bootstrap interval (runs resampled 1000 times, seeded).\n"
    )
    sm_all = T.success_matrix(runs, rep.tol, rep.dtol)
    paths = T.write_table(
        rep.tdir / "success",
        rep.tfmt,
        display=T.success_display(sm_all),
        raw=sm_all,
        caption=f"Success rate in percent, every method (all tracks and tiers): {rule}.",
        label="tab:success",
        index_label="method",
    )
    md.append("All methods in one table: " + _links(paths, rep.dest) + "\n")
    for track, tier in facets(runs):
        key = f"{_safe(track)}__{_safe(tier)}"
        sel = ert_df[(ert_df["track"] == track) & (ert_df["tier"] == tier)]
        if not len(sel):
            continue
        md.append(f"### {track} track, {tier} data\n")
        sm = T.pivot(sel, "success_pct")
        md += rep.table(
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

        md += rep.table(
            f"ert__{key}",
            T.pivot(sel, ert_cell),
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
            md += rep.table(
                f"targets__{key}",
                T.pivot(ts, lambda r: dash_if_nan(r["reached"], lambda v: f"{v:.0f}")),
                ts.reset_index(drop=True),
                f"Cost targets reached ({track} track, {tier} data): percentage of (run, target) "
                f"pairs whose final cost reaches the target, over k = "
                f"{', '.join(map(str, COST_KS))} (per k in the CSV).",
                f"tab:targets-{key}",
                index_label="method",
                raw_kw={"index": False},
            )
    return md


def section_table1(rep: Report) -> list[str]:
    """Table 1 (residual error of the identified parameters) per method and budget, the derived
    exponent a, and the model-error notes."""
    from bench.report import tables as T

    runs, dtol = rep.runs, rep.dtol
    md = ["## Table 1: residual error of the identified parameters\n"]
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
        md += rep.table(
            "a_exponent",
            T.a_display(at),
            at,
            "The exponent coefficient a (MPa^(1−b)) derived from each method's identified "
            "parameters, median over runs, with its signed error against the reference a in "
            "percent.",
            "tab:a-exponent",
            index_label="method",
        )
    budgets = rep.budgets
    for method in rep.methods:
        for budget in budgets if len(budgets) > 1 else [None]:
            t = T.table1(runs, method, budget=budget)
            if not any(t.attrs["n_runs"].values()):
                continue
            suffix = f"__b{budget}" if budget is not None else ""
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
                rep.tdir / f"table1__{_safe(method)}{suffix}",
                rep.tfmt,
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
                md.append(_model_error_note(rep, t, sel))
            md.append(_links(paths, rep.dest) + "\n")
    return md


def section_comparison(rep: Report) -> list[str]:
    """The comparison per case and method."""
    from bench.report import tables as T

    comp = T.comparison(rep.runs, rep.tol, rep.dtol)
    return ["## Comparison per case and method\n"] + rep.table(
        "comparison",
        T.comparison_display(comp),
        comp,
        "Comparison per case and method (with its data tier, model-error treatment and, when not "
        f"the defaults, track and Jacobian): success = {rep.rule}; forward evaluations (median "
        "and interquartile range) and forward-equivalents (measured; charges included), median "
        "final cost, median max |error| of the identified parameters, median wall time per run.",
        "tab:comparison",
        index=False,
    )


def section_jacobian(rep: Report) -> list[str]:
    """Runs that differ only in their Jacobian, side by side (none: no section)."""
    if not len(rep.jac):
        return []
    return ["## Finite-difference against exact Jacobians\n"] + rep.table(
        "jacobian",
        _jacobian_display(rep.jac),
        rep.jac,
        "Runs that differ only in their Jacobian, side by side: iterations, forward "
        "evaluations, forward-equivalents (measured) and final max |parameter error| (%).",
        "tab:jacobian",
        index=False,
    )


def section_posterior(rep: Report) -> list[str]:
    """The posterior interval widths of the MCMC runs and the posterior study (none: no
    section)."""
    from bench.report.posterior import width_table

    if not len(rep.post):
        return []
    return ["## Posterior (MCMC)\n"] + rep.table(
        "posterior_widths",
        width_table(rep.post),
        rep.post,
        "Posterior 95 % interval width in percent of the reference per parameter (in "
        "brackets the Laplace approximation's mean ± 2 sd width), the chain length in "
        "autocorrelation times (smallest over the parameters), and the paper's Table-1 error "
        "of a for comparison.",
        "tab:posterior",
        index=False,
        raw_kw={"index": False},
    )


def section_figures(rep: Report) -> list[str]:
    """The figures (runtime ECDFs, convergence per method family, posterior panels) and their
    index (``rep.figures`` false: no section)."""
    if not rep.figures:
        return []
    from bench.report import metrics as M
    from bench.report import tables as T
    from bench.report.figures import write_figures
    from bench.report.metrics import COST_KS, ERR_TARGETS

    dest, cases = rep.dest, rep.cases
    figs = write_figures(
        rep.runs,
        rep.history,
        dest / "figures",
        pdf="pdf" in rep.formats,
        progress=rep.progress,
        posterior=rep.post,
    )
    md = ["## Figures\n"]
    md.append(
        "Line styles and markers distinguish methods and parameters (greys only)."
        + (" PDF versions sit next to the PNGs." if "pdf" in rep.formats else "")
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
    return md


def section_data(rep: Report) -> list[str]:
    """The tidy DataFrames as parquet files (only with the ``parquet`` format)."""
    if "parquet" not in rep.formats:
        return []
    paths = []
    for df, name in ((rep.runs, "runs.parquet"), (rep.history, "history.parquet")):
        df = df.copy()
        df.attrs = {}
        p = rep.dest / name
        df.to_parquet(p, index=False)
        paths.append(p)
    return [
        "## Data\n",
        "The tidy DataFrames (one row per run; one row per history row): "
        + ", ".join(f"[{p.name}]({_rel(p, rep.dest)})" for p in paths)
        + ".\n",
    ]


#: The sections of report.md in order.
SECTIONS = (
    section_overview,
    section_completeness,
    section_unreadable,
    section_findings,
    section_success,
    section_table1,
    section_comparison,
    section_jacobian,
    section_posterior,
    section_figures,
    section_data,
)


def dash_if_nan(v, fmt):
    """``fmt(v)``, or the dash when ``v`` is None or NaN."""
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
        ("iterations", "iterations", lambda v: dash_if_nan(v, lambda x: f"{x:.0f}")),
        ("evaluations", "evals", lambda v: dash_if_nan(v, lambda x: f"{x:.0f}")),
        ("forward-equivalents", "fe", lambda v: dash_if_nan(v, fmt_num)),
        ("max |err| (%)", "max_err", lambda v: dash_if_nan(v, fmt_pct)),
    ):
        for j in js:
            c = f"{col}.{j}"
            out[f"{what} {j}"] = jac[c].map(f) if c in jac else "–"
    return out


def _model_error_note(rep: Report, t, sel) -> str:
    """The note under a model-error Table 1 (:mod:`bench.report.model_error_note`), its links
    relative to ``rep.dest``."""
    from bench.paths import results_root
    from bench.report import model_error_note as N

    dest, dirs = rep.dest, rep.model_error_dirs
    settings = N.run_settings(sel, rep.records)
    study = N.load_study(dirs, settings)
    found = [Path(d) for d in dirs or () if Path(d).is_dir()]
    conv_dirs = N.convergence_dirs(found)
    if study is not None:  # the convergence study for the inverse meshes it does not cover
        study = {**N.load_convergence(conv_dirs, settings), **study}
    doc = Path(__file__).resolve().parents[2] / "docs" / "objective.md"
    name = "`results/studies/model_error`"
    if found:
        d = found[0]
        shown = (
            "results/studies/model_error"
            if d.resolve() == (results_root() / "studies" / "model_error").resolve()
            else _rel(d, dest)
        )
        target = d / "overview.md" if (d / "overview.md").is_file() else d
        name = f"[`{shown}`]({_rel(target, dest)})"
    conv_name = "`results/studies/convergence/hex27-g8`"
    if conv_dirs:  # linked to the study's overview (one level up) when there is one
        c = conv_dirs[0]
        shown = (
            "results/studies/" + "/".join(N.CONVERGENCE_STUDY)
            if c.resolve() == results_root().joinpath("studies", *N.CONVERGENCE_STUDY).resolve()
            else _rel(c, dest)
        )
        target = c.parent / "overview.md" if (c.parent / "overview.md").is_file() else c
        conv_name = f"[`{shown}`]({_rel(target, dest)})"
    return N.model_error_note(
        t,
        settings,
        study,
        tol=rep.tol,
        derived_tol=rep.dtol,
        doc=_rel(doc, dest) if doc.is_file() else None,
        study_name=name,
        convergence_name=conv_name,
    )


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

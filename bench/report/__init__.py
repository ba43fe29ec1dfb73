"""The report of a results directory: tables, figures and ``report.md`` in ``DIR/report/``.

The report reads only the records on disk (through :func:`bench.store.to_frames`); it knows
nothing of how the runs were executed. Record files it cannot read (and those ``femubench run``
moved into ``DIR/runs/corrupt/``) are listed in report.md and on stderr. It is rebuilt from scratch
each time in a temporary directory that then replaces ``DIR/report`` (so no stale table or figure
survives).

Layout::

    DIR/report/report.md                         ties everything together
    DIR/report/tables/table1__<method>.{md,csv,tex}
    DIR/report/tables/comparison.{md,csv,tex}
    DIR/report/tables/success.{md,csv,tex}
    DIR/report/figures/history/<case>__<method>.png   (a) x/x_REF, (b) cost vs iteration
    DIR/report/figures/<case>__convergence.png        best cost vs evaluations, all methods
    DIR/report/figures/<case>__ecdf.png               runtime ECDF, all methods
    DIR/report/figures/all__ecdf.png                  runtime ECDF over all cases
    DIR/report/runs.parquet, history.parquet          with --format parquet
"""

from __future__ import annotations

import os
import shutil
import sys
import tempfile
from pathlib import Path

TABLE_FORMATS = ("md", "csv", "tex")


def write_report(
    out_dir: str | Path,
    formats=("md", "csv", "tex"),
    *,
    tol: float = 1.0,
    figures: bool = True,
    progress: bool = False,
) -> Path:
    """Write the report of ``out_dir`` into ``out_dir/report``; return the path of report.md.

    ``formats``: any of md, csv, tex (tables), pdf (figures also as PDF), parquet (the tidy
    DataFrames ``runs.parquet`` and ``history.parquet``). ``tol``: success tolerance in percent.
    Every record file that could not be read is named on stderr and in report.md. ``progress``: a
    progress bar (stderr) over the figures.
    """
    from bench import store

    out_dir = Path(out_dir)
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
    final = out_dir / "report"
    tmp = Path(tempfile.mkdtemp(dir=out_dir, prefix=".report-"))
    try:
        build_report(
            runs,
            history,
            tmp,
            formats,
            tol=tol,
            figures=figures,
            source=out_dir,
            unreadable=unreadable,
            set_aside=set_aside,
            progress=progress,
        )
        old = None
        if final.exists():
            old = out_dir / f".report-old-{os.getpid()}"
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
) -> Path:
    """Write the tables, figures and report.md of ``runs``/``history`` into ``dest``.

    ``unreadable``: ``(path, reason)`` of the record files that could not be read; ``set_aside``:
    the files moved into ``runs/corrupt/``; both are listed in report.md."""
    from bench.report import tables as T

    dest.mkdir(parents=True, exist_ok=True)
    tdir = dest / "tables"
    tfmt = [f for f in formats if f in TABLE_FORMATS]
    methods = T.method_order(runs["method"].unique())
    cases = T.case_order(runs["case"].unique())
    budgets = sorted(int(b) for b in runs["budget"].unique())
    md: list[str] = []
    md.append(f"# femubench report: `{source.resolve().name}`\n")
    md += _overview(runs, history, cases, methods, budgets, tol)
    if unreadable or set_aside:
        md.append("## Unreadable records\n")
        md.append(
            "Record files that could not be read as records (truncated, empty, not JSON or of the "
            "wrong shape). Unreadable records in `runs/` are left out of every table below; rerun "
            "the suite to redo their runs (`femubench run` moves them to `runs/corrupt/` first).\n"
        )
        lines = unreadable_lines(unreadable, set_aside, base=source)
        md.append("".join(f"- {line}\n" for line in lines))

    # --- Table 1 per method (x budget) ------------------------------------------------------
    md.append("## Table 1: residual error of the identified parameters\n")
    md.append(
        "Signed error of each identified parameter with respect to its reference value, "
        "100 (x/x_REF − 1) in percent; median over seeds and starts where a case has several "
        f"runs; `{T.DASH}` marks a parameter that is not active in the case. Crashed runs are "
        "left out (see the comparison table).\n"
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
            md.append(_links(paths, dest) + "\n")

    # --- comparison -------------------------------------------------------------------------
    comp = T.comparison(runs, tol)
    cdisp = T.comparison_display(comp)
    ccap = (
        "Comparison per case and method (with its data tier and model-error treatment): success = "
        f"every |parameter error| ≤ {tol:g} %; forward evaluations (median and interquartile "
        "range) and forward-equivalents (a run with exact sensitivities weighs its wall time over "
        "a plain run's; high-fidelity runs of a correction included), median final cost, median "
        "max |error|, median wall time per run."
    )
    paths = T.write_table(
        tdir / "comparison",
        tfmt,
        display=cdisp,
        raw=comp,
        caption=ccap,
        label="tab:comparison",
        index=False,
    )
    md.append("## Comparison per case and method\n")
    md.append(ccap + "\n")
    md.append(T.to_markdown(cdisp, index=False))
    md.append(_links(paths, dest) + "\n")

    sm = T.success_matrix(runs, tol)
    scap = f"Success rate in percent (every |parameter error| ≤ {tol:g} %), all budgets pooled."
    paths = T.write_table(
        tdir / "success",
        tfmt,
        display=T.success_display(sm),
        raw=sm,
        caption=scap,
        label="tab:success",
        index_label="method",
    )
    md.append("## Success rate\n")
    md.append(scap + "\n")
    md.append(T.to_markdown(T.success_display(sm), index_label="method"))
    md.append(_links(paths, dest) + "\n")

    # --- figures ----------------------------------------------------------------------------
    if figures:
        from bench.report.figures import COST_KS, ERR_TARGETS, write_figures

        figs = write_figures(
            runs, history, dest / "figures", pdf="pdf" in formats, progress=progress
        )
        md.append("## Figures\n")
        md.append(
            "Line styles and markers distinguish methods and parameters (greys only)."
            + (" PDF versions sit next to the PNGs." if "pdf" in formats else "")
            + "\n"
        )
        md.append("### Across methods\n")
        md.append(
            "*Convergence*: best cost so far against forward evaluations, median over the runs of "
            "each method (number of runs in the legend). *Runtime ECDF* (COCO style): fraction of "
            "(run, target) pairs reached within a number of forward evaluations; (a) cost targets "
            f"J − J_best ≤ 10^−k (J_init − J_best), k = {', '.join(map(str, COST_KS))}, with "
            "J_best the best cost any run reached on the case and J_init the median initial cost; "
            "(b) parameter targets max_i |x_i/x_i^REF − 1| ≤ "
            f"{', '.join(f'{t:g}' for t in ERR_TARGETS)} %.\n"
        )
        if figs["ecdf_all"] is not None:
            md.append(f"![runtime ECDF, all cases]({_rel(figs['ecdf_all'], dest)})\n")
        for case in cases:
            if case in figs["convergence"]:
                md.append(f"#### {case}\n")
                md.append(f"![{case}: convergence]({_rel(figs['convergence'][case], dest)})\n")
                md.append(f"![{case}: runtime ECDF]({_rel(figs['ecdf'][case], dest)})\n")
        md.append("### Iteration histories (like the paper's Figs 6–14)\n")
        md.append(
            "For each case and method, the run with the median final cost: (a) normalised "
            "parameters x_i/x_i^REF against iteration, with each parameter's box [lower, "
            "upper]/x_i^REF as a bracket of the same line style right of the last iteration and a "
            "ring where a final parameter lies on a bound, (b) cost against iteration (log "
            "scale).\n"
        )
        hist = figs["history"]
        cols = [(m, b) for m in methods for b in budgets if any((c, m, b) in hist for c in cases)]
        head = ["case"] + [m + (f" (b{b})" if len(budgets) > 1 else "") for m, b in cols]
        rows = []
        for c in cases:
            cells = [
                f"[fig]({_rel(hist[(c, m, b)], dest)})" if (c, m, b) in hist else T.DASH
                for m, b in cols
            ]
            rows.append([c] + cells)
        if cols:
            md.append(
                "| "
                + " | ".join(head)
                + " |\n|"
                + "|".join(["---"] * len(head))
                + "|\n"
                + "".join("| " + " | ".join(r) + " |\n" for r in rows)
            )

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


def _overview(runs, history, cases, methods, budgets, tol) -> list[str]:
    from bench.report import tables as T

    n_crashed = int(runs["crashed"].sum())
    seeds = sorted(int(s) for s in runs["seed"].unique())
    starts = sorted(runs["start"].unique())
    suites = sorted(s for s in runs["suite"].dropna().unique())
    hashes = sorted(str(h) for h in runs["data_hash"].dropna().unique())
    meshes = sorted(str(m) for m in runs["mesh"].dropna().unique())
    lines = [
        f"- **{len(runs)} runs** ({n_crashed} crashed) from suite(s) "
        f"{', '.join(f'`{s}`' for s in suites) or T.DASH}",
        f"- cases ({len(cases)}): {', '.join(cases)}",
        f"- methods ({len(methods)}): {', '.join(methods)}",
        f"- budgets (forward evaluations): {', '.join(map(str, budgets))}; seeds: "
        f"{', '.join(map(str, seeds))}; starts: {', '.join(starts)}; mesh: "
        f"{', '.join(meshes) or T.DASH}",
        f"- data file hash(es): {', '.join(f'`{h[:16]}`' for h in hashes) or T.DASH}",
        f"- success criterion: every identified parameter within **{tol:g} %** of its reference "
        "value",
        f"- total wall time of the runs: {runs['wall_s'].sum() / 3600.0:.2f} h",
        "",
    ]
    return lines


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

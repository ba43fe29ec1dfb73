"""The report of a results directory: tables, figures and ``report.md`` in ``DIR/report/``.

The report reads only the records on disk (through :func:`bench.experiment.store.to_frames`); it
knows nothing of how the runs were executed. Record files it cannot read (and those ``femubench
run`` moved into ``DIR/runs/corrupt/``) are listed in report.md and on stderr. It is rebuilt from
scratch each time in a temporary directory that then replaces ``DIR/report`` (so no stale table or
figure survives).

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

import os
import shutil
import sys
import tempfile
from pathlib import Path

from bench.report.sections import TABLE_FORMATS, unreadable_lines

__all__ = ["TABLE_FORMATS", "build_report", "study_dirs", "unreadable_lines", "write_report"]


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
    from bench.experiment import store
    from bench.report.catalogue import case_facts
    from bench.report.tables import SUCCESS_TOL

    out_dir = Path(out_dir)
    tol = SUCCESS_TOL if tol is None else tol
    formats = [f.lower() for f in formats]
    records, unreadable = store.scan_records(out_dir)
    set_aside = store.set_aside_files(out_dir)
    for line in unreadable_lines(unreadable, set_aside):
        print(f"femubench report: {line}", file=sys.stderr)
    from bench.report.extras import is_user_record, write_extras

    user = [r for r in records if is_user_record(r)]  # user problems: their own report
    records = [r for r in records if not is_user_record(r)]
    runs, history = store.to_frames(out_dir, records, facts=case_facts)
    if not len(runs) and not user:
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
    from bench.report import dest as report_dest
    from bench.report.model_error_note import convergence_dirs

    inputs = [*posterior_dirs, *model_error_dirs, *convergence_dirs(model_error_dirs)]
    report_dest.check_dest(out_dir, final, inputs)
    lock = report_dest.lock(final.parent)  # held until the report is in place
    tmp = Path(tempfile.mkdtemp(dir=final.parent, prefix=report_dest.TMP_PREFIX))
    report_dest.mark(tmp)
    try:
        if len(runs):
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
        write_extras(records + user, user, tmp, formats, source=out_dir)
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
        lock.close()
    return final / "report.md"


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
    """Write the tables, figures and report.md of ``runs``/``history`` into ``dest``: the
    sections of :data:`bench.report.sections.SECTIONS` in order.

    ``unreadable``: ``(path, reason)`` of the record files that could not be read; ``set_aside``:
    the files moved into ``runs/corrupt/``; both are listed in report.md. ``records``: the records
    themselves (MCMC posteriors); ``posterior_dirs``: folders holding the posterior study's
    ``<case>/summary.json``; ``model_error_dirs``: folders holding the model-error study's
    ``<case>/*.json`` (none found: the notes under the model-error Tables 1 say so)."""
    from bench.report.sections import SECTIONS, prepare
    from bench.report.warnings import warnings_section

    dest.mkdir(parents=True, exist_ok=True)
    rep = prepare(
        runs,
        history,
        dest,
        [f.lower() for f in formats],
        tol=tol,
        tol_a=tol_a,
        source=source,
        records=records,
        posterior_dirs=posterior_dirs,
        figures=figures,
        progress=progress,
        unreadable=unreadable,
        set_aside=set_aside,
        model_error_dirs=model_error_dirs,
    )
    md: list[str] = []
    for section in SECTIONS:
        md += section(rep)
    md += warnings_section(records)  # the records' plausibility warnings, if any
    (dest / "report.md").write_text("\n".join(md), encoding="utf-8")
    return dest / "report.md"

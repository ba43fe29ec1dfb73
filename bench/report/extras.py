"""What the report adds to report.md beyond the FE sections: the user-problem report
(:mod:`bench.report.user_problems`), the statistics of the FE runs (format ``stats``) and the
IOHprofiler / COCO exports (:mod:`bench.report.export`), in one call from
:func:`bench.report.write_report`.

Without user problems and without the ``stats``, ``ioh`` and ``coco`` formats it writes nothing
(so the FE reports render exactly as before)."""

from __future__ import annotations

from pathlib import Path

from bench.report.user_problems import is_user_record

__all__ = ["EXPORT_FORMATS", "STATS_FORMAT", "is_user_record", "write_extras"]

#: the report formats that are exports (folders next to report.md)
EXPORT_FORMATS = ("ioh", "coco")
#: the report format that adds the statistics section of the FE runs (rank tests, fixed-target
#: and fixed-budget views); off by default, so that the FE reports render as before
STATS_FORMAT = "stats"


def write_extras(records, user, dest: Path, formats, *, source: Path) -> list[str]:
    """Append the user-problem section to ``dest/report.md`` (made with a title when the
    directory has only user problems) and write the requested exports of all ``records`` into
    ``dest/ioh`` and ``dest/coco``; return the markdown added."""
    from bench.report import export
    from bench.report.sections import TABLE_FORMATS
    from bench.report.user_problems import fe_statistics, section

    dest = Path(dest)
    report = dest / "report.md"
    tfmt = [f for f in formats if f in TABLE_FORMATS]
    md = section(user, dest, tfmt, source) if user else []
    if "stats" in formats:
        md += fe_statistics(records, dest, tfmt)
    done = []
    if "ioh" in formats:
        n = len(export.write_ioh(records, dest / "ioh"))
        done.append(
            f"IOHprofiler (`ioh.logger.Analyzer` format, for IOHanalyzer): [ioh/](ioh) "
            f"({n} function files)"
        )
    if "coco" in formats:
        files, skipped = export.write_coco(records, dest / "coco")
        done.append(
            f"COCO (`bbob-new2`, read by `cocopp.main('coco/<method>')`): [coco/](coco) "
            f"({len(files)} .info files)"
            + (
                f"; {skipped} runs of problems outside COCO's suites left out (cocopp reads its "
                "own suites only; they are in the IOH export)"
                if skipped
                else ""
            )
        )
    if done:
        md += ["## Exports\n", "".join(f"- {d}\n" for d in done)]
    if not md:
        return md
    text = (
        report.read_text(encoding="utf-8")
        if report.is_file()
        else (f"# femubench report: `{Path(source).resolve().name}`\n")
    )
    report.write_text(text + "\n" + "\n".join(md), encoding="utf-8")
    return md

"""The shipped report of results/default renders byte for byte from its records (the report reads
files only, so a code change that is not meant to change it leaves it as it is), its figures
included (the shipped PNGs were converted by ``femubench figures compact``: the same bytes)."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from bench.report import write_report

SHIPPED = Path(__file__).resolve().parents[1] / "results" / "default"


def _render(figures: bool) -> tuple[str, dict[str, bytes], dict[str, bytes]]:
    """Render results/default into a temporary folder beside its report (the same depth, so the
    relative links agree); return report.md, the table files and the PNG figures."""
    dest = SHIPPED / f".report-test-{os.getpid()}-{int(figures)}"
    try:
        text = write_report(SHIPPED, dest=dest, figures=figures).read_text(encoding="utf-8")
        return text, _tables(dest), _figures(dest)
    finally:
        shutil.rmtree(dest, ignore_errors=True)


def _tables(report: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted((report / "tables").iterdir())}


def _figures(report: Path) -> dict[str, bytes]:
    return {str(p.relative_to(report)): p.read_bytes() for p in sorted(report.rglob("*.png"))}


def test_shipped_default_report_renders_identically_without_figures():
    text, tables, figures = _render(figures=False)
    shipped = (SHIPPED / "report" / "report.md").read_text(encoding="utf-8")
    head, sep, rest = shipped.partition("\n\n## Figures\n")
    assert sep, "the shipped report has a Figures section"
    after = rest.partition("\n## ")  # the sections after Figures (plausibility warnings), if any
    tail = "\n\n## " + after[2] if after[1] else "\n"
    assert text == head + tail
    assert tables == _tables(SHIPPED / "report")
    assert figures == {}


@pytest.mark.slow
def test_shipped_default_report_renders_identically_with_figures():
    text, tables, figures = _render(figures=True)
    assert text == (SHIPPED / "report" / "report.md").read_text(encoding="utf-8")
    assert tables == _tables(SHIPPED / "report")
    assert len(figures) >= 40 and figures == _figures(SHIPPED / "report")

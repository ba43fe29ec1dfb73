"""The shipped report of results/default renders byte for byte from its records (the report reads
files only, so a code change that is not meant to change it leaves it as it is)."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from bench.report import write_report

SHIPPED = Path(__file__).resolve().parents[1] / "results" / "default"


def _render(figures: bool) -> tuple[str, dict[str, bytes]]:
    """Render results/default into a temporary folder beside its report (the same depth, so the
    relative links agree); return report.md and the table files."""
    dest = SHIPPED / f".report-test-{os.getpid()}-{int(figures)}"
    try:
        text = write_report(SHIPPED, dest=dest, figures=figures).read_text(encoding="utf-8")
        return text, _tables(dest)
    finally:
        shutil.rmtree(dest, ignore_errors=True)


def _tables(report: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted((report / "tables").iterdir())}


def test_shipped_default_report_renders_identically_without_figures():
    text, tables = _render(figures=False)
    shipped = (SHIPPED / "report" / "report.md").read_text(encoding="utf-8")
    head, sep, rest = shipped.partition("\n\n## Figures\n")
    assert sep, "the shipped report has a Figures section"
    after = rest.partition("\n## ")  # the sections after Figures (plausibility warnings), if any
    tail = "\n\n## " + after[2] if after[1] else "\n"
    assert text == head + tail
    assert tables == _tables(SHIPPED / "report")


@pytest.mark.slow
def test_shipped_default_report_renders_identically_with_figures():
    text, tables = _render(figures=True)
    assert text == (SHIPPED / "report" / "report.md").read_text(encoding="utf-8")
    assert tables == _tables(SHIPPED / "report")

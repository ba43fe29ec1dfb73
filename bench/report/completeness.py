"""What a report is missing: the runs a suite planned against the records present.

``femubench run`` writes ``DIR/<suite>.plan.json`` (format ``femubench-plan/1``: the config hash
and label of every planned run). The report section :func:`section_completeness` states per
suite the planned, present, crashed and missing runs (naming the first :data:`NAMED` missing and
crashed ones), and the records ``femubench run`` set aside because they were made on other data
(``DIR/runs/stale/``). A folder without a plan file gets no section.
"""

from __future__ import annotations

import json
from pathlib import Path

#: Missing or crashed runs named per suite (the rest are counted).
NAMED = 10


def read_plans(source: Path) -> list[tuple[Path, dict]]:
    """``(path, plan)`` of every readable ``*.plan.json`` of the results folder ``source``; a
    plan that cannot be read is returned as ``{"error": why}``."""
    out = []
    for path in sorted(Path(source).glob("*.plan.json")):
        try:
            plan = json.loads(path.read_text(encoding="utf-8"))
            if not isinstance(plan, dict) or not isinstance(plan.get("runs"), list):
                raise ValueError("not a plan (no list 'runs')")
            out.append((path, plan))
        except (OSError, UnicodeDecodeError, ValueError) as exc:
            out.append((path, {"error": f"{type(exc).__name__}: {exc}"}))
    return out


def completeness(plan: dict, records) -> dict:
    """``{"planned", "present", "crashed", "missing"}`` of one plan against ``records`` (counts;
    ``crashed`` and ``missing`` are lists of labels)."""
    by_hash = {r["config_hash"]: r for r in records}
    present = [p for p in plan["runs"] if p.get("hash") in by_hash]
    return {
        "planned": len(plan["runs"]),
        "present": len(present),
        "crashed": [p.get("label", p["hash"]) for p in present if by_hash[p["hash"]].get("error")],
        "missing": [
            p.get("label", p.get("hash")) for p in plan["runs"] if p.get("hash") not in by_hash
        ],
    }


def _named(labels: list[str]) -> str:
    shown = ", ".join(f"`{x}`" for x in labels[:NAMED])
    return shown + (f" and {len(labels) - NAMED} more" if len(labels) > NAMED else "")


def section_completeness(rep) -> list[str]:
    """The section of report.md: planned / present / crashed / missing runs per suite."""
    plans = read_plans(rep.source)
    if not plans:
        return []
    from bench.experiment import store

    stale = store.set_aside_files(rep.source, store.STALE)
    records = store.scan_records(rep.source)[0]  # user problems' records too
    rows = ["| suite | planned | present | crashed | missing |", "|---|---:|---:|---:|---:|"]
    notes = []
    for path, plan in plans:
        if "error" in plan:
            notes.append(f"- plan `{path.name}` cannot be read: {plan['error']}\n")
            continue
        c = completeness(plan, records)
        name = plan.get("suite", path.name)
        rows.append(
            f"| {name} | {c['planned']} | {c['present']} | {len(c['crashed'])} | "
            f"{len(c['missing'])} |"
        )
        if c["missing"]:
            notes.append(f"- {name}: missing {_named(c['missing'])}\n")
        if c["crashed"]:
            notes.append(
                f"- {name}: crashed {_named(c['crashed'])} (`femubench run --retry-failed` "
                "runs them again)\n"
            )
    if stale:
        present = {r.get("config_hash") for r in records}
        rerun = sum(p.name.split(".")[0] in present for p in stale)
        notes.append(
            f"- {len(stale)} record(s) made on other data than today's were set aside in "
            f"`runs/stale/`; {rerun} of their runs have a record made again\n"
        )
    done = all("error" not in p and not completeness(p, records)["missing"] for _, p in plans)
    intro = (
        "Every planned run has a record."
        if done
        else "Runs the suite planned (`<suite>.plan.json`, written by `femubench run`) that have "
        "no record here: the tables below leave them out; rerun the suite to make them."
    )
    blocks = ["## Completeness\n", intro + "\n", "\n".join(rows) + "\n"]
    return blocks + (["".join(notes)] if notes else [])

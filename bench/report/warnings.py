"""The report's list of plausibility warnings: what the runs' records say cannot be right (data in
the wrong units, a cost far above the data's size, parameters on a bound; see
problems.inverse.plausibility), grouped by message with the runs that issued it.

Only the records are read (their ``warnings`` field, plain strings ``"Category: message"``);
records without plausibility warnings add nothing to report.md.
"""

from __future__ import annotations

#: the prefix of a plausibility warning in a record's ``warnings``
PREFIX = "PlausibilityWarning: "
#: run labels listed per message (the rest are counted)
MAX_RUNS = 5


def run_label(record: dict) -> str:
    """``case/method/s<seed>/<start><index>/b<budget>`` of a record's config."""
    c = record.get("config") or {}
    return (
        f"{c.get('case')}/{c.get('method')}/s{c.get('seed')}/{c.get('start')}"
        f"{c.get('start_index', 0)}/b{c.get('budget')}"
    )


def plausibility_warnings(records) -> dict[str, list[str]]:
    """Message -> labels of the runs whose record carries it, in record order."""
    out: dict[str, list[str]] = {}
    for record in records:
        for text in record.get("warnings") or []:
            if isinstance(text, str) and text.startswith(PREFIX):
                out.setdefault(text[len(PREFIX) :], []).append(run_label(record))
    return out


def warnings_section(records) -> list[str]:
    """Markdown lines of the section "Plausibility warnings" ([] when no record has one)."""
    found = plausibility_warnings(records)
    if not found:
        return []
    n_runs = len({label for labels in found.values() for label in labels})
    md = [
        "## Plausibility warnings",
        "",
        f"{n_runs} run(s) gave numbers that cannot be right (see docs/objective.md, "
        "\"Plausibility checks\"):",
        "",
    ]
    for message, labels in found.items():
        more = f" and {len(labels) - MAX_RUNS} more" if len(labels) > MAX_RUNS else ""
        md.append(f"- {message} — {len(labels)} run(s): {', '.join(labels[:MAX_RUNS])}{more}")
    return md + [""]

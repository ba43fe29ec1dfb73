"""``femubench cases``: the nine Table-1 cases with their parameters, bounds, default starts and
default model-error treatment."""

from __future__ import annotations

NAME = "cases"
HELP = (
    "List the nine identification cases with their default model-error treatment (table, or "
    "--json)."
)


def add_arguments(p) -> None:
    p.add_argument("--json", action="store_true", help="print a JSON list, one object per case")
    p.add_argument("--analytic", action="store_true", help="also list the analytic test problems")


def main(args) -> int:
    import json

    from problems.inverse.cases import CASES, all_cases, default_treatment

    cases = all_cases() if args.analytic else CASES
    if args.json:
        print(
            json.dumps(
                [
                    {**c.to_dict(), "default_treatment": default_treatment(c.name).to_dict()}
                    for c in cases.values()
                ],
                indent=1,
            )
        )
        return 0
    for case in cases.values():
        fixed = ", ".join(f"{k} = {v}" for k, v in case.fixed.items())
        print(f"\n{case.name}  (form {case.form}, hardening {case.hardening}; fixed: {fixed})")
        print(
            f"  default model-error treatment (--correction default): "
            f"{default_treatment(case.name).label()}"
        )
        print(
            f"  {'parameter':10} {'unit':10} {'reference':>12} {'lower':>12} {'upper':>12} "
            f"{'start':>12}"
        )
        for p, s in zip(case.parameters, case.start):
            print(
                f"  {p.name:10} {p.unit:10} {p.reference:12.6g} {p.lower:12.6g} {p.upper:12.6g} "
                f"{s:12.6g}"
            )
    return 0

"""``femubench solvers``: every registered optimisation method with its library, family and
options."""

from __future__ import annotations

NAME = "solvers"
HELP = "List the optimisation methods with their library, family and options (table, or --json)."


def add_arguments(p) -> None:
    p.add_argument("--json", action="store_true", help="print a JSON list, one object per method")
    p.add_argument("--family", choices=["local", "global", "sampling"], help="only this family")
    p.add_argument("--options", action="store_true", help="also describe every option")
    p.add_argument(
        "--markdown",
        action="store_true",
        help="print docs/solver_options.md (every method's declared options)",
    )


def format_table(infos, describe: bool = False) -> str:
    """The plain-text table of :class:`~solvers.base.MethodInfo` objects."""
    lines = [f"{'method':18} {'library':15} {'family':9} {'random':6}  options (default)"]
    for info in infos:
        opts = ", ".join(f"{k}={o.default!r}" for k, o in info.options.items())
        lines.append(
            f"{info.name:18} {info.library:15} {info.family:9} "
            f"{'yes' if info.stochastic else 'no':6}  {opts}"
        )
        if describe:
            lines.append(f"    {info.description}")
            lines += [
                f"    {k:20} {o.default!r:>14}  {o.help} (allowed: {o.range_text()})"
                for k, o in info.options.items()
            ]
    lines.append("Any other nlopt algorithm also works as nlopt:<NAME> (e.g. nlopt:LN_PRAXIS).")
    return "\n".join(lines)


def main(args) -> int:
    import json

    from solvers import METHODS

    infos = [i for i in METHODS.values() if args.family in (None, i.family)]
    if args.markdown:
        from solvers.options import markdown

        print(markdown({i.name: i for i in infos}), end="")
    elif args.json:
        print(json.dumps([i.to_dict() for i in infos], indent=1))
    else:
        print(format_table(infos, args.options))
    return 0

"""The ``femubench`` command line: discovers the sub-commands in :mod:`bench.commands`."""
from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys

import bench.commands


def build_parser() -> argparse.ArgumentParser:
    """Return the top-level parser with one sub-parser per module of :mod:`bench.commands`."""
    parser = argparse.ArgumentParser(
        prog="femubench",
        description="Benchmark local and global optimizers on the identification of "
        "extended Drucker-Prager parameters of concrete from a cube compression test.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for info in sorted(pkgutil.iter_modules(bench.commands.__path__), key=lambda m: m.name):
        module = importlib.import_module(f"bench.commands.{info.name}")
        if not hasattr(module, "NAME"):
            continue
        p = sub.add_parser(module.NAME, help=module.HELP, description=module.HELP)
        module.add_arguments(p)
        p.set_defaults(_main=module.main)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the console script; returns the process exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "_main", None):
        parser.print_help()
        return 0
    try:
        return int(args._main(args) or 0)
    except (ValueError, FileNotFoundError) as exc:  # bad input: a clear message, no traceback
        print(f"femubench {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())

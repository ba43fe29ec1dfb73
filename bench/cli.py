"""The ``femubench`` command line: discovers the sub-commands in :mod:`bench.commands`."""
from __future__ import annotations

import argparse
import importlib
import os
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
    parser.add_argument("--version", action="version", version=f"%(prog)s {package_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for info in sorted(pkgutil.iter_modules(bench.commands.__path__), key=lambda m: m.name):
        module = importlib.import_module(f"bench.commands.{info.name}")
        if not hasattr(module, "NAME"):
            continue
        p = sub.add_parser(module.NAME, help=module.HELP, description=module.HELP)
        module.add_arguments(p)
        p.set_defaults(_main=module.main)
    return parser


def package_version() -> str:
    """The installed version of femubench (``unknown`` when it is not installed)."""
    from importlib import metadata

    try:
        return metadata.version("femubench")
    except metadata.PackageNotFoundError:
        return "unknown"


def main(argv: list[str] | None = None) -> int:
    """Entry point of the console script; returns the process exit code.

    Bad input (ValueError, or an OSError such as a missing file or an output path that is a
    directory) gives a one-line message and exit code 2; a closed output pipe (``femubench ... |
    head``) ends the program quietly with exit code 141; Ctrl-C with 130.
    """
    try:
        try:
            return run(argv)
        finally:
            sys.stdout.flush()  # a closed pipe shows here, not at interpreter exit
    except BrokenPipeError:
        silence_stdout()
        return 141  # 128 + SIGPIPE, like other tools whose reader went away
    except KeyboardInterrupt:
        print("femubench: interrupted", file=sys.stderr)
        return 130


def run(argv: list[str] | None = None) -> int:
    """Parse ``argv`` and run the sub-command; bad input becomes a message and exit code 2."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "_main", None):
        parser.print_help()
        return 0
    try:
        return int(args._main(args) or 0)
    except BrokenPipeError:
        raise
    except (ValueError, OSError) as exc:  # bad input: a clear message, no traceback
        print(f"femubench {args.command}: error: {exc}", file=sys.stderr)
        return 2


def silence_stdout() -> None:
    """Point stdout at /dev/null, so that flushing it at exit raises no second BrokenPipeError."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):  # stdout without a file descriptor (captured)
        pass
    finally:
        os.close(devnull)


if __name__ == "__main__":
    raise SystemExit(main())

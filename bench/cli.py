"""The ``femubench`` command line: discovers the sub-commands in :mod:`bench.commands`."""

from __future__ import annotations

import argparse
import importlib
import os
import pkgutil
import sys

import bench.commands


class UsageError(ValueError):
    """A command line argparse rejected (unknown option, bad value); ``prog`` is the
    (sub-)command."""

    def __init__(self, prog: str, message: str):
        super().__init__(message)
        self.prog = prog


class Parser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one line (no usage block):
    ``femubench CMD: error: ...``."""

    def error(self, message):
        raise UsageError(self.prog, message)


def build_parser() -> argparse.ArgumentParser:
    """Return the top-level parser with one sub-parser per module of :mod:`bench.commands`.

    Every sub-parser goes through :func:`bench.commands._args.harden`: options declared with a bare
    ``int``/``float`` or none get checked types (finite numbers, seeds >= 0, counts >= 1, mesh
    specs).
    """
    from bench.commands._args import harden

    parser = Parser(
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
        harden(p)
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

    Bad input (a rejected option, a ValueError, or an OSError such as a missing file or an output
    path that is a directory) gives a one-line message and exit code 2; a closed output pipe
    (``femubench ... | head``) ends the program quietly with exit code 141; Ctrl-C with 130. Any
    other exception (a bug, or a library error no check foresaw) is one line too, with exit code 1;
    ``FEMUBENCH_DEBUG=1`` shows its traceback instead.
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
    try:
        args = parser.parse_args(argv)
    except UsageError as exc:
        hint = (
            f" (see '{exc.prog} --help')"
            if exc.prog != "femubench"
            else " (see 'femubench --help')"
        )
        print(f"{exc.prog}: error: {one_line(exc)}{hint}", file=sys.stderr)
        return 2
    if not getattr(args, "_main", None):
        parser.print_help()
        return 0
    try:
        return int(args._main(args) or 0)
    except (BrokenPipeError, KeyboardInterrupt):
        raise
    except (ValueError, OSError) as exc:  # bad input: a clear message, no traceback
        print(f"femubench {args.command}: error: {one_line(exc)}", file=sys.stderr)
        return 2
    except Exception as exc:  # noqa: BLE001 - the last resort: never a raw library traceback
        if os.environ.get("FEMUBENCH_DEBUG"):
            raise
        print(
            f"femubench {args.command}: internal error: {type(exc).__name__}: {one_line(exc)} "
            "(set FEMUBENCH_DEBUG=1 for the traceback)",
            file=sys.stderr,
        )
        return 1


def one_line(exc: BaseException) -> str:
    """The message of ``exc`` on one line (its class name if it has none). A deliberate list of
    problems (lines starting ``  - ``, e.g. every error of a suite file) keeps one line per
    problem."""
    text = str(exc).strip()
    if "\n  - " in text:
        return "\n".join(
            ("  " if line.startswith("  - ") else "") + " ".join(line.split())
            for line in text.splitlines()
        )
    return " ".join(text.split()) or type(exc).__name__


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

"""One module per CLI sub-command.

Each module defines ``NAME`` (the sub-command), ``HELP`` (one line), ``add_arguments(parser)``
and ``main(args) -> int``. Modules are discovered automatically by :mod:`bench.cli`; keep heavy
imports inside ``main`` so that ``femubench --help`` stays fast.
"""

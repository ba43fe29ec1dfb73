"""Objects built once per discretisation and shared by every run on it (the fused assembler,
linear solvers with their symbolic analysis, orderings): used by the Newton solver
(:mod:`problems.fe.newton`) and the sensitivity solves (:mod:`problems.fe.ddm`)."""

from __future__ import annotations

import weakref

_SHARED: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def shared(owner, key, make):
    """The object ``key`` of ``owner`` (a discretisation), built by ``make()`` on first use and
    dropped with ``owner``."""
    d = _SHARED.setdefault(owner, {})
    if key not in d:
        d[key] = make()
    return d[key]

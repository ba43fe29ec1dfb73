"""Progress bars and running-time warnings of the commands (stderr only; stdout stays the result).

* :func:`enabled` — a progress bar is drawn only on a terminal and without ``--quiet``.
* :class:`EvaluationProgress` — a tqdm bar fed by the evaluator's observer hook
  (``objective.observers``; :mod:`problems.inverse.evaluator`): forward evaluations out of the
  budget, best cost so far, elapsed time and tqdm's estimate of the time left (evaluations left
  over the measured rate).
* :func:`forward_run_s` / :func:`warn_if_long` — a rough time estimate of a number of FE forward
  runs on a mesh, and a one-line warning when it exceeds an hour.

How the estimate is made: one forward run (10 snapshots, plastic) on the ``coarse`` mesh solved as
the eighth (1 029 dofs) takes :data:`COARSE_RUN_S` = 0.3 s on one core (bench/perf/forward.py:
0.17 s measured on a quiet core, 0.3 s on the shared 2-core machine); the time grows with the
solved dofs to the power :data:`DOFS_EXPONENT` = 1.5, the growth measured between ``coarse``
(0.17 s, 1 029 dofs) and ``paper`` (4.7 s, 9 450 dofs) by bench/perf/forward.py (the sparse
factorisation grows faster than linearly). ``paper`` is then ~8 s per plastic run on a loaded
core, ``fine`` (27 783 dofs) ~40 s. Analytic cases cost nothing.
"""

from __future__ import annotations

import math
import sys
import time

COARSE_RUN_S = 0.3  #: s, one plastic forward run on coarse (eighth, 1 029 dofs), one core
COARSE_DOFS = 1029  #: dofs of the coarse eighth model
DOFS_EXPONENT = 1.5  #: run time ~ dofs ** DOFS_EXPONENT (coarse -> paper, bench/perf/forward.py)
WARN_ABOVE_S = 3600.0  #: warn when an estimate exceeds this, s


def enabled(quiet: bool = False, stream=None) -> bool:
    """True when a progress bar should be drawn: not ``quiet``, and ``stream`` (default stderr) is
    a terminal."""
    stream = sys.stderr if stream is None else stream
    try:
        return not quiet and bool(stream.isatty())
    except (AttributeError, ValueError):  # closed or fake stream
        return False


class EvaluationProgress:
    """A tqdm bar on stderr fed by the observer hook of one or more evaluators.

    ``total``: the budget (forward evaluations) if known; otherwise the first evaluator budget seen.
    The bar counts the forward evaluations of every evaluator it observes (a correction may build
    several objectives; ``solve`` resets an evaluator's counters: both continue the count) and
    shows the best cost seen. Use as a context manager, either attached to an evaluator::

        with EvaluationProgress(objective, total=budget, desc=case, disable=not enabled(quiet)):
            solve(objective, ...)

    or handed to code that builds its evaluators (``identify(spec, observers=[bar])``).
    """

    def __init__(
        self, evaluator=None, *, total: int | None = None, desc: str = "", disable: bool = False
    ):
        from tqdm import tqdm

        self.evaluator = evaluator
        self.bar = tqdm(
            total=total,
            desc=desc,
            unit="eval",
            file=sys.stderr,
            disable=disable,
            dynamic_ncols=True,
            leave=False,
        )
        # id(evaluator) -> (id of its log, n_evals seen)
        self._last: dict[int, tuple[int, int]] = {}
        self._best = math.inf
        self._t_postfix = 0.0

    def __call__(self, evaluator, evaluation) -> None:
        try:
            key, log = id(evaluator), id(evaluator.log)
            seen_log, last = self._last.get(key, (log, 0))
            n = evaluator.n_evals
            if log != seen_log or n < last:  # counters reset (reset() makes a new log): a new phase
                last = 0
            if self.bar.total is None and evaluator.budget is not None:
                self.bar.total = evaluator.budget + self.bar.n
            if n > last:
                self.bar.update(n - last)
            self._last[key] = (log, n)
            best = evaluator.best
            now = time.monotonic()
            if best is not None and best.cost < self._best and now - self._t_postfix > 0.5:
                self._best, self._t_postfix = best.cost, now
                self.bar.set_postfix_str(f"best cost {best.cost:.4g}", refresh=False)
        except Exception:  # noqa: BLE001 - an observer must never break an evaluation
            pass

    def __enter__(self):
        if self.evaluator is not None:
            self.evaluator.observers.append(self)
        return self

    def __exit__(self, *exc):
        if self.evaluator is not None and self in self.evaluator.observers:
            self.evaluator.observers.remove(self)
        self.bar.close()
        return False


def solved_dofs(mesh: str) -> int:
    """Degrees of freedom of the model the FE code solves for ``mesh`` (eighth or quarter)."""
    from problems.fe.mesh import parse_mesh_spec

    spec = parse_mesh_spec(mesh)
    p = 2 if spec.element == "hex27" else 1  # node intervals per element edge
    nx, ny, nz = (p * n for n in spec.shape)
    layers = nz // 2 if spec.symmetry == "eighth" else nz
    return 3 * (nx + 1) * (ny + 1) * (layers + 1)


def forward_run_s(mesh: str) -> float:
    """Rough wall time of one plastic forward run on ``mesh`` and one core, s (module docstring)."""
    return COARSE_RUN_S * (solved_dofs(mesh) / COARSE_DOFS) ** DOFS_EXPONENT


def format_duration(seconds: float) -> str:
    """``"0.3 s"``, ``"45 s"``, ``"12 min"``, ``"3.4 h"``, ``"2.1 days"``."""
    if seconds < 9.5:
        return f"{seconds:.1g} s"
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    if seconds < 2 * 86400:
        return f"{seconds / 3600:.1f} h"
    return f"{seconds / 86400:.1f} days"


def time_estimate(n_runs: float, mesh: str, workers: int = 1) -> float:
    """Rough wall time, s, of ``n_runs`` forward runs on ``mesh`` over ``workers`` processes."""
    return n_runs * forward_run_s(mesh) / max(1, workers)


def warn_if_long(
    command: str, n_runs: float, mesh: str, *, workers: int | None = 1, what: str = "", stream=None
) -> float:
    """Print one warning line on stderr when ``n_runs`` FE runs on ``mesh`` likely take more than an
    hour; return the estimate, s. ``workers`` None means one per core."""
    import os

    w = workers or os.cpu_count() or 1
    est = time_estimate(n_runs, mesh, w)
    if est > WARN_ABOVE_S:
        per = forward_run_s(mesh)
        print(
            f"femubench {command}: warning: {what or 'these settings'}: up to {n_runs:.0f} "
            f"forward run(s) on mesh {mesh} at ~{format_duration(per)} each on {w} worker(s) "
            f"take about {format_duration(est)} (rough estimate: {COARSE_RUN_S:g} s per coarse "
            f"run, scaled by solved dofs^{DOFS_EXPONENT:g})",
            file=stream or sys.stderr,
            flush=True,
        )
    return est

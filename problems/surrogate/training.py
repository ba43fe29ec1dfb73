"""Training runs of a forward model over a design, counted so that their cost can be charged.

Every point of the design is first checked (``model.check``, cheap, no run): infeasible points
are skipped and recorded with their reason. The feasible points go through a mapper in batches
(``mapper(fn, items) -> list``, e.g. a Dask mapper of :mod:`bench.parallel`), with a tqdm bar.
Runs that fail (``ok=False``, non-finite or wrongly shaped values, or the model raised) are
recorded and excluded from the snapshot matrix. The wall time of each run (measured where it
ran) is summed, so that the cost of a surrogate can be charged to the identifications using it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from problems.inverse.protocol import RunModel


@dataclass
class Runs:
    """The outcome of running a model over a set of points.

    X           : (n_ok, d) successful points, physical units
    Y           : (n_ok, m) their measurement vectors (units of the model)
    wall_s      : (n_ok,) wall time of each successful run, s
    failed      : list of ``(x, message)`` of runs that failed (ran, but ok=False)
    infeasible  : list of ``(x, reason)`` of points that ``check`` rejected (not run)
    fe_wall_s   : sum of the wall times of all runs, failed ones included, s (machine time)
    elapsed_s   : wall-clock time of the whole batch loop, s (elapsed, with the parallelism)
    """

    X: np.ndarray
    Y: np.ndarray
    wall_s: np.ndarray
    failed: list = field(default_factory=list)
    infeasible: list = field(default_factory=list)
    fe_wall_s: float = 0.0
    elapsed_s: float = 0.0

    @property
    def n_ok(self) -> int:
        return len(self.X)

    @property
    def n_failed(self) -> int:
        return len(self.failed)

    @property
    def n_infeasible(self) -> int:
        return len(self.infeasible)

    @property
    def n_runs(self) -> int:
        """Forward runs paid for: successful plus failed (infeasible points were not run)."""
        return self.n_ok + self.n_failed

    def cost(self) -> dict:
        """The counts and times, JSON-ready."""
        return {
            "n_runs": self.n_runs,
            "n_ok": self.n_ok,
            "n_failed": self.n_failed,
            "n_infeasible": self.n_infeasible,
            "fe_wall_s": float(self.fe_wall_s),
            "elapsed_s": float(self.elapsed_s),
            "median_run_s": float(np.median(self.wall_s)) if len(self.wall_s) else float("nan"),
        }

    def subset(self, index) -> "Runs":
        """The successful runs ``index`` (failures and infeasible points are not carried over)."""
        return Runs(self.X[index], self.Y[index], self.wall_s[index])


def run_points(
    model,
    X,
    *,
    mapper=None,
    batch: int = 16,
    progress: bool = False,
    desc: str = "runs",
    n_values: int | None = None,
) -> Runs:
    """Run ``model`` at the rows of ``X`` (physical units) through ``mapper`` in batches of
    ``batch``.

    n_values : expected length of a measurement vector (default: that of the first success)
    """
    from tqdm import tqdm

    from problems.inverse.evaluator import sequential_map

    X = np.atleast_2d(np.asarray(X, float))
    if batch < 1:
        raise ValueError(f"batch = {batch} is out of range: must be >= 1")
    mapper = mapper or sequential_map
    infeasible, feasible = [], []
    for x in X:
        reason = model.check(x)
        (feasible.append(x) if reason is None else infeasible.append((x, reason)))
    fn = RunModel(model)
    xs, ys, walls, failed, total = [], [], [], [], 0.0
    t0 = time.perf_counter()
    with tqdm(total=len(feasible), desc=desc, unit="run", disable=not progress) as bar:
        for i in range(0, len(feasible), batch):
            chunk = feasible[i : i + batch]
            for x, res in zip(chunk, mapper(fn, chunk)):
                total += float(res.wall_s)
                reason = _failure(res, n_values)
                if reason is not None:
                    failed.append((x, reason))
                    continue
                n_values = n_values or len(res.values)
                xs.append(x)
                ys.append(np.asarray(res.values, float))
                walls.append(float(res.wall_s))
            bar.update(len(chunk))
    d = X.shape[1]
    return Runs(
        np.array(xs).reshape(-1, d),
        np.array(ys).reshape(len(xs), -1) if ys else np.empty((0, n_values or 0)),
        np.array(walls),
        failed,
        infeasible,
        total,
        time.perf_counter() - t0,
    )


def _failure(res, n_values: int | None) -> str | None:
    if not res.ok:
        return res.message or "failed"
    v = np.asarray(res.values, float) if res.values is not None else None
    if v is None or v.ndim != 1 or (n_values and v.size != n_values):
        return f"values of shape {None if v is None else v.shape}, expected ({n_values},)"
    if not np.all(np.isfinite(v)):
        return "non-finite values"
    return None

r"""Hold-out validation of a surrogate against fresh runs of the model it stands for.

The hold-out points are a design drawn with a seed of their own: none of them is used in
training or in model selection. For each block ``b`` of the measurement vector (``u_h``, ``u_v``,
``displacement``, ``force``) and the errors ``e = U_surrogate(x) - U_model(x)`` over the successful
hold-out points:

* ``rms_sigma`` = sqrt(mean (e / sigma)^2), ``max_sigma`` = max |e / sigma|  (units of the noise);
* ``mean_abs`` = mean |e|, ``max_abs`` = max |e| in the block's unit (um for displacements, kN
  for the force).

``variance`` (m,) = mean over the hold-out points of e^2 per measurement (units of the measurement
squared): the surrogate's error variance that a likelihood adds to the noise variance.
The cost of one evaluation is measured in the same process: the median CPU time
(``time.process_time``) of one surrogate call (``__call__``, checks included, the measurement
vector; timed in groups of 20, the CPU clock's resolution), of one evaluation of the misfit
(``misfit_eval_s``: the cost path an objective takes, :mod:`problems.surrogate.misfit`, against a
hold-out run as data; and per point in a batch of 1000, ``misfit_batch_eval_s``) and of one plain
run of the model (after a warm-up run), and their ratios (``speed_ratio`` is the misfit's: one
surrogate evaluation of an objective against one FE run). CPU time, because the hold-out runs'
wall times on loaded workers mostly measure the wait for a core (they are kept as
``fe_worker_wall_s``). Without the model at hand the hold-out runs' median wall time stands in
for it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

#: display units of the FE measurement blocks: (label, factor from the model's unit)
FE_UNITS = {
    "u_h": ("um", 1e3),
    "u_v": ("um", 1e3),
    "displacement": ("um", 1e3),
    "force": ("kN", 1.0),
}


@dataclass
class Validation:
    """Hold-out errors and the cost of one evaluation (see the module docstring)."""

    n_points: int
    n_failed: int
    n_infeasible: int
    blocks: dict
    surrogate_eval_s: float
    surrogate_jacobian_s: float
    fe_eval_s: float
    n_extrapolated: int = 0
    variance: np.ndarray | None = field(default=None, repr=False)
    fe_worker_wall_s: float | None = None
    clock: str = "cpu"
    misfit_eval_s: float | None = None
    misfit_batch_eval_s: float | None = None

    @property
    def speed_ratio(self) -> float:
        """FE evaluation time over the time of one surrogate evaluation of an objective (the
        misfit's, else the call's)."""
        one = self.misfit_eval_s or self.surrogate_eval_s
        return self.fe_eval_s / one if one > 0 else float("inf")

    def summary(self) -> dict:
        """JSON-ready summary (the per-measurement variance is left out: it is stored as an
        array)."""
        return {
            "n_points": self.n_points,
            "n_failed": self.n_failed,
            "n_infeasible": self.n_infeasible,
            "n_extrapolated": self.n_extrapolated,
            "blocks": self.blocks,
            "surrogate_eval_s": self.surrogate_eval_s,
            "surrogate_jacobian_s": self.surrogate_jacobian_s,
            "misfit_eval_s": self.misfit_eval_s,
            "misfit_batch_eval_s": self.misfit_batch_eval_s,
            "fe_eval_s": self.fe_eval_s,
            "speed_ratio": self.speed_ratio,
            "clock": self.clock,
            "fe_worker_wall_s": self.fe_worker_wall_s,
        }

    def format(self) -> str:
        """A printable table."""
        return format_summary(self.summary())


def format_summary(s: dict) -> str:
    """The printable table of a validation summary (as stored in a model's JSON)."""
    lines = [
        f"hold-out validation: {s['n_points']} points ({s['n_failed']} failed, "
        f"{s['n_infeasible']} infeasible, {s['n_extrapolated']} extrapolated)",
        f"  {'block':>12} {'rms/sigma':>10} {'max/sigma':>10} {'mean |e|':>10} {'max |e|':>10}  "
        "unit",
    ]
    for name, b in s["blocks"].items():
        lines.append(
            f"  {name:>12} {b['rms_sigma']:10.3g} {b['max_sigma']:10.3g} {b['mean_abs']:10.3g} "
            f"{b['max_abs']:10.3g}  {b['unit']}"
        )
    misfit = s.get("misfit_eval_s")
    lines.append(
        f"  one evaluation: surrogate values {s['surrogate_eval_s'] * 1e3:.3g} ms (with Jacobian "
        f"{s['surrogate_jacobian_s'] * 1e3:.3g} ms)"
        + (
            f", misfit {misfit * 1e6:.3g} us (in a batch of 1000: "
            f"{s['misfit_batch_eval_s'] * 1e6:.3g} us a point)"
            if misfit
            else ""
        )
        + f"; model {s['fe_eval_s']:.3g} s: ratio {s['speed_ratio']:.3g} "
        f"({s.get('clock', 'wall')} time)"
    )
    return "\n".join(lines)


def cpu_per_call(fn, points, group: int = 20) -> float:
    """Median CPU time of one ``fn(x)`` over ``points``, timed in groups of ``group`` calls, s."""
    times = []
    for i in range(0, len(points), group):
        chunk = points[i : i + group]
        t0 = time.process_time()
        for x in chunk:
            fn(x)
        times.append((time.process_time() - t0) / len(chunk))
    return float(np.median(times))


def validate(
    surrogate,
    runs,
    sigma,
    blocks: dict[str, slice],
    units: dict | None = None,
    model=None,
    model_repeats: int = 3,
) -> Validation:
    """Compare ``surrogate`` with the successful hold-out ``runs``
    (:class:`~problems.surrogate.training.Runs`).

    sigma  : (m,) the data's standard deviations, units of the model
    blocks : named slices of the measurement vector
    units  : {block: (label, factor)} display units (default: the model's, factor 1)
    model  : the model the surrogate stands for, run ``model_repeats`` + 1 times in this process
             to time one plain run (None: the hold-out runs' median wall time)
    """
    if runs.n_ok == 0:
        raise ValueError("hold-out validation needs at least one successful hold-out run")
    sigma = np.broadcast_to(np.asarray(sigma, float), (runs.Y.shape[1],))
    units = units or {}
    pred, n_extra = [], 0
    for x in runs.X:
        res = surrogate(x)
        if not res.ok:
            raise ValueError(
                f"surrogate rejected a hold-out point the model accepted: {res.message}"
            )
        n_extra += res.message.startswith("extrapolation")
        pred.append(res.values)
    worker_wall = float(np.median(runs.wall_s))
    t = time_evaluations(surrogate, runs.X, runs.Y[0], sigma, model, model_repeats)
    if model is None:
        t["fe_eval_s"], t["clock"] = worker_wall, "wall (hold-out runs)"
    E = np.array(pred) - runs.Y
    out = {}
    for name, sl in blocks.items():
        e, s = E[:, sl], sigma[sl]
        label, factor = units.get(name, ("", 1.0))
        out[name] = {
            "rms_sigma": float(np.sqrt(np.mean((e / s) ** 2))),
            "max_sigma": float(np.max(np.abs(e / s))),
            "mean_abs": float(np.mean(np.abs(e)) * factor),
            "max_abs": float(np.max(np.abs(e)) * factor),
            "unit": label,
        }
    return Validation(
        runs.n_ok,
        runs.n_failed,
        runs.n_infeasible,
        out,
        t["surrogate_eval_s"],
        t["surrogate_jacobian_s"],
        t["fe_eval_s"],
        int(n_extra),
        np.mean(E**2, axis=0),
        worker_wall,
        t["clock"],
        t["misfit_eval_s"],
        t["misfit_batch_eval_s"],
    )


def time_evaluations(surrogate, points, data, sigma, model=None, model_repeats: int = 3) -> dict:
    """CPU times in this process, s: one surrogate call (``surrogate_eval_s``; with the Jacobian
    ``surrogate_jacobian_s``), one misfit evaluation against ``data`` with ``sigma`` on the
    surrogate's cost path (``misfit_eval_s``; per point in a batch of 1000,
    ``misfit_batch_eval_s``; None without a cost path), one plain run of ``model``
    (``fe_eval_s``, after a warm-up run; None without a model), at the physical ``points``;
    ``speed_ratio`` = FE over the misfit (else over the call), ``clock``."""
    points = np.atleast_2d(np.asarray(points, float))
    tiled = np.tile(points, (max(1, 1000 // len(points) + 1), 1))
    out = {
        "surrogate_eval_s": cpu_per_call(surrogate, tiled[:200]),
        "surrogate_jacobian_s": cpu_per_call(lambda x: surrogate(x, jacobian=True), points[:20]),
        "misfit_eval_s": None,
        "misfit_batch_eval_s": None,
        "fe_eval_s": None,
        "clock": "cpu",
    }
    if hasattr(surrogate, "misfit_of"):
        from problems.inverse.problem import LeastSquaresProblem

        mid = 0.5 * (surrogate.lower + surrogate.upper)
        problem = LeastSquaresProblem(
            surrogate,
            data,
            surrogate.lower,
            surrogate.upper,
            np.where(mid != 0, mid, 1.0),
            sigma=sigma,
        )
        misfit = surrogate.misfit_of(problem)
        misfit(tiled[:1])  # warm-up (compiled kernels)
        out["misfit_eval_s"] = cpu_per_call(misfit, tiled[:200])
        t0 = time.process_time()
        misfit(tiled[:1000])
        out["misfit_batch_eval_s"] = (time.process_time() - t0) / len(tiled[:1000])
    if model is not None:
        model(points[0])  # warm-up (compiled kernels, caches)
        out["fe_eval_s"] = cpu_per_call(model, points[1 : 1 + model_repeats], group=1)
    one = out["misfit_eval_s"] or out["surrogate_eval_s"]
    out["speed_ratio"] = out["fe_eval_s"] / one if out["fe_eval_s"] else None
    return out

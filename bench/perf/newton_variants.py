"""Would a line search or a better predictor save Newton iterations? (a benchmark, not a test)

    OMP_NUM_THREADS=1 python -m bench.perf.newton_variants [--mesh coarse] [--cases all]
    [--points 0] [--seed 0]

Per case (at its reference, then at ``--points`` seeded Latin-hypercube points of its box), the
default forward run (10 snapshots to 1.5 mm, FORWARD_SETTINGS) with three predictors of an
increment:

* ``tangent`` (production): the prescribed increment spread over the body by the tangent at the
  converged state, K_ff du_f = -K_fp du_p (one linear solve);
* ``extrapolated``: the previous increment's displacement increment scaled by the step ratio (no
  predictor solve);
* ``tangent+corr``: the tangent predictor plus the previous increment's nonlinear correction
  (its converged increment minus its own tangent predictor), scaled by the step ratio.

Printed per case and variant: linear solves (Newton iterations counted as in ``Response``),
material updates (residual evaluations, plus the one virgin tangent of a run), cuts and wall
seconds. The variants plug into the production Newton solver through its public predictor hook
(``problems.fe.newton.run(predictor=...)``). For a line search, from the
production runs' residual histories: the Newton steps whose residual did not fall (ratio >= 1,
where a backtracking line search would act at all) and the largest ratio r_{k+1}/r_k; where none
rises, a line search can only add residual evaluations.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from problems.fe.newton import run
from problems.inverse.cases import CASES
from problems.inverse.forward import FEForwardModel, case_material, discretisation


class VariantPredictor:
    """A :class:`problems.fe.newton.Predictor`: ``variant`` one of :data:`VARIANTS` (see the
    module docstring)."""

    def __init__(self, variant: str):
        self.variant = variant
        self._prev = None  # (du of the last converged increment, its predictor, its dtop)
        self._pending = (None, 0.0)  # (predictor, dtop) of the increment under way

    def predict(self, du, dtop_mm, tangent):
        if self.variant == "extrapolated" and self._prev is not None:
            self._pending = (None, dtop_mm)
            return self._prev[0] * (dtop_mm / self._prev[2]), ""
        du, why = tangent()
        self._pending = (du.copy(), dtop_mm)
        if not why and self.variant == "tangent+corr" and self._prev is not None:
            du_prev, pred_prev, dtop_prev = self._prev
            if pred_prev is not None:
                du = du + (du_prev - pred_prev) * (dtop_mm / dtop_prev)
        return du, why

    def converged(self, du) -> None:
        self._prev = (du.copy(), self._pending[0], self._pending[1])


class CountingMaterial:
    """``material`` with its ``update`` calls counted (material updates = residual
    evaluations)."""

    def __init__(self, material):
        self._material = material
        self.updates = 0

    def update(self, *args, **kw):
        self.updates += 1
        return self._material.update(*args, **kw)

    def __getattr__(self, name):
        return getattr(self._material, name)


def _run(model, x, variant):
    """One forward run of ``model`` at ``x`` with the predictor ``variant``: (response, material
    updates, wall s)."""
    material = CountingMaterial(case_material(model.case, x))
    predictor = None if variant == "tangent" else VariantPredictor(variant)
    t = time.perf_counter()
    disc = discretisation(model.mesh, model.specimen_mm)
    r = run(disc, material, model.loading, model.settings, predictor=predictor)
    return r, material.updates, time.perf_counter() - t


VARIANTS = ("tangent", "extrapolated", "tangent+corr")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--mesh", default="coarse")
    ap.add_argument("--cases", default="all")
    ap.add_argument("--points", type=int, default=0, help="box points per case besides the ref.")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    names = list(CASES) if args.cases == "all" else args.cases.split(",")
    print("per variant: linear solves / material updates / cuts / wall s (the runs of one point)")
    head = " ".join(f"{v:>24}" for v in VARIANTS)
    print(f"{'case':24} {'points':>6} {head}  rises  max ratio")
    totals = {v: np.zeros(4) for v in VARIANTS}
    _run(FEForwardModel(CASES[names[0]], args.mesh), CASES[names[0]].reference, "tangent")  # warm
    rises_all, steps_all, worst_all = 0, 0, 0.0
    for name in names:
        case = CASES[name]
        model = FEForwardModel(case, args.mesh)
        X = [case.reference]
        if args.points:
            X += [x for x in case.random_starts(args.points, seed=args.seed) if not model.check(x)]
        sums = {v: np.zeros(4) for v in VARIANTS}
        rises, steps, worst, used = 0, 0, 0.0, 0
        for x in X:
            runs = {v: _run(model, x, v) for v in VARIANTS}
            if not all(r.converged for r, _, _ in runs.values()):
                continue  # compare like with like
            used += 1
            for v, (r, upd, wall) in runs.items():
                sums[v] += (r.iterations, upd, r.cuts, wall)
            for h in runs["tangent"][0].residual_history:
                ratios = np.array(h[1:]) / np.array(h[:-1])
                rises += int(np.count_nonzero(ratios >= 1.0))
                steps += ratios.size
                worst = max(worst, float(ratios.max(initial=0.0)))
        for v in VARIANTS:
            totals[v] += sums[v]
        rises_all, steps_all = rises_all + rises, steps_all + steps
        worst_all = max(worst_all, worst)
        cells = " ".join(
            f"{'/'.join(str(int(c)) for c in sums[v][:3]) + f'/{sums[v][3]:.2f}':>24}"
            for v in VARIANTS
        )
        print(f"{name:24} {used:6d} {cells} {rises:6d} {worst:10.3g}", flush=True)
    print(
        "total: "
        + ", ".join(
            f"{v} {int(totals[v][0])} solves / {int(totals[v][1])} updates / {totals[v][3]:.2f} s"
            for v in VARIANTS
        )
        + f"; residual rises {rises_all} of {steps_all} Newton steps (largest ratio "
        f"{worst_all:.3g})"
    )


if __name__ == "__main__":
    main()

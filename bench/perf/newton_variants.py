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
material updates (residual evaluations), cuts and wall seconds. For a line search, from the
production runs' residual histories: the Newton steps whose residual did not fall (ratio >= 1,
where a backtracking line search would act at all) and the largest ratio r_{k+1}/r_k; where none
rises, a line search can only add residual evaluations.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import problems.fe.newton as fe_newton
from problems.fe.newton import _Increment, forcing_term
from problems.inverse.cases import CASES
from problems.inverse.forward import FEForwardModel


class _VariantNewton(fe_newton._Newton):
    """The production Newton with another predictor (see the module docstring)."""

    variant = "tangent"

    def __init__(self, *a, **kw):
        super().__init__(*a, **kw)
        self.material_updates = 0
        self._prev = None  # (du of the last converged increment, its predictor, its dtop)

    def increment(self, u_n, stress_n, state_n, D_n, dtop_mm):
        s, bc = self.settings, self.bc
        du = np.zeros_like(u_n)
        du[bc.top_z] = dtop_mm
        pred = None
        if self.variant == "extrapolated" and self._prev is not None:
            du = self._prev[0] * (dtop_mm / self._prev[2])
            corr = du[bc.free].copy()
        else:
            if D_n is None:
                D_n = self._virgin_tangent()
            Kff, rhs = self._predictor(D_n, du)
            corr, why = self._solve(Kff, rhs, D_n, fe_newton.ETA_PREDICTOR)
            self.iterations += 1
            if why:
                return _Increment(False, why)
            du[bc.free] += corr
            pred = du.copy()
            if self.variant == "tangent+corr" and self._prev is not None:
                du_prev, pred_prev, dtop_prev = self._prev
                if pred_prev is not None:
                    du += (du_prev - pred_prev) * (dtop_mm / dtop_prev)
        norms = []
        for _ in range(s.max_iterations):
            deps = self._strain(du)
            upd = self.material.update(deps, stress_n, state_n)
            self.material_updates += 1
            if not np.all(upd.ok):
                return _Increment(False, "material return mapping failed")
            f_int = self._internal_force(upd.stress)
            r_free = f_int[bc.free]
            scale = max(np.linalg.norm(f_int[bc.fixed]), 1e-30)
            rel_r = np.linalg.norm(r_free) / scale
            rel_u = np.linalg.norm(corr) / max(np.linalg.norm(du), 1e-30)
            norms.append(rel_r)
            if not np.isfinite(rel_r):
                return _Increment(False, "residual is not finite")
            if rel_r <= s.rtol_force * (1.0 if rel_u <= s.rtol_displacement else s.linear_rtol):
                self.residual_history.append(norms)
                self._prev = (du.copy(), pred, dtop_mm)
                return self._converged(
                    u=u_n + du,
                    stress=upd.stress,
                    state=upd.state,
                    tangent=upd.tangent,
                    f_int=f_int,
                    strain_increment=deps,
                )
            corr, why = self._solve(
                self._tangent_free(upd.tangent), -r_free, upd.tangent, forcing_term(rel_r, s)
            )
            self.iterations += 1
            if why or not np.all(np.isfinite(corr)):
                return _Increment(False, why or "non-finite correction")
            du[bc.free] += corr
        return _Increment(False, "no convergence")


def _run(model, x, variant):
    """One forward run with the predictor ``variant``: (response, material updates, wall s)."""
    made = []

    class Newton(_VariantNewton):
        def __init__(self, *a, **kw):
            super().__init__(*a, **kw)
            self.variant = variant
            made.append(self)

    saved = fe_newton._Newton
    fe_newton._Newton = Newton
    try:
        t = time.perf_counter()
        r = model.response(x)
        wall = time.perf_counter() - t
    finally:
        fe_newton._Newton = saved
    return r, made[0].material_updates, wall


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

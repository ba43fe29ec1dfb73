"""Accuracy and cost of the exact (DDM) Jacobians of the FE forward model (not a test).

    OMP_NUM_THREADS=1 python -m bench.perf.jacobian [--meshes coarse,paper] [--cases all|NAME,...]
                      [--paper-cases linear-compression,hyperbolic-shear,exponent-tension]
                      [--modes auto|direct,krylov|auto,auto-2pass|auto,auto-f64|auto-keep,auto]
                      [--repeat 2] [--step 1e-5] [--no-fd]

Per mesh and case, at the case's reference: the best of ``--repeat`` plain forward evaluations
``model(x)`` and of evaluations with the Jacobian ``model(x, jacobian=True)`` (response + dU/dx,
6 identified parameters), alternated so that both see the same machine load, and their ratio
(``cost``, wall time: the target is <= 1.6; ``cpu``: the same ratio of this process's CPU times,
steadier when other processes share the cores); where the sensitivity time went (material: the
material pass(es) per increment and the affine update; assem: pseudo-loads, strains,
internal-force sensitivities and converged tangents; solve: factorisations + back-substitutions
or Krylov iterations, ``its``; ``ref``: refinement steps of the mixed-precision direct solves
above ``mixed_min_dofs`` free dofs); then, unless ``--no-fd``, the largest relative 2-norm
error of a Jacobian column against central differences of plain runs with relative step
``--step`` (default 1e-5) and the parameter it belongs to, and the same with a step 100 times
smaller (``err/100``): where a Gauss point starts to yield within the first step of the reference
(a kink of the discrete response: the one-sided differences converge to the DDM column from one
side only), the smaller step is in the clean range again.
``--modes direct,krylov`` times each sensitivity solve mode of problems/fe/ddm.py (the
measured choice behind ``auto``); ``--modes auto,auto-2pass`` the one material pass per increment
against the two ``sensitivity`` calls of the first implementation; ``--modes auto,auto-f64`` the
direct solves with a double LU at every size against the default (``-f32``: mixed precision at
every size; the measured choice behind ``mixed_min_dofs``); ``--modes auto-keep,auto`` without
and with the hand-over of that factorisation to the next increment's Newton predictor
(``hand_over``). Each mode is a :class:`~problems.fe.ddm.SensitivitySettings` of the
model's Newton settings. ``coarse`` runs all nine
cases, ``paper`` only ``--paper-cases``.
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np

from bench.perf.linear_solvers import split_specs
from problems.fe.ddm import SOLVE_MODES, SensitivitySettings
from problems.inverse.cases import CASES
from problems.inverse.forward import FEForwardModel, discretisation

PAPER_CASES = "linear-compression,hyperbolic-shear,exponent-tension"

#: ``--modes`` values, as sensitivity settings: the ``-2pass`` variants time the two
#: ``sensitivity`` calls per increment of the first implementation, ``-f64`` direct solves with a
#: double LU whatever the size, ``-f32`` with the single-precision LU and refinement whatever the
#: size, ``-keep`` without handing the direct solves' factorisation to the next increment's Newton
#: predictor
MODES = {
    **{m: SensitivitySettings(mode=m) for m in SOLVE_MODES},
    **{f"{m}-2pass": SensitivitySettings(mode=m, affine=False) for m in SOLVE_MODES},
    **{f"{m}-f64": SensitivitySettings(mode=m, mixed_min_dofs=2**62) for m in ("auto", "direct")},
    **{f"{m}-f32": SensitivitySettings(mode=m, mixed_min_dofs=0) for m in ("auto", "direct")},
    **{f"{m}-keep": SensitivitySettings(mode=m, hand_over=False) for m in ("auto", "direct")},
}


def with_mode(model: FEForwardModel, mode: str) -> FEForwardModel:
    """``model`` with the sensitivity settings of ``--modes`` value ``mode``."""
    return dataclasses.replace(
        model, settings=dataclasses.replace(model.settings, sensitivity=MODES[mode])
    )


def timed(fn):
    """(wall s, CPU s of this process, fn())."""
    t, c = time.perf_counter(), time.process_time()
    out = fn()
    return time.perf_counter() - t, time.process_time() - c, out


def measure(mesh: str, name: str, modes, repeat: int, step: float | None) -> list[str]:
    case = CASES[name]
    model = FEForwardModel(case, mesh)
    x = case.reference
    FEForwardModel(case, "1,1,2")(x, jacobian=True)  # compiled kernels loaded outside the timings
    best_plain, best = np.inf, {m: np.inf for m in modes}
    cpu_plain, cpu = np.inf, {m: np.inf for m in modes}
    out = {}
    models = {mode: with_mode(model, mode) for mode in modes}
    for _ in range(repeat):
        t, c, plain = timed(lambda: model(x))
        best_plain, cpu_plain = min(best_plain, t), min(cpu_plain, c)
        for mode in modes:
            t, c, res = timed(lambda: models[mode](x, jacobian=True))
            best[mode], cpu[mode] = min(best[mode], t), min(cpu[mode], c)
            out[mode] = res
    if not plain.ok or any(not r.ok or r.jacobian is None for r in out.values()):
        return [f"{mesh:8} {name:22} failed: {plain.message or next(iter(out.values())).message}"]
    err, worst, err_small = np.nan, "", np.nan
    if step:
        J = out[modes[0]].jacobian
        errs = {s: [] for s in (step, step / 100.0)}
        for s in errs:
            for j in range(len(x)):
                h = s * abs(x[j])
                xp, xm = x.copy(), x.copy()
                xp[j] += h
                xm[j] -= h
                g = (model(xp).values - model(xm).values) / (2.0 * h)
                errs[s].append(np.linalg.norm(J[:, j] - g) / np.linalg.norm(g))
        err, err_small = max(errs[step]), max(errs[step / 100.0])
        worst = case.names[int(np.argmax(errs[step]))]
    rows = []  # the split of the sensitivity time: one more run per mode
    for mode in modes:
        m = models[mode]
        tm = m.response(x, sensitivities=m.material_chain(x)[0]).sensitivities.timing
        solve = tm["factor_s"] + tm["solve_s"]
        rows.append(
            f"{mesh:8} {3 * discretisation(mesh).mesh.n_nodes:>6} {name:22} {mode:9} "
            f"{best_plain:7.3f} {best[mode]:7.3f} {best[mode] / best_plain:5.2f} "
            f"{cpu[mode] / cpu_plain:5.2f} "
            f"{tm['material_s']:6.3f} {tm['assembly_s']:6.3f} {solve:6.3f} "
            f"{tm['krylov_iterations']:5d} {tm['refinements']:3d} {err:9.1e} {worst:>7} "
            f"{err_small:9.1e}"
        )
    return rows


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--meshes", default="coarse,paper")
    ap.add_argument(
        "--cases", default="all", help="cases on every mesh but paper: all | comma-separated names"
    )
    ap.add_argument(
        "--paper-cases", default=PAPER_CASES, help="cases on paper (comma-separated, or all)"
    )
    ap.add_argument(
        "--modes",
        default="auto",
        help="sensitivity paths to time (comma-separated): auto, direct, krylov, or one of them "
        "with -2pass (two material calls per increment); auto or direct with -f64 (double LU at "
        "every size), -f32 (mixed precision at every size) or -keep (no hand-over of the factor to "
        "the Newton predictor)",
    )
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--step", type=float, default=1e-5, help="relative central-difference step")
    ap.add_argument("--no-fd", action="store_true", help="skip the central differences")
    args = ap.parse_args(argv)
    modes = args.modes.split(",")
    for m in modes:
        if m not in MODES:
            raise SystemExit(f"mode {m!r} is unknown; allowed: {', '.join(MODES)}")
    print(
        f"{'mesh':8} {'dofs':>6} {'case':22} {'mode':9} {'plain s':>7} {'jac s':>7} {'cost':>5} "
        f"{'cpu':>5} "
        f"{'mater':>6} {'assem':>6} {'solve':>6} {'its':>5} {'ref':>3} {'max err':>9} {'worst':>7} "
        f"{'err/100':>9}",
        flush=True,
    )
    for mesh in split_specs(args.meshes):  # NX,NY,NZ specs stay whole
        spec = args.paper_cases if mesh.split(":")[0] == "paper" else args.cases
        names = list(CASES) if spec == "all" else spec.split(",")
        for name in names:
            if name not in CASES:
                raise SystemExit(f"case {name!r} is unknown; allowed: {', '.join(CASES)}")
            for row in measure(mesh, name, modes, args.repeat, None if args.no_fd else args.step):
                print(row, flush=True)


if __name__ == "__main__":
    main()

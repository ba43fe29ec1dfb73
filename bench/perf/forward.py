"""Benchmark of one complete forward run (not a test): DOFs, wall time, where the time goes, and
the speed-up over the old code path measured in the same run.

    OMP_NUM_THREADS=1 python -m bench.perf.forward [--meshes coarse,paper] [--cases
    linear-compression|all|elastic|NAME,...]
                                                   [--repeat 3] [--no-baseline]

Per mesh spec (``MESH[:eighth|quarter]``: ``coarse`` solves the eighth model, ``coarse:quarter``
the whole height) and material, the best of ``--repeat`` runs of the default 10-snapshot test
(1.5 mm, friction plates, FORWARD_SETTINGS: rtol 1e-10) with the production settings (fused
assembly, ``linear_solver="auto"``), split into assembly (tangent, internal force, strain),
material update, factorisation and solve (Krylov iterations in ``kryl``); then, unless
``--no-baseline``, the old code path on the same input (SuperLU per Newton iteration + numpy
assembly: ``NewtonSettings(linear_solver="superlu", assembly="numpy")``), its best wall time,
the speed-up old / new and the largest relative difference of the plate forces. The runs of the
two paths alternate, so both see the same machine load. Run it with ``OMP_NUM_THREADS=1`` for
one-core figures.

Where the ``crosscheck`` extra (openseespy) is installed (or with ``--opensees yes``), each mesh
also gets the same run in OpenSees: the quarter model of the same mesh (``bbarBrick``, same nodes,
``nDMaterial DruckerPrager``) with the linear form OpenSees has (K = 1) at the cross-check's
reference with psi = 15 deg (``bench/crosscheck``), friction plates, 1.5 mm in 10 snapshots, the
strategy that converges there (Newton with 5x smaller steps: its baseline of 10 steps diverges,
``docs/crosscheck_opensees.md``), against femubench's default run of the same material on this
mesh spec; printed: both wall times, the ratio OpenSees / femubench, and the largest relative
difference of the plate forces (OpenSees integrates in 5x smaller increments, so the two answers
differ by the step size, ~0.5 %; at equal increments they agree to the solvers' tolerances,
``femubench crosscheck``). Give ``MESH:quarter`` to compare the same quarter model.
``--opensees no`` skips it (on ``coarse`` OpenSees takes minutes, on ``paper`` far longer).
"""

from __future__ import annotations

import argparse
import dataclasses
import re
import time

import numpy as np

from problems.fe.mesh import parse_mesh_spec
from problems.fe.newton import Loading, discretise, run
from problems.inverse.cases import CASES
from problems.inverse.forward import FORWARD_SETTINGS, case_material
from problems.materials import LinearElastic


def split_specs(text: str) -> list[str]:
    """Mesh specs of a comma-separated list; ``NX,NY,NZ`` triples (optionally ``:symmetry``) stay
    whole."""
    specs = re.findall(r"\d+\s*,\s*\d+\s*,\s*\d+(?::\w+)?|[A-Za-z]\w*(?::\w+)?", text)
    if not specs:
        raise SystemExit(f"no mesh spec in {text!r}")
    return specs


#: the code path before the fused assembly and the CHOLMOD-preconditioned Krylov solver
BASELINE = dict(linear_solver="superlu", assembly="numpy")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--meshes", default="coarse,paper")
    ap.add_argument(
        "--cases", default="linear-compression", help="all | elastic | comma-separated case names"
    )
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-baseline", action="store_true", help="skip the old code path")
    ap.add_argument(
        "--opensees",
        choices=("auto", "yes", "no"),
        default="auto",
        help="the same run in OpenSees (auto: where openseespy is installed)",
    )
    args = ap.parse_args(argv)
    if args.opensees == "auto":
        from bench.crosscheck.loader import installed

        args.opensees = "yes" if installed() else "no"
    names = ["elastic"] + list(CASES) if args.cases == "all" else args.cases.split(",")
    for name in names:
        if name != "elastic" and name not in CASES:
            raise SystemExit(f"case {name!r} is unknown; allowed: elastic, all, {', '.join(CASES)}")
    new_settings = FORWARD_SETTINGS
    old_settings = dataclasses.replace(FORWARD_SETTINGS, **BASELINE)
    head = (
        f"{'mesh':14} {'dofs':>6} {'material':20} {'ok':>3} {'incr':>4} {'iter':>4} {'kryl':>5} "
        f"{'fact':>4} {'wall s':>7} {'assem':>6} {'mater':>6} {'factor':>6} {'solve':>6} "
        f"{'F kN':>8}"
    )
    if not args.no_baseline:
        head += f" | {'old s':>7} {'speed-up':>8} {'max dF/F':>8}"
    print(head)
    for spec in split_specs(args.meshes):
        t = time.perf_counter()
        ms = parse_mesh_spec(spec)
        disc = discretise(ms.mesh, symmetry=ms.symmetry)
        setup = time.perf_counter() - t
        for name in names:
            mat = (
                LinearElastic()
                if name == "elastic"
                else case_material(CASES[name], CASES[name].reference)
            )
            best = {}
            for _ in range(args.repeat):
                for key, settings in (("new", new_settings), ("old", old_settings)):
                    if key == "old" and args.no_baseline:
                        continue
                    r = run(disc, mat, Loading(), settings)
                    if key not in best or r.wall_s < best[key].wall_s:
                        best[key] = r
            r = best["new"]
            tm = r.timing
            line = (
                f"{spec:14} {disc.mesh.n_dofs:6d} {name:20} {'yes' if r.converged else 'NO':>3} "
                f"{r.increments:4d} {r.iterations:4d} {tm['krylov_iterations']:5d} "
                f"{tm['factorisations']:4d} {r.wall_s:7.3f} {tm['assembly_s']:6.3f} "
                f"{tm['material_s']:6.3f} {tm['factor_s']:6.3f} {tm['solve_s']:6.3f} "
                f"{r.reaction_kN[-1] if len(r.reaction_kN) else float('nan'):8.2f}"
            )
            if "old" in best:
                o = best["old"]
                same = len(o.reaction_kN) == len(r.reaction_kN) and len(r.reaction_kN) > 0
                dF = np.max(np.abs(r.reaction_kN / o.reaction_kN - 1.0)) if same else float("nan")
                line += f" | {o.wall_s:7.3f} {o.wall_s / r.wall_s:8.2f} {dF:8.1e}"
            print(line, flush=True)
        print(f"{spec:14} setup (B-bar, sparsity pattern): {setup:.3f} s")
        if args.opensees == "yes":
            print(opensees_line(spec, disc, args.repeat), flush=True)


def opensees_line(spec: str, disc, repeat: int) -> str:
    """The same run in OpenSees and in femubench on the mesh of ``disc`` (see the module
    docstring), as one printed line."""
    from bench.crosscheck.mapping import REFERENCE, opensees_parameters
    from bench.crosscheck.opensees_box import CURES, opensees_box
    from bench.crosscheck.reference import DELTA_MM, femubench_material, mapped

    p = {**REFERENCE, "psi": 15.0}
    mat = femubench_material(p)
    ours = min(
        (run(disc, mat, Loading(), FORWARD_SETTINGS) for _ in range(repeat)), key=lambda r: r.wall_s
    )
    strategy = next(c for c in CURES if c.substeps == 5)
    theirs = opensees_box(
        disc.full_mesh,
        opensees_parameters(**mapped(p)),
        DELTA_MM,
        10,
        "friction",
        strategy=strategy,
    )
    n = min(len(theirs.reaction_kN), len(ours.reaction_kN))
    dF = np.max(np.abs(theirs.reaction_kN[:n] / ours.reaction_kN[:n] - 1.0)) if n else float("nan")
    return (
        f"{spec:14} OpenSees, same mesh (quarter), linear DP K = 1, psi = 15: "
        f"{'converged' if theirs.converged else 'FAILED'} ({strategy.name}, "
        f"{sum(theirs.step_iterations)} iterations) in {theirs.wall_s:.2f} s; femubench "
        f"{ours.wall_s:.3f} s ({ours.iterations} iterations): OpenSees / femubench = "
        f"{theirs.wall_s / ours.wall_s:.1f}; max dF/F {dF:.1e} over {n} snapshots"
    )


if __name__ == "__main__":
    main()

"""Benchmark of one complete forward run (not a test): DOFs, wall time and where the time goes.

    python -m bench.perf.forward [--meshes coarse,paper] [--cases all|elastic|NAME,...] [--repeat 3]

Prints, per mesh and material, the best of ``--repeat`` runs of the default 10-snapshot test
(1.5 mm, friction plates) split into assembly, material update and linear solve. Run it with
``OMP_NUM_THREADS=1`` for one-core figures.
"""
from __future__ import annotations

import argparse
import time

from problems.inverse.cases import CASES
from problems.fe.newton import Loading, discretise, run
from problems.inverse.forward import FORWARD_SETTINGS, case_material
from problems.materials import LinearElastic
from problems.fe.mesh import parse_mesh_spec


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--meshes", default="coarse,paper")
    ap.add_argument("--cases", default="all", help="all | elastic | comma-separated case names")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    names = list(CASES) if args.cases == "all" else args.cases.split(",")
    print(f"{'mesh':8} {'dofs':>7} {'material':24} {'ok':>3} {'incr':>4} {'iter':>4} {'cuts':>4} "
          f"{'wall s':>8} {'assem s':>8} {'mater s':>8} {'solve s':>8} {'F kN':>9}")
    for spec in args.meshes.split(","):
        t = time.perf_counter()
        ms = parse_mesh_spec(spec)  # "coarse" solves the eighth model, "coarse:quarter" the whole height
        disc = discretise(ms.mesh, symmetry=ms.symmetry)
        setup = time.perf_counter() - t
        for name in ["elastic"] + [n for n in names if n != "elastic"] if args.cases == "all" else names:
            mat = LinearElastic() if name == "elastic" else case_material(CASES[name], CASES[name].reference)
            best = min((run(disc, mat, Loading(), FORWARD_SETTINGS) for _ in range(args.repeat)), key=lambda r: r.wall_s)
            tm = best.timing
            print(f"{spec:8} {disc.mesh.n_dofs:7d} {name:24} {'yes' if best.converged else 'NO':>3} {best.increments:4d} "
                  f"{best.iterations:4d} {best.cuts:4d} {best.wall_s:8.3f} {tm['assembly_s']:8.3f} "
                  f"{tm['material_s']:8.3f} {tm['solve_s']:8.3f} {best.reaction_kN[-1] if len(best.reaction_kN) else float('nan'):9.2f}")
        print(f"{spec:8} setup (B-bar, sparsity pattern): {setup:.3f} s")


if __name__ == "__main__":
    main()

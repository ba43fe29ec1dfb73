"""Cost of the candidate inverse meshes of issue 25 (not a test): forward run and response + exact
Jacobian, as ratios to the ``coarse`` 8-node baseline measured in the same run.

    OMP_NUM_THREADS=1 nice python -m bench.perf.inverse_meshes
        [--meshes "3,3,6:g4:hex27,4,4,8:g4:hex27,...,coarse,6,6,12:g4"]
        [--cases linear-compression,hyperbolic-shear,exponent-tension] [--repeat 3] [--out PATH]

Per mesh (``dofs``: of the quarter mesh, whose lower half the eighth model solves) and case, at
the case's reference parameters: the CPU time of this process (best of
``--repeat``; CPU rather than wall time because the cores are shared) of the plain forward
evaluation ``FEForwardModel(case, mesh)(x)`` (1.5 mm in 10 snapshots, the default loading and
Newton settings: what one evaluation of the inverse loop costs) and of ``model(x, jacobian=True)``
(response + exact DDM Jacobian of the identified parameters), the two alternating so both see
the same load; ``J/run`` their ratio; ``x coarse`` the plain run's and ``J x coarse`` the
Jacobian run's time divided by those of ``coarse`` (6 x 6 x 12 uniform 8-node, eighth model) for
the same case in this run; Newton iterations and factorisations of the plain run (``spd``: of them
CHOLMOD factors of the positive definite substitute, problems/fe/newton.py ``positive_part``).
Issue 25's targets for the default inverse model: a forward run <= 1.5 s on one idle core and
response + Jacobian <= 1.6 runs; the last table gives each mesh's worst case against them.
``--out`` also writes the printed text there (atomically).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from bench.perf.jacobian import PAPER_CASES
from bench.perf.linear_solvers import split_specs
from problems.inverse.cases import CASES
from problems.inverse.forward import FEForwardModel, discretisation
from problems.io.atomic import atomic_write_text

MESHES = (
    "3,3,6:g4:hex27,4,4,8:g4:hex27,4,4,8:g8:hex27,5,5,10:g4:hex27,5,5,10:g8:hex27,"
    "6,6,12:g8:hex27,coarse,6,6,12:g4"
)
BASELINE = "coarse"
RUN_TARGET_S, JACOBIAN_TARGET = 1.5, 1.6


def cpu(fn):
    """(CPU s of this process, fn())."""
    c = time.process_time()
    out = fn()
    return time.process_time() - c, out


def measure(mesh: str, name: str, repeat: int) -> dict:
    """Best CPU seconds of a plain and of a Jacobian evaluation of ``name`` on ``mesh`` at the
    case's reference, with the plain run's Newton counters."""
    case = CASES[name]
    model = FEForwardModel(case, mesh)
    x = case.reference
    model(x)  # the discretisation (built once per process) outside the timings
    run_s, jac_s = np.inf, np.inf
    for _ in range(repeat):
        c, plain = cpu(lambda: model(x))
        run_s = min(run_s, c)
        c, full = cpu(lambda: model(x, jacobian=True))
        jac_s = min(jac_s, c)
        if not (plain.ok and full.ok and full.jacobian is not None):
            raise SystemExit(f"{mesh} {name}: {plain.message or full.message}")
    r = model.response(x)
    return {
        "mesh": mesh,
        "case": name,
        "dofs": 3 * discretisation(mesh).full_mesh.n_nodes,
        "run_s": run_s,
        "jac_s": jac_s,
        "iterations": r.iterations,
        "factorisations": r.timing["factorisations"],
        "spd": r.timing["spd_substitutes"],
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--meshes", default=MESHES, help="comma-separated mesh specs")
    ap.add_argument("--cases", default=PAPER_CASES, help="comma-separated case names")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", type=Path, help="also write the printed text here")
    args = ap.parse_args(argv)
    meshes = split_specs(args.meshes)
    names = args.cases.split(",")
    for name in names:
        if name not in CASES:
            print(f"--cases: case {name!r} is unknown; allowed: {', '.join(CASES)}")
            return 2
    if args.repeat < 1:
        print(f"--repeat {args.repeat}: a whole number >= 1")
        return 2
    if BASELINE not in meshes:
        meshes.append(BASELINE)
    lines: list[str] = []

    def say(text=""):
        print(text, flush=True)
        lines.append(text)

    FEForwardModel(CASES[names[0]], "1,1,2")(CASES[names[0]].reference, jacobian=True)  # compile
    say(f"CPU s, best of {args.repeat}; ratios to {BASELINE} of the same case in this run")
    say(
        f"{'mesh':16} {'dofs':>6} {'case':22} {'run s':>7} {'run+J s':>8} {'J/run':>6} "
        f"{'x coarse':>8} {'J x coarse':>10} {'its':>4} {'fact':>4} {'spd':>3}"
    )
    rows = {(m, n): measure(m, n, args.repeat) for n in names for m in meshes}
    for m in meshes:
        for n in names:
            r, b = rows[m, n], rows[BASELINE, n]
            say(
                f"{m:16} {r['dofs']:>6} {n:22} {r['run_s']:7.2f} {r['jac_s']:8.2f} "
                f"{r['jac_s'] / r['run_s']:6.2f} {r['run_s'] / b['run_s']:8.2f} "
                f"{r['jac_s'] / b['jac_s']:10.2f} {r['iterations']:>4} {r['factorisations']:>4} "
                f"{r['spd']:>3}"
            )
    say()
    say(
        f"worst case per mesh (targets: run <= {RUN_TARGET_S} s on one idle core, "
        f"run+J <= {JACOBIAN_TARGET} runs)"
    )
    say(f"{'mesh':16} {'run s':>7} {'x coarse':>8} {'J/run':>6}  meets both")
    for m in meshes:
        rs = [rows[m, n] for n in names]
        run_s = max(r["run_s"] for r in rs)
        ratio = max(r["run_s"] / rows[BASELINE, r["case"]]["run_s"] for r in rs)
        jr = max(r["jac_s"] / r["run_s"] for r in rs)
        ok = run_s <= RUN_TARGET_S and jr <= JACOBIAN_TARGET
        say(f"{m:16} {run_s:7.2f} {ratio:8.2f} {jr:6.2f}  {'yes' if ok else 'no'}")
    if args.out:
        atomic_write_text(args.out, "\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

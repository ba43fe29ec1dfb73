"""Benchmark of the linear solvers on real Newton tangents (not a test).

    OMP_NUM_THREADS=1 python -m bench.perf.linear_solvers [--meshes paper,paper:quarter,fine]
    [--case linear-compression] [--repeat 3]

For each mesh spec (``MESH[:eighth|quarter]``, see ``problems.fe.mesh.parse_mesh_spec``) the
forward model runs the default test (10 snapshots to 1.5 mm, friction plates) with the case at its
reference; a hook keeps the tangents of the last increment (plastic everywhere): the predictor's
tangent (the converged state of snapshot 9) and the tangent of the last Newton correction. On
the free-free block of the last correction tangent, in nested-dissection order, it times
(best of ``--repeat``):

* ``superlu``   SuperLU (scipy), ND order kept, diagonal pivoting: today's reference, exact;
* ``umfpack``   UMFPACK (kvxopt), symbolic analysis once, numeric factorisation per matrix, exact;
* ``chol-sym``  CHOLMOD (kvxopt) of the symmetric part, symbolic once (ND order), preconditioning
                GMRES on the exact non-symmetric tangent ("fresh": factor of this tangent;
                "reused": factor of the predictor tangent, i.e. of the previous converged state;
                "elastic": factor of the elastic stiffness);
* ``pyamg``     smoothed-aggregation AMG of the symmetric part (pyamg, when installed) as GMRES
                preconditioner;
* ``pardiso``   MKL PARDISO, structurally symmetric LU (pypardiso, when installed).

Columns: ``setup`` (once per pattern), ``factor`` (per matrix), ``solve`` of one right-hand side to
a relative residual of 1e-12 (exact for direct solvers; GMRES iterations ``its``) and to 1e-6
(a typical Newton forcing term), ``7 rhs`` (seven right-hand sides at once to 1e-12, the
sensitivity use), and the ratios of SuperLU's factor + solve to the method's, for one and for
seven right-hand sides, measured in the same run. Times in seconds, one core when run with
``OMP_NUM_THREADS=1``.
"""

from __future__ import annotations

import argparse
import dataclasses
import re
import time

import numpy as np

from problems.fe import newton as nw
from problems.fe.linear_solver import CholmodGmresSolver, cholmod_available, gmres, superlu_factor
from problems.fe.mesh import parse_mesh_spec
from problems.inverse.cases import CASES
from problems.inverse.forward import FORWARD_SETTINGS, case_material


def split_specs(text: str) -> list[str]:
    """Mesh specs of a comma-separated list; ``NX,NY,NZ`` triples and their ``:TOKEN`` suffixes
    (symmetry, grading ``gR``, element) stay whole."""
    specs = re.findall(r"\d+\s*,\s*\d+\s*,\s*\d+(?::[\w.]+)*|[A-Za-z]\w*(?::[\w.]+)*", text)
    if not specs:
        raise SystemExit(f"no mesh spec in {text!r}")
    return specs


def last_increment_tangents(settings):
    """``(settings with the hook, kept)``: the Newton settings whose ``on_linear_solve`` hook keeps
    the (K_ff, rhs) of every solve of the last increment in ``kept["solves"]`` (a predictor starts
    an increment)."""
    kept: dict = {"solves": []}

    def keep(kind, Kff, rhs):
        if kind == "predictor":
            kept["solves"] = []
        kept["solves"].append((Kff.copy(), rhs.copy()))

    return dataclasses.replace(settings, on_linear_solve=keep), kept


def best(f, repeat):
    """Smallest wall time of ``repeat`` calls of f, and the last result."""
    ts, out = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        out = f()
        ts.append(time.perf_counter() - t)
    return min(ts), out


def _krylov(A, psolve, b, rtol):
    x, its, ok = gmres(A.dot, psolve, b, rtol, maxiter=400)
    res = np.linalg.norm(A @ x - b) / np.linalg.norm(b)
    return its if ok else -its, res


def measure(spec: str, case: str, repeat: int) -> list[tuple]:
    ms = parse_mesh_spec(spec)
    disc = nw.discretise(ms.mesh, symmetry=ms.symmetry)
    mat = case_material(CASES[case], CASES[case].reference)
    settings, kept = last_increment_tangents(FORWARD_SETTINGS)
    r = nw.run(disc, mat, nw.Loading(), settings)
    if not r.converged:
        raise SystemExit(f"{spec}: the forward run failed: {r.message}")
    bc = nw.BoundaryConditions(disc, nw.Loading().plates)
    A = kept["solves"][-1][0]  # last correction: the most plastic tangent
    A_pred = kept["solves"][0][0]  # predictor: converged state of the previous snapshot
    A.sort_indices()
    A_pred.sort_indices()
    n = A.shape[0]
    perm = bc.elimination_order
    pos = np.full(disc.pattern.n_dofs, -1)
    pos[bc.free] = np.arange(len(bc.free))
    b = kept["solves"][-2][1][pos[perm]] if len(kept["solves"]) > 1 else np.ones(n)
    B7 = np.random.default_rng(0).standard_normal((n, 7))
    asym = abs(A - A.T).max() / abs(A).max()
    print(
        f"\n{spec}: {n} free dofs, nnz {A.nnz}, max|K - K^T| / max|K| = {asym:.2g}, "
        f"{r.iterations} Newton solves in the run"
    )
    rows = []

    # --- SuperLU (today)
    t_f, lu = best(lambda: superlu_factor(A), repeat)
    t_1, _ = best(lambda: lu.solve(b), repeat)
    t_7, _ = best(lambda: lu.solve(B7), repeat)
    rows.append(("superlu", 0.0, t_f, t_1, 0, t_1, 0, t_7))
    ref1, ref7 = t_f + t_1, t_f + t_7

    # --- UMFPACK (kvxopt)
    if cholmod_available():
        import kvxopt
        import kvxopt.umfpack as umf

        cols = np.repeat(np.arange(n), np.diff(A.indptr))
        Ak = kvxopt.spmatrix(A.data, A.indices.astype(int), cols.astype(int), (n, n))
        t_s, Fs = best(lambda: umf.symbolic(Ak), 1)
        t_f, Fn = best(lambda: umf.numeric(Ak, Fs), repeat)

        def usolve(R):
            X = kvxopt.matrix(np.asfortranarray(R))
            umf.solve(Ak, Fn, X)
            return X

        t_1, _ = best(lambda: usolve(b), repeat)
        t_7, _ = best(lambda: usolve(B7), repeat)
        rows.append(("umfpack", t_s, t_f, t_1, 0, t_1, 0, t_7))

        # --- CHOLMOD of the symmetric part + GMRES
        solver = CholmodGmresSolver()
        t_s, _ = best(lambda: solver.factorise(A), 1)  # first call: symbolic analysis + numeric
        for label, M in (
            ("chol-sym fresh", A),
            ("chol-sym reused", A_pred),
            ("chol-sym elastic", None),
        ):
            if M is None:  # the virgin (elastic) tangent
                D0 = mat.update(np.zeros((1, 6)), np.zeros((1, 6)), mat.initial_state(1)).tangent[0]
                M = bc.free_block(nw.FusedAssembler(disc.B, disc.dV, disc.pattern).matrix(D0))
                M.sort_indices()
            t_f, F = best(lambda: solver.factorise(M), repeat)
            F = F.for_matrix(A)
            t_1, (its1, _) = best(lambda: _krylov(A, F._psolve, b, 1e-12), repeat)
            t_6, (its6, _) = best(lambda: _krylov(A, F._psolve, b, 1e-6), repeat)
            t_7, _ = best(lambda: F.solve(B7, 1e-12), repeat)
            rows.append(
                (label, t_s if label.endswith("fresh") else 0.0, t_f, t_1, its1, t_6, its6, t_7)
            )

    # --- pyamg (optional)
    try:
        import pyamg
    except ImportError:
        pyamg = None
    if pyamg is not None:
        S = (0.5 * (A + A.T)).tocsr()
        t_f, ml = best(lambda: pyamg.smoothed_aggregation_solver(S, B=None, max_coarse=500), 1)
        psolve = lambda v: ml.solve(v, tol=1e-30, maxiter=1, cycle="V")  # noqa: E731  one V-cycle
        t_1, (its1, _) = best(lambda: _krylov(A, psolve, b, 1e-12), 1)
        t_6, (its6, _) = best(lambda: _krylov(A, psolve, b, 1e-6), 1)
        rows.append(("pyamg(SA)+gmres", 0.0, t_f, t_1, its1, t_6, its6, float("nan")))

    # --- MKL PARDISO (optional)
    try:
        import pypardiso
    except ImportError:
        pypardiso = None
    if pypardiso is not None:
        Ar = A.tocsr()
        Ar.sort_indices()
        ps = pypardiso.PyPardisoSolver(mtype=1)
        ps.set_iparm(1, 1)
        ps.set_iparm(2, 2)
        ps.set_iparm(8, 0)
        ps.set_phase(11)
        t_s, _ = best(lambda: ps._call_pardiso(Ar, np.zeros((n, 1))), 1)
        ps.set_phase(22)
        t_f, _ = best(lambda: ps._call_pardiso(Ar, np.zeros((n, 1))), repeat)
        ps.set_phase(33)
        t_1, _ = best(lambda: ps._call_pardiso(Ar, b.reshape(-1, 1).copy()), repeat)
        t_7, _ = best(lambda: ps._call_pardiso(Ar, np.array(B7)), repeat)
        rows.append(("pardiso (MKL)", t_s, t_f, t_1, 0, t_1, 0, t_7))

    print(
        f"{'method':18} {'setup s':>8} {'factor s':>9} {'solve s':>8} {'its':>4} {'@1e-6 s':>8} "
        f"{'its':>4} {'7 rhs s':>8} {'x SLU 1rhs':>10} {'x SLU 7rhs':>10}"
    )
    for name, t_s, t_f, t_1, its1, t_6, its6, t_7 in rows:
        print(
            f"{name:18} {t_s:8.3f} {t_f:9.3f} {t_1:8.4f} {its1:4d} {t_6:8.4f} {its6:4d} {t_7:8.4f} "
            f"{ref1 / (t_f + t_1):10.2f} {ref7 / (t_f + t_7):10.2f}"
        )
    return rows


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--meshes", default="paper,paper:quarter,fine")
    ap.add_argument("--case", default="linear-compression")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    if args.case not in CASES:
        raise SystemExit(f"case {args.case!r} is unknown; allowed: {', '.join(CASES)}")
    for spec in split_specs(args.meshes):
        measure(spec, args.case, args.repeat)


if __name__ == "__main__":
    main()

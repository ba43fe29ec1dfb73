"""Benchmark (not a test): 20-node serendipity against 27-node Lagrange hexahedra, measured with an
independent code (scikit-fem) on the project's graded meshes; elastic bonded cube (issue 25).

    OMP_NUM_THREADS=1 python -m bench.perf.hex20 [--grading 4] [--hex8 4,6,8,12,16,24,32]
        [--hex20 2,3,4,6,8,10,12,16] [--hex27 2,3,4,6,8,12] [--reference 16]
        [--locking 2,4] [--locking-reference 12] [--out PATH]

(about 6 CPU-min with the defaults, peak memory 7.5 GB: the scikit-fem assembly of the 27-node
reference; shipped: results/perf/hex20.txt, g8, and
results/perf/hex20_g4.txt)

The problem: the bonded quarter cube of the project (x, y in [0, 75], z in [0, 150] mm; symmetry
u_x = 0 on x = 0, u_y = 0 on y = 0; bonded plates, u = 0 on z = 0, u_x = u_y = 0 and
u_z = -delta on z = 150 mm), linear elastic E = 30 GPa, delta = 0.1 mm, solved as the project's
eighth model (z <= 75 mm, u_z = -delta/2 on the mid-plane; exact on these meshes, whose z
coordinates mirror about mid-height). A mesh ``n`` of a family is the quarter mesh spec
``n,n,2n:gR`` (``--grading R``); the node coordinates along each axis are the project's
(:func:`problems.fe.mesh.graded_box_mesh`), so both codes see the same geometry. Elements
(scikit-fem, pure displacement): ``hex8`` 8-node trilinear (2x2x2 Gauss), ``hex20`` 20-node
serendipity (3x3x3), ``hex20r`` the same with reduced 2x2x2 integration, ``hex27`` 27-node
Lagrange (3x3x3); ``Q2-P1`` is the project's own 27-node element (problems/fe/element.py).

Printed (units in the headers):
1. the cross-check of the two codes: scikit-fem ``hex27`` against the project's 27-node element with
   the B-bar switched off, same mesh, force and front-face field (relative differences);
2. per element and mesh: the quarter's dofs (the project's convention, as in docs/fe_model.md),
   the free dofs, the non-zeros of the solved (eighth) stiffness and of its Cholesky factor
   (CHOLMOD supernodal with its own ordering, for every element: nnz(L), the fill), CPU s of
   assembly and of the solve (process clock), the whole-cube plate force (kN) and its error
   against the independent 461.88 kN and against the Richardson extrapolation F_inf of the last
   three 27-node meshes (%), the RMS front-face error (x = 75 mm, u_y and u_z on the 14 x 29
   measurement grid) against the 27-node ``--reference`` mesh in sigma = 1 um/sqrt(12), the
   observed orders in h (force against F_inf, field) and an estimate of the field reference's
   own error;
3. each element's errors interpolated (log-log between neighbouring meshes) at the free dofs, the
   nnz and the nnz(L) of each 27-node mesh, as ratios to the 27-node error: accuracy at equal
   cost (no field ratio where the 27-node error is < 3 x the reference's own);
4. locking, the proxy for isochoric plastic flow: at nu = 0.3, 0.49, 0.499, 0.4999, the force of
   ``hex20``, ``hex20r`` (on each ``--locking`` mesh and on the one of about the 27-node mesh's
   dofs), ``hex27`` (scikit-fem) and Q2-P1 (project) as a ratio to Q2-P1 on the
   ``--locking-reference`` mesh (its own change from n - 2 is printed as its uncertainty);
5. the zero-energy modes of one free 20-node element (eigenvalues < 1e-9 of the largest; 6 are
   rigid-body modes) under full and reduced integration, and whether they survive in the
   assembled constrained meshes (smallest / largest eigenvalue of the solved stiffness, Cholesky).

CPU times are scikit-fem's (Python-level assembly, one form evaluation per pair of basis
functions), not the project's fused compiled kernels: only dofs and non-zeros are comparable costs.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from bench.paths import output_file
from problems.analysis.convergence import SIGMA_DISPLACEMENT_MM, observed_order, richardson
from problems.fe.front_face import front_face_operator, measurement_grid
from problems.fe.mesh import SIZE_MM, parse_mesh_spec
from problems.io.atomic import atomic_write_text

E_MPA, NU, DELTA_MM = 30_000.0, 0.2, 0.1
#: whole-cube plate force of the bonded cube at delta = 0.1 mm, E = 30 GPa, nu = 0.2, kN (issue 25)
REFERENCE_KN = 461.88
#: scikit-fem element, Gauss points per direction of each element key
ELEMENTS = {
    "hex8": ("ElementHex1", 2),
    "hex20": ("ElementHexS2", 3),
    "hex20r": ("ElementHexS2", 2),
    "hex27": ("ElementHex2", 3),
}
LOCKING_NUS = (0.3, 0.49, 0.499, 0.4999)


def family_spec(n: int, grading: float) -> str:
    """The quarter mesh spec ``n,n,2n:gR`` of mesh ``n`` of a family."""
    return f"{n},{n},{2 * n}:g{grading:g}"


def axis_coordinates(spec: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Node coordinates (mm) along x, y and z of the element corners of a quarter mesh spec (the
    project's graded builder; any element token is ignored)."""
    mesh = dataclasses.replace(parse_mesh_spec(spec), element="hex8").build()
    return tuple(np.unique(mesh.nodes[:, i]) for i in range(3))


def quarter_dofs(spec: str, element: str) -> int:
    """Dofs of the whole quarter mesh (3 per node; hex20: corners and edge mid-points)."""
    nx, ny, nz = parse_mesh_spec(spec).shape
    if element in ("hex27", "Q2-P1"):
        return 3 * (2 * nx + 1) * (2 * ny + 1) * (2 * nz + 1)
    corners = (nx + 1) * (ny + 1) * (nz + 1)
    if element == "hex8":
        return 3 * corners
    edges = nx * (ny + 1) * (nz + 1) + (nx + 1) * ny * (nz + 1) + (nx + 1) * (ny + 1) * nz
    return 3 * (corners + edges)


def vector_basis(mesh, element: str):
    """scikit-fem vector basis of ``element`` (a key of :data:`ELEMENTS`, with its Gauss rule) on
    a scikit-fem hexahedral mesh."""
    import skfem

    cls, points = ELEMENTS[element]
    basis = skfem.Basis(mesh, skfem.ElementVector(getattr(skfem, cls)()), intorder=2 * points - 1)
    assert basis.X.shape[1] == points**3, (element, basis.X.shape)
    return basis


def eighth_mesh(spec: str):
    """scikit-fem mesh of the eighth model (z <= mid-height) of quarter mesh ``spec``."""
    import skfem

    x, y, z = axis_coordinates(spec)
    return skfem.MeshHex.init_tensor(x, y, z[: (len(z) - 1) // 2 + 1])


def _cholesky_solve(A: sp.spmatrix, rhs: np.ndarray) -> tuple[np.ndarray, object]:
    """x = A^-1 rhs by CHOLMOD (supernodal, its own fill-reducing ordering) and the factor;
    ArithmeticError unless A is positive definite."""
    import kvxopt
    import kvxopt.cholmod as cholmod

    c = sp.tril(A).tocoo()
    K = kvxopt.spmatrix(c.data, c.row.astype(int), c.col.astype(int), c.shape)
    b = kvxopt.matrix(np.asarray(rhs, float))
    cholmod.options["supernodal"] = 2
    F = cholmod.symbolic(K, uplo="L")
    cholmod.numeric(K, F)
    cholmod.solve(F, b)
    return np.array(b).ravel(), F


def factor_size(F) -> int:
    """Stored entries of a CHOLMOD factor (supernodal: with the zeros its dense blocks hold)."""
    import kvxopt.cholmod as cholmod

    return len(cholmod.getfactor(F))


def skfem_solve(spec: str, element: str, nu: float = NU, points=None) -> dict:
    """The elastic bonded cube on quarter mesh ``spec`` with a scikit-fem element (a key of
    :data:`ELEMENTS`), solved as the eighth model.

    Returns ``force_kN`` (whole cube, compression positive), ``free_dofs`` and ``nnz`` of the
    solved stiffness, ``cpu_assemble`` / ``cpu_solve`` (s), ``quarter_dofs`` and, when
    ``points`` (m, 2) = (y, z) mm on the front face are given, ``u_h``, ``u_v`` (m,) mm there
    (the quarter's answer: the upper half unfolded from the eighth)."""
    from skfem import asm, condense
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    basis = vector_basis(eighth_mesh(spec), element)
    z_mid = basis.mesh.p[2].max()
    t0 = time.process_time()
    K = asm(linear_elasticity(*lame_parameters(E_MPA, nu)), basis).tocsr()
    t1 = time.process_time()

    def dofs(axis, value):
        return basis.get_dofs(lambda p: np.isclose(p[axis], value))

    bottom = dofs(2, 0.0)
    top_z = dofs(2, z_mid).all("u^3")
    fixed = np.unique(
        np.concatenate([dofs(0, 0.0).all("u^1"), dofs(1, 0.0).all("u^2"), bottom.all(), top_z])
    )
    u = np.zeros(basis.N)
    u[top_z] = -0.5 * DELTA_MM
    A, b, _, free = condense(K, np.zeros(basis.N), x=u, D=fixed)
    u[free], factor = _cholesky_solve(A, b)
    t2 = time.process_time()
    out = {
        "spec": spec,
        "element": element,
        "quarter_dofs": quarter_dofs(spec, element),
        "free_dofs": int(len(free)),
        "nnz": int(A.nnz),
        "nnz_L": factor_size(factor),
        "cpu_assemble": t1 - t0,
        "cpu_solve": t2 - t1,
        "force_kN": 4.0 * float((K @ u)[bottom.all("u^3")].sum()) / 1000.0,
    }
    if points is not None:
        out.update(skfem_front_face(basis, u, points))
    return out


def skfem_front_face(basis, u: np.ndarray, points) -> dict:
    """u_y, u_z (mm) of an eighth-model solution at front-face points (y, z) mm of the whole
    height: z > 75 mm read from the mirror image (u_z = -delta - u_z(150 - z))."""
    pts = np.atleast_2d(np.asarray(points, float))
    upper = pts[:, 1] > 0.5 * SIZE_MM[2]
    z = np.where(upper, SIZE_MM[2] - pts[:, 1], pts[:, 1])
    probe = np.vstack([np.full(len(pts), SIZE_MM[0]), pts[:, 0], z])
    (_, _), (uy, by), (uz, bz) = basis.split(u)
    v = bz.probes(probe) @ uz
    return {"u_h": by.probes(probe) @ uy, "u_v": np.where(upper, -DELTA_MM - v, v)}


def project_solve(spec: str, nu: float = NU, use_b_bar: bool = True, points=None) -> dict:
    """The same bonded cube with the project's code (eighth model, the spec's element)."""
    from problems.fe.newton import Loading, discretise, run
    from problems.materials import LinearElastic

    mesh = parse_mesh_spec(spec).mesh
    t = time.process_time()
    r = run(
        discretise(mesh, use_b_bar=use_b_bar, symmetry="eighth"),
        LinearElastic(E_MPA, nu),
        Loading(DELTA_MM, 1),
    )
    out = {"force_kN": float(r.reaction_kN[-1]), "cpu": time.process_time() - t}
    if points is not None:
        W = front_face_operator(r.mesh, points)
        out["u_h"], out["u_v"] = W @ r.displacements[-1, :, 1], W @ r.displacements[-1, :, 2]
    return out


def rms_sigma(a: dict, b: dict) -> float:
    """RMS front-face difference, both components, in sigma = 1 um/sqrt(12)."""
    d = np.concatenate([a["u_h"] - b["u_h"], a["u_v"] - b["u_v"]])
    return float(np.sqrt(np.mean(d**2)) / SIGMA_DISPLACEMENT_MM)


def zero_energy_modes(element: str, tol: float = 1e-9) -> int:
    """Eigenvalues of one free element's stiffness (a non-cubic brick, 1 x 1.3 x 0.8 mm) below
    ``tol`` times the largest: 6 rigid-body modes plus any spurious ones."""
    import skfem
    from skfem import asm
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    mesh = skfem.MeshHex.init_tensor(np.array([0.0, 1.0]), np.array([0.0, 1.3]), np.array([0, 0.8]))
    basis = vector_basis(mesh, element)
    lam = np.linalg.eigvalsh(asm(linear_elasticity(*lame_parameters(E_MPA, NU)), basis).toarray())
    return int(np.sum(lam < tol * lam.max()))


def constrained_spectrum(spec: str, element: str) -> dict:
    """Smallest / largest eigenvalue of the solved (free-free) stiffness of the eighth model of
    ``spec`` (dense; small meshes only) and whether CHOLMOD factorises it."""
    from skfem import asm, condense
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    basis = vector_basis(eighth_mesh(spec), element)
    K = asm(linear_elasticity(*lame_parameters(E_MPA, NU)), basis).tocsr()

    def dofs(axis, value):
        return basis.get_dofs(lambda p: np.isclose(p[axis], value))

    fixed = np.unique(
        np.concatenate(
            [
                dofs(0, 0.0).all("u^1"),
                dofs(1, 0.0).all("u^2"),
                dofs(2, 0.0).all(),
                dofs(2, basis.mesh.p[2].max()).all("u^3"),
            ]
        )
    )
    A = condense(K, D=fixed, expand=False)
    lam = np.linalg.eigvalsh(A.toarray())
    try:
        _cholesky_solve(A, np.ones(A.shape[0]))
        cholesky = True
    except ArithmeticError:
        cholesky = False
    return {"free_dofs": A.shape[0], "ratio": float(lam[0] / lam[-1]), "cholesky": cholesky}


def loglog_at(costs, errors, target: float) -> float | None:
    """|error| interpolated linearly in log-log at ``target`` cost; None outside the range."""
    c, e = np.log(np.asarray(costs, float)), np.log(np.abs(np.asarray(errors, float)))
    t = np.log(target)
    if t < c.min() - 1e-12 or t > c.max() + 1e-12:
        return None
    order = np.argsort(c)
    return float(np.exp(np.interp(t, c[order], e[order])))


def _lists(text: str, option: str) -> list[int]:
    try:
        values = [int(t) for t in text.split(",") if t.strip()]
    except ValueError:
        values = []
    if not values or min(values) < 1 or sorted(set(values)) != values:
        raise ValueError(
            f"{option} = {text!r} is out of range: increasing whole numbers >= 1, comma-separated"
        )
    return values


def _fmt(v, spec=".3g") -> str:
    return "–" if v is None else format(v, spec)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--grading", type=float, default=4.0, help="gR of every mesh (1: uniform)")
    ap.add_argument("--hex8", default="4,6,8,12,16,24,32", help="8-node meshes n (n,n,2n)")
    ap.add_argument("--hex20", default="2,3,4,6,8,10,12,16", help="20-node meshes n (both rules)")
    ap.add_argument("--hex27", default="2,3,4,6,8,12", help="27-node meshes n")
    ap.add_argument("--reference", type=int, default=16, help="27-node field reference n")
    ap.add_argument("--locking", default="2,4", help="meshes n of the locking study")
    ap.add_argument("--locking-reference", type=int, default=12, help="Q2-P1 reference n")
    ap.add_argument("--out", type=Path, help="also write the printed text here (atomically)")
    args = ap.parse_args(argv)
    try:
        if not (np.isfinite(args.grading) and args.grading >= 1.0):
            raise ValueError(f"--grading = {args.grading!r} is out of range: a number >= 1")
        fams = {
            "hex8": _lists(args.hex8, "--hex8"),
            "hex20": _lists(args.hex20, "--hex20"),
            "hex27": _lists(args.hex27, "--hex27"),
        }
        fams["hex20r"] = fams["hex20"]
        locking = _lists(args.locking, "--locking")
        for opt, n, low in (
            ("--reference", args.reference, max(fams["hex27"])),
            # its uncertainty is its change from n - 2, a mesh of >= 1 element
            ("--locking-reference", args.locking_reference, max(2, *locking)),
        ):
            if n <= low:
                raise ValueError(f"{opt} = {n} is out of range: a whole number > {low}")
        if len(fams["hex27"]) < 2:
            raise ValueError(f"--hex27 = {args.hex27!r} is out of range: at least two meshes")
        if args.out is not None:  # before minutes of work, not after
            try:
                output_file(str(args.out))
            except argparse.ArgumentTypeError as exc:
                raise ValueError(f"--out {exc}") from None
        try:
            import skfem  # noqa: F401
        except ImportError:
            raise ValueError(
                "this benchmark needs scikit-fem (a test dependency): pip install -e '.[test]'"
            ) from None
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2

    g = args.grading
    lines: list[str] = []

    def say(text: str = "") -> None:
        print(text, flush=True)
        lines.append(text)

    points = measurement_grid()
    say(f"# 20-node vs 27-node hexahedra, scikit-fem, bonded elastic cube (graded g{g:g})")
    say(f"E = {E_MPA:g} MPa, nu = {NU}, delta = {DELTA_MM} mm; eighth models; force: whole cube")
    say()

    # 1. cross-check of the codes
    spec = family_spec(max(2, min(fams["hex27"])), g)
    a = skfem_solve(spec, "hex27", points=points)
    b = project_solve(spec + ":hex27", use_b_bar=False, points=points)
    scale = max(np.abs(b["u_h"]).max(), np.abs(b["u_v"]).max())
    dfield = max(np.abs(a["u_h"] - b["u_h"]).max(), np.abs(a["u_v"] - b["u_v"]).max()) / scale
    say(f"## 1. cross-check on {spec}: scikit-fem hex27 vs project 27-node without B-bar")
    say(
        f"force {a['force_kN']:.9f} vs {b['force_kN']:.9f} kN: relative difference "
        f"{abs(a['force_kN'] / b['force_kN'] - 1):.1e}; front face max |du| / max |u| {dfield:.1e}"
    )
    say()

    # 2. sequences
    ref_spec = family_spec(args.reference, g)
    ref = skfem_solve(ref_spec, "hex27", points=points)
    rows: dict[str, list[dict]] = {}
    for element, sizes in fams.items():
        rows[element] = [
            {**skfem_solve(family_spec(n, g), element, points=points), "n": n} for n in sizes
        ]
    f27 = [r["force_kN"] for r in rows["hex27"]] + [ref["force_kN"]]
    n27 = fams["hex27"] + [args.reference]
    h27 = [1.0 / n for n in n27[-3:]]  # element sizes up to a common factor (same grading)
    p_inf = observed_order(h27, f27[-3:])
    f_inf = float(richardson(h27[1], h27[2], f27[-2], f27[-1], p_inf))
    say(f"## 2. sequences (field reference: hex27 {ref_spec}, {ref['free_dofs']} free dofs)")
    say(
        f"F_inf = {f_inf:.4f} kN (Richardson of hex27 n = {n27[-3]}, {n27[-2]}, {n27[-1]}, "
        f"observed order {p_inf:.2f}); {ref_spec} hex27: {ref['force_kN']:.4f} kN; independent "
        f"{REFERENCE_KN} kN"
    )
    say()
    say(
        "| element | quarter mesh | quarter dofs | free dofs | nnz | nnz(L) | CPU asm s | "
        "CPU solve s | "
        "force kN | err vs 461.88 % | err vs F_inf % | RMS front face σ | order force | "
        "order field |"
    )
    say("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for element, rs in rows.items():
        for i, r in enumerate(rs):
            r["err_pct"] = 100.0 * (r["force_kN"] / REFERENCE_KN - 1.0)
            r["err_inf_pct"] = 100.0 * (r["force_kN"] / f_inf - 1.0)
            r["rms_sigma"] = rms_sigma(r, ref)
            po = pf = None
            if i:
                q = rs[i - 1]
                lr = np.log(r["n"] / q["n"])
                po = np.log(abs(q["err_inf_pct"] / r["err_inf_pct"])) / lr
                pf = np.log(q["rms_sigma"] / r["rms_sigma"]) / lr
            say(
                f"| {element} | {r['spec']} | {r['quarter_dofs']} | {r['free_dofs']} | {r['nnz']} "
                f"| {r['nnz_L']} "
                f"| {r['cpu_assemble']:.2f} | {r['cpu_solve']:.2f} | {r['force_kN']:.4f} | "
                f"{r['err_pct']:+.4f} | {r['err_inf_pct']:+.4f} | {r['rms_sigma']:.3f} | "
                f"{_fmt(po, '.2f')} | {_fmt(pf, '.2f')} |"
            )
    say()
    r1, r2 = rows["hex27"][-2:]
    p_field = np.log(r1["rms_sigma"] / r2["rms_sigma"]) / np.log(r2["n"] / r1["n"])
    ref_error = r2["rms_sigma"] / ((args.reference / r2["n"]) ** p_field - 1)
    say(
        f"the field reference's own error, estimated from hex27 n = {r1['n']}, {r2['n']} (order "
        f"{p_field:.2f}): {ref_error:.4f} σ"
    )
    say()

    # 3. equal cost
    say("## 3. at equal cost: error / 27-node error, log-log interpolated at each 27-node mesh")
    say(
        "(force error against F_inf; '–': outside the element's measured range; 'ref': the "
        "27-node field error is < 3 x the reference's own, no ratio)"
    )
    say()
    say(
        "| 27-node mesh | cost | value | hex8 force | hex20 force | hex20r force | hex8 field | "
        "hex20 field | hex20r field |"
    )
    say("|---|---|---|---|---|---|---|---|---|")
    for r27 in rows["hex27"]:
        for cost in ("free_dofs", "nnz", "nnz_L"):
            cells = []
            for key in ("err_inf_pct", "rms_sigma"):  # force, field
                for element in ("hex8", "hex20", "hex20r"):
                    rs = rows[element]
                    v = loglog_at([r[cost] for r in rs], [r[key] for r in rs], r27[cost])
                    if key == "rms_sigma" and r27[key] < 3 * ref_error:
                        cells.append("ref")
                    else:
                        cells.append(_fmt(None if v is None else v / abs(r27[key]), ".2f"))
            say(f"| {r27['spec']} | {cost} | {r27[cost]} | " + " | ".join(cells) + " |")
    say()

    # 4. locking
    ref_lock = family_spec(args.locking_reference, g) + ":hex27"
    coarser = family_spec(args.locking_reference - 2, g) + ":hex27"
    F_ref = {nu: project_solve(ref_lock, nu)["force_kN"] for nu in LOCKING_NUS}
    F_prev = {nu: project_solve(coarser, nu)["force_kN"] for nu in LOCKING_NUS}
    say(f"## 4. locking: force / Q2-P1 on {ref_lock} (the project's element)")
    say(
        "reference kN: "
        + ", ".join(
            f"nu {nu}: {F_ref[nu]:.3f} ({100 * (F_ref[nu] / F_prev[nu] - 1):+.4f} % vs {coarser})"
            for nu in LOCKING_NUS
        )
    )
    say()
    say(
        "| element | quarter mesh | free dofs | "
        + " | ".join(f"nu {nu}" for nu in LOCKING_NUS)
        + " |"
    )
    say("|---|---|---|" + "---|" * len(LOCKING_NUS))
    for n in locking:
        # the 20-node meshes on n and at about the 27-node mesh's dofs
        n_eq = min(
            range(n, 2 * n + 1),
            key=lambda m: abs(
                quarter_dofs(family_spec(m, g), "hex20") - quarter_dofs(family_spec(n, g), "hex27")
            ),
        )
        runs = [(e, m) for e in ("hex20", "hex20r") for m in sorted({n, n_eq})]
        for element, m in runs + [("hex27", n), ("Q2-P1", n)]:
            s = family_spec(m, g)
            ratios = []
            for nu in LOCKING_NUS:
                if element == "Q2-P1":  # the same nodes and constraints as hex27 on this mesh
                    F = project_solve(s + ":hex27", nu)["force_kN"]
                else:
                    r = skfem_solve(s, element, nu)
                    F, dofs = r["force_kN"], r["free_dofs"]
                ratios.append(F / F_ref[nu])
            say(f"| {element} | {s} | {dofs} | " + " | ".join(f"{v:.4f}" for v in ratios) + " |")
    say()

    # 5. zero-energy modes
    say("## 5. zero-energy modes of the 20-node element (6 are rigid-body modes)")
    say(
        f"one free element: full 3x3x3 {zero_energy_modes('hex20')}, reduced 2x2x2 "
        f"{zero_energy_modes('hex20r')} (27-node full {zero_energy_modes('hex27')})"
    )
    say()
    say("| quarter mesh | free dofs | hex20 λmin/λmax | hex20r λmin/λmax | hex20r Cholesky |")
    say("|---|---|---|---|---|")
    for n in (1, 2, 4):
        s = family_spec(n, g)
        full, red = constrained_spectrum(s, "hex20"), constrained_spectrum(s, "hex20r")
        say(
            f"| {s} | {full['free_dofs']} | {full['ratio']:.2e} | {red['ratio']:.2e} | "
            f"{'ok' if red['cholesky'] else 'FAILED'} |"
        )
    if args.out:
        atomic_write_text(args.out, "\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

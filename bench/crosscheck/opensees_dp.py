r"""Cross-check of the linear Drucker-Prager form (K = 1) against OpenSees (not a test).

    python -m bench.crosscheck.opensees_dp [--out DIR] [--mesh coarse|NX,NY,NZ] [--skip-cube]
                                           [--psi 35,15] [--all-strategies]

Needs ``openseespy`` (``pip install openseespy``; 3.7.1.2 used here) and matplotlib for the PNGs.
Runs (1) one element under frictionless uniaxial compression and (2) the quarter cube between
friction plates, both in femubench's FE (:mod:`problems.fe.newton`) and in OpenSees (``bbarBrick`` /
``stdBrick`` + ``nDMaterial DruckerPrager``) on the *same* mesh and load steps, prints a table and
writes ``opensees_dp.json`` and PNG overlays to ``--out`` (default ``results/crosscheck``).
Results and discussion: ``docs/crosscheck_opensees.md``.

Parameter mapping (derivation)
------------------------------
femubench, linear form with K = 1 and compression hardening (p = -I1/3 compression positive,
q = sqrt(3 J2) = sqrt(3/2) ||s||, angles in degrees)::

    F = q - p tan(beta) - d,   d = (1 - tan(beta)/3) sigma_c,   sigma_c = sigma0 + H eqps
    G = q - p tan(psi),        d eps_pl = d lambda dG/dsigma,  d eqps = (1 - tan(psi)/3) d lambda

(the last from plastic-work equivalence, :func:`problems.materials.hardening.linear_eqps_constant`;
in uniaxial compression it makes ``eqps = |eps_pl_11|``).

OpenSees ``nDMaterial DruckerPrager tag K G sigmaY rho rhoBar Kinf Ko delta1 delta2 H theta density``
(``SRC/material/nD/DruckerPrager.cpp``, I1 = tr(sigma) tension positive, ||.|| the Frobenius norm
of the *tensor*)::

    f1 = ||s - beta_kin|| + rho I1 - sqrt(2/3) Kiso(alpha1),
    Kiso(a) = sigmaY + theta H a + (Kinf - Ko)(1 - exp(-delta1 a)),   kinematic modulus (1 - theta) H
    f2 = I1 - T(alpha2),  T = To exp(-delta2 alpha2),  To = sqrt(2/3) sigmaY / rho  (tension cutoff)
    d eps_pl = gamma (n + rhoBar 1),  n = s/||s||,  d alpha1 = sqrt(2/3) gamma,  d alpha2 = rhoBar gamma

1. Yield surface. With I1 = -3p and q = sqrt(3/2) ||s||, ``F / sqrt(3/2) = ||s|| + sqrt(2/3)
   tan(beta)/3 I1 - sqrt(2/3) d``: the same cone as f1 (beta_kin = 0) iff

       rho = sqrt(2/3) tan(beta)/3,     Kiso(alpha1) = d = (1 - tan(beta)/3)(sigma0 + H eqps).

2. Flow. ``dG/dsigma = sqrt(3/2) n + tan(psi)/3 1 = sqrt(3/2) (n + rhoBar 1)`` with
   ``rhoBar = sqrt(2/3) tan(psi)/3``, so gamma = sqrt(3/2) d lambda. OpenSees documents
   0 <= rhoBar <= rho, i.e. psi <= beta (associated: psi = beta, rhoBar = rho).

3. Hardening variable. ``d alpha1 = sqrt(2/3) gamma = d lambda``: OpenSees's alpha1 is *our
   plastic multiplier* on any stress path (not only in uniaxial compression), and
   ``eqps = (1 - tan(psi)/3) alpha1``. In uniaxial compression alpha1 = sqrt(2/3) ||dev eps_pl||
   = |dev eps_pl_11| = |eps_pl_11| + eps_pl_vol/3 = eqps / (1 - tan(psi)/3). Hence, purely
   isotropic (theta = 1) and linear (Kinf = Ko = delta1 = 0)::

       sigmaY = (1 - tan(beta)/3) sigma0,      H_os = (1 - tan(beta)/3)(1 - tan(psi)/3) H.

4. Elasticity: K = E / (3 (1 - 2 nu)), G = E / (2 (1 + nu)); density 0 (static); atmPressure
   irrelevant (the pressure-dependent moduli are only switched on by ``updateMaterialStage 1``).

5. Tension cutoff: f2 cannot be removed and ``To`` is not an input: OpenSees sets it to the apex
   of the *initial* cone, I1 = sqrt(2/3) sigmaY / rho = 3 sigma0 (1 - tan(beta)/3) / tan(beta)
   (65.7 MPa, a hydrostatic tension of 21.9 MPa for the reference values). With delta2 = 0 it
   stays there; it is then active only where the mean stress exceeds that tension, which
   compression of the cube never reaches, whereas femubench returns such states to the
   (hardened) cone apex. The two models are identical for I1 < To.

Reference values (the issue): E = 30 000 MPa, nu = 0.2, beta = 35 deg, psi = 35 deg (associated)
and 15 deg (non-associated), sigma0 = 20 MPa, H = 1 500 MPa, 1.5 mm on 150 mm.
"""
from __future__ import annotations

import argparse
import contextlib
import ctypes
import importlib.util
import json
import math
import os
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

REFERENCE = {"E": 30_000.0, "nu": 0.2, "beta": 35.0, "psi": 35.0, "sigma0": 20.0, "H": 1_500.0}
SIZE_MM = 150.0          # single element edge, and cube height
DELTA_MM = 1.5           # plate displacement
#: front-face points (y, z) mm reported one by one for the cube
FRONT_POINTS = np.array([[37.5, 75.0], [75.0, 75.0], [75.0, 140.0], [37.5, 10.0]])
_SQ23 = math.sqrt(2.0 / 3.0)


# ============================================================================================
# The mapping (pure: no openseespy)
# ============================================================================================

def _tan(deg: float) -> float:
    return math.tan(math.radians(deg))


def opensees_parameters(E: float, nu: float, beta: float, psi: float, sigma0: float, H: float) -> dict:
    """OpenSees ``nDMaterial DruckerPrager`` arguments equivalent to femubench's linear form with
    K = 1 and compression hardening (see the module docstring). Angles in degrees, MPa.

    Returns the arguments by their OpenSees names, in command order after the tag:
    ``K G sigmaY rho rhoBar Kinf Ko delta1 delta2 H theta density``.
    """
    if not (E > 0 and -1.0 < nu < 0.5):
        raise ValueError(f"E = {E!r}, nu = {nu!r}: need E > 0 and -1 < nu < 0.5")
    if not (0.0 < beta < math.degrees(math.atan(3.0))):
        raise ValueError(f"beta = {beta!r} deg: need 0 < beta < atan(3) = 71.57 deg")
    if not (0.0 <= psi <= beta):
        raise ValueError(f"psi = {psi!r} deg: OpenSees's DruckerPrager needs 0 <= rhoBar <= rho, i.e. "
                         f"0 <= psi <= beta = {beta!r} deg")
    if not (sigma0 > 0 and H >= 0):
        raise ValueError(f"sigma0 = {sigma0!r}, H = {H!r}: need sigma0 > 0 and H >= 0 MPa")
    tb, tp = _tan(beta), _tan(psi)
    return {
        "K": E / (3.0 * (1.0 - 2.0 * nu)),
        "G": E / (2.0 * (1.0 + nu)),
        "sigmaY": (1.0 - tb / 3.0) * sigma0,
        "rho": _SQ23 * tb / 3.0,
        "rhoBar": _SQ23 * tp / 3.0,
        "Kinf": 0.0,
        "Ko": 0.0,
        "delta1": 0.0,
        "delta2": 0.0,
        "H": (1.0 - tb / 3.0) * (1.0 - tp / 3.0) * H,
        "theta": 1.0,
        "density": 0.0,
    }


def eqps_from_alpha(alpha, psi: float):
    """femubench's eqps from OpenSees's alpha1 (= our plastic multiplier): (1 - tan(psi)/3) alpha1."""
    return (1.0 - _tan(psi) / 3.0) * np.asarray(alpha, float)


def tension_cutoff_I1(osp: dict) -> float:
    """I1 (MPa, tension positive) of OpenSees's fixed tension cutoff plane, sqrt(2/3) sigmaY / rho."""
    return _SQ23 * osp["sigmaY"] / osp["rho"] if osp["rho"] > 0 else 1e10


def opensees_yield_value(stress, alpha, osp: dict) -> np.ndarray:
    """OpenSees's f1 = ||s|| + rho I1 - sqrt(2/3) Kiso(alpha1) (MPa; theta = 1, no kinematic part)
    for stresses (n, 6) in femubench's Voigt order ``[xx, yy, zz, yz, xz, xy]``."""
    s = np.atleast_2d(np.asarray(stress, float))
    I1 = s[:, :3].sum(axis=1)
    dev = s[:, :3] - I1[:, None] / 3.0
    norm = np.sqrt((dev**2).sum(axis=1) + 2.0 * (s[:, 3:] ** 2).sum(axis=1))
    a = np.asarray(alpha, float)
    kiso = (osp["sigmaY"] + osp["theta"] * osp["H"] * a
            + (osp["Kinf"] - osp["Ko"]) * (1.0 - np.exp(-osp["delta1"] * a)))
    return norm + osp["rho"] * I1 - _SQ23 * kiso


def opensees_flow_direction(stress, osp: dict) -> np.ndarray:
    """OpenSees's plastic strain rate per unit gamma, n + rhoBar 1, in femubench's engineering
    Voigt components (shear entries 2 n_ij), shape (n, 6)."""
    s = np.atleast_2d(np.asarray(stress, float))
    I1 = s[:, :3].sum(axis=1)
    dev = s.copy()
    dev[:, :3] -= I1[:, None] / 3.0
    norm = np.sqrt((dev[:, :3] ** 2).sum(axis=1) + 2.0 * (dev[:, 3:] ** 2).sum(axis=1))
    n = dev / norm[:, None]
    out = n.copy()
    out[:, :3] += osp["rhoBar"]
    out[:, 3:] *= 2.0
    return out


def uniaxial_closed_form(strain, E, nu, beta, psi, sigma0, H):
    """Exact uniaxial compression of the linear form (K = 1) with linear compression hardening.

    ``strain``: axial shortening (> 0). Returns the axial stress (MPa, compression positive) and
    the lateral strain (> 0 = expansion). On the cone F = (1 - tan(beta)/3)(sigma - sigma_c), so
    sigma = sigma0 + H eqps = E (sigma0 + H eps) / (E + H) after yield, eqps = eps - sigma/E, and
    the lateral plastic strain is eqps (1/2 + tan(psi)/3) / (1 - tan(psi)/3).
    """
    eps = np.asarray(strain, float)
    sig = np.where(E * eps > sigma0, E * (sigma0 + H * eps) / (E + H), E * eps)
    ep = eps - sig / E
    tp = _tan(psi)
    return sig, nu * sig / E + ep * (0.5 + tp / 3.0) / (1.0 - tp / 3.0)


def relative_difference(a, b) -> float:
    """max |a - b| / max |b| over the common points (0 when both are empty)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    n = min(a.size, b.size)
    if n == 0:
        return float("nan")
    a, b = a.ravel()[:n], b.ravel()[:n]
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


def pointwise_relative_difference(a, b, floor: float = 0.0) -> float:
    """max over points of |a - b| / max(|b|, floor)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    n = min(a.size, b.size)
    if n == 0:
        return float("nan")
    a, b = a.ravel()[:n], b.ravel()[:n]
    return float(np.max(np.abs(a - b) / np.maximum(np.abs(b), max(floor, 1e-300))))


# ============================================================================================
# femubench side
# ============================================================================================

def femubench_material(p: dict):
    from problems.materials.drucker_prager import make_material

    return make_material("linear", "compression", {"E": p["E"], "nu": p["nu"], "beta": p["beta"], "K": 1.0,
                                                   "psi": p["psi"], "sigma0": p["sigma0"], "H": p["H"]})


def material_point_uniaxial(material, axial_strain, tol: float = 1e-11):
    """Drive ``material`` at one point: prescribed axial shortening (z), zero lateral stress
    (Newton on the lateral strains with the consistent tangent), no shear.

    Returns axial stress (compression positive), lateral strain (expansion positive), eqps."""
    sig = np.zeros((1, 6))
    state = material.initial_state(1)
    eps = np.zeros(6)
    nu = getattr(material, "nu", 0.2)
    prev = 0.0
    out_s, out_l, out_e = [], [], []
    for e in np.asarray(axial_strain, float):
        de = np.zeros(6)
        de[2] = -(e - prev)
        de[:2] = nu * (e - prev)
        for _ in range(60):
            upd = material.update(de[None], sig, state)
            if not upd.ok.all():
                raise RuntimeError("material return mapping failed in the material-point driver")
            r = upd.stress[0, :2]
            if np.abs(r).max() <= tol * max(1.0, abs(upd.stress[0, 2])):
                break
            de[:2] -= np.linalg.solve(upd.tangent[0][:2, :2], r)
        else:
            raise RuntimeError("material-point driver: lateral stress did not vanish")
        sig, state, eps, prev = upd.stress, upd.state, eps + de, e
        out_s.append(-sig[0, 2])
        out_l.append(eps[0])
        out_e.append(state[0, 0])
    return np.array(out_s), np.array(out_l), np.array(out_e)


def femubench_box(mesh, material, delta: float, steps: int, plates: str, substeps: int = 1):
    """femubench's FE run (default Newton settings, ``substeps`` increments per snapshot);
    returns its Response and the wall time."""
    from problems.fe.newton import Loading, NewtonSettings, discretise, run

    t0 = time.perf_counter()
    resp = run(discretise(mesh), material, Loading(delta, steps, plates), NewtonSettings(substeps=substeps))
    return resp, time.perf_counter() - t0


# ============================================================================================
# OpenSees side
# ============================================================================================

_OPS = None


def load_opensees():
    """Import ``openseespy.opensees``. The Linux wheel's bundled liblapack needs the bundled libblas
    and libgfortran, which the dynamic loader does not find by itself (RUNPATH is not transitive):
    preload them globally first."""
    global _OPS
    if _OPS is not None:
        return _OPS
    spec = importlib.util.find_spec("openseespylinux")
    if spec is not None and spec.origin:
        libdir = Path(spec.origin).parent / "lib"
        for name in ("libquadmath.so.0", "libgfortran.so.4", "libgomp.so.1", "libblas.so.3", "liblapack.so.3"):
            if (libdir / name).exists():
                with contextlib.suppress(OSError):
                    ctypes.CDLL(str(libdir / name), mode=ctypes.RTLD_GLOBAL)
    try:
        import openseespy.opensees as ops
    except Exception as exc:  # noqa: BLE001 - report any import failure the same way
        raise SystemExit(f"openseespy is not importable ({exc}); install it with `pip install openseespy`") from exc
    _OPS = ops
    return ops


def openseespy_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("openseespy")
    except PackageNotFoundError:
        return "?"


@contextlib.contextmanager
def captured_output(path: Path):
    """Redirect the process's stdout and stderr (file descriptors, so C++ output too) to ``path``."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = os.dup(1), os.dup(2)
    with open(path, "ab") as f:
        os.dup2(f.fileno(), 1)
        os.dup2(f.fileno(), 2)
        try:
            yield
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(saved[0])
            os.close(saved[1])


@dataclass(frozen=True)
class Strategy:
    """OpenSees solution settings for one attempt."""

    name: str
    substeps: int = 1                                   # analysis steps per snapshot
    test: tuple = ("NormUnbalance", 1e-4, 25)           # N: ~1e-9 of the plate force
    algorithm: tuple = ("Newton",)
    system: str = "UmfPack"
    constraints: tuple = ("Transformation",)


BASELINE = Strategy("Newton, 10 steps, NormUnbalance 1e-4 N")
#: the usual cures, tried in this order when the baseline fails: first at the same load steps,
#: then with smaller steps
CURES = (
    Strategy("Newton, NormDispIncr 1e-10 mm", test=("NormDispIncr", 1e-10, 50)),
    Strategy("KrylovNewton", algorithm=("KrylovNewton",), test=("NormUnbalance", 1e-4, 100)),
    Strategy("NewtonLineSearch", algorithm=("NewtonLineSearch", "-type", "Bisection"), test=("NormUnbalance", 1e-4, 100)),
    Strategy("ModifiedNewton", algorithm=("ModifiedNewton",), test=("NormUnbalance", 1e-4, 200)),
    Strategy("Newton, Penalty constraint handler", constraints=("Penalty", 1e12, 1e12)),
    Strategy("Newton, 2x smaller steps", substeps=2),
    Strategy("Newton, 5x smaller steps", substeps=5),
    Strategy("Newton, 10x smaller steps", substeps=10),
)


@dataclass
class OpenSeesRun:
    strategy: str
    element: str
    converged: bool
    snapshots_mm: np.ndarray
    reaction_kN: np.ndarray          # whole-specimen force for the quarter cube (x4), kN, compression > 0
    force_N: np.ndarray              # force on the modelled body, N
    displacements: np.ndarray        # (N, n_nodes, 3) mm
    stress: np.ndarray               # (N, n_elements, 6) element mean, femubench Voigt order
    wall_s: float
    failure: dict = field(default_factory=dict)
    log: str = ""
    step_iterations: list = field(default_factory=list)   # Newton iterations of each analysis step
    step_norms: list = field(default_factory=list)        # test norms of each step's iterations


# OpenSees brick stress output sigma11, sigma22, sigma33, sigma12, sigma23, sigma13 -> [xx, yy, zz, yz, xz, xy]
_OS_TO_VOIGT = [0, 1, 2, 4, 5, 3]


def opensees_box(mesh, osp: dict, delta: float, steps: int, plates: str, *, element: str = "bbarBrick",
                 strategy: Strategy = BASELINE, quarter: bool = True, log_dir: Path | None = None) -> OpenSeesRun:
    """The plate test of ``mesh`` in OpenSees with the same boundary conditions as
    :class:`problems.fe.BoundaryConditions`: u_x = 0 on x = 0, u_y = 0 on y = 0, u_z = 0 at the
    bottom, u_z = -delta (sp constraint, linear in the load factor) at the top, and with friction
    plates u_x = u_y = 0 at bottom and top. Node tag = femubench node index + 1."""
    ops = load_opensees()
    nn = mesh.n_nodes
    fixed = np.zeros((nn, 3), int)
    fixed[mesh.face("x0"), 0] = 1
    fixed[mesh.face("y0"), 1] = 1
    fixed[mesh.face("z0"), 2] = 1
    if plates == "friction":
        for face in ("z0", "z1"):
            fixed[mesh.face(face), :2] = 1
    top = mesh.face("z1")
    log_path = Path(tempfile.mkstemp(prefix="opensees_", suffix=".log", dir=log_dir)[1])
    t0 = time.perf_counter()
    out_u, out_s, out_f, out_d = [], [], [], []
    failure: dict = {}
    step_iterations: list[int] = []
    step_norms: list[list[float]] = []
    with captured_output(log_path):
        ops.wipe()
        ops.model("basic", "-ndm", 3, "-ndf", 3)
        for i, (x, y, z) in enumerate(mesh.nodes):
            ops.node(i + 1, float(x), float(y), float(z))
            if fixed[i].any():
                ops.fix(i + 1, *map(int, fixed[i]))
        ops.nDMaterial("DruckerPrager", 1, *(float(osp[k]) for k in (
            "K", "G", "sigmaY", "rho", "rhoBar", "Kinf", "Ko", "delta1", "delta2", "H", "theta", "density")))
        for e, conn in enumerate(mesh.elements):
            ops.element(element, e + 1, *map(int, conn + 1), 1)
        ops.timeSeries("Linear", 1)
        ops.pattern("Plain", 1, 1)
        for n in top:
            ops.sp(int(n) + 1, 3, -float(delta))
        ops.constraints(*strategy.constraints)
        ops.numberer("RCM")
        ops.system(strategy.system)
        ops.test(*strategy.test)
        ops.algorithm(*strategy.algorithm)
        ops.integrator("LoadControl", 1.0 / (steps * strategy.substeps))
        ops.analysis("Static")
        for k in range(1, steps + 1):
            for j in range(strategy.substeps):
                ok = ops.analyze(1)
                step_iterations.append(int(ops.testIter()))
                step_norms.append([float(v) for v in ops.testNorm()[:step_iterations[-1]]])
                if ok < 0:
                    norms = list(ops.testNorm())
                    failure = {"snapshot": k, "substep": j + 1,
                               "top_mm_from": float(delta * ((k - 1) * strategy.substeps + j) / (steps * strategy.substeps)),
                               "top_mm_to": float(delta * ((k - 1) * strategy.substeps + j + 1) / (steps * strategy.substeps)),
                               "iterations": int(ops.testIter()), "last_norms": [float(v) for v in norms[-6:]],
                               "first_norms": [float(v) for v in norms[:6]]}
                    break
            if failure:
                break
            ops.reactions()
            u = np.array([ops.nodeDisp(i + 1) for i in range(nn)])
            stress = np.array([np.reshape(ops.eleResponse(e + 1, "stresses"), (8, 6)).mean(axis=0)
                               for e in range(mesh.n_elements)])[:, _OS_TO_VOIGT]
            out_u.append(u)
            out_s.append(stress)
            out_f.append(-sum(ops.nodeReaction(int(n) + 1, 3) for n in top))
            out_d.append(-float(np.mean(u[top, 2])))
        ops.wipe()
    wall = time.perf_counter() - t0
    log = log_path.read_text(errors="replace")
    log_path.unlink()
    f = np.array(out_f)
    return OpenSeesRun(strategy.name, element, not failure, np.array(out_d), (4.0 if quarter else 1.0) * f / 1000.0,
                       f, np.array(out_u).reshape(-1, nn, 3), np.array(out_s).reshape(-1, mesh.n_elements, 6),
                       wall, failure, log, step_iterations, step_norms)


def summarise_log(log: str, limit: int = 6) -> dict:
    """Counts of OpenSees's messages and the first distinct lines (the log can be very long)."""
    lines = [ln.strip() for ln in log.splitlines() if ln.strip()]
    ignore = ("DruckerPrager nDmaterial", "Process 0 Terminating")
    lines = [ln for ln in lines if not ln.startswith(ignore)]
    distinct: list[str] = []
    for ln in lines:
        key = ln[:80]
        if key not in distinct and len(distinct) < limit:
            distinct.append(key)
    return {"lines": len(lines), "first": distinct,
            "jact_messages": sum("Jact" in ln for ln in lines),
            "normcep_messages": sum("NormCep" in ln for ln in lines),
            "failed_messages": sum("failed" in ln.lower() for ln in lines)}


# ============================================================================================
# The two comparisons
# ============================================================================================

def single_element(p: dict, steps: int, log_dir: Path) -> dict:
    """One 150 mm brick, frictionless plates, 1.5 mm: femubench FE (1x1x1), material point,
    closed form and OpenSees (bbarBrick and stdBrick)."""
    from problems.fe.mesh import box_mesh

    mesh = box_mesh(1, 1, 1, size_mm=(SIZE_MM, SIZE_MM, SIZE_MM))
    mat = femubench_material(p)
    osp = opensees_parameters(**{k: p[k] for k in ("E", "nu", "beta", "psi", "sigma0", "H")})
    resp, wall_fe = femubench_box(mesh, mat, DELTA_MM, steps, "frictionless")
    if not resp.converged:
        raise RuntimeError(f"femubench single element failed: {resp.message}")
    strain = resp.snapshots_mm / SIZE_MM
    x1 = mesh.face("x1")
    ours = {"stress": -resp.stress[:, 0, 2], "lateral": resp.displacements[:, x1, 0].mean(axis=1) / SIZE_MM,
            "eqps": resp.state[:, 0, 0]}
    mp_s, mp_l, mp_e = material_point_uniaxial(mat, strain)
    cf_s, cf_l = uniaxial_closed_form(strain, **{k: p[k] for k in ("E", "nu", "beta", "psi", "sigma0", "H")})
    out = {"psi": p["psi"], "strain": strain, "femubench": ours, "wall_femubench_s": wall_fe,
           "material_point": {"stress": mp_s, "lateral": mp_l, "eqps": mp_e},
           "closed_form": {"stress": cf_s, "lateral": cf_l}, "opensees": {}, "differences": {}}
    for element in ("bbarBrick", "stdBrick"):
        r = opensees_box(mesh, osp, DELTA_MM, steps, "frictionless", element=element, quarter=False, log_dir=log_dir)
        n = len(r.snapshots_mm)
        os_s = -r.stress[:, 0, 2]
        os_l = r.displacements[:, x1, 0].mean(axis=1) / SIZE_MM
        out["opensees"][element] = {"converged": r.converged, "stress": os_s, "lateral": os_l,
                                    "force_stress": r.force_N / SIZE_MM**2, "wall_s": r.wall_s,
                                    "step_iterations": r.step_iterations,
                                    "failure": r.failure, "log": summarise_log(r.log)}
        out["differences"][element] = {
            "snapshots_compared": n,
            "stress_vs_femubench": pointwise_relative_difference(os_s, ours["stress"][:n]),
            "lateral_vs_femubench": pointwise_relative_difference(os_l, ours["lateral"][:n]),
            "stress_vs_closed_form": pointwise_relative_difference(os_s, cf_s[:n]),
            "lateral_vs_closed_form": pointwise_relative_difference(os_l, cf_l[:n]),
            "reaction_vs_element_stress": pointwise_relative_difference(r.force_N / SIZE_MM**2, os_s),
        }
    out["differences"]["femubench"] = {
        "stress_vs_closed_form": pointwise_relative_difference(ours["stress"], cf_s),
        "lateral_vs_closed_form": pointwise_relative_difference(ours["lateral"], cf_l),
        "stress_vs_material_point": pointwise_relative_difference(ours["stress"], mp_s),
        "lateral_vs_material_point": pointwise_relative_difference(ours["lateral"], mp_l),
        "eqps_vs_abs_eps_pl_11": pointwise_relative_difference(ours["eqps"], strain - ours["stress"] / p["E"], floor=1e-12),
    }
    return out


def cube(p: dict, mesh_spec: str, steps: int, all_strategies: bool, log_dir: Path) -> dict:
    """The quarter cube between friction plates: femubench vs OpenSees bbarBrick on the same mesh.

    Every OpenSees attempt is compared with femubench at the same increments (``substeps`` per
    snapshot): both integrate the same equations by backward Euler, so converged answers must
    agree to the solvers' tolerances whatever tangent each Newton uses."""
    from problems.fe.front_face import front_face_operator, measurement_grid
    from problems.fe.mesh import parse_mesh

    mesh = parse_mesh(mesh_spec)
    mat = femubench_material(p)
    osp = opensees_parameters(**{k: p[k] for k in ("E", "nu", "beta", "psi", "sigma0", "H")})
    W_pts = front_face_operator(mesh, FRONT_POINTS)
    W_grid = front_face_operator(mesh, measurement_grid())
    x1 = mesh.face("x1")

    def fields(u):
        """u_h, u_v at the named points and on the 406-point grid, and u_x (bulge) on the front face."""
        if len(u) == 0:
            return {k: np.zeros((0,)) for k in ("uh_pts", "uv_pts", "uh_grid", "uv_grid", "bulge_max")}
        return {"uh_pts": u[:, :, 1] @ W_pts.T, "uv_pts": u[:, :, 2] @ W_pts.T,
                "uh_grid": u[:, :, 1] @ W_grid.T, "uv_grid": u[:, :, 2] @ W_grid.T,
                "bulge_max": u[:, x1, 0].max(axis=1)}

    ours_by_substeps: dict[int, dict] = {}

    def ours(substeps: int) -> dict:
        if substeps not in ours_by_substeps:
            resp, wall = femubench_box(mesh, mat, DELTA_MM, steps, "friction", substeps)
            ours_by_substeps[substeps] = {
                "substeps": substeps, "snapshots_mm": resp.snapshots_mm, "reaction_kN": resp.reaction_kN,
                **fields(resp.displacements), "converged": resp.converged, "message": resp.message,
                "wall_s": wall, "increments": resp.increments, "iterations": resp.iterations, "cuts": resp.cuts,
                "residual_history_last": resp.residual_history[-1] if resp.residual_history else [],
                "residual_history": resp.residual_history,
                "max_eqps": resp.state[:, :, 0].max(axis=1) if len(resp.state) else np.zeros(0),
                "max_I1": resp.stress[:, :, :3].sum(axis=2).max(axis=1) if len(resp.stress) else np.zeros(0)}
        return ours_by_substeps[substeps]

    ours(1)
    attempts = []
    for strategy in (BASELINE,) + CURES:
        r = opensees_box(mesh, osp, DELTA_MM, steps, "friction", strategy=strategy, log_dir=log_dir)
        n = len(r.snapshots_mm)
        f = fields(r.displacements)
        ref = ours(strategy.substeps) if r.converged else ours_by_substeps[1]
        m = min(n, len(ref["snapshots_mm"]))
        diffs = {}
        if m:
            diffs = {
                "femubench_substeps": ref["substeps"],
                "snapshots_compared": m,
                "force": pointwise_relative_difference(r.reaction_kN[:m], ref["reaction_kN"][:m]),
                "u_h_grid": relative_difference(f["uh_grid"][:m], ref["uh_grid"][:m]),
                "u_v_grid": relative_difference(f["uv_grid"][:m], ref["uv_grid"][:m]),
                "bulge_max": pointwise_relative_difference(f["bulge_max"][:m], ref["bulge_max"][:m]),
            }
        attempts.append({"strategy": r.strategy, "substeps": strategy.substeps, "converged": r.converged,
                         "snapshots_mm": r.snapshots_mm, "reaction_kN": r.reaction_kN, **f, "wall_s": r.wall_s,
                         "failure": r.failure, "log": summarise_log(r.log), "differences": diffs,
                         "step_iterations": r.step_iterations,
                         "norms_last_step": r.step_norms[-1] if r.step_norms else [],
                         "step_norms_all": r.step_norms,
                         "norms_first_step": r.step_norms[0] if r.step_norms else [],
                         "max_I1": (r.stress[:, :, :3].sum(axis=2).max(axis=1) if n else np.zeros(0))})
        if r.converged and not all_strategies:
            break
    return {"psi": p["psi"], "mesh": mesh.info(), "femubench": ours_by_substeps[1],
            "femubench_runs": list(ours_by_substeps.values()), "opensees": attempts,
            "tension_cutoff_I1": tension_cutoff_I1(osp), "front_points": FRONT_POINTS}


# ============================================================================================
# Why OpenSees's Newton struggles: its material tangent
# ============================================================================================

#: strain states (engineering, femubench Voigt order) at which the tangent is audited
AUDIT_STRAINS = {
    "uniaxial-like (axisymmetric)": np.array([3e-4, 3e-4, -2e-3, 0.0, 0.0, 0.0]),
    "general 3-D": np.array([5e-4, 2e-4, -2e-3, 4e-4, -3e-4, 2e-4]),
}


def dp_return(eps, osp: dict, tangent_norm: str = "trial"):
    """One backward-Euler step of OpenSees's cone (single surface, theta = 1, linear hardening)
    from the virgin state to the total strain ``eps`` (engineering, femubench Voigt order),
    re-derived here: radial return ``s = s_tr - 2 G gamma n``, ``I1 = I1_tr - 9 K rhoBar gamma``,
    ``gamma = f_tr / (2 G + 2/3 H + 9 K rho rhoBar)``, and the algorithmic tangent

        C = Ce - (2G n + 3K rhoBar 1)(2G n + 3K rho 1)/den - 4 G^2 gamma / ||eta|| (IIdev - n n).

    ``tangent_norm = "trial"`` uses ||eta|| = ||s_tr|| (the consistent tangent);
    ``"returned"`` uses ||s_n+1|| = ||s_tr|| - 2 G gamma, as OpenSees does (see the note).
    Returns (stress, tangent) in femubench's Voigt order."""
    K, G, rho, rb = osp["K"], osp["G"], osp["rho"], osp["rhoBar"]
    one = np.array([1.0, 1, 1, 0, 0, 0])
    IIdev = np.zeros((6, 6))
    IIdev[:3, :3] = np.eye(3) - 1.0 / 3.0
    IIdev[3:, 3:] = 0.5 * np.eye(3)
    Ce = K * np.outer(one, one) + 2.0 * G * IIdev
    sig = Ce @ np.asarray(eps, float)
    I1 = sig[:3].sum()
    s = sig - I1 / 3.0 * one
    norm = math.sqrt((s[:3] ** 2).sum() + 2.0 * (s[3:] ** 2).sum())
    f = norm + rho * I1 - _SQ23 * osp["sigmaY"]
    if f <= 0.0:
        return sig, Ce
    n = s / norm
    den = 2.0 * G + 2.0 / 3.0 * osp["H"] * osp["theta"] + 9.0 * K * rho * rb
    gamma = f / den
    sig = sig - 3.0 * K * rb * gamma * one - 2.0 * G * gamma * n
    eta = norm if tangent_norm == "trial" else norm - 2.0 * G * gamma
    C = (Ce - np.outer(2.0 * G * n + 3.0 * K * rb * one, 2.0 * G * n + 3.0 * K * rho * one) / den
         - 4.0 * G * G * gamma / eta * (IIdev - np.outer(n, n)))
    return sig, C


def _one_element_prescribed(ops, u, osp, want_matrix=False):
    """Unit stdBrick with all 24 displacements prescribed (penalty), one step from the virgin
    state: element nodal forces, the assembled tangent (penalty on the diagonal only) and the
    Gauss-point-mean stress."""
    from problems.fe.mesh import HEX_CORNERS

    ops.wipe()
    ops.model("basic", "-ndm", 3, "-ndf", 3)
    for i, c in enumerate(HEX_CORNERS.astype(float)):
        ops.node(i + 1, *map(float, c))
    ops.nDMaterial("DruckerPrager", 1, *(float(osp[k]) for k in (
        "K", "G", "sigmaY", "rho", "rhoBar", "Kinf", "Ko", "delta1", "delta2", "H", "theta", "density")))
    ops.element("stdBrick", 1, *range(1, 9), 1)
    ops.timeSeries("Linear", 1)
    ops.pattern("Plain", 1, 1)
    for i in range(8):
        for d in range(3):
            ops.sp(i + 1, d + 1, float(u[i, d]))
    ops.constraints("Penalty", 1e14, 1e14)
    ops.numberer("Plain")
    ops.system("FullGeneral")
    ops.test("NormDispIncr", 1e-15, 20)
    ops.algorithm("Newton")
    ops.integrator("LoadControl", 1.0)
    ops.analysis("Static")
    if ops.analyze(1) < 0:
        raise RuntimeError("one-element prescribed-displacement analysis failed")
    forces = np.array(ops.eleResponse(1, "forces"))
    A = np.array(ops.printA("-ret")).reshape(24, 24) if want_matrix else None
    eq = np.array([ops.nodeDOFs(i + 1) for i in range(8)]).ravel() if want_matrix else None
    stress = np.reshape(ops.eleResponse(1, "stresses"), (8, 6)).mean(axis=0)[_OS_TO_VOIGT]
    return forces, (A[np.ix_(eq, eq)] if want_matrix else None), stress


def tangent_audit(osp: dict, log_dir: Path) -> list[dict]:
    """Recover the material tangent OpenSees hands to the element and compare it with the
    derivative of OpenSees's own stress (finite differences) and with the two formulas of
    :func:`dp_return`. Homogeneous strain in a unit stdBrick, so all Gauss points share one
    tangent C and the element matrix is linear in C: ``K_e = sum_g B_g^T C B_g dV_g``; the 36
    entries of C follow by least squares from the off-diagonal entries of K_e."""
    from problems.fe.element import GAUSS_WEIGHTS, gradients, strain_operator
    from problems.fe.mesh import HEX_CORNERS

    ops = load_opensees()
    X = HEX_CORNERS.astype(float)
    dNdx, detJ = gradients(X[None])
    B = strain_operator(dNdx)[0]
    dV = detJ[0] * GAUSS_WEIGHTS
    M = np.zeros((576, 36))
    for k in range(36):
        Ck = np.zeros(36)
        Ck[k] = 1.0
        Ck = Ck.reshape(6, 6)
        M[:, k] = sum(B[g].T @ Ck @ B[g] * dV[g] for g in range(8)).ravel()
    off = ~np.eye(24, dtype=bool).ravel()
    out = []
    log_path = Path(tempfile.mkstemp(prefix="opensees_audit_", suffix=".log", dir=log_dir)[1])
    with captured_output(log_path):
        for name, eps in AUDIT_STRAINS.items():
            E = np.array([[eps[0], eps[5] / 2, eps[4] / 2], [eps[5] / 2, eps[1], eps[3] / 2],
                          [eps[4] / 2, eps[3] / 2, eps[2]]])
            u = X @ E.T
            _, A, stress = _one_element_prescribed(ops, u, osp, want_matrix=True)
            h = 1e-9
            Kfd = np.column_stack([
                (_one_element_prescribed(ops, (u.ravel() + h * e).reshape(8, 3), osp)[0]
                 - _one_element_prescribed(ops, (u.ravel() - h * e).reshape(8, 3), osp)[0]) / (2 * h)
                for e in np.eye(24)])
            C_os = np.linalg.lstsq(M[off], A.ravel()[off], rcond=None)[0].reshape(6, 6)
            C_fd = np.linalg.lstsq(M, Kfd.ravel(), rcond=None)[0].reshape(6, 6)
            s_ref, C_trial = dp_return(eps, osp, "trial")
            _, C_ret = dp_return(eps, osp, "returned")
            scale = np.abs(C_fd).max()
            out.append({"state": name, "strain": eps, "stress_opensees": stress, "stress_rederived": s_ref,
                        "stress_difference": float(np.abs(stress - s_ref).max() / np.abs(s_ref).max()),
                        "C_opensees": C_os, "C_finite_difference": C_fd,
                        "opensees_vs_fd": float(np.abs(C_os - C_fd).max() / scale),
                        "consistent_formula_vs_fd": float(np.abs(C_trial - C_fd).max() / scale),
                        "returned_norm_formula_vs_opensees": float(np.abs(C_ret - C_os).max() / scale)})
        ops.wipe()
    log_path.unlink()
    return out


# ============================================================================================
# Output
# ============================================================================================

def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    if isinstance(x, (np.floating, float)):
        return None if not np.isfinite(x) else float(x)
    if isinstance(x, np.integer):
        return int(x)
    return x


_BULKY = ("uh_grid", "uv_grid", "step_norms_all", "residual_history")


def _slim(x):
    """The report without the per-point grids and per-step residual histories (plots only)."""
    if isinstance(x, dict):
        return {k: _slim(v) for k, v in x.items() if k not in _BULKY}
    if isinstance(x, list):
        return [_slim(v) for v in x]
    return x


def print_report(report: dict) -> None:
    print(f"openseespy {report['openseespy']}  |  total wall time {report['wall_s']:.1f} s")
    print("\nParameter mapping (femubench linear, K = 1 -> OpenSees DruckerPrager):")
    for m in report["mappings"]:
        osp = m["opensees"]
        print(f"  psi = {m['psi']:>4g} deg: " + "  ".join(f"{k}={v:.6g}" for k, v in osp.items())
              + f"  | tension cutoff I1 = {m['tension_cutoff_I1']:.4g} MPa")
    print("\nSingle element (150 mm, frictionless, 1.5 mm): max pointwise relative difference")
    print(f"  {'psi':>4} {'model':22} {'axial stress':>13} {'lateral strain':>15} {'final sigma MPa':>16} {'final eps_lat':>14}")
    for se in report["single_element"]:
        d = se["differences"]
        print(f"  {se['psi']:>4g} {'femubench vs closed':22} {d['femubench']['stress_vs_closed_form']:13.2e} "
              f"{d['femubench']['lateral_vs_closed_form']:15.2e} {se['femubench']['stress'][-1]:16.4f} "
              f"{se['femubench']['lateral'][-1]:14.6e}")
        print(f"  {se['psi']:>4g} {'femubench vs mat.point':22} {d['femubench']['stress_vs_material_point']:13.2e} "
              f"{d['femubench']['lateral_vs_material_point']:15.2e}")
        for el, o in se["opensees"].items():
            dd = d[el]
            print(f"  {se['psi']:>4g} {'OpenSees ' + el + ' vs fem.':22} {dd['stress_vs_femubench']:13.2e} "
                  f"{dd['lateral_vs_femubench']:15.2e} {o['stress'][-1]:16.4f} {o['lateral'][-1]:14.6e}"
                  f"  ({sum(o['step_iterations'])} Newton iterations in {len(o['step_iterations'])} steps)"
                  f"{'' if o['converged'] else '  (FAILED: ' + str(o['failure']) + ')'}")
    for cb in report.get("cube", []):
        print(f"\nQuarter cube {cb['mesh']['nx']}x{cb['mesh']['ny']}x{cb['mesh']['nz']}, friction plates, "
              f"psi = {cb['psi']:g} deg (OpenSees tension cutoff at I1 = {cb['tension_cutoff_I1']:.4g} MPa)")
        for o in cb["femubench_runs"]:
            print(f"  femubench, {o['substeps']:3d} increment(s)/snapshot: "
                  f"{'converged' if o['converged'] else 'FAILED ' + o['message']}, F = {o['reaction_kN'][-1]:.3f} kN "
                  f"at {o['snapshots_mm'][-1]:.3g} mm, {o['increments']} increments, {o['iterations']} iterations, "
                  f"{o['wall_s']:.1f} s, max I1 {o['max_I1'].max():.3g} MPa")
        for a in cb["opensees"]:
            head = f"  OpenSees [{a['strategy']}]: "
            its = a["step_iterations"]
            if a["converged"]:
                d = a["differences"]
                print(head + f"converged, {len(its)} steps, {sum(its)} iterations (max {max(its)}/step), "
                      f"{a['wall_s']:.1f} s, F = {a['reaction_kN'][-1]:.3f} kN;\n      max rel. diff. vs femubench "
                      f"at the same increments: force {d['force']:.2e}, u_h grid {d['u_h_grid']:.2e}, "
                      f"u_v grid {d['u_v_grid']:.2e}, bulge {d['bulge_max']:.2e}")
            else:
                fl = a["failure"]
                print(head + f"FAILED at snapshot {fl['snapshot']} (step {fl['top_mm_from']:.4g} -> {fl['top_mm_to']:.4g} mm) "
                      f"after {fl['iterations']} iterations, {sum(its)} in all, {a['wall_s']:.1f} s;\n      norms "
                      f"{' '.join('%.2g' % v for v in fl['first_norms'])} ... {' '.join('%.2g' % v for v in fl['last_norms'][-3:])}; "
                      f"{len(a['snapshots_mm'])} snapshots done; OpenSees log: {a['log']['first'][:2]}")
        good = [a for a in cb["opensees"] if a["converged"]]
        if good:
            a = good[0]
            ref = next(o for o in cb["femubench_runs"] if o["substeps"] == a["substeps"])
            m = min(len(a["snapshots_mm"]), len(ref["snapshots_mm"]))
            print(f"  front-face points at {ref['snapshots_mm'][m - 1]:.3g} mm, femubench ({ref['substeps']} incr./snapshot)"
                  f" / OpenSees [{a['strategy']}] (y, z mm: u_h, u_v mm):")
            for i, (y, z) in enumerate(cb["front_points"]):
                print(f"    ({y:5.1f}, {z:5.1f}): u_h {ref['uh_pts'][m - 1][i]:+.6f} / {a['uh_pts'][m - 1][i]:+.6f}   "
                      f"u_v {ref['uv_pts'][m - 1][i]:+.6f} / {a['uv_pts'][m - 1][i]:+.6f}")
            o1 = cb["femubench"]
            print(f"  step-size effect (femubench 10 vs {ref['substeps'] * 10} increments): force "
                  f"{pointwise_relative_difference(o1['reaction_kN'], ref['reaction_kN']):.2e}, u_h grid "
                  f"{relative_difference(o1['uh_grid'], ref['uh_grid']):.2e}")
    if report.get("tangent_audit"):
        print("\nOpenSees material tangent (psi = 35) vs the derivative of its own stress (one element, "
              "homogeneous strain), max |dC| / max |C|:")
        for t in report["tangent_audit"]:
            print(f"  {t['state']:30}: OpenSees tangent {t['opensees_vs_fd']:.2e}, consistent formula "
                  f"{t['consistent_formula_vs_fd']:.2e}; OpenSees = formula with the returned ||s|| to "
                  f"{t['returned_norm_formula_vs_opensees']:.2e}; stress vs re-derived return {t['stress_difference']:.1e}")


def plot(report: dict, out: Path) -> list[str]:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib not installed: no plots")
        return []
    files = []
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    colours = ["C0", "C3", "C2", "C4"]
    for c, se in zip(colours, report["single_element"]):
        e = 1e3 * np.asarray(se["strain"])
        lab = f"psi={se['psi']:g}"
        e0 = np.r_[0.0, e]
        for ax, key in zip(axes, ("stress", "lateral")):
            scale = 1.0 if key == "stress" else 1e3
            ax.plot(e0, scale * np.r_[0.0, se["closed_form"][key]], "-", color=c, lw=3, alpha=0.3,
                    label=f"closed form, {lab}")
            ax.plot(e0, scale * np.r_[0.0, se["femubench"][key]], "-", color=c, lw=1.2,
                    label=f"femubench FE 1x1x1, {lab}")
            ax.plot(e0, scale * np.r_[0.0, se["material_point"][key]], ":", color="k", lw=1)
            for mk, (el, o) in zip(("o", "x"), se["opensees"].items()):
                n = len(o[key])
                ax.plot(e[:n][::3], scale * np.asarray(o[key])[::3], mk, color=c, ms=5, mfc="none",
                        label=f"OpenSees {el}, {lab}")
    axes[0].set_xlabel("axial shortening (1e-3)")
    axes[0].set_ylabel("axial stress, compression (MPa)")
    axes[1].set_xlabel("axial shortening (1e-3)")
    axes[1].set_ylabel("lateral strain (1e-3)")
    axes[0].legend(fontsize=7)
    axes[0].set_title("single element, uniaxial compression")
    axes[1].set_title("dilatancy (dotted: femubench material point)")
    fig.tight_layout()
    path = out / "single_element.png"
    fig.savefig(path, dpi=120)
    plt.close(fig)
    files.append(str(path))

    if report.get("cube"):
        fig, axes = plt.subplots(1, 3, figsize=(16, 4.6))
        for c, cb in zip(colours, report["cube"]):
            ours = cb["femubench"]
            axes[0].plot(np.r_[0, ours["snapshots_mm"]], np.r_[0, ours["reaction_kN"]], "-", color=c,
                         label=f"femubench, psi={cb['psi']:g}")
            for a in cb["opensees"]:
                if len(a["snapshots_mm"]):
                    axes[0].plot(a["snapshots_mm"], a["reaction_kN"], "o" if a["converged"] else "D", color=c,
                                 mfc="none", ms=7 if a["converged"] else 5,
                                 label=f"OpenSees [{a['strategy']}]{'' if a['converged'] else ' (failed after)'}, "
                                       f"psi={cb['psi']:g}")
            conv = [a for a in cb["opensees"] if a["converged"]]
            if conv:
                a = conv[0]
                ref = next(o for o in cb["femubench_runs"] if o["substeps"] == a["substeps"])
                m = min(len(a["snapshots_mm"]), len(ref["snapshots_mm"])) - 1
                # u_h along the front face y = 70 mm: the grid is z fastest, 29 z values per y
                grid_z = np.arange(5.0, 145.0 + 1e-9, 5.0)
                nz = grid_z.size
                axes[1].plot(np.asarray(ref["uh_grid"][m])[-nz:], grid_z, "-", color=c,
                             label=f"femubench, psi={cb['psi']:g}")
                axes[1].plot(np.asarray(a["uh_grid"][m])[-nz:], grid_z, "o", color=c, mfc="none",
                             label=f"OpenSees, psi={cb['psi']:g}")
                axes[1].set_title(f"front face y = 70 mm at {ref['snapshots_mm'][m]:.3g} mm "
                                  f"(both at OpenSees's converged step size)", fontsize=10)
                k = int(np.argmax(a["step_iterations"]))
                nrm = np.asarray(a["step_norms_all"][k])
                axes[2].semilogy(np.arange(1, nrm.size + 1), nrm / nrm[0], "o-", color=c, mfc="none",
                                 label=f"OpenSees [{a['strategy']}], step {k + 1}, psi={cb['psi']:g}")
                hist = ref["residual_history"][k] if len(ref["residual_history"]) > k else []
                if len(hist):
                    axes[2].semilogy(np.arange(1, len(hist) + 1), np.asarray(hist) / hist[0], "s-", color=c,
                                     label=f"femubench, step {k + 1}, psi={cb['psi']:g}")
        axes[2].set_xlabel("Newton iteration")
        axes[2].set_ylabel("residual / first residual")
        axes[2].set_title("convergence rate")
        axes[2].legend(fontsize=6)
        axes[0].set_xlabel("plate displacement (mm)")
        axes[0].set_ylabel("plate force, whole cube (kN)")
        axes[0].set_title("quarter cube, friction plates")
        axes[0].legend(fontsize=6)
        axes[1].set_xlabel("u_h = u_y (mm)")
        axes[1].set_ylabel("z (mm)")
        axes[1].legend(fontsize=7)
        fig.tight_layout()
        path = out / "cube.png"
        fig.savefig(path, dpi=120)
        plt.close(fig)
        files.append(str(path))
    return files


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default="results/crosscheck", help="output folder (JSON + PNG)")
    ap.add_argument("--mesh", default="coarse", help="cube mesh: coarse | paper | NX,NY,NZ")
    ap.add_argument("--skip-cube", action="store_true", help="only the single element")
    ap.add_argument("--psi", default="35,15", help="dilatancy angles to run, degrees (<= beta = 35)")
    ap.add_argument("--steps", type=int, default=10, help="cube load steps (snapshots)")
    ap.add_argument("--element-steps", type=int, default=60, help="single-element load steps")
    ap.add_argument("--all-strategies", action="store_true",
                    help="run every OpenSees solution strategy on the cube, not only until one converges")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    load_opensees()
    psis = [float(s) for s in args.psi.split(",") if s.strip()]
    report = {"openseespy": openseespy_version(), "reference": REFERENCE, "mappings": [], "single_element": [],
              "cube": [], "tangent_audit": []}
    with tempfile.TemporaryDirectory() as tmp:
        for psi in psis:
            p = {**REFERENCE, "psi": psi}
            osp = opensees_parameters(**p)
            report["mappings"].append({"psi": psi, "opensees": osp, "tension_cutoff_I1": tension_cutoff_I1(osp)})
            report["single_element"].append(single_element(p, args.element_steps, Path(tmp)))
            if psi == psis[0]:
                report["tangent_audit"] = tangent_audit(osp, Path(tmp))
            if not args.skip_cube:
                report["cube"].append(cube(p, args.mesh, args.steps, args.all_strategies, Path(tmp)))
    report["wall_s"] = time.perf_counter() - t0
    report["plots"] = plot(report, out)
    (out / "opensees_dp.json").write_text(json.dumps(_jsonable(_slim(report)), indent=1))
    print_report(report)
    print(f"\nwrote {out / 'opensees_dp.json'}" + "".join(f", {f}" for f in report["plots"]))
    return report


if __name__ == "__main__":
    main()

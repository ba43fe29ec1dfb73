"""What the OpenSees results are compared with: femubench's own answers (material, material-point
driver, FE run of the plate test), the exact uniaxial solution, and the two difference measures.

Units: MPa, mm, kN; strains dimensionless; angles in degrees.
"""

from __future__ import annotations

import math
import time

import numpy as np

from bench.crosscheck.mapping import MAPPED

#: single-element edge and cube height (mm), and the plate displacement (mm)
SIZE_MM = 150.0
DELTA_MM = 1.5


def mapped(p: dict) -> dict:
    """The parameters of ``p`` that the mapping and the closed form take (:data:`MAPPED`)."""
    return {k: p[k] for k in MAPPED}


def femubench_material(p: dict):
    """femubench's linear Drucker-Prager form with K = 1 and compression hardening."""
    from problems.materials.drucker_prager import make_material

    return make_material(
        "linear",
        "compression",
        {
            "E": p["E"],
            "nu": p["nu"],
            "beta": p["beta"],
            "K": 1.0,
            "psi": p["psi"],
            "sigma0": p["sigma0"],
            "H": p["H"],
        },
    )


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
    resp = run(
        discretise(mesh), material, Loading(delta, steps, plates), NewtonSettings(substeps=substeps)
    )
    return resp, time.perf_counter() - t0


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
    tp = math.tan(math.radians(psi))
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

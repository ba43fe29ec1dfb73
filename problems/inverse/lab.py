"""Parameters for a lab: bounds and start of each Drucker-Prager variant from the test itself.

A laboratory knows no reference values. :func:`lab_case` builds the identification case of a
variant (form x hardening) for an imported experiment from documented heuristics applied to its
own data (:func:`curve_summary`), never from a case's reference:

* **E** from the DIC strain: in the central half of the face (|z - h/2| <= h/4) the vertical
  strain of each image is the slope of u_v against z (least squares with a y term for what is
  left of a rotation); E is the least-squares slope through the origin of the nominal stress
  F / A against that strain over the images below 40 % of the peak force (the first image if
  none is). Bounds [0.5, 2] x.
* **The uniaxial yield stress sigma_c** from the nominal stress-strain curve (F / A against
  delta / h): the intersection of its initial secant line through the origin (the first
  image) with the line through its last two images (the hardening branch). Where the curve is
  still nearly linear (last slope > 90 % of the first) sigma_c is the last nominal stress.
* **H** from the same two slopes: the tangent-to-initial ratio r = E_t / E of the curve gives the
  uniaxial hardening modulus H_c = E r / (1 - r) (linear hardening, ``sigma = sigma_c + H_c
  eps_p``), kept >= 0.02 E when the curve softens. Bounds [0.2, 5] x.
* **The shape of the surface**, which one uniaxial test barely sees: beta 30 deg in [15, 55],
  psi 10 deg in [2, 40], K 0.9 in [0.778, 1], b 1.4 in [1.05, 2.5] (ranges of normal concrete),
  and the hydrostatic tension strength pt0 from the peak stress f_c by the fib Model Code's mean
  tensile strength f_ctm = 0.3 f_c^(2/3) (MPa), bounds [0.3, 3] x.
* **sigma0 of the variant**: the yield stress, in the variant's hardening test (compression,
  shear or tension), of the initial surface of its form through sigma_c with the shape above
  (:func:`problems.inverse.cases.sigma0_of`); H scaled by the same ratio. Bounds [0.4, 2] x.

The case's ``reference`` is the start (z = x / start in the solvers; no reference is known).
"""

from __future__ import annotations

import numpy as np

from problems.inverse.case import Case, Parameter
from problems.inverse.cases import ACTIVE, FIXED, UNITS, get_case, sigma0_of
from problems.inverse.data import Dataset

#: the surface shape a start assumes and its box: (start, lower, upper)
SHAPE = {"beta": (30.0, 15.0, 55.0), "psi": (10.0, 2.0, 40.0), "K": (0.9, 0.778, 1.0)}
B_START = (1.4, 1.05, 2.5)
#: relative boxes of the parameters derived from the test: (lower, upper) x start
RELATIVE = {"E": (0.5, 2.0), "sigma0": (0.4, 2.0), "H": (0.2, 5.0), "pt0": (0.3, 3.0)}
#: images below this fraction of the peak force count as elastic for E
ELASTIC_FRACTION = 0.4


def vertical_strain(data: Dataset) -> np.ndarray:
    """(N,) vertical strain (compression positive) of each image in the central half of the face
    (|z - h/2| <= h/4): minus the slope of u_v against z (with a y term), -."""
    H = data.settings.specimen_mm[2]
    y = np.array(data.meta.get("fold_sign", np.ones(len(data.points)))) * data.points[:, 0]
    z = data.points[:, 1]
    mid = np.abs(z - H / 2) <= H / 4
    if mid.sum() < 3:
        mid = np.ones_like(z, bool)
    M = np.column_stack([np.ones(mid.sum()), z[mid], y[mid]])
    coef, *_ = np.linalg.lstsq(M, data.u_v[:, mid].T, rcond=None)
    return -coef[1]


def curve_summary(data: Dataset) -> dict:
    """What the heuristics read off a test (module docstring): area (mm^2), peak force (kN),
    E from the DIC strain and from the force (MPa), sigma_c, the tangent ratio r, H_c, f_c,
    f_ctm (MPa)."""
    W, H = data.settings.specimen_mm[1], data.settings.specimen_mm[2]
    area = data.settings.specimen_mm[0] * W
    F = np.asarray(data.reaction_kN, float)
    d = np.asarray(data.snapshots_mm, float)
    stress = F * 1e3 / area  # MPa
    strain = d / H
    eps = vertical_strain(data)
    elastic = F <= ELASTIC_FRACTION * F.max()
    if not elastic.any():
        elastic = np.arange(len(F)) == 0
    ok = elastic & (eps > 0)
    E_dic = float(np.sum(stress[ok] * eps[ok]) / np.sum(eps[ok] ** 2)) if ok.any() else np.nan
    k0 = stress[0] / strain[0]  # initial secant of the nominal curve, MPa
    kt = (stress[-1] - stress[-2]) / (strain[-1] - strain[-2]) if len(F) > 1 else k0
    r = kt / k0
    if r < 0.9:
        eps_y = (stress[-1] - kt * strain[-1]) / (k0 - kt)
        sigma_c = float(k0 * eps_y)
    else:
        sigma_c = float(stress[-1])
    E = E_dic if np.isfinite(E_dic) and E_dic > 0 else float(k0)
    H_c = float(E * r / (1.0 - r)) if 0.0 < r < 0.98 else np.nan
    if not np.isfinite(H_c) or H_c < 0.02 * E:
        H_c = 0.02 * E
    f_c = float(stress.max())
    return {
        "area_mm2": float(area),
        "peak_force_kN": float(F.max()),
        "E_dic_MPa": E_dic,
        "E_force_MPa": float(k0),
        "E_MPa": E,
        "tangent_ratio": float(r),
        "sigma_c_MPa": sigma_c,
        "H_c_MPa": H_c,
        "f_c_MPa": f_c,
        "f_ctm_MPa": 0.3 * f_c ** (2.0 / 3.0),
    }


def lab_case(variant: str, data: Dataset, summary: dict | None = None) -> Case:
    """The identification case of ``variant`` (a case name ``form-hardening``) for the test
    ``data``: its parameters with start and bounds from :func:`curve_summary` (module
    docstring); ``reference`` = start."""
    base = get_case(variant)
    s = summary or curve_summary(data)
    shape = {k: v[0] for k, v in SHAPE.items()} | {"b": B_START[0], "pt0": s["f_ctm_MPa"]}
    surface = {k: shape[k] for k in ("beta", "K", "pt0", "b")}
    sigma0 = sigma0_of(base.form, base.hardening, s["sigma_c_MPa"], **surface)
    start = {
        "E": s["E_MPa"],
        "sigma0": sigma0,
        "H": s["H_c_MPa"] * sigma0 / s["sigma_c_MPa"],
        **shape,
    }
    if base.form == "hyperbolic" and base.hardening == "tension":
        # its surface needs pt0 > sigma0 / 3 (docs/drucker_prager.md)
        start["pt0"] = max(start["pt0"], 0.5 * sigma0)
    params = []
    for name in ACTIVE[base.form]:
        v = float(start[name])
        if name in SHAPE:
            lo, hi = SHAPE[name][1:]
        elif name == "b":
            lo, hi = B_START[1:]
        else:
            lo, hi = (v * f for f in RELATIVE[name])
        params.append(Parameter(name, UNITS[name], v, lo, hi))
    return Case(
        base.name,
        base.form,
        base.hardening,
        tuple(params),
        dict(FIXED),
        derive=base.derive,
        initial=tuple(p.reference for p in params),
    )

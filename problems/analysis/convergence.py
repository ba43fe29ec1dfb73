"""Mesh convergence of the forward model: observed order, Richardson extrapolation, errors in
sigma units and the linearised parameter bias of a mesh (the mathematics; the study's runs and
files are in :mod:`bench.studies.convergence`).

A *family* is a sequence of meshes of one element and one grading refined by element count
(h_0 > h_1 > h_2 > ..., h the mean element edge, mm). For three successive members with answers
q_0, q_1, q_2 (a number or a whole measurement block) the observed order p solves

    |q_1 - q_0| / |q_2 - q_1| = (h_0^p - h_1^p) / (h_1^p - h_2^p)

(norms for blocks; any refinement ratios), and the Richardson extrapolation of the last two is

    q_inf = q_2 + (q_2 - q_1) h_2^p / (h_1^p - h_2^p).

Errors are in units of the data's noise: sigma = 1 um / sqrt(12) (the rounding of a displacement
to 1 um) for each front-face displacement and 1 kN for the plate force (issue 25). The linearised
bias of a mesh is the Gauss-Newton step a perfect optimiser would take from the reference x_ref,
when the mesh's response at x_ref misses the reference data by r = U_mesh(x_ref) - U_ref:
dx = -(J^T W J)^-1 J^T W r, W = diag(1 / sigma^2), J the mesh's exact Jacobian; restricted to
the rows of a measurement region (a plate margin, :func:`plate_margin_study`) it is the bias of a
fit of that region, and sqrt diag (J^T W J)^-1 the noise sd of its estimate. With
r = U_ref - round(U_ref) (the reference's rounding to the data's resolution) the same step is the
rounding floor (:func:`rounding_floor`): what the exact model finds on the rounded data.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq

from problems.inverse import layout

#: one front-face displacement's noise, mm: the rounding of a value to 1 um
SIGMA_DISPLACEMENT_MM = 1e-3 / math.sqrt(12.0)
#: the plate force's noise, kN
SIGMA_FORCE_KN = 1.0
#: observed orders outside this range are reported, but extrapolation uses the clipped value
ORDER_RANGE = (0.5, 4.0)
#: the last two observed orders of an asymptotic family agree within this fraction
ORDER_AGREEMENT = 0.25


def element_size_mm(volume_mm3: float, n_elements: int) -> float:
    """Mean element edge of a mesh, mm: (volume / elements)^(1/3)."""
    return (float(volume_mm3) / int(n_elements)) ** (1.0 / 3.0)


def observed_order(h, q) -> float:
    """Observed order p of three successive answers ``q`` (3, ...) on meshes of sizes ``h`` (3,)
    mm, coarse to fine (see the module docstring); nan when the differences do not shrink
    monotonically (no asymptotic range) or p would lie outside (0.05, 12)."""
    h = np.asarray(h, float)
    q = np.asarray(q, float).reshape(3, -1)
    if not (h[0] > h[1] > h[2] > 0):
        raise ValueError(f"mesh sizes h = {h.tolist()} mm must decrease (coarse to fine)")
    d1, d2 = np.linalg.norm(q[1] - q[0]), np.linalg.norm(q[2] - q[1])
    if q.shape[1] == 1 and (q[1, 0] - q[0, 0]) * (q[2, 0] - q[1, 0]) <= 0:
        return math.nan  # oscillating: no order
    if not (d1 > 0 and d2 > 0):
        return math.nan
    target = math.log(d1 / d2)

    def gap(p):
        return math.log((h[0] ** p - h[1] ** p) / (h[1] ** p - h[2] ** p)) - target

    lo, hi = 0.05, 12.0
    if gap(lo) * gap(hi) > 0:
        return math.nan
    return float(brentq(gap, lo, hi, xtol=1e-10))


def richardson(h1: float, h2: float, q1, q2, p: float) -> np.ndarray:
    """Richardson extrapolation to h = 0 of the answers ``q1``, ``q2`` on meshes of sizes
    ``h1 > h2`` (mm) with order ``p``."""
    q1, q2 = np.asarray(q1, float), np.asarray(q2, float)
    return q2 + (q2 - q1) * h2**p / (h1**p - h2**p)


def noise_sd(n_snapshots: int, n_points: int) -> np.ndarray:
    """Noise standard deviation of each entry of the measurement vector (mm or kN)."""
    b = layout.blocks(n_snapshots, n_points)
    sd = np.empty(layout.size(n_snapshots, n_points))
    sd[b["displacement"]] = SIGMA_DISPLACEMENT_MM
    sd[b["force"]] = SIGMA_FORCE_KN
    return sd


def extrapolate(h, values, n_snapshots: int, n_points: int) -> dict:
    """Observed orders and the Richardson-extrapolated measurement vector of the last three
    members of a family.

    h      : (k >= 3,) element sizes, mm, coarse to fine
    values : (k, 2 N m + N) measurement vectors at the same parameters

    Returns ``asymptotic`` (:func:`asymptotic`), ``order_field`` (from the norm of the front-face
    displacement differences),
    ``order_force`` (force at the last snapshot), ``orders_field_all`` (every triple),
    ``values`` (the extrapolated vector: displacements with the field order, forces with the force
    order, each clipped to :data:`ORDER_RANGE`; the finest member where an order is nan) and
    ``finest_error_sigma`` (RMS front-face distance of the finest member to the extrapolation, in
    sigma: Richardson's estimate of its own error).
    """
    h = np.asarray(h, float)
    v = np.asarray(values, float)
    if len(h) < 3 or v.shape[0] != len(h):
        raise ValueError(f"extrapolation needs >= 3 meshes with answers, got {len(h)}")
    b = layout.blocks(n_snapshots, n_points)
    disp, force = b["displacement"], b["force"]
    triples = [slice(i, i + 3) for i in range(len(h) - 2)]
    orders_field = [observed_order(h[t], v[t, disp]) for t in triples]
    orders_force = [observed_order(h[t], v[t, force][:, -1]) for t in triples]
    p_u, p_f = orders_field[-1], orders_force[-1]
    out = v[-1].copy()
    for sl, p in ((disp, p_u), (force, p_f)):
        if np.isfinite(p):
            out[sl] = richardson(
                h[-2], h[-1], v[-2, sl], v[-1, sl], float(np.clip(p, *ORDER_RANGE))
            )
    return {
        "asymptotic": asymptotic(orders_field, orders_force),
        "order_field": p_u,
        "order_force": p_f,
        "orders_field_all": orders_field,
        "orders_force_all": orders_force,
        "values": out,
        "finest_error_sigma": errors(v[-1], out, n_snapshots, n_points)["rms_sigma"],
    }


def asymptotic(orders_field, orders_force, tolerance: float = ORDER_AGREEMENT) -> bool:
    """True when the observed orders of the last two triples agree, field and force each within
    ``tolerance`` (relative): the family is in its asymptotic range, where Richardson's
    extrapolation and error estimate hold. False with fewer than two triples (unknown)."""
    for orders in (orders_field, orders_force):
        if len(orders) < 2 or not np.all(np.isfinite(orders[-2:])):
            return False
        if abs(orders[-1] - orders[-2]) > tolerance * abs(orders[-1]):
            return False
    return True


def errors(values, reference, n_snapshots: int, n_points: int) -> dict:
    """A mesh's answer against a reference measurement vector: ``rms_sigma`` (RMS front-face
    displacement error, both components and every snapshot, in sigma), ``force_rms_sigma`` (RMS
    force error over the snapshots, in sigma = kN) and ``force_last_pct`` (force error at the last
    snapshot, %)."""
    v, ref = np.asarray(values, float), np.asarray(reference, float)
    b = layout.blocks(n_snapshots, n_points)
    du = v[b["displacement"]] - ref[b["displacement"]]
    df = v[b["force"]] - ref[b["force"]]
    return {
        "rms_sigma": float(np.sqrt(np.mean(du**2)) / SIGMA_DISPLACEMENT_MM),
        "force_rms_sigma": float(np.sqrt(np.mean(df**2)) / SIGMA_FORCE_KN),
        "force_last_pct": float(100.0 * df[-1] / ref[b["force"]][-1]),
    }


def linearised_bias(jacobian, residual, sd, x_ref) -> np.ndarray:
    """Relative Gauss-Newton step dx / x_ref (fractions) from ``x_ref`` for a residual
    ``residual`` = model - data (m,) with exact Jacobian ``jacobian`` (m, n) and noise ``sd`` (m,):
    dx = -(J^T W J)^-1 J^T W r, W = diag(sd^-2), solved by least squares on the whitened,
    column-scaled system (columns scaled by x_ref for conditioning)."""
    x_ref = np.asarray(x_ref, float)
    A = np.asarray(jacobian, float) * x_ref[None, :] / np.asarray(sd, float)[:, None]
    rhs = np.asarray(residual, float) / np.asarray(sd, float)
    dz, *_ = np.linalg.lstsq(A, -rhs, rcond=None)
    return dz


def rounding_floor(jacobians, exact, rounded, sd, x_ref) -> tuple[np.ndarray, np.ndarray]:
    """The rounding floor of a data set: the linearised step (fractions of ``x_ref``) the exact
    data model itself takes on its rounded data, residual r = ``exact`` - ``rounded`` (m,) (the
    data model's response at ``x_ref`` and the data made from it), noise ``sd`` (m,):
    :func:`linearised_bias` with ``jacobians[0]`` (m, n), the best available Jacobian. Returns
    ``(floor, spread)``: ``spread`` (n,) the largest |difference| of the floor with any other of
    ``jacobians`` (its uncertainty from the Jacobian; zeros with one). For a linear model the
    floor is exact, and a model's linearised bias against the rounded data is its bias against
    the exact data plus the floor (superposition)."""
    r = np.asarray(exact, float) - np.asarray(rounded, float)
    floors = [linearised_bias(J, r, sd, x_ref) for J in jacobians]
    spread = np.max(np.abs(np.array(floors) - floors[0]), axis=0)
    return floors[0], spread


def parameter_sd(jacobian, sd, x_ref) -> np.ndarray:
    """Noise standard deviation of each parameter's least-squares estimate relative to ``x_ref``
    (fractions): sqrt diag (J^T W J)^-1 / x_ref, W = diag(sd^-2), for the noise ``sd`` (m,) of
    the measurement and the exact Jacobian ``jacobian`` (m, n) (the linearised covariance; by
    the singular values of the whitened, column-scaled system)."""
    x_ref = np.asarray(x_ref, float)
    A = np.asarray(jacobian, float) * x_ref[None, :] / np.asarray(sd, float)[:, None]
    _, s, vt = np.linalg.svd(A, full_matrices=False)
    return np.sqrt(np.sum((vt / s[:, None]) ** 2, axis=0))


def plate_margin_study(
    jacobian, residuals: dict, x_ref, points, margins_mm, n_snapshots: int, height_mm: float
) -> list[dict]:
    """The linearised bias and noise of a mesh's estimate for each plate margin (the measurement
    region of :class:`problems.inverse.build.Region`).

    jacobian   : (2 N m + N, n) the mesh's exact Jacobian at ``x_ref``
    residuals  : {label: (2 N m + N,) model - data at ``x_ref``}, e.g. the mesh's response minus
                 the data (the untreated bias) or a finer mesh's response minus the data (the
                 limit of the iterated correction with that mesh, to first order)
    points     : (m, 2) front-face points (y, z), mm; ``height_mm`` the specimen's height, mm
    margins_mm : plate margins, mm

    Per margin ``{"margin_mm", "points"`` (front-face points kept), ``"sd"`` (n,) (each
    parameter's noise sd, fractions of ``x_ref``: :func:`parameter_sd` with :func:`noise_sd`),
    ``"bias"`` ({label: (n,) fractions}: :func:`linearised_bias`)``}``, on the rows of the kept
    points' ``u_h`` and ``u_v`` in every snapshot and of every force."""
    from problems.inverse.build import plate_margin_mask

    points = np.asarray(points, float)
    J = np.asarray(jacobian, float)
    sd = noise_sd(n_snapshots, len(points))
    out = []
    for margin in margins_mm:
        keep = plate_margin_mask(points, margin, height_mm)
        rows = layout.point_rows(keep, n_snapshots)
        out.append(
            {
                "margin_mm": float(margin),
                "points": int(keep.sum()),
                "sd": parameter_sd(J[rows], sd[rows], x_ref),
                "bias": {
                    label: linearised_bias(J[rows], np.asarray(r, float)[rows], sd[rows], x_ref)
                    for label, r in residuals.items()
                },
            }
        )
    return out


#: order p of the discretisation band of an identified parameter (:func:`gci_band`), per mesh
#: family ("element gGRADING", else the element; an anisotropic grading, ``gzR`` other than
#: ``gR``, was never studied and takes the element's): the smallest order observed in the shipped
#: convergence studies of that family (results/studies/convergence, every case, field and force,
#: every triple; few families are asymptotic throughout), rounded down. A smaller p widens the
#: band. hex27 g8 (the default inverse model's, nine cases, with the fifth mesh
#: 18,18,36:g8:hex27): down to 1.13, exponent-tension's force on the five-mesh study's finest
#: triple 9,9,18 / 12,12,24 / 18,18,36 (the field's orders are higher); other hex27 gradings
#: (g4, nine cases): down to 0.93; hex8 (nine cases): down to 0.68
GCI_ORDERS = {"hex27 g8": 1.13, "hex27": 0.92, "hex8": 0.67}
#: Roache's safety factor of a grid convergence index from two discretisations, or from three
#: outside the asymptotic range (1.25 is for three grids with an asymptotic observed order)
GCI_SAFETY = 3.0


def refinement_ratio(coarse: str, fine: str) -> float:
    """Refinement ratio r = h_coarse / h_fine of two mesh specs of one specimen: the cube root
    of their element-count ratio (1.5 for ``6,6,12:g8:hex27`` -> ``9,9,18:g8:hex27``)."""
    from problems.fe.mesh import parse_mesh_spec

    n_c = math.prod(parse_mesh_spec(coarse).shape)
    n_f = math.prod(parse_mesh_spec(fine).shape)
    if n_f <= n_c:
        raise ValueError(f"mesh {fine!r} is not finer than {coarse!r} ({n_f} <= {n_c} elements)")
    return (n_f / n_c) ** (1.0 / 3.0)


def gci_order(mesh: str) -> float:
    """The order of :func:`gci_band` for estimates on ``mesh``'s family (:data:`GCI_ORDERS`)."""
    from problems.fe.mesh import parse_mesh_spec

    spec = parse_mesh_spec(mesh)
    if spec.grading_z is not None:  # anisotropic: not the family of its lateral ratio
        return GCI_ORDERS[spec.element]
    return GCI_ORDERS.get(f"{spec.element} g{spec.grading:g}", GCI_ORDERS[spec.element])


def gci_band(x_coarse, x_fine, ratio: float, order: float, safety: float = GCI_SAFETY):
    """Grid convergence index (Roache) of the finer of two estimates: the half-width (same units
    as ``x``) of the band around ``x_fine`` that holds the discretisation-free value,

        U = safety * |x_fine - x_coarse| / (ratio^order - 1),

    the Richardson estimate of the finer estimate's own discretisation error times a safety
    factor. ``x_coarse``, ``x_fine``: the estimates (e.g. identified parameters) from the
    coarser and the finer discretisation; ``ratio`` > 1: h_coarse / h_fine; ``order``: of the
    family (:func:`gci_order`). Returns an array shaped like ``x``."""
    if not ratio > 1.0 or not order > 0.0 or not safety >= 1.0:
        raise ValueError(
            f"GCI needs ratio > 1, order > 0 and safety >= 1 (got {ratio}, {order}, {safety})"
        )
    diff = np.abs(np.asarray(x_fine, float) - np.asarray(x_coarse, float))
    return safety * diff / (ratio**order - 1.0)

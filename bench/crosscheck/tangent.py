"""Why OpenSees's Newton struggles on the cube: the material tangent it hands to the element,
recovered from a one-element model and compared with the derivative of its own stress and with
the two tangent formulas of :func:`bench.crosscheck.mapping.dp_return`. Strains dimensionless,
stresses and moduli in MPa.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from bench.crosscheck.loader import captured_output, load_opensees
from bench.crosscheck.mapping import OPENSEES_ARGS, dp_return
from bench.crosscheck.opensees_box import OS_TO_VOIGT

#: strain states (engineering, femubench Voigt order) at which the tangent is audited
AUDIT_STRAINS = {
    "uniaxial-like (axisymmetric)": np.array([3e-4, 3e-4, -2e-3, 0.0, 0.0, 0.0]),
    "general 3-D": np.array([5e-4, 2e-4, -2e-3, 4e-4, -3e-4, 2e-4]),
}


def _one_element_prescribed(ops, u, osp, want_matrix=False):
    """Unit stdBrick with all 24 displacements prescribed (penalty), one step from the virgin
    state: element nodal forces, the assembled tangent (penalty on the diagonal only) and the
    Gauss-point-mean stress."""
    from problems.fe.mesh import HEX_CORNERS

    ops.wipe()
    ops.model("basic", "-ndm", 3, "-ndf", 3)
    for i, c in enumerate(HEX_CORNERS.astype(float)):
        ops.node(i + 1, *map(float, c))
    ops.nDMaterial("DruckerPrager", 1, *(float(osp[k]) for k in OPENSEES_ARGS))
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
    stress = np.reshape(ops.eleResponse(1, "stresses"), (8, 6)).mean(axis=0)[OS_TO_VOIGT]
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
            E = np.array(
                [
                    [eps[0], eps[5] / 2, eps[4] / 2],
                    [eps[5] / 2, eps[1], eps[3] / 2],
                    [eps[4] / 2, eps[3] / 2, eps[2]],
                ]
            )
            u = X @ E.T
            _, A, stress = _one_element_prescribed(ops, u, osp, want_matrix=True)
            h = 1e-9
            Kfd = np.column_stack(
                [
                    (
                        _one_element_prescribed(ops, (u.ravel() + h * e).reshape(8, 3), osp)[0]
                        - _one_element_prescribed(ops, (u.ravel() - h * e).reshape(8, 3), osp)[0]
                    )
                    / (2 * h)
                    for e in np.eye(24)
                ]
            )
            C_os = np.linalg.lstsq(M[off], A.ravel()[off], rcond=None)[0].reshape(6, 6)
            C_fd = np.linalg.lstsq(M, Kfd.ravel(), rcond=None)[0].reshape(6, 6)
            s_ref, C_trial = dp_return(eps, osp, "trial")
            _, C_ret = dp_return(eps, osp, "returned")
            scale = np.abs(C_fd).max()
            out.append(
                {
                    "state": name,
                    "strain": eps,
                    "stress_opensees": stress,
                    "stress_rederived": s_ref,
                    "stress_difference": float(np.abs(stress - s_ref).max() / np.abs(s_ref).max()),
                    "C_opensees": C_os,
                    "C_finite_difference": C_fd,
                    "opensees_vs_fd": float(np.abs(C_os - C_fd).max() / scale),
                    "consistent_formula_vs_fd": float(np.abs(C_trial - C_fd).max() / scale),
                    "returned_norm_formula_vs_opensees": float(np.abs(C_ret - C_os).max() / scale),
                }
            )
        ops.wipe()
    log_path.unlink()
    return out

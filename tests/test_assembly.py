"""The fused (numba) assembly against the numpy reference: tangent, internal force, strain."""

import numpy as np
import pytest

from problems.fe.assembly import FusedAssembler, element_forces, element_matrices, split_operator
from problems.fe.mesh import box_mesh, distort
from problems.fe.newton import discretise


def _rel(a, b):
    return np.abs(a - b).max() / np.abs(b).max()


@pytest.mark.parametrize("use_b_bar", [True, False])
def test_fused_kernels_match_numpy_reference_on_distorted_mesh(use_b_bar):
    disc = discretise(distort(box_mesh(3, 4, 5), 0.25, seed=3), use_b_bar=use_b_bar)
    ne, n_pts = disc.mesh.n_elements, disc.n_points
    rng = np.random.default_rng(0)
    D = rng.standard_normal((n_pts, 6, 6)) * 1e4  # non-symmetric, like a plastic tangent
    stress = rng.standard_normal((n_pts, 6)) * 10.0
    u = rng.standard_normal(disc.pattern.n_dofs) * 1e-2
    fa = FusedAssembler(disc.B, disc.dV, disc.pattern)
    assert fa.c_const == use_b_bar
    K_ref = disc.pattern.matrix(element_matrices(disc.B, D.reshape(ne, 8, 6, 6), disc.dV))
    assert _rel(fa.tangent(D), K_ref.data) < 1e-12
    # one (6, 6) tangent shared by all points (the virgin state)
    D0 = D[0]
    K0 = disc.pattern.matrix(element_matrices(disc.B, np.broadcast_to(D0, (ne, 8, 6, 6)), disc.dV))
    assert _rel(fa.tangent(D0), K0.data) < 1e-12
    f_ref = disc.pattern.vector(element_forces(disc.B, stress.reshape(ne, 8, 6), disc.dV))
    assert _rel(fa.internal_force(stress), f_ref) < 1e-12
    eps_ref = np.einsum("egia,ea->egi", disc.B, u[disc.pattern.edofs]).reshape(-1, 6)
    assert _rel(fa.strain(u), eps_ref) < 1e-12


def test_split_operator_rejects_a_foreign_operator():
    disc = discretise(box_mesh(1, 1, 1))
    B = disc.B.copy()
    B[0, 0, 3, 0] = 1.0  # u_x in the yz row: not a small-strain operator
    with pytest.raises(ValueError, match="not of the form"):
        split_operator(B)

"""Assembly of the global tangent, internal force and strain increment on a fixed sparsity pattern.

The CSR pattern and the map from element-matrix entries to CSR slots (:class:`Pattern`) are
computed once per mesh. Two implementations use them:

* :class:`FusedAssembler` (production): compiled (numba) kernels that loop over elements, form
  each element matrix in an nd x nd local buffer (nd = 3 n: 24 for the 8-node, 81 for the 27-node
  hexahedron; the kernels read n off the arrays they are given) and add it straight into the CSR
  data array through the slot map; likewise the internal force and the strain increment. No
  per-element temporaries of shape (ne, nd, nd) are created.
* :func:`element_matrices` / :func:`element_forces` + :meth:`Pattern.matrix` /
  :meth:`Pattern.vector` (reference): batched numpy products and one ``np.bincount``. They are what
  the fused kernels are tested against and the "numpy" assembly of
  :class:`~problems.fe.newton.NewtonSettings`, used by ``bench/perf/forward.py`` to time the old
  code path.

How the fused tangent saves work: every strain operator of this code has the form
``B_g = P Bs_g + (1/3) m c_g^T`` with ``Bs_g`` the standard (sparse) small-strain operator of the
shape-function gradients at Gauss point g, ``m = [1, 1, 1, 0, 0, 0]``, ``P = I - m m^T / 3`` the
deviatoric projector (P m = 0) and ``c_g`` the volumetric row (the element mean b-bar for the
mean-dilatation element, the projection onto {1, x, y, z} of the Q2-P1 element, the point's own
divergence row for a standard element). Then

    B_g^T D B_g = Bs^T (P D P) Bs + (1/3) Bs^T P D m c^T + (1/3) c m^T D P Bs
                  + (1/9) (m^T D m) c c^T,

and for B-bar (c the same at all Gauss points) the last three terms sum over g into two rank-one
updates per element. The first term uses the sparsity of ``Bs`` (three non-zeros per column).
That is about half the arithmetic of the dense ``B^T D B`` and vectorises over rows of nd.
Element matrices of DENSE_MIN_DOFS rows or more (the 27-node element) are instead one dense BLAS
product per element (:func:`_tangent_dense_kernel`), which is faster at that size.

Units: B in 1/mm, D and stress in MPa, dV in mm^3; K in N/mm, forces in N, strain dimensionless.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numba import njit

from problems.numba_cache import heal as heal_numba_cache

_JIT = dict(cache=True, nogil=True, error_model="numpy")


@dataclass(frozen=True, eq=False)
class Pattern:
    """CSR sparsity of the global matrix and the scatter map of element entries.

    edofs   : (ne, nd) global dof numbers of each element (nd = 3 x nodes per element)
    slot    : (ne * nd * nd,) CSR data index of every element-matrix entry
    indptr, indices : the CSR structure, n_dofs x n_dofs
    """

    edofs: np.ndarray
    slot: np.ndarray
    indptr: np.ndarray
    indices: np.ndarray
    n_dofs: int

    def matrix(self, Ke: np.ndarray) -> sp.csr_matrix:
        """Global matrix from element matrices Ke (ne, nd, nd) (numpy reference path)."""
        data = np.bincount(self.slot, weights=Ke.ravel(), minlength=len(self.indices))
        return self.csr(data)

    def vector(self, fe: np.ndarray) -> np.ndarray:
        """Global vector from element vectors fe (ne, nd) (numpy reference path)."""
        return np.bincount(self.edofs.ravel(), weights=fe.ravel(), minlength=self.n_dofs)

    def csr(self, data: np.ndarray) -> sp.csr_matrix:
        """The CSR matrix with this pattern and values ``data`` (nnz,) (no copy)."""
        return sp.csr_matrix((data, self.indices, self.indptr), shape=(self.n_dofs, self.n_dofs))


def build_pattern(elements: np.ndarray, n_nodes: int) -> Pattern:
    """Sparsity pattern of 3-dof-per-node hexahedra (ne, 8) or (ne, 27) over ``n_nodes`` nodes."""
    nd = 3 * elements.shape[1]
    edofs = (3 * elements[:, :, None] + np.arange(3)).reshape(len(elements), nd)
    n = 3 * n_nodes
    rows = np.repeat(edofs, nd, axis=1).ravel()
    cols = np.tile(edofs, (1, nd)).ravel()
    keys, slot = np.unique(rows.astype(np.int64) * n + cols, return_inverse=True)
    indptr = np.searchsorted(keys // n, np.arange(n + 1)).astype(np.int64)
    return Pattern(edofs, slot.ravel(), indptr, (keys % n).astype(np.int64), n)


def element_matrices(B: np.ndarray, D: np.ndarray, dV: np.ndarray) -> np.ndarray:
    """Ke = sum_g B_g^T D_g B_g dV_g for B (ne, g, 6, nd), D (ne, g, 6, 6), dV (ne, g)
    -> (ne, nd, nd).

    Numpy reference of :meth:`FusedAssembler.tangent`.
    """
    DB = np.matmul(D, B) * dV[..., None, None]
    ne, g, _, nd = B.shape
    # Contract over (g, 6) as one matrix product per element: (ne, nd, g*6) @ (ne, g*6, nd).
    Bt = B.transpose(0, 3, 1, 2).reshape(ne, nd, g * 6)
    return np.matmul(Bt, DB.reshape(ne, g * 6, nd))


def element_forces(B: np.ndarray, stress: np.ndarray, dV: np.ndarray) -> np.ndarray:
    """fe = sum_g B_g^T sigma_g dV_g for stress (ne, g, 6) -> (ne, nd). Numpy reference."""
    return np.einsum("egia,egi->ea", B, stress * dV[..., None])


def split_operator(B: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
    """Write B (ne, g, 6, nd) as ``P Bs_g + (1/3) m c_g^T`` (see the module docstring).

    Returns the shape-function gradients G (ne, g, n, 3) 1/mm read off the shear rows of B, the
    volumetric rows c (ne, g, nd) 1/mm, and whether c is the same at all Gauss points of each
    element (mean dilatation). Raises ValueError if B does not have that form.
    """
    # xz/uz, yz/uz, yz/uy
    G = np.stack([B[:, :, 4, 2::3], B[:, :, 3, 2::3], B[:, :, 3, 1::3]], axis=-1)
    c = B[:, :, 0] + B[:, :, 1] + B[:, :, 2]
    ne, ng, _, nd = B.shape
    Bs = np.zeros((ne, ng, 6, nd // 3, 3))
    gx, gy, gz = G[..., 0], G[..., 1], G[..., 2]
    Bs[:, :, 0, :, 0], Bs[:, :, 1, :, 1], Bs[:, :, 2, :, 2] = gx, gy, gz
    Bs[:, :, 3, :, 1], Bs[:, :, 3, :, 2] = gz, gy
    Bs[:, :, 4, :, 0], Bs[:, :, 4, :, 2] = gz, gx
    Bs[:, :, 5, :, 0], Bs[:, :, 5, :, 1] = gy, gx
    Bs = Bs.reshape(ne, ng, 6, nd)
    Bs[:, :, :3] -= (Bs[:, :, 0] + Bs[:, :, 1] + Bs[:, :, 2])[:, :, None] / 3.0
    Bs[:, :, :3] += c[:, :, None] / 3.0
    scale = max(np.abs(B).max(), 1e-300)
    if np.abs(Bs - B).max() > 1e-12 * scale:
        raise ValueError(
            "strain operator is not of the form P Bs + m c^T / 3 (not a hexahedral B or B-bar)"
        )
    const = bool(np.abs(c - c[:, :1]).max() <= 1e-14 * scale)
    return np.ascontiguousarray(G), np.ascontiguousarray(c), const


#: element matrices with at least this many rows (the 27-node element's 81) are formed as one dense
#: product per element, Ke = Bbar_e^T (w D Bbar)_e over all Gauss points (a BLAS dgemm of
#: (nd x 6 g) (6 g x nd)) by :func:`_tangent_dense_kernel`: measured, 27-node 6 x 6 x 12 eighth,
#: one thread, 19 ms per tangent against 38 ms with the sparse form of :func:`_tangent_kernel`.
#: The 8-node element (24 rows) keeps the sparse form, whose answers the shipped results hold bit
#: for bit (the dense product was 6.1 ms against 9.3 ms on 12 x 12 x 24 there, equal to 5e-16)
DENSE_MIN_DOFS = 81


class FusedAssembler:
    """Compiled assembly on one discretisation: tangent data, internal force, strain increment.

    B  : (ne, g, 6, nd) strain operator, 1/mm (standard or B-bar; nd = 24 or 81)
    dV : (ne, g) integration weights, mm^3
    pattern : the CSR pattern and slot map
    """

    def __init__(self, B: np.ndarray, dV: np.ndarray, pattern: Pattern):
        self.B = np.ascontiguousarray(B, dtype=float)
        self.dV = np.ascontiguousarray(dV, dtype=float)
        self.pattern = pattern
        self.G, self.c, self.c_const = split_operator(self.B)
        # element matrices of at least DENSE_MIN_DOFS rows: one dense product per element
        self.dense = self.B.shape[3] >= DENSE_MIN_DOFS
        self.edofs = np.ascontiguousarray(pattern.edofs, dtype=np.int64)
        self.slot = np.ascontiguousarray(pattern.slot, dtype=np.int64)

    def tangent(
        self, D: np.ndarray, slot: np.ndarray | None = None, nnz: int | None = None
    ) -> np.ndarray:
        """Sparse-matrix data of K = sum_e sum_g B^T D B dV, N/mm, for D (n_points, 6, 6) or one
        (6, 6) MPa.

        By default the CSR data (nnz,) of the pattern. ``slot`` (ne * nd^2,) maps every element
        entry to a position in an array of ``nnz`` values instead, -1 dropping it: that assembles
        any sub-block (e.g. the free-free block, already permuted) without the full matrix.
        """
        D = np.ascontiguousarray(D, dtype=float)
        D = D.reshape(-1, 6, 6)
        if D.shape[0] not in (1, self.dV.size):
            raise ValueError(f"tangent D has {D.shape[0]} points; expected 1 or {self.dV.size}")
        if slot is None:
            slot, nnz = self.slot, len(self.pattern.indices)
        elif nnz is None or len(slot) != len(self.slot):
            raise ValueError(
                "a custom slot map needs one entry per element-matrix entry and the output size nnz"
            )
        out = np.empty(nnz)
        if self.dense:
            _tangent_dense_kernel(
                self.B, D, self.dV, np.ascontiguousarray(slot, dtype=np.int64), out
            )
            return out
        _tangent_kernel(
            self.G,
            self.c,
            self.c_const,
            D,
            self.dV,
            np.ascontiguousarray(slot, dtype=np.int64),
            out,
        )
        return out

    def matrix(self, D: np.ndarray) -> sp.csr_matrix:
        """K as a CSR matrix on the pattern, N/mm."""
        return self.pattern.csr(self.tangent(D))

    def internal_force(self, stress: np.ndarray) -> np.ndarray:
        """f = sum_e sum_g B^T sigma dV (n_dofs,), N, for stress (n_points, 6) MPa."""
        out = np.empty(self.pattern.n_dofs)
        _force_kernel(
            self.B,
            np.ascontiguousarray(stress, dtype=float).reshape(-1, 6),
            self.dV,
            self.edofs,
            out,
        )
        return out

    def strain(self, u: np.ndarray) -> np.ndarray:
        """Strain (n_points, 6) (engineering shear) of the nodal displacement vector u (n_dofs,)
        mm."""
        out = np.empty((self.dV.size, 6))
        _strain_kernel(self.B, np.ascontiguousarray(u, dtype=float), self.edofs, out)
        return out


@njit(**_JIT)
def _scatter(Ke, e, slot, data):
    """Add element ``e``'s matrix ``Ke`` (nd, nd) to ``data[slot[nd^2 e + nd a + b]]``, skipping
    slots of -1 (entries of constrained dofs)."""
    nd = Ke.shape[0]
    base = e * nd * nd
    for a in range(nd):
        for k in range(nd):
            j = slot[base + a * nd + k]
            if j >= 0:
                data[j] += Ke[a, k]


@njit(**_JIT)
def _tangent_kernel(G, c, c_const, D, dV, slot, data):
    """data[:] = values of sum_e sum_g B^T D B dV with B = P Bs(G) + m c^T / 3 (module docstring),
    element entry (e, a, b) added to data[slot[nd^2 e + nd a + b]] unless that slot is -1
    (nd = 3 n, n = G.shape[2] nodes per element)."""
    ne, ng = dV.shape
    nn = G.shape[2]
    nd = 3 * nn
    per_point = D.shape[0] > 1
    data[:] = 0.0
    Ke = np.empty((nd, nd))
    X = np.empty((6, nd))
    Dt = np.empty((6, 6))
    Dm = np.empty(6)
    mD = np.empty(6)
    pdm = np.empty(6)
    pmd = np.empty(6)
    U = np.empty(nd)
    V = np.empty(nd)
    third = 1.0 / 3.0
    for e in range(ne):
        Ke[:, :] = 0.0
        U[:] = 0.0
        V[:] = 0.0
        s = 0.0
        for g in range(ng):
            q = e * ng + g if per_point else 0
            w = dV[e, g]
            for i in range(6):
                Dm[i] = D[q, i, 0] + D[q, i, 1] + D[q, i, 2]  # D m
                mD[i] = D[q, 0, i] + D[q, 1, i] + D[q, 2, i]  # m^T D
            mDm = Dm[0] + Dm[1] + Dm[2]
            for i in range(6):  # Dt = w P D P
                for j in range(6):
                    v = D[q, i, j]
                    if j < 3:
                        v -= third * Dm[i]
                    if i < 3:
                        v -= third * mD[j]
                        if j < 3:
                            v += third * third * mDm
                    Dt[i, j] = w * v
            for i in range(6):  # w/3 P D m, w/3 P D^T m
                corr = third * mDm if i < 3 else 0.0
                pdm[i] = w * third * (Dm[i] - corr)
                pmd[i] = w * third * (mD[i] - corr)
            for b in range(nn):  # X = Dt Bs
                gx = G[e, g, b, 0]
                gy = G[e, g, b, 1]
                gz = G[e, g, b, 2]
                for r in range(6):
                    X[r, 3 * b] = gx * Dt[r, 0] + gz * Dt[r, 4] + gy * Dt[r, 5]
                    X[r, 3 * b + 1] = gy * Dt[r, 1] + gz * Dt[r, 3] + gx * Dt[r, 5]
                    X[r, 3 * b + 2] = gz * Dt[r, 2] + gy * Dt[r, 3] + gx * Dt[r, 4]
            for a in range(nn):  # Ke += Bs^T X
                gx = G[e, g, a, 0]
                gy = G[e, g, a, 1]
                gz = G[e, g, a, 2]
                for k in range(nd):
                    Ke[3 * a, k] += gx * X[0, k] + gz * X[4, k] + gy * X[5, k]
                    Ke[3 * a + 1, k] += gy * X[1, k] + gz * X[3, k] + gx * X[5, k]
                    Ke[3 * a + 2, k] += gz * X[2, k] + gy * X[3, k] + gx * X[4, k]
                U[3 * a] += gx * pdm[0] + gz * pdm[4] + gy * pdm[5]
                U[3 * a + 1] += gy * pdm[1] + gz * pdm[3] + gx * pdm[5]
                U[3 * a + 2] += gz * pdm[2] + gy * pdm[3] + gx * pdm[4]
                V[3 * a] += gx * pmd[0] + gz * pmd[4] + gy * pmd[5]
                V[3 * a + 1] += gy * pmd[1] + gz * pmd[3] + gx * pmd[5]
                V[3 * a + 2] += gz * pmd[2] + gy * pmd[3] + gx * pmd[4]
            sg = w * mDm * third * third
            if c_const:
                s += sg
            else:  # rank-one terms of this point
                for a in range(nd):
                    ua = U[a] + sg * c[e, g, a]
                    ca = c[e, g, a]
                    for k in range(nd):
                        Ke[a, k] += ua * c[e, g, k] + ca * V[k]
                U[:] = 0.0
                V[:] = 0.0
        if c_const:
            for a in range(nd):
                ua = U[a] + s * c[e, 0, a]
                ca = c[e, 0, a]
                for k in range(nd):
                    Ke[a, k] += ua * c[e, 0, k] + ca * V[k]
        _scatter(Ke, e, slot, data)


@njit(**_JIT)
def _tangent_dense_kernel(B, D, dV, slot, data):
    """data[:] = values of sum_e Bbar_e^T X_e with Bbar_e = B[e] as a (6 g, nd) matrix and
    X_e = (w_g D_g B[e, g]) stacked over the Gauss points g (one dgemm per element); element entry
    (e, a, b) added to data[slot[nd^2 e + nd a + b]] unless that slot is -1."""
    ne, ng, _, nd = B.shape
    per_point = D.shape[0] > 1
    data[:] = 0.0
    X = np.empty((ng * 6, nd))
    for e in range(ne):
        for g in range(ng):
            q = e * ng + g if per_point else 0
            w = dV[e, g]
            for i in range(6):
                r = 6 * g + i
                X[r, :] = 0.0
                for j in range(6):
                    dij = w * D[q, i, j]
                    for k in range(nd):
                        X[r, k] += dij * B[e, g, j, k]
        Ke = np.dot(B[e].reshape(ng * 6, nd).T, X)
        _scatter(Ke, e, slot, data)


@njit(**_JIT)
def _force_kernel(B, stress, dV, edofs, out):
    """out[:] = sum_e sum_g B^T sigma dV scattered to the global dofs."""
    ne, ng = dV.shape
    nd = B.shape[3]
    out[:] = 0.0
    fe = np.empty(nd)
    for e in range(ne):
        fe[:] = 0.0
        for g in range(ng):
            p = e * ng + g
            w = dV[e, g]
            for i in range(6):
                si = stress[p, i] * w
                for a in range(nd):
                    fe[a] += B[e, g, i, a] * si
        for a in range(nd):
            out[edofs[e, a]] += fe[a]


@njit(**_JIT)
def _strain_kernel(B, u, edofs, out):
    """out[p] = B_p u_e: the strain at every Gauss point."""
    ne, ng, _, nd = B.shape
    ue = np.empty(nd)
    for e in range(ne):
        for a in range(nd):
            ue[a] = u[edofs[e, a]]
        for g in range(ng):
            p = e * ng + g
            for i in range(6):
                s = 0.0
                for a in range(nd):
                    s += B[e, g, i, a] * ue[a]
                out[p, i] = s


heal_numba_cache(globals())  # a torn cache file of these kernels: named, removed

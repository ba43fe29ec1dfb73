"""Vectorised assembly of the global tangent and internal force on a fixed sparsity pattern.

The CSR pattern and the map from element-matrix entries to CSR slots are computed once per
mesh; assembling is then one ``np.bincount`` over all (element, a, b) entries.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp


@dataclass(frozen=True, eq=False)
class Pattern:
    """CSR sparsity of the global matrix and the scatter map of element entries.

    edofs   : (ne, 24) global dof numbers of each element
    slot    : (ne * 24 * 24,) CSR data index of every element-matrix entry
    indptr, indices : the CSR structure, n_dofs x n_dofs
    """

    edofs: np.ndarray
    slot: np.ndarray
    indptr: np.ndarray
    indices: np.ndarray
    n_dofs: int

    def matrix(self, Ke: np.ndarray) -> sp.csr_matrix:
        """Global matrix from element matrices Ke (ne, 24, 24)."""
        data = np.bincount(self.slot, weights=Ke.ravel(), minlength=len(self.indices))
        return sp.csr_matrix((data, self.indices, self.indptr), shape=(self.n_dofs, self.n_dofs))

    def vector(self, fe: np.ndarray) -> np.ndarray:
        """Global vector from element vectors fe (ne, 24)."""
        return np.bincount(self.edofs.ravel(), weights=fe.ravel(), minlength=self.n_dofs)


def build_pattern(elements: np.ndarray, n_nodes: int) -> Pattern:
    """Sparsity pattern of 3-dof-per-node hexahedra (ne, 8) over ``n_nodes`` nodes."""
    edofs = (3 * elements[:, :, None] + np.arange(3)).reshape(len(elements), 24)
    n = 3 * n_nodes
    rows = np.repeat(edofs, 24, axis=1).ravel()
    cols = np.tile(edofs, (1, 24)).ravel()
    keys, slot = np.unique(rows.astype(np.int64) * n + cols, return_inverse=True)
    indptr = np.searchsorted(keys // n, np.arange(n + 1)).astype(np.int64)
    return Pattern(edofs, slot.ravel(), indptr, (keys % n).astype(np.int64), n)


def element_matrices(B: np.ndarray, D: np.ndarray, dV: np.ndarray) -> np.ndarray:
    """Ke = sum_g B_g^T D_g B_g dV_g for B (ne, g, 6, 24), D (ne, g, 6, 6), dV (ne, g) -> (ne, 24, 24)."""
    DB = np.matmul(D, B) * dV[..., None, None]
    ne, g = B.shape[:2]
    # Contract over (g, 6) as one matrix product per element: (ne, 24, g*6) @ (ne, g*6, 24).
    Bt = B.transpose(0, 3, 1, 2).reshape(ne, 24, g * 6)
    return np.matmul(Bt, DB.reshape(ne, g * 6, 24))


def element_forces(B: np.ndarray, stress: np.ndarray, dV: np.ndarray) -> np.ndarray:
    """fe = sum_g B_g^T sigma_g dV_g for stress (ne, g, 6) -> (ne, 24)."""
    return np.einsum("egia,egi->ea", B, stress * dV[..., None])

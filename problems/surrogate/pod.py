r"""Proper orthogonal decomposition of the snapshot matrix, truncated in units of the noise.

The training measurement vectors ``Y`` (n, m) are centred by their mean ``ybar`` and scaled by
the data's standard deviations ``sigma`` (m,):  ``Yc = (Y - ybar) / sigma``  (dimensionless, one
unit = one standard deviation of the measurement). Its thin SVD ``Yc = U S V^T`` gives the modes
``Phi = V[:, :r]`` (orthonormal columns) and the coefficients ``A = Yc Phi``; a measurement vector
is reconstructed as ``y = ybar + sigma * (Phi a)``.

Truncation rule. Because ``U`` has orthonormal columns, the projection error of the training
snapshots restricted to a block ``b`` of the measurement vector (``u_h``, ``u_v``, ``force``) is
exactly

    E_b(r) = || Yc_b - (U S V^T)_b,r ||_F^2 = sum_{j > r} s_j^2 ||V_{b, j}||^2

so its root mean square per value, in units of sigma, is ``rms_b(r) = sqrt(E_b(r) / (n m_b))``.
The number of modes ``r`` is the smallest with ``rms_b(r) <= tol_sigma`` for every block (default
``tol_sigma = 0.1``: the truncation adds at most a tenth of the measurement noise, in RMS, to any
block). Taking the blocks apart matters: the force block has N values against 2 N m displacement
values and would be invisible in a global energy fraction. The criterion is met on the training
snapshots; new points also carry the (larger) regression error, measured by the hold-out
validation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class POD:
    """A truncated POD basis.

    mean            : (m,) mean training measurement vector, units of the model
    scale           : (m,) scale of each measurement (the data's sigma), units of the model
    modes           : (m, r) orthonormal modes of the scaled snapshots
    singular_values : (k,) all singular values of the scaled centred snapshot matrix (k = min(n, m))
    tol_sigma       : truncation tolerance, RMS per block in units of sigma
    projection_rms  : {block: RMS projection error of the training snapshots at r modes, in sigma}
    """

    mean: np.ndarray
    scale: np.ndarray
    modes: np.ndarray
    singular_values: np.ndarray
    tol_sigma: float
    projection_rms: dict

    @property
    def n_modes(self) -> int:
        return self.modes.shape[1]

    def coefficients(self, Y) -> np.ndarray:
        """(q, r) POD coefficients of measurement vectors ``Y`` (q, m) (dimensionless)."""
        return ((np.atleast_2d(Y) - self.mean) / self.scale) @ self.modes

    def reconstruct(self, A) -> np.ndarray:
        """Measurement vectors (q, m) from coefficients ``A`` (q, r), units of the model."""
        return self.mean + self.scale * (np.atleast_2d(A) @ self.modes.T)

    def energy_fraction(self) -> float:
        """Fraction of the centred scaled snapshot energy kept by the truncation."""
        s2 = self.singular_values**2
        return float(s2[: self.n_modes].sum() / s2.sum()) if s2.sum() > 0 else 1.0


def truncation_rms(
    singular_values, Vt, blocks: dict[str, slice], n_snapshots: int
) -> dict[str, np.ndarray]:
    """``{block: rms_b(r) for r = 0..k}``: RMS projection error of the training snapshots in
    units of sigma when ``r`` modes are kept (see the module docstring)."""
    s2 = np.asarray(singular_values, float) ** 2
    out = {}
    for name, sl in blocks.items():
        w = np.sum(Vt[:, sl] ** 2, axis=1)  # ||V_{b, j}||^2
        tail = np.concatenate([np.cumsum((s2 * w)[::-1])[::-1], [0.0]])  # E_b(r), r = 0..k
        m_b = len(range(*sl.indices(Vt.shape[1])))
        out[name] = np.sqrt(np.maximum(tail, 0.0) / (n_snapshots * m_b))
    return out


def fit_pod(
    Y,
    scale,
    *,
    tol_sigma: float = 0.1,
    blocks: dict[str, slice] | None = None,
    max_modes: int | None = None,
    separate: tuple[str, ...] = (),
) -> POD:
    """The POD of the snapshots ``Y`` (n, m) scaled by ``scale`` (m,), truncated by the rule of the
    module docstring (``max_modes`` caps ``r``; then the criterion may not be met, see
    ``projection_rms``).

    separate : names of ``blocks`` kept out of the POD: each of their values is a coefficient of
               its own (an identity column, so the modes stay orthonormal and the block is exact,
               projection error 0); the POD and its truncation are those of the other blocks. The
               modes are block-diagonal: POD modes first (zero on the separate rows), then one
               column per separate value. Used for the N force values, which the shared POD of
               the 2 N m displacements represents poorly.
    """
    Y = np.asarray(Y, float)
    n, m = Y.shape
    if separate:
        return _fit_pod_separate(Y, scale, tol_sigma, blocks or {}, max_modes, tuple(separate))
    scale = np.broadcast_to(np.asarray(scale, float), (m,)).copy()
    if n < 2:
        raise ValueError(f"POD needs at least 2 snapshots, got {n}")
    if np.any(~(scale > 0)) or not np.all(np.isfinite(scale)):
        raise ValueError("POD scale must be positive and finite")
    if not tol_sigma > 0:
        raise ValueError(f"tol_sigma = {tol_sigma} is out of range: must be > 0")
    blocks = blocks or {"all": slice(0, m)}
    mean = Y.mean(axis=0)
    _, s, Vt = np.linalg.svd((Y - mean) / scale, full_matrices=False)
    rms = truncation_rms(s, Vt, blocks, n)
    worst = np.max(np.vstack(list(rms.values())), axis=0)  # (k + 1,)
    r = int(np.argmax(worst <= tol_sigma)) if np.any(worst <= tol_sigma) else len(s)
    r = max(r, 1)
    if max_modes is not None:
        r = max(1, min(r, int(max_modes)))
    return POD(
        mean,
        scale,
        np.ascontiguousarray(Vt[:r].T),
        s,
        float(tol_sigma),
        {k: float(v[r]) for k, v in rms.items()},
    )


def _fit_pod_separate(Y, scale, tol_sigma, blocks, max_modes, separate) -> POD:
    """:func:`fit_pod` with the ``separate`` blocks as identity columns (see there)."""
    n, m = Y.shape
    unknown = [b for b in separate if b not in blocks]
    if unknown:
        raise ValueError(f"separate blocks {unknown} are not among the blocks {list(blocks)}")
    sep_rows = np.zeros(m, bool)
    for b in separate:
        sep_rows[blocks[b]] = True
    rest = np.flatnonzero(~sep_rows)
    if rest.size == 0:
        raise ValueError("separate blocks cover the whole measurement vector: nothing to POD")
    # blocks of the POD part, re-indexed into the kept rows (contiguous blocks stay contiguous)
    pos = np.full(m, -1)
    pos[rest] = np.arange(rest.size)
    sub_blocks = {}
    for k, sl in blocks.items():
        idx = np.arange(m)[sl]
        if k in separate or sep_rows[idx].any():
            continue
        sub_blocks[k] = slice(int(pos[idx[0]]), int(pos[idx[-1]]) + 1)
    scale = np.broadcast_to(np.asarray(scale, float), (m,))
    inner = fit_pod(
        Y[:, rest],
        scale[rest],
        tol_sigma=tol_sigma,
        blocks=sub_blocks or None,
        max_modes=max_modes,
    )
    sep_idx = np.flatnonzero(sep_rows)
    modes = np.zeros((m, inner.n_modes + sep_idx.size))
    modes[rest, : inner.n_modes] = inner.modes
    modes[sep_idx, inner.n_modes + np.arange(sep_idx.size)] = 1.0
    mean = Y.mean(axis=0)
    rms = dict(inner.projection_rms)
    rms.update({b: 0.0 for b in separate})
    for k, sl in blocks.items():  # mixed blocks (e.g. all) from their parts
        if k not in rms:
            rows = np.arange(m)[sl]
            rms[k] = float(
                np.sqrt(
                    sum(
                        inner.projection_rms[j] ** 2 * len(range(*sub_blocks[j].indices(rest.size)))
                        for j in sub_blocks
                        if np.all(np.isin(rest[sub_blocks[j]], rows))
                    )
                    / rows.size
                )
            )
    return POD(
        mean,
        np.array(scale, float),
        np.ascontiguousarray(modes),
        inner.singular_values,
        float(tol_sigma),
        rms,
    )

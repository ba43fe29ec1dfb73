"""The IC-GN inner step, in two interchangeable back-ends.

One step, for the active subsets ``gi`` with warp matrices ``A`` (k, 2, 3), evaluates the
deformed image at the warped subset points (B-spline interpolation) and returns

    b      (k, 6)  sum_i S_i^T r_i   with  r_i = f~_i - (Df / Dg) g~_i
    rr     (k,)    sum_i r_i^2
    dg     (k,)    Dg = ||g - mean g||
    inside (k,)    the warped subset lies inside the image

* ``scipy``: warped coordinates by GEMM, ``scipy.ndimage.map_coordinates`` for the spline
  (~6-9 M points/s), numpy reductions. Always available.
* ``numba``: the same arithmetic fused in one compiled loop per subset (no (k, P)
  temporaries), several times faster. Used when numba is importable, unless the environment
  variable ``FEMUBENCH_DIC_BACKEND=scipy`` is set. Both agree to rounding (tested).
"""

from __future__ import annotations

import os

import numpy as np

try:  # optional accelerator
    if os.environ.get("FEMUBENCH_DIC_BACKEND", "").lower() == "scipy":
        raise ImportError
    import numba
except ImportError:  # pragma: no cover - depends on the environment
    numba = None

AVAILABLE = ("scipy", "numba") if numba is not None else ("scipy",)
DEFAULT_BACKEND = "numba" if numba is not None else "scipy"


def corners_inside(cx, cy, A, h, rows, cols) -> np.ndarray:
    """Whether the four warped corners (hence the whole affine-warped subset) lie in the image."""
    ok = np.ones(len(A), dtype=bool)
    for sx in (-h, h):
        for sy in (-h, h):
            x = cx + A[:, 0, 2] + A[:, 0, 0] * sx + A[:, 0, 1] * sy
            y = cy + A[:, 1, 2] + A[:, 1, 0] * sx + A[:, 1, 1] * sy
            ok &= (x >= 0) & (x <= cols - 1) & (y >= 0) & (y <= rows - 1)
    return ok


def step_scipy(spline, cx, cy, gi, A, Xi, f0, fx, fy, df):
    """The IC-GN step with scipy/numpy (see module docstring)."""
    rows, cols = spline.shape
    h = int(round(Xi[:, 1].max()))
    cxs, cys = cx[gi].astype(float), cy[gi].astype(float)
    inside = corners_inside(cxs, cys, A, h, rows, cols)
    XiT = Xi.T
    X = cxs[:, None] + np.column_stack([A[:, 0, 2], A[:, 0, 0], A[:, 0, 1]]) @ XiT
    Y = cys[:, None] + np.column_stack([A[:, 1, 2], A[:, 1, 0], A[:, 1, 1]]) @ XiT
    g = spline.values(X, Y)
    g0 = g - g.mean(axis=1, keepdims=True)
    dg = np.sqrt(np.einsum("ij,ij->i", g0, g0))
    scale = np.where(dg > 0, df[gi] / np.where(dg > 0, dg, 1.0), 0.0)
    r = f0[gi] - scale[:, None] * g0
    rr = np.einsum("ij,ij->i", r, r)
    b = np.hstack([(fx[gi] * r) @ Xi, (fy[gi] * r) @ Xi])
    return b, rr, dg, inside


if numba is not None:

    @numba.njit(cache=True, nogil=True)
    def _mirror(i, n):  # scipy.ndimage 'mirror' extension of the coefficients
        if n == 1:
            return 0
        period = 2 * n - 2
        i = i % period
        if i >= n:
            i = period - i
        return i

    @numba.njit(cache=True, nogil=True, inline="always")
    def _weights(t, order, w):
        if order == 3:
            t2 = t * t
            t3 = t2 * t
            s = 1.0 - t
            w[0] = s * s * s / 6.0
            w[1] = (3.0 * t3 - 6.0 * t2 + 4.0) / 6.0
            w[2] = (-3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0) / 6.0
            w[3] = t3 / 6.0
        else:
            # quintic: beta5(t + 2), beta5(t + 1), beta5(t),
            #          beta5(1 - t), beta5(2 - t), beta5(3 - t)
            for j in range(6):
                x = abs(t + 2.0 - j)
                if x < 1.0:
                    x2 = x * x
                    w[j] = (66.0 - 60.0 * x2 + 30.0 * x2 * x2 - 10.0 * x2 * x2 * x) / 120.0
                elif x < 2.0:
                    x2 = x * x
                    w[j] = (
                        51.0
                        + 75.0 * x
                        - 210.0 * x2
                        + 150.0 * x2 * x
                        - 45.0 * x2 * x2
                        + 5.0 * x2 * x2 * x
                    ) / 120.0
                elif x < 3.0:
                    y = 3.0 - x
                    w[j] = y * y * y * y * y / 120.0
                else:
                    w[j] = 0.0

    @numba.njit(cache=True, nogil=True)
    def _step_nb(c, order, cx, cy, gi, A, dx, dy, f0, fx, fy, df, h, b, rr, dg, inside):
        rows, cols = c.shape
        P = dx.size
        m = order // 2  # support: floor(x) - m .. floor(x) + m + 1
        nw = order + 1
        wx = np.empty(6)
        wy = np.empty(6)
        g = np.empty(P)
        for s in range(gi.size):
            j = gi[s]
            a00, a01, a02 = A[s, 0, 0], A[s, 0, 1], A[s, 0, 2]
            a10, a11, a12 = A[s, 1, 0], A[s, 1, 1], A[s, 1, 2]
            x0, y0 = cx[j] + a02, cy[j] + a12
            ok = True
            for sx in (-h, h):
                for sy in (-h, h):
                    xc = x0 + a00 * sx + a01 * sy
                    yc = y0 + a10 * sx + a11 * sy
                    if not (xc >= 0.0 and xc <= cols - 1 and yc >= 0.0 and yc <= rows - 1):
                        ok = False
            inside[s] = ok
            if not ok:
                continue
            sg = 0.0
            for i in range(P):
                x = x0 + a00 * dx[i] + a01 * dy[i]
                y = y0 + a10 * dx[i] + a11 * dy[i]
                ix = int(np.floor(x))
                iy = int(np.floor(y))
                _weights(x - ix, order, wx)
                _weights(y - iy, order, wy)
                val = 0.0
                if ix - m >= 0 and ix + m + 1 < cols and iy - m >= 0 and iy + m + 1 < rows:
                    for a in range(nw):
                        r = iy - m + a
                        acc = 0.0
                        for q in range(nw):
                            acc += wx[q] * c[r, ix - m + q]
                        val += wy[a] * acc
                else:
                    for a in range(nw):
                        r = _mirror(iy - m + a, rows)
                        acc = 0.0
                        for q in range(nw):
                            acc += wx[q] * c[r, _mirror(ix - m + q, cols)]
                        val += wy[a] * acc
                g[i] = val
                sg += val
            mean = sg / P
            s2 = 0.0
            for i in range(P):
                t = g[i] - mean
                s2 += t * t
            d = np.sqrt(s2)
            dg[s] = d
            scale = df[j] / d if d > 0.0 else 0.0
            b0 = b1 = b2 = b3 = b4 = b5 = 0.0
            r2 = 0.0
            for i in range(P):
                r = f0[j, i] - scale * (g[i] - mean)
                r2 += r * r
                ax = fx[j, i] * r
                ay = fy[j, i] * r
                b0 += ax
                b1 += ax * dx[i]
                b2 += ax * dy[i]
                b3 += ay
                b4 += ay * dx[i]
                b5 += ay * dy[i]
            b[s, 0], b[s, 1], b[s, 2], b[s, 3], b[s, 4], b[s, 5] = b0, b1, b2, b3, b4, b5
            rr[s] = r2

    def step_numba(spline, cx, cy, gi, A, Xi, f0, fx, fy, df):
        """The IC-GN step compiled with numba (see module docstring)."""
        k = len(gi)
        b = np.zeros((k, 6))
        rr = np.zeros(k)
        dg = np.zeros(k)
        inside = np.zeros(k, dtype=np.bool_)
        h = float(round(Xi[:, 1].max()))
        _step_nb(
            spline.coeffs,
            spline.order,
            cx,
            cy,
            np.ascontiguousarray(gi, dtype=np.int64),
            np.ascontiguousarray(A[:, :2, :]),
            np.ascontiguousarray(Xi[:, 1]),
            np.ascontiguousarray(Xi[:, 2]),
            f0,
            fx,
            fy,
            df,
            h,
            b,
            rr,
            dg,
            inside,
        )
        return b, rr, dg, inside


if numba is not None:

    @numba.njit(cache=True, nogil=True)
    def _splat_nb(G, Ux, Uy, deformed, C, R, cx, cy, sig, amp, n, cutoff):
        Hs, Ws = G.shape
        for k in range(C.size):
            rho = int(np.ceil((cutoff * sig[k] + 1.0) * n))
            inv = 0.5 / (sig[k] * sig[k])
            a = amp[k]
            for dr in range(-rho, rho + 1):
                r = R[k] + dr
                if r < 0 or r >= Hs:
                    continue
                ynom = (r + 0.5) / n - 0.5
                for dc in range(-rho, rho + 1):
                    if dr * dr + dc * dc > rho * rho:
                        continue
                    c = C[k] + dc
                    if c < 0 or c >= Ws:
                        continue
                    X = (c + 0.5) / n - 0.5
                    Y = ynom
                    if deformed:
                        X -= Ux[r, c]
                        Y -= Uy[r, c]
                    dx = X - cx[k]
                    dy = Y - cy[k]
                    G[r, c] += a * np.exp(-(dx * dx + dy * dy) * inv)


def splat_numba(shape_super, Ux, Uy, C, R, centres, sig, amp, n, cutoff):
    """Blob field on the super-grid, compiled: each blob adds ``A exp(-|X - X_k|^2 / 2 s^2)`` to
    the sub-samples within its window (same windows as the numpy path in ``speckle``)."""
    G = np.zeros(shape_super)
    deformed = Ux is not None
    if not deformed:
        Ux = Uy = np.zeros((1, 1), dtype=np.float32)
    _splat_nb(
        G,
        Ux,
        Uy,
        deformed,
        np.ascontiguousarray(C, dtype=np.int64),
        np.ascontiguousarray(R, dtype=np.int64),
        np.ascontiguousarray(centres[:, 0], dtype=float),
        np.ascontiguousarray(centres[:, 1], dtype=float),
        np.ascontiguousarray(sig, dtype=float),
        np.ascontiguousarray(amp, dtype=float),
        int(n),
        float(cutoff),
    )
    return G


def get_step(backend: str | None):
    """The step function of ``backend`` ('scipy', 'numba' or None for the default)."""
    name = backend or DEFAULT_BACKEND
    if name == "scipy":
        return step_scipy
    if name == "numba":
        if numba is None:
            raise ValueError("the numba back-end was requested but numba is not installed")
        return step_numba
    raise ValueError(f"unknown DIC back-end {backend!r}: use 'scipy' or 'numba'")

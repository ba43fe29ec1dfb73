r"""Compiled kernels of the surrogate's cost path (numba): the Gaussian-process posterior mean of
all POD coefficients and the misfit in the space of the coefficients, one call per batch.

GP mean (Matern 5/2, the kernel of every shipped surrogate; other kernels use the numpy path)::

    a_o(z) = y_std_o * sum_i k_c(z, x_i) alpha_io + y_mean_o,   c = component of output o
    k_c = amp_c (1 + s + s^2 / 3) exp(-s),   s = sqrt(5 sum_j (z_j - x_ij)^2 / l_cj^2)

ordered for the vector unit: training points innermost, the squared distances from the
differences (as numpy does: an expansion into norms would lose digits for short length scales,
and the weights of an ill-conditioned GP amplify every digit), ``exp(-s)`` as a table of
``exp(-k / 64)`` times a degree-6 Taylor polynomial of the remainder (relative error <= 3 eps,
tested; numba has no vectorised ``exp`` without Intel's SVML, which the llvmlite wheels lack) for
points in the unit box when every ``s`` there is within :data:`EXP_REACH` (all shipped
surrogates: s <= 28), ``math.exp`` otherwise; each sum over the training points in eight
interleaved partial sums (a fixed order: the same bits whatever the vector width). FMA
contraction is allowed. The result equals the long-double GP mean within the rounding bound
``eps * sum_i |k_i alpha_io| * y_std_o`` times a small factor, as numpy's does (tested); with the
weights of the shipped GPs (``sum |k alpha|`` up to ~1e13 times the coefficient itself) both
differ from the exact mean by ~1e-3 in units of sigma.

Misfit (see :mod:`problems.inverse.reduced`)::

    cost(a) = c_perp + || g - T a ||^2,   T (r, r) upper triangular
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, uint64

from problems.numba_cache import heal as heal_numba_cache

_STEPS = 64.0
#: the reach of the exponential's table: exp(-x) for 0 <= x <= EXP_REACH
EXP_REACH = 40.0
_TABLE = np.exp(-np.arange(int(EXP_REACH * _STEPS) + 2) / _STEPS)
_C1, _C2, _C3, _C4, _C5, _C6 = (-1.0, 1.0 / 2, -1.0 / 6, 1.0 / 24, -1.0 / 120, 1.0 / 720)


@njit(inline="always", fastmath={"contract"})
def exp_neg(x):
    """exp(-x) for 0 <= x <= EXP_REACH: ``exp(-k / 64)`` from a 20 kB table times a degree-6
    Taylor polynomial of exp(-f), 0 <= f < 1/64 (a global table: as an argument it would stop
    the vectorisation)."""
    k = uint64(x * _STEPS)
    f = x - k * (1.0 / _STEPS)
    p = (((((_C6 * f + _C5) * f + _C4) * f + _C3) * f + _C2) * f + _C1) * f + 1.0
    return _TABLE[k] * p


@njit(cache=True)
def exp_neg_array(x):
    """:func:`exp_neg` over an array (for tests)."""
    out = np.empty_like(x)
    for i in range(x.size):
        out[i] = exp_neg(x[i])
    return out


@njit(inline="always", fastmath={"contract"})
def _dot(k, a):
    """sum_i k_i a_i in eight interleaved partial sums (a fixed order the vector unit follows)."""
    n = k.size
    nb = n - n % 8
    s0 = s1 = s2 = s3 = s4 = s5 = s6 = s7 = 0.0
    for i in range(0, nb, 8):
        s0 += k[i] * a[i]
        s1 += k[i + 1] * a[i + 1]
        s2 += k[i + 2] * a[i + 2]
        s3 += k[i + 3] * a[i + 3]
        s4 += k[i + 4] * a[i + 4]
        s5 += k[i + 5] * a[i + 5]
        s6 += k[i + 6] * a[i + 6]
        s7 += k[i + 7] * a[i + 7]
    s = ((s0 + s1) + (s2 + s3)) + ((s4 + s5) + (s6 + s7))
    for i in range(nb, n):
        s += k[i] * a[i]
    return s


@njit(inline="always", fastmath={"contract"})
def _gp_mean_point(z, XT, W, alphaT, starts, outputs, y, reach, k, t2, out):
    """Coefficients ``out`` (r,) at one scaled point ``z`` (d,); ``k`` (n,), ``t2`` (d, n) are
    scratch; ``reach``:
    every s of a point in the unit box is within the table's reach."""
    d, n = XT.shape
    unit = reach
    for j in range(d):
        unit = unit and 0.0 <= z[j] <= 1.0
    for j in range(d):  # squared differences, shared by the components
        zj = z[j]
        for i in range(n):
            t = zj - XT[j, i]
            t2[j, i] = t * t
    for c in range(W.shape[0]):
        if d == 6:  # the nine cases: one pass over the training points
            w0, w1, w2, w3, w4, w5 = W[c, 0], W[c, 1], W[c, 2], W[c, 3], W[c, 4], W[c, 5]
            q0, q1, q2, q3, q4, q5 = t2[0], t2[1], t2[2], t2[3], t2[4], t2[5]
            for i in range(n):
                k[i] = ((w0 * q0[i] + w1 * q1[i]) + (w2 * q2[i] + w3 * q3[i])) + (
                    w4 * q4[i] + w5 * q5[i]
                )
        else:
            for i in range(n):
                k[i] = 0.0
            for j in range(d):
                w = W[c, j]
                for i in range(n):
                    k[i] += w * t2[j, i]
        if unit:  # s <= the table's reach
            for i in range(n):
                s = math.sqrt(k[i])
                k[i] = ((s * (1.0 / 3.0) + 1.0) * s + 1.0) * exp_neg(s)
        else:
            for i in range(n):
                s = math.sqrt(k[i])
                k[i] = ((s * (1.0 / 3.0) + 1.0) * s + 1.0) * math.exp(-s)
        for o in range(starts[c], starts[c + 1]):
            col = outputs[o]
            out[col] = _dot(k, alphaT[col]) * y[1, col] + y[0, col]


@njit(cache=True)
def gp_mean(Z, XT, W, alphaT, starts, outputs, y, reach, out):
    """GP posterior means ``out`` (q, r) at scaled points ``Z`` (q, d).

    XT (d, n) training points; W (C, d) ``5 / l_cj^2``; alphaT (r, n)
    amplitude * alpha of each output; starts
    (C + 1,) and outputs (r,) the outputs of component c are ``outputs[starts[c]:starts[c+1]]``;
    y (2, r) output mean and standard deviation; ``reach``: the largest ``s`` of a point in the
    unit box is within :data:`EXP_REACH` (then such points take :func:`exp_neg`, all others
    ``math.exp``)."""
    k, t2 = np.empty(XT.shape[1]), np.empty(XT.shape)
    for p in range(Z.shape[0]):
        _gp_mean_point(Z[p], XT, W, alphaT, starts, outputs, y, reach, k, t2, out[p])


@njit(cache=True)
def surrogate_costs(
    X,
    limits,
    code,
    idx,
    consts,
    XT,
    W,
    alphaT,
    starts,
    outputs,
    y,
    reach,
    TT,
    g,
    c_perp,
    A,
    costs,
    clear,
):
    """For the physical points ``X`` (q, d): ``clear`` (q,) = inside the box ``limits[0:2]``
    (inclusive) and passing the material screen (:mod:`problems.surrogate.screen`, open
    ranges ``limits[2:4]``, ``code``, ``idx``, ``consts``); the GP means ``A`` (q, r) at the
    scaled points and the misfits ``costs`` (q,) ``c_perp + ||g - T a||^2`` (``TT = T^T``, T upper
    triangular). Every point is evaluated; the caller uses the costs of the valid ones.
    Returns the number of points not clear."""
    d = X.shape[1]
    k, t2 = np.empty(XT.shape[1]), np.empty(XT.shape)
    z = np.empty(d)
    r = g.size
    e = np.empty(r)
    n_unclear = 0
    for p in range(X.shape[0]):
        x = X[p]
        inside = True
        for j in range(d):
            inside = inside and limits[0, j] <= x[j] <= limits[1, j]
            z[j] = (x[j] - limits[0, j]) / (limits[1, j] - limits[0, j])
        clear[p] = inside and _clear(x, limits[2], limits[3], code, idx, consts)
        n_unclear += not clear[p]
        a = A[p]
        _gp_mean_point(z, XT, W, alphaT, starts, outputs, y, reach, k, t2, a)
        for i in range(r):
            e[i] = g[i]
        for j in range(r):  # e = g - T a, column by column (T^T stored: contiguous columns)
            aj = a[j]
            for i in range(j + 1):
                e[i] -= TT[j, i] * aj
        total = 0.0
        for i in range(r):
            total += e[i] * e[i]
        costs[p] = c_perp + total
    return n_unclear


# --------------------------------------------------------------------------------------------
# The material screen (problems.surrogate.screen.Screen)
# --------------------------------------------------------------------------------------------

#: relative margin of the screen's inequalities
MARGIN = 1e-9

#: form conditions the screen knows
NONE, HYPERBOLIC, EXPONENT_FROM_PT0, EXPONENT = 0, 1, 2, 3


@njit(cache=True)
def _clear(x, lo, hi, code, idx, consts) -> bool:
    """Point ``x`` passes the screen: inside the open ranges ``lo < x < hi`` and the form's
    condition ``code`` (on the parameters at ``idx``; ``consts`` = q_hat, p_hat) by the margin."""
    for j in range(x.size):
        if not (x[j] > lo[j] and x[j] < hi[j]):
            return False
    if code == NONE:
        return True
    q_hat, p_hat = consts[0], consts[1]
    s0 = x[idx[0]]
    S = q_hat * s0
    if code == HYPERBOLIC:
        A = math.tan(math.radians(x[idx[1]])) * (x[idx[2]] + p_hat * s0)
        return A > MARGIN * S and A < S * (1.0 - MARGIN)
    if code == EXPONENT_FROM_PT0:
        pt0, b = x[idx[1]], x[idx[2]]
        num = pt0 + p_hat * s0  # a = num / S^b > 0
        return num > MARGIN * (abs(pt0) + abs(p_hat * s0)) and math.isfinite(num / S**b)
    if code == EXPONENT:
        a, b = x[idx[1]], x[idx[2]]
        aS = a * S**b
        return math.isfinite(aS) and aS - p_hat * s0 > MARGIN * (abs(aS) + abs(p_hat * s0))
    return False


@njit(cache=True)
def screen_points(X, lo, hi, code, idx, consts, out) -> None:
    """``out[k]`` = row k of ``X`` passes the screen."""
    for k in range(X.shape[0]):
        out[k] = _clear(X[k], lo, hi, code, idx, consts)


class PackedGP:
    """The arrays of :func:`gp_mean` for a :class:`~problems.surrogate.regression.GPFit` whose
    components share their training points and a Matern 5/2 kernel (``None`` from
    :meth:`of` otherwise)."""

    __slots__ = ("args",)

    def __init__(self, args):
        self.args = args

    @classmethod
    def of(cls, fit) -> "PackedGP | None":
        packed = getattr(fit, "_packed", None)
        if packed is None or fit.components[0].nu != 2.5:
            return None
        X, inv_ls2, amp, comp, alpha, y_mean, y_std = packed
        order = np.argsort(comp, kind="stable")
        starts = np.searchsorted(comp[order], np.arange(len(amp) + 1)).astype(np.int64)
        W = np.ascontiguousarray(5.0 * inv_ls2.T)  # s^2 = sum_j W_cj (z_j - x_ij)^2
        # the largest s of a point z in the unit box: |z_j - x_ij| <= max(|x_ij|, |1 - x_ij|)
        reach = np.max(np.maximum(X**2, (1.0 - X) ** 2), axis=0)  # (d,)
        s_max = math.sqrt(5.0 * float(np.max(reach @ inv_ls2)))
        return cls(
            (
                np.ascontiguousarray(X.T),
                W,
                np.ascontiguousarray((alpha * amp[comp]).T),
                starts,
                order.astype(np.int64),
                np.vstack([y_mean, y_std]),
                s_max * (1.0 + 1e-9) < EXP_REACH,
            )
        )

    @property
    def n_outputs(self) -> int:
        return self.args[2].shape[0]

    def mean(self, Z) -> np.ndarray:
        """(q, r) coefficients at scaled points ``Z`` (q, d)."""
        Z = np.ascontiguousarray(np.atleast_2d(Z), dtype=float)
        out = np.empty((len(Z), self.n_outputs))
        gp_mean(Z, *self.args, out)
        return out


heal_numba_cache(globals())  # a torn cache file of these kernels: named, removed

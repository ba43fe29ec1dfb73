r"""Regression of the POD coefficients over the scaled parameters
``z = (x - lower) / (upper - lower)``.

Two families, both stored as plain arrays (no fitted library object is kept, so a stored model
loads without scikit-learn and pickles small), both with a cheap exact gradient ``da/dz``:

RBF
    ``a(z) = sum_i w_i phi(eps ||z - z_i||) + sum_j c_j p_j((z - shift) / scale)``, fitted with
    :class:`scipy.interpolate.RBFInterpolator` (``(K + lambda I) w + P c = A``, ``P^T w = 0``;
    ``lambda = 0`` interpolates the training points). Kernel, shape parameter ``eps`` and
    smoothing ``lambda`` are chosen by k-fold cross-validation (:func:`select_rbf`). The gradient
    differentiates the kernel: ``d phi / dz = phi'(r) / r * eps^2 (z - z_i)``.
GP
    Gaussian-process posterior means (:class:`sklearn.gaussian_process.GaussianProcessRegressor`,
    ``normalize_y``) with an anisotropic Matern (``nu`` = 1.5 or 2.5) or squared-exponential
    (``nu = inf``) kernel times a constant, plus a white-noise term; hyper-parameters by maximum
    marginal likelihood. The leading ``n_individual`` modes get a GP each (own length scales);
    the remaining modes share one multi-output GP. Prediction ``a(z) = std * k(z, Z) alpha + mean``,
    gradient from ``dk/dz``.

Scores are errors in units of the measurement noise: because the modes are orthonormal in the
scaled space, a coefficient error ``da`` is a measurement error ``sigma * Phi da``, and its mean
square over block ``b`` is ``da^T (Phi_b^T Phi_b) da / m_b`` (:class:`Scorer`).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from functools import cached_property

import numpy as np

#: kernels of scipy's RBFInterpolator that need no shape parameter (eps = 1)
SCALE_FREE = ("thin_plate_spline", "cubic", "quintic", "linear")
#: default candidates of the RBF cross-validation: (kernel, eps) pairs and smoothing values
RBF_KERNELS = (
    ("thin_plate_spline", 1.0),
    ("cubic", 1.0),
    ("quintic", 1.0),
    ("multiquadric", 1.0),
    ("multiquadric", 3.0),
    ("gaussian", 1.0),
    ("gaussian", 3.0),
)
RBF_SMOOTHING = (0.0, 1e-6, 1e-4, 1e-2)


# --------------------------------------------------------------------------------------------
# Scores in units of sigma
# --------------------------------------------------------------------------------------------


class Scorer:
    """Mean-square errors per block, in units of sigma^2, of coefficient errors (or of scaled
    measurement errors). ``score`` is the mean over the blocks of their mean squares, so that the
    N force values weigh as much as the 2 N m displacements."""

    def __init__(self, modes: np.ndarray, blocks: dict[str, slice]):
        self.blocks = blocks
        m = modes.shape[0]
        self.sizes = {k: len(range(*sl.indices(m))) for k, sl in blocks.items()}
        self.grams = {k: modes[sl].T @ modes[sl] for k, sl in blocks.items()}

    def coefficient_ms(self, dA) -> dict[str, float]:
        """{block: mean square error, sigma^2} of coefficient errors ``dA`` (q, r)."""
        dA = np.atleast_2d(dA)
        return {
            k: float(np.einsum("qi,ij,qj->", dA, G, dA) / (len(dA) * self.sizes[k]))
            for k, G in self.grams.items()
        }

    def scaled_ms(self, E) -> dict[str, float]:
        """{block: mean square} of scaled measurement errors ``E`` (q, m)
        (already divided by sigma)."""
        E = np.atleast_2d(E)
        return {k: float(np.mean(E[:, sl] ** 2)) for k, sl in self.blocks.items()}

    @staticmethod
    def score(ms: dict[str, float]) -> float:
        return float(np.mean(list(ms.values())))


# --------------------------------------------------------------------------------------------
# RBF
# --------------------------------------------------------------------------------------------


def _phi(kernel: str, r: np.ndarray) -> np.ndarray:
    if kernel == "linear":
        return -r
    if kernel == "thin_plate_spline":
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(r > 0, r * r * np.log(np.where(r > 0, r, 1.0)), 0.0)
    if kernel == "cubic":
        return r**3
    if kernel == "quintic":
        return -(r**5)
    if kernel == "multiquadric":
        return -np.sqrt(r * r + 1.0)
    if kernel == "inverse_multiquadric":
        return 1.0 / np.sqrt(r * r + 1.0)
    if kernel == "inverse_quadratic":
        return 1.0 / (r * r + 1.0)
    if kernel == "gaussian":
        return np.exp(-r * r)
    raise ValueError(f"RBF kernel {kernel!r} is unknown")


def _dphi_over_r(kernel: str, r: np.ndarray) -> np.ndarray:
    """``phi'(r) / r``; at ``r = 0`` (a centre) the contribution ``(z - z_i) phi'/r`` is set to
    0."""
    safe = np.where(r > 0, r, 1.0)
    if kernel == "linear":
        g = -1.0 / safe
    elif kernel == "thin_plate_spline":
        g = 2.0 * np.log(safe) + 1.0
    elif kernel == "cubic":
        g = 3.0 * r
    elif kernel == "quintic":
        g = -5.0 * r**3
    elif kernel == "multiquadric":
        g = -1.0 / np.sqrt(r * r + 1.0)
    elif kernel == "inverse_multiquadric":
        g = -((r * r + 1.0) ** -1.5)
    elif kernel == "inverse_quadratic":
        g = -2.0 / (r * r + 1.0) ** 2
    elif kernel == "gaussian":
        g = -2.0 * np.exp(-r * r)
    else:
        raise ValueError(f"RBF kernel {kernel!r} is unknown")
    return np.where(r > 0, g, 0.0)


def _monomials(xhat: np.ndarray, powers: np.ndarray) -> np.ndarray:
    """(q, P) monomials ``prod_i xhat_i^p_ji``."""
    return np.prod(xhat[:, None, :] ** powers[None, :, :], axis=2)


def _monomial_gradient(xhat: np.ndarray, powers: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """(P, d) derivatives of the monomials at one point ``xhat`` (d,) with respect to z."""
    P, d = powers.shape
    out = np.zeros((P, d))
    for i in range(d):
        p = powers[:, i]
        lowered = powers.copy()
        lowered[:, i] = np.maximum(p - 1, 0)
        out[:, i] = np.where(p > 0, p * np.prod(xhat[None, :] ** lowered, axis=1), 0.0) / scale[i]
    return out


@dataclass(frozen=True, eq=False)
class RBFFit:
    """A fitted RBF of the coefficients (arrays of :class:`scipy.interpolate.RBFInterpolator`).

    centres (n, d), coeffs (n + P, r), shift (d,), scale (d,), powers (P, d) as in scipy.
    """

    centres: np.ndarray
    coeffs: np.ndarray
    shift: np.ndarray
    scale: np.ndarray
    powers: np.ndarray
    kernel: str
    epsilon: float
    smoothing: float

    kind = "rbf"

    @property
    def n_outputs(self) -> int:
        return self.coeffs.shape[1]

    def predict(self, Z) -> np.ndarray:
        """(q, r) coefficients at scaled points ``Z`` (q, d)."""
        Z = np.atleast_2d(np.asarray(Z, float))
        n = len(self.centres)
        r = self.epsilon * np.sqrt(np.sum((Z[:, None, :] - self.centres[None]) ** 2, axis=2))
        out = _phi(self.kernel, r) @ self.coeffs[:n]
        if len(self.powers):
            out += _monomials((Z - self.shift) / self.scale, self.powers) @ self.coeffs[n:]
        return out

    def gradient(self, z) -> np.ndarray:
        """(r, d) derivative of the coefficients with respect to ``z`` at one point ``z`` (d,)."""
        z = np.asarray(z, float)
        n = len(self.centres)
        diff = z[None, :] - self.centres
        r = self.epsilon * np.sqrt(np.sum(diff**2, axis=1))
        dK = (_dphi_over_r(self.kernel, r) * self.epsilon**2)[:, None] * diff  # (n, d)
        out = self.coeffs[:n].T @ dK
        if len(self.powers):
            out += self.coeffs[n:].T @ _monomial_gradient(
                (z - self.shift) / self.scale, self.powers, self.scale
            )
        return out

    def settings(self) -> dict:
        return {
            "kind": "rbf",
            "kernel": self.kernel,
            "epsilon": self.epsilon,
            "smoothing": self.smoothing,
        }

    def arrays(self) -> dict[str, np.ndarray]:
        return {
            "centres": self.centres,
            "coeffs": self.coeffs,
            "shift": self.shift,
            "scale": self.scale,
            "powers": self.powers,
        }

    @classmethod
    def from_stored(cls, arrays: dict, settings: dict) -> "RBFFit":
        return cls(
            arrays["centres"],
            arrays["coeffs"],
            arrays["shift"],
            arrays["scale"],
            np.asarray(arrays["powers"], int),
            settings["kernel"],
            float(settings["epsilon"]),
            float(settings["smoothing"]),
        )


def fit_rbf(
    Z, A, *, kernel: str = "thin_plate_spline", epsilon: float = 1.0, smoothing: float = 0.0
) -> RBFFit:
    """Fit the coefficients ``A`` (n, r) over scaled points ``Z`` (n, d) with scipy's
    RBFInterpolator."""
    from scipy.interpolate import RBFInterpolator

    Z, A = np.asarray(Z, float), np.asarray(A, float)
    itp = RBFInterpolator(Z, A, kernel=kernel, epsilon=epsilon, smoothing=smoothing)
    return RBFFit(
        Z.copy(),
        np.asarray(itp._coeffs, float).reshape(len(Z) + len(itp.powers), -1),
        np.asarray(itp._shift, float),
        np.asarray(itp._scale, float),
        np.asarray(itp.powers, int),
        kernel,
        float(itp.epsilon),
        float(smoothing),
    )


def kfold(n: int, folds: int, seed: int) -> list[np.ndarray]:
    """Seeded split of ``range(n)`` into ``folds`` test index sets."""
    folds = max(2, min(folds, n))
    return np.array_split(np.random.default_rng(seed).permutation(n), folds)


def select_rbf(
    Z,
    A,
    scorer: Scorer,
    *,
    kernels=RBF_KERNELS,
    smoothing=RBF_SMOOTHING,
    folds: int = 5,
    seed: int = 0,
) -> tuple[dict, list[dict]]:
    """The (kernel, epsilon, smoothing) with the lowest k-fold cross-validation score, and the table
    of all candidates (``{"kernel", "epsilon", "smoothing", "score", "rms_sigma": {block: ...}}``;
    score ``inf`` when a fit was singular)."""
    from numpy.linalg import LinAlgError

    Z, A = np.asarray(Z, float), np.asarray(A, float)
    splits = kfold(len(Z), folds, seed)
    table = []
    for kernel, eps in kernels:
        for lam in smoothing:
            pred = np.empty_like(A)
            try:
                for test in splits:
                    train = np.setdiff1d(np.arange(len(Z)), test)
                    pred[test] = fit_rbf(
                        Z[train], A[train], kernel=kernel, epsilon=eps, smoothing=lam
                    ).predict(Z[test])
                ms = scorer.coefficient_ms(pred - A)
                score = scorer.score(ms)
            except (LinAlgError, ValueError):
                ms, score = {}, math.inf
            if not np.isfinite(score):
                score = math.inf
            table.append(
                {
                    "kernel": kernel,
                    "epsilon": float(eps),
                    "smoothing": float(lam),
                    "score": score,
                    "rms_sigma": {k: math.sqrt(v) for k, v in ms.items()},
                }
            )
    best = min(table, key=lambda row: row["score"])
    if not math.isfinite(best["score"]):
        raise ValueError(
            "every RBF candidate failed (singular systems): too few or duplicate training points"
        )
    return {k: best[k] for k in ("kernel", "epsilon", "smoothing")}, table


# --------------------------------------------------------------------------------------------
# Gaussian process
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class GPComponent:
    """The posterior mean of one GP over some modes.

    outputs      : (k,) indices of the modes it predicts
    X            : (n, d) training points (scaled)
    alpha        : (n, k) ``K^-1 (y - mean) / std``
    y_mean, y_std: (k,) normalisation of the outputs
    amplitude    : constant factor of the kernel (normalised units)
    length_scale : (d,) length scales (scaled units)
    nu           : Matern smoothness, 1.5, 2.5, or inf (squared exponential)
    """

    outputs: np.ndarray
    X: np.ndarray
    alpha: np.ndarray
    y_mean: np.ndarray
    y_std: np.ndarray
    amplitude: float
    length_scale: np.ndarray
    nu: float

    def _k(self, diff: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Kernel values k(d) and ``(dk/dz) / (z - x_i) * l^2`` factor for differences (..., d)."""
        d = np.sqrt(np.sum((diff / self.length_scale) ** 2, axis=-1))
        a = self.amplitude
        if self.nu == 1.5:
            e = np.exp(-math.sqrt(3.0) * d)
            return a * (1.0 + math.sqrt(3.0) * d) * e, -3.0 * a * e
        if self.nu == 2.5:
            e = np.exp(-math.sqrt(5.0) * d)
            return a * (1.0 + math.sqrt(5.0) * d + 5.0 / 3.0 * d * d) * e, -5.0 / 3.0 * a * (
                1.0 + math.sqrt(5.0) * d
            ) * e
        k = a * np.exp(-0.5 * d * d)
        return k, -k

    def predict(self, Z) -> np.ndarray:
        Z = np.atleast_2d(np.asarray(Z, float))
        k, _ = self._k(Z[:, None, :] - self.X[None])
        return (k @ self.alpha) * self.y_std + self.y_mean

    def gradient(self, z) -> np.ndarray:
        """(k, d) derivative of the predicted modes at one point ``z``."""
        diff = np.asarray(z, float)[None, :] - self.X
        _, f = self._k(diff)
        dk = f[:, None] * diff / self.length_scale**2  # (n, d)
        return (self.alpha.T @ dk) * self.y_std[:, None]


@dataclass(frozen=True, eq=False)
class GPFit:
    """Gaussian-process regression of all coefficients: one or more :class:`GPComponent`."""

    components: tuple[GPComponent, ...]
    n_outputs: int

    kind = "gp"

    @cached_property
    def _packed(self):
        """All components at once when they share the training points and ``nu`` (the usual
        case): ``(X, inv_ls2 (d, C), amplitude (C,), comp (r,), alpha (n, r), y_mean, y_std)``;
        None otherwise (then the components are evaluated one by one)."""
        cs = self.components
        X = cs[0].X
        if any(c.nu != cs[0].nu or c.X.shape != X.shape or not np.array_equal(c.X, X) for c in cs):
            return None
        r = self.n_outputs
        comp = np.zeros(r, int)
        alpha = np.zeros((len(X), r))
        y_mean, y_std = np.zeros(r), np.ones(r)
        for i, c in enumerate(cs):
            comp[c.outputs] = i
            alpha[:, c.outputs] = c.alpha
            y_mean[c.outputs], y_std[c.outputs] = c.y_mean, c.y_std
        inv_ls2 = np.column_stack([1.0 / c.length_scale**2 for c in cs])
        amp = np.array([c.amplitude for c in cs])
        return X, inv_ls2, amp, comp, alpha, y_mean, y_std

    def _kernel(self, d, amp, derivative: bool = True):
        """Kernel values and ``(dk/dd) / d`` (None unless ``derivative``) of the packed components
        at scaled distances ``d`` (..., C)."""
        nu = self.components[0].nu
        if nu == 1.5:
            e = amp * np.exp(-math.sqrt(3.0) * d)
            return (1.0 + math.sqrt(3.0) * d) * e, (-3.0 * e if derivative else None)
        if nu == 2.5:
            sd = math.sqrt(5.0) * d
            e = np.exp(-sd)
            e *= amp
            k = sd * sd
            k *= 1.0 / 3.0
            k += sd
            k += 1.0
            k *= e
            return k, (-5.0 / 3.0 * (1.0 + sd) * e if derivative else None)
        k = amp * np.exp(-0.5 * d * d)
        return k, (-k if derivative else None)

    def predict(self, Z) -> np.ndarray:
        Z = np.atleast_2d(np.asarray(Z, float))
        packed = self._packed
        if packed is None:
            out = np.empty((len(Z), self.n_outputs))
            for c in self.components:
                out[:, c.outputs] = c.predict(Z)
            return out
        X, inv_ls2, amp, comp, alpha, y_mean, y_std = packed
        if len(Z) == 1:
            diff = Z[0] - X  # (n, d)
            k, _ = self._kernel(np.sqrt((diff * diff) @ inv_ls2), amp, False)  # (n, C)
            return (np.einsum("nr,nr->r", k[:, comp], alpha) * y_std + y_mean)[None]
        out = np.empty((len(Z), self.n_outputs))
        counts = np.bincount(comp, minlength=len(amp))
        single = np.flatnonzero(counts == 1)  # components of one output: a weighted sum each
        single_out = np.array([np.flatnonzero(comp == c)[0] for c in single], int)
        alpha_single = alpha[:, single_out]  # (n, S)
        groups = [(c, np.flatnonzero(comp == c)) for c in np.flatnonzero(counts > 1)]
        # small chunks: the (q, n, C) temporaries stay in cache
        step = max(1, 40_000 // (len(X) * max(len(amp), X.shape[1])))
        for i in range(0, len(Z), step):
            diff = Z[i : i + step, None, :] - X[None]  # (q, n, d): no cancellation
            k, _ = self._kernel(np.sqrt((diff * diff) @ inv_ls2), amp, False)  # (q, n, C)
            if single.size:
                out[i : i + step, single_out] = np.sum(k[:, :, single] * alpha_single, axis=1)
            for c, cols in groups:
                out[i : i + step, cols] = k[:, :, c] @ alpha[:, cols]
        return out * y_std + y_mean

    def gradient(self, z) -> np.ndarray:
        packed = self._packed
        if packed is None:
            out = np.empty((self.n_outputs, len(np.atleast_1d(z))))
            for c in self.components:
                out[c.outputs] = c.gradient(z)
            return out
        X, inv_ls2, amp, comp, alpha, y_mean, y_std = packed
        diff = np.asarray(z, float) - X  # (n, d)
        _, f = self._kernel(np.sqrt((diff * diff) @ inv_ls2), amp)  # (n, C)
        G = (f[:, comp] * alpha).T @ diff  # (r, d)
        return G * inv_ls2[:, comp].T * y_std[:, None]

    def settings(self) -> dict:
        return {
            "kind": "gp",
            "n_outputs": self.n_outputs,
            "nu": [float(c.nu) for c in self.components],
            "amplitude": [c.amplitude for c in self.components],
            "length_scale": [c.length_scale.tolist() for c in self.components],
        }

    def arrays(self) -> dict[str, np.ndarray]:
        out = {}
        for i, c in enumerate(self.components):
            for name in ("outputs", "X", "alpha", "y_mean", "y_std", "length_scale"):
                out[f"gp{i}_{name}"] = getattr(c, name)
        return out

    @classmethod
    def from_stored(cls, arrays: dict, settings: dict) -> "GPFit":
        comps = []
        for i, (nu, amp) in enumerate(zip(settings["nu"], settings["amplitude"])):
            comps.append(
                GPComponent(
                    np.asarray(arrays[f"gp{i}_outputs"], int),
                    arrays[f"gp{i}_X"],
                    arrays[f"gp{i}_alpha"],
                    arrays[f"gp{i}_y_mean"],
                    arrays[f"gp{i}_y_std"],
                    float(amp),
                    arrays[f"gp{i}_length_scale"],
                    float(nu),
                )
            )
        return cls(tuple(comps), int(settings["n_outputs"]))


def fit_gp_component(
    Z, Y, outputs, *, nu: float = 2.5, restarts: int = 2, seed: int = 0
) -> GPComponent:
    """Fit one scikit-learn GP to the columns ``outputs`` of ``Y`` (shared hyper-parameters)."""
    from sklearn.exceptions import ConvergenceWarning
    from sklearn.gaussian_process import GaussianProcessRegressor
    from sklearn.gaussian_process.kernels import RBF, ConstantKernel, Matern, WhiteKernel

    Z = np.asarray(Z, float)
    y = np.asarray(Y, float)[:, outputs]
    d = Z.shape[1]
    shape = (
        Matern(np.full(d, 0.5), (1e-2, 1e3), nu=nu)
        if math.isfinite(nu)
        else RBF(np.full(d, 0.5), (1e-2, 1e3))
    )
    kernel = ConstantKernel(1.0, (1e-3, 1e5)) * shape + WhiteKernel(1e-6, (1e-12, 1e-1))
    gp = GaussianProcessRegressor(
        kernel, normalize_y=True, n_restarts_optimizer=restarts, random_state=seed
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        gp.fit(Z, y)
    k = len(outputs)
    amp = float(gp.kernel_.k1.k1.constant_value)
    ls = np.broadcast_to(np.asarray(gp.kernel_.k1.k2.length_scale, float), (d,)).copy()
    return GPComponent(
        np.asarray(outputs, int),
        Z.copy(),
        np.asarray(gp.alpha_, float).reshape(len(Z), k),
        np.broadcast_to(np.asarray(gp._y_train_mean, float), (k,)).copy(),
        np.broadcast_to(np.asarray(gp._y_train_std, float), (k,)).copy(),
        amp,
        ls,
        float(nu),
    )


def fit_gp(
    Z,
    A,
    *,
    nu: float = 2.5,
    n_individual: int = 8,
    restarts: int = 2,
    seed: int = 0,
    individual: tuple[int, ...] = (),
) -> GPFit:
    """GP regression of all coefficients ``A`` (n, r): one GP per leading mode up to
    ``n_individual`` and per column in ``individual`` (e.g. the separate force values), one
    shared multi-output GP for the rest."""
    if nu not in (1.5, 2.5) and math.isfinite(nu):
        raise ValueError(f"GP nu = {nu} is unsupported; allowed: 1.5, 2.5, inf")
    A = np.asarray(A, float)
    r = A.shape[1]
    own = sorted(set(range(min(n_individual, r))) | {int(j) for j in individual if 0 <= j < r})
    groups = [np.array([j]) for j in own]
    rest = np.setdiff1d(np.arange(r), own)
    if rest.size:
        groups.append(rest)
    comps = tuple(
        fit_gp_component(Z, A, g, nu=nu, restarts=restarts, seed=seed + i)
        for i, g in enumerate(groups)
    )
    return GPFit(comps, r)


def from_stored(arrays: dict, settings: dict):
    """The regression stored by ``arrays()`` and ``settings()``."""
    kind = settings.get("kind")
    if kind == "rbf":
        return RBFFit.from_stored(arrays, settings)
    if kind == "gp":
        return GPFit.from_stored(arrays, settings)
    raise ValueError(f"regression kind {kind!r} is unknown; allowed: rbf, gp")

"""Cheap analytic forward models that go through the very same
:class:`~problems.inverse.evaluator.Evaluator`.

They let every solver be tested in seconds, with known answers:

``analytic-smooth``
    A smooth elasto-plastic uniaxial compression curve with dilatancy, Drucker-Prager-like,
    parameters ``E, sigma0, H, psi``. Strains ``eps_k`` (40 points up to 4e-3) are split into an
    elastic part ``ee = eps / (1 + (E eps / sigma0)^2)^(1/2)`` (it saturates at ``sigma0 / E``) and
    a plastic part ``ep = eps - ee``; measured are the axial stress ``E ee + H ep``
    (MPa, sigma 0.05) and the lateral expansion ``nu ee + (1 + tan psi) ep / 2`` (sigma 2e-6). Well
    conditioned, cost 0 at the reference (inside the bounds).
``analytic-multimodal``
    A sinusoid frequency fit ``y(t) = a sin(omega t) + c`` on ``t in [0, 15] s`` (80 points, sigma
    0.05), parameters ``a, omega, c``: seven local minima in ``omega`` over ``[1, 4]`` rad/s, each
    with cost about 1.8e4, and the global one (cost 0) at ``omega = 2``; its basin is roughly
    ``omega in [1.7, 2.3]`` (a fifth of the range). The default start (``omega = 1.5``) lies in the
    basin of the local minimum at 1.5, so a local method started there fails.
``analytic-rastrigin``
    Rastrigin in residual form: ``u_i = (x_i / ref_i - 1) / 0.1``, residuals
    ``[u_i, sqrt(20) sin(pi u_i)]`` so that ``cost = sum u_i^2 + 20 sin^2(pi u_i)`` (the Rastrigin
    function with A = 10), 3 parameters, asymmetric bounds, about 700 local minima near integer
    ``u``; the global basin is ``|u_i| < 1/2`` (``|x_i / ref_i - 1| < 5 %``), global minimum 0 at
    the reference.
``analytic-linear``
    ``y = A x`` (20 x 3), sigma 0.05: with the uniform prior on the (wide) box the posterior is
    Gaussian to within 20 standard deviations; :meth:`LinearModel.posterior` gives its mean and
    covariance. For the MCMC tests.
``analytic-infeasible``
    ``analytic-smooth`` where ``check`` rejects ``psi > 25`` deg (the top fifth of its range).
``analytic-failing``
    ``analytic-smooth`` whose ``__call__`` fails (``ok=False``) for ``sigma0 > 24`` MPa.

:func:`analytic_objective` returns the objective with synthetic data made at the reference, plus
``noise`` times the nominal measurement standard deviation of Gaussian noise (seeded).
All models are module-level classes, hence picklable.
"""

from __future__ import annotations

import math

import numpy as np

from problems.inverse.case import Case, Parameter
from problems.inverse.evaluator import Evaluator
from problems.inverse.problem import LeastSquaresProblem
from problems.inverse.protocol import ForwardResult


class StressStrainModel:
    """Smooth uniaxial compression curve with dilatancy (see the module docstring)."""

    names = ("E", "sigma0", "H", "psi")
    nu = 0.2
    sigma_stress = 0.05  # MPa
    sigma_lateral = 2e-6  # strain

    def __init__(self, n_points: int = 40, max_strain: float = 4e-3):
        self.strain = np.linspace(0.0, max_strain, n_points + 1)[1:]

    @property
    def n_values(self) -> int:
        return 2 * self.strain.size

    def sigma(self) -> np.ndarray:
        m = self.strain.size
        return np.concatenate([np.full(m, self.sigma_stress), np.full(m, self.sigma_lateral)])

    def blocks(self) -> dict[str, slice]:
        m = self.strain.size
        return {"stress": slice(0, m), "lateral": slice(m, 2 * m)}

    def values(self, x) -> np.ndarray:
        """U_N(x); works for complex x too (complex-step derivatives)."""
        E, s0, H, psi = x
        eps = self.strain
        ee = eps / np.sqrt(1.0 + (E * eps / s0) ** 2)
        ep = eps - ee
        stress = E * ee + H * ep
        lateral = self.nu * ee + 0.5 * (1.0 + np.tan(psi * math.pi / 180.0)) * ep
        return np.concatenate([stress, lateral])

    def jacobian(self, x) -> np.ndarray:
        """dU_N/dx (physical), exact to rounding (complex step)."""
        x = np.asarray(x, dtype=float)
        J = np.empty((self.n_values, x.size))
        for i in range(x.size):
            h = 1e-30 * max(abs(x[i]), 1.0)
            xc = x.astype(complex)
            xc[i] += 1j * h
            J[:, i] = self.values(xc).imag / h
        return J

    def check(self, x) -> str | None:
        return None

    def __call__(self, x) -> ForwardResult:
        return ForwardResult(True, self.values(np.asarray(x, dtype=float)))


class InfeasibleStressStrainModel(StressStrainModel):
    """``check`` rejects a dilatancy angle above 25 deg."""

    psi_max = 25.0

    def check(self, x) -> str | None:
        if x[3] > self.psi_max:
            return (
                f"dilatancy angle psi = {x[3]:.4g} deg above {self.psi_max:g} deg is not admissible"
            )
        return None


class FailingStressStrainModel(StressStrainModel):
    """``__call__`` fails (``ok=False``) for ``sigma0 > 24`` MPa, like a non-converged FE run."""

    sigma0_max = 24.0

    def __call__(self, x) -> ForwardResult:
        if x[1] > self.sigma0_max:
            return ForwardResult(
                False, None, f"return mapping did not converge (sigma0 = {x[1]:.4g} MPa)"
            )
        return super().__call__(x)


class SinusoidModel:
    """``y(t) = a sin(omega t) + c``: multimodal in ``omega`` (see the module docstring)."""

    names = ("a", "omega", "c")
    sigma = 0.05

    def __init__(self, n_points: int = 80, duration: float = 15.0):
        self.t = np.linspace(0.0, duration, n_points)

    def values(self, x) -> np.ndarray:
        a, w, c = x
        return a * np.sin(w * self.t) + c

    def jacobian(self, x) -> np.ndarray:
        a, w, c = x
        return np.column_stack(
            [np.sin(w * self.t), a * self.t * np.cos(w * self.t), np.ones_like(self.t)]
        )

    def check(self, x) -> str | None:
        return None

    def __call__(self, x) -> ForwardResult:
        return ForwardResult(True, self.values(np.asarray(x, dtype=float)))


class RastriginModel:
    """Residual form of Rastrigin: values ``[u, sqrt(2A) sin(pi u)]``, data zero, A = 10."""

    names = ("a", "b", "c")
    reference = np.array([2.0, 5.0, 8.0])
    u_lower = np.array([-3.4, -5.2, -2.7])
    u_upper = np.array([5.6, 3.8, 4.3])
    scale = 0.1  # u = (x / ref - 1) / scale
    A = 10.0

    def u(self, x) -> np.ndarray:
        return (np.asarray(x) / self.reference - 1.0) / self.scale

    def values(self, x) -> np.ndarray:
        u = self.u(x)
        return np.concatenate([u, math.sqrt(2 * self.A) * np.sin(math.pi * u)])

    def jacobian(self, x) -> np.ndarray:
        u = self.u(x)
        du = 1.0 / (self.reference * self.scale)
        return np.vstack(
            [np.diag(du), np.diag(math.sqrt(2 * self.A) * math.pi * np.cos(math.pi * u) * du)]
        )

    def check(self, x) -> str | None:
        return None

    def __call__(self, x) -> ForwardResult:
        return ForwardResult(True, self.values(np.asarray(x, dtype=float)))


class LinearModel:
    """``y = A x`` with a fixed, seeded 20 x 3 design matrix."""

    names = ("p", "q", "r")
    reference = np.array([1.0, 2.0, 3.0])
    sigma = 0.05

    def __init__(self, m: int = 20, seed: int = 12345):
        rng = np.random.default_rng(seed)
        t = np.linspace(0.0, 1.0, m)
        self.A = np.column_stack([np.ones(m), t, t**2]) + 0.5 * rng.standard_normal((m, 3))

    def values(self, x) -> np.ndarray:
        return self.A @ np.asarray(x)

    def jacobian(self, x) -> np.ndarray:
        return self.A.copy()

    def posterior(self, data, sigma=None) -> tuple[np.ndarray, np.ndarray]:
        """Posterior mean and covariance (physical) under a flat prior: the weighted LS solution."""
        s = self.sigma if sigma is None else sigma
        W = self.A / s
        cov = np.linalg.inv(W.T @ W)
        return cov @ (W.T @ (np.asarray(data) / s)), cov

    def check(self, x) -> str | None:
        return None

    def __call__(self, x) -> ForwardResult:
        return ForwardResult(True, self.values(np.asarray(x, dtype=float)))


# --- cases --------------------------------------------------------------------------------


def _smooth_parameters() -> tuple[Parameter, ...]:
    return (
        Parameter("E", "MPa", 30_000.0, 15_000.0, 45_000.0),
        Parameter("sigma0", "MPa", 20.0, 14.0, 26.0),
        Parameter("H", "MPa", 1_500.0, 750.0, 2_250.0),
        Parameter("psi", "deg", 15.0, 5.0, 30.0),
    )


def _sinusoid_parameters() -> tuple[Parameter, ...]:
    return (
        Parameter("a", "-", 1.0, 0.5, 2.0),
        Parameter("omega", "rad/s", 2.0, 1.0, 4.0),
        Parameter("c", "-", 1.0, 0.5, 1.5),
    )


def _rastrigin_parameters() -> tuple[Parameter, ...]:
    m = RastriginModel
    lo = m.reference * (1 + m.scale * m.u_lower)
    hi = m.reference * (1 + m.scale * m.u_upper)
    return tuple(
        Parameter(n, "-", float(r), float(a), float(b))
        for n, r, a, b in zip(m.names, m.reference, lo, hi)
    )


def _linear_parameters() -> tuple[Parameter, ...]:
    m = LinearModel
    return tuple(
        Parameter(n, "-", float(r), 0.5 * float(r), 1.5 * float(r))
        for n, r in zip(m.names, m.reference)
    )


_MODELS = {
    "analytic-smooth": (StressStrainModel, _smooth_parameters),
    "analytic-multimodal": (SinusoidModel, _sinusoid_parameters),
    "analytic-rastrigin": (RastriginModel, _rastrigin_parameters),
    "analytic-linear": (LinearModel, _linear_parameters),
    "analytic-infeasible": (InfeasibleStressStrainModel, _smooth_parameters),
    "analytic-failing": (FailingStressStrainModel, _smooth_parameters),
}

ANALYTIC_CASES: dict[str, Case] = {
    name: Case(name, "analytic", "none", params(), {}, kind="analytic")
    for name, (_, params) in _MODELS.items()
}


def analytic_model(name: str):
    """A fresh forward model of the analytic case ``name``."""
    if name not in _MODELS:
        raise ValueError(f"analytic case {name!r} is unknown; allowed: {', '.join(_MODELS)}")
    return _MODELS[name][0]()


def analytic_objective(name: str, *, noise: float = 0.0, seed: int = 0, mapper=None) -> Evaluator:
    """Objective of the analytic case ``name`` with synthetic data made at the case's reference.

    ``noise`` is in units of the nominal measurement standard deviation (the objective's sigma):
    ``noise=1`` gives statistically consistent data. ``seed`` seeds that noise.
    """
    case = ANALYTIC_CASES.get(name) or analytic_model(name)  # analytic_model raises the ValueError
    model = analytic_model(name)
    if isinstance(model, StressStrainModel):
        sigma, blocks = model.sigma(), model.blocks()
    elif isinstance(model, (LinearModel, SinusoidModel)):
        sigma, blocks = model.sigma, None
    else:
        sigma, blocks = 1.0, {"u": slice(0, 3), "oscillation": slice(3, 6)}
    clean = np.asarray(model(case.reference).values, dtype=float)
    data = clean.copy()
    if isinstance(model, RastriginModel):
        data[:] = 0.0  # exact zeros rather than rounding noise
    if noise:
        data = data + noise * np.broadcast_to(sigma, data.shape) * np.random.default_rng(
            seed
        ).standard_normal(data.size)
    problem = LeastSquaresProblem(
        model,
        data,
        case.lower,
        case.upper,
        case.reference,
        sigma=sigma,
        blocks=blocks,
        provenance={"case": name, "data_tier": "synthetic", "noise": noise, "seed": seed},
    )
    return Evaluator(problem, mapper=mapper)

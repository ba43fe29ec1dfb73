r"""The cost of an identification problem on a surrogate, without the measurement vector.

A surrogate is affine in its POD coefficients, ``U(x) = ybar + diag(sigma) Phi a(z)``, so the
whitened misfit is ``c_perp + ||g - T a||^2`` (:mod:`problems.inverse.reduced`): a point costs the
regression of ``r`` coefficients and O(r^2), not the reconstruction of the m (~8 000) values.
:class:`SurrogateMisfit` does this for a batch of points in one compiled call
(:func:`problems.surrogate._kernels.surrogate_costs`: box, material screen, GP mean, misfit) when
the regression is the shipped kind (Matern 5/2 GP), and with numpy otherwise. Points the screen
does not pass are decided by the model's own ``check`` (exact messages); the residual vector of a
point is made only on request. The evaluator takes this path for every plain evaluation of a
model offering ``misfit_of`` (counts, cache and budget unchanged).
"""

from __future__ import annotations

import numpy as np

from problems.inverse.reduced import AffineMisfit
from problems.surrogate._kernels import surrogate_costs
from problems.surrogate.screen import NONE, Screen


class SurrogateMisfit:
    """Costs of ``problem`` at physical points, on the surrogate ``model``."""

    def __init__(self, model, problem):
        self.model = model
        self.affine = AffineMisfit.of(problem, *model.affine_form())
        gp = model._packed_gp
        case = getattr(model.checker, "case", None)
        screen = Screen.of(case) if case is not None else None
        if case is not None and tuple(case.names) != tuple(model.names):
            screen = None  # not the case's own parameters: the rule decides every point
        if model.checker is not None and screen is None:
            gp = None  # a rule the screen does not know: every point through the rule (numpy)
        if screen is None:  # no material rule: the box alone
            d = len(model.names)
            screen = Screen(
                np.full(d, -np.inf), np.full(d, np.inf), NONE, np.zeros(1, np.int64), np.zeros(2)
            )
        self._compiled = None
        if gp is not None:
            limits = np.vstack([model.lower, model.upper, screen.lo, screen.hi])
            a = self.affine
            self._compiled = (limits, screen.code, screen.idx, screen.consts) + gp.args
            self._compiled += (np.ascontiguousarray(a.T.T), a.g, a.c_perp)
            if gp.n_outputs != a.n_coefficients:  # the kernel does not check bounds
                raise ValueError(
                    f"GP of {gp.n_outputs} outputs for {a.n_coefficients} POD coefficients"
                )
            self(np.array([0.5 * (model.lower + model.upper)]))  # compile / load now, not in a run

    def __call__(self, X) -> tuple[np.ndarray, np.ndarray, list]:
        """``(costs (q,), coefficients (q, r), reasons)`` at the physical points ``X`` (q, d):
        ``reasons[k]`` is None for a valid point, else why it is invalid (then its cost is
        meaningless). Points must be finite."""
        X = np.asarray(X, dtype=float)
        if X.ndim == 1:
            X = X[None]
        if not X.flags.c_contiguous:
            X = np.ascontiguousarray(X)
        q = len(X)
        if self._compiled is None:
            reasons = [self._check(x) for x in X]
            A = self.model.coefficients(self.model.to_scaled(X))
            return self.affine.costs(A), A, reasons
        A = np.empty((q, self.affine.n_coefficients))
        costs = np.empty(q)
        clear = np.empty(q, bool)
        reasons = [None] * q
        if surrogate_costs(X, *self._compiled, A, costs, clear):
            for k in np.flatnonzero(~clear):
                reasons[k] = self._check(X[k])
        return costs, A, reasons

    def _check(self, x) -> str | None:
        """The model's rule at ``x`` (an exception is a reason too, for that point only)."""
        try:
            return self.model.check(x)
        except Exception as exc:
            return f"check raised {type(exc).__name__}: {exc}"

    def messages(self, X) -> list[str]:
        """The note of each valid point (extrapolation), as the model's own call gives it."""
        if self.model._covers_box:
            return [""] * len(X)
        return [self.model.extrapolation_message(x) for x in X]

    def residual(self, a) -> np.ndarray:
        """(m,) whitened residual at the coefficients ``a``."""
        return self.affine.residual(a)

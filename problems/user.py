"""User problems: any least-squares problem or scalar objective, named by an entry point.

A suite (``[problems.<name>]``, docs/suites.md) or the CLI (``femubench identify --problem``)
names a problem by an *entry point*: ``package.module:factory`` or ``path/to/file.py:factory``,
called with the keyword arguments given next to it. The factory returns one of

* a :class:`~problems.inverse.problem.LeastSquaresProblem` (a forward model, data, sigma, box,
  reference; :func:`least_squares` builds one from a plain function ``model(x) -> values``);
* a :class:`ScalarProblem`: a scalar objective ``f(x)`` to minimise over a box (finite or
  infinite bounds). Its cost *is* f: no residual is faked, so only the methods that need nothing
  but costs run on it (the least-squares methods refuse it, see
  :data:`solvers.base.LEAST_SQUARES_ONLY`);
* a :class:`UserProblem`: either of the above plus a start, a known optimum (``f_min`` and/or
  ``x_ref``) and the problem's own success rule (:class:`SuccessRule`).

Success rules are plain data (they go into every record, so that the report applies them without
importing anything from here):

* ``f-target``: success when ``f_best - f_min <= target`` (COCO's rule; needs ``f_min``);
* ``digits``: success when every parameter has at least ``digits`` correct significant digits
  against ``x_ref`` (``-log10(|x - x_ref| / |x_ref|)``; NIST StRD's log relative error);
* ``solver``: the solver's own verdict (status converged, or a global method's normal end).
"""

from __future__ import annotations

import importlib
import importlib.util
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from problems.inverse.problem import FAILURE_COST, LeastSquaresProblem, outer_box
from problems.inverse.protocol import ForwardResult

RULE_KINDS = ("f-target", "digits", "solver")


class FunctionModel:
    """A forward model over a plain function ``fn(x) -> values`` (an array, or one float for a
    scalar objective); ``fn`` must be picklable (a module-level function or a class instance) to
    run on a cluster. ``check(x)``: an optional cheap feasibility test (None when feasible)."""

    def __init__(self, fn: Callable, names, check: Callable | None = None):
        self.fn = fn
        self.names = tuple(names)
        self._check = check

    def check(self, x) -> str | None:
        return None if self._check is None else self._check(x)

    def __call__(self, x) -> ForwardResult:
        return ForwardResult(True, np.atleast_1d(np.asarray(self.fn(x), dtype=float)).ravel())


@dataclass(eq=False)
class ScalarProblem:
    """A scalar objective ``f(x)`` over the box ``[lower, upper]`` (bounds may be infinite).

    objective : a plain function ``f(x) -> float`` or a forward model returning one value
    lower, upper : (n,) bounds (``-inf``/``inf`` allowed; the methods that need a finite box
                 refuse an infinite one)
    reference : (n,) scale of each parameter (solvers work in ``z = x / reference``; default 1:
                 no scaling; also the scale of finite-difference steps)
    names     : parameter names (default ``x0 .. x{n-1}``)

    It offers what the evaluator uses of a :class:`LeastSquaresProblem` (box, scaling,
    ``classify``): the cost of a point is ``f(x)`` itself, and the "value vector" the evaluator
    keeps of it is ``[f(x)]`` (what finite differences difference for a gradient).
    """

    objective: Any
    lower: np.ndarray
    upper: np.ndarray
    reference: np.ndarray | None = None
    names: tuple[str, ...] | None = None
    provenance: dict = field(default_factory=dict)

    #: marks a problem whose cost is a value, not a sum of squared residuals
    scalar = True

    def __post_init__(self):
        self.lower = np.asarray(self.lower, dtype=float).ravel().copy()
        self.upper = np.asarray(self.upper, dtype=float).ravel().copy()
        n = self.lower.size
        ref = np.ones(n) if self.reference is None else self.reference
        self.reference = np.asarray(ref, dtype=float).ravel().copy()
        if self.names is None:
            self.names = tuple(getattr(self.objective, "names", ())) or tuple(
                f"x{i}" for i in range(n)
            )
        self.names = tuple(self.names)
        if not (len(self.names) == self.upper.size == self.reference.size == n) or n == 0:
            raise ValueError(
                f"names, lower, upper and reference must have the same length >= 1 (got "
                f"{len(self.names)}, {n}, {self.upper.size}, {self.reference.size})"
            )
        if np.any(self.reference == 0) or not np.all(np.isfinite(self.reference)):
            raise ValueError("reference values must be finite and non-zero (z = x / reference)")
        if np.any(np.isnan(self.lower)) or np.any(np.isnan(self.upper)):
            raise ValueError("bounds must be numbers (-inf and inf allowed), not NaN")
        if np.any(self.lower > self.upper):
            raise ValueError("a lower bound is above its upper bound")
        self.model = (
            self.objective
            if callable(getattr(self.objective, "check", None))
            else FunctionModel(self.objective, self.names)
        )
        self._outer = outer_box(self.lower, self.upper, self.reference)
        zl, zu = self.lower / self.reference, self.upper / self.reference
        self.lower_z, self.upper_z = np.minimum(zl, zu), np.maximum(zl, zu)
        self.blocks = {"f": slice(0, 1)}
        self.data = np.zeros(1)  # no data: the objective is the cost
        self.failure_residual = np.array([FAILURE_COST])

    n_params = property(lambda self: self.reference.size)
    n_residuals = 1
    to_physical = LeastSquaresProblem.to_physical
    to_scaled = LeastSquaresProblem.to_scaled
    classify = LeastSquaresProblem.classify
    check = LeastSquaresProblem.check

    def whiten(self, d):
        raise TypeError("a scalar problem has no residuals to whiten")

    def residual(self, values) -> tuple[np.ndarray | None, str]:
        """The value vector ``[f]`` of the model's output, or (None, why) when unusable."""
        if values is None:
            return None, "objective returned no value"
        v = np.asarray(values, dtype=float).ravel()
        if v.size != 1:
            return None, f"objective returned {v.size} values, expected one"
        if not math.isfinite(float(v[0])):
            return None, "objective returned a non-finite value"
        return v, ""

    def residual_jacobian(self, jacobian_x) -> np.ndarray:
        """d[f]/dz (1, n) from the model's df/dx."""
        return np.asarray(jacobian_x, float).reshape(1, -1) * self.reference[None, :]

    def split(self, r) -> dict[str, float]:
        return {"f": float(r[0])}


def is_scalar(problem) -> bool:
    """Whether ``problem`` is a scalar objective (its cost is ``f``, not a sum of squares)."""
    return bool(getattr(problem, "scalar", False))


def least_squares(
    model: Callable,
    data,
    lower,
    upper,
    *,
    sigma=None,
    reference=None,
    names=None,
    provenance: dict | None = None,
) -> LeastSquaresProblem:
    """A :class:`LeastSquaresProblem` over a plain function ``model(x) -> values`` (m,):
    ``R = (data - model(x)) / sigma``. ``reference`` (default 1: no scaling) scales the
    parameters (``z = x / reference``) and the finite-difference steps."""
    lower = np.asarray(lower, float).ravel()
    names = tuple(names) if names is not None else tuple(f"x{i}" for i in range(lower.size))
    ref = np.ones(lower.size) if reference is None else reference
    return LeastSquaresProblem(
        model=FunctionModel(model, names),
        data=data,
        lower=lower,
        upper=upper,
        reference=ref,
        sigma=sigma,
        provenance=dict(provenance or {}),
    )


@dataclass(frozen=True)
class SuccessRule:
    """A problem's own success rule (see the module docstring): ``kind`` in :data:`RULE_KINDS`;
    ``target`` the f-gap of ``f-target`` (same units as f); ``digits`` the correct significant
    digits of ``digits``."""

    kind: str = "solver"
    target: float = 1e-8
    digits: float = 4.0

    def __post_init__(self):
        if self.kind not in RULE_KINDS:
            raise ValueError(
                f"success rule {self.kind!r} is unknown; allowed: {', '.join(RULE_KINDS)}"
            )
        if not (self.target > 0 and self.digits > 0):
            raise ValueError(
                f"success rule: target = {self.target!r} and digits = {self.digits!r} must be > 0"
            )

    def describe(self) -> str:
        """The rule in words, e.g. ``f − f_min ≤ 1e-08``."""
        if self.kind == "f-target":
            return f"f − f_min ≤ {self.target:g}"
        if self.kind == "digits":
            return f"≥ {self.digits:g} correct digits of every parameter"
        return "the solver's own verdict (converged, or a global method's normal end)"

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, "target": self.target, "digits": self.digits}


@dataclass(eq=False)
class UserProblem:
    """A problem with what a benchmark needs to judge it.

    problem : a :class:`LeastSquaresProblem` or :class:`ScalarProblem`
    x0      : (n,) physical start ("default" start); default: the centre of a finite box, else
              the reference
    f_min   : the known minimum cost (for ``f-target`` success and COCO/IOH export), or None
    x_ref   : (n,) the known optimum (for ``digits`` success), or None
    success : the success rule (default ``f-target`` when ``f_min`` is known, ``digits`` when
              only ``x_ref`` is, else ``solver``)
    name    : shown in reports; ``description``: free text
    """

    problem: Any
    x0: np.ndarray | None = None
    f_min: float | None = None
    x_ref: np.ndarray | None = None
    success: SuccessRule | None = None
    name: str = ""
    description: str = ""

    def __post_init__(self):
        p = self.problem
        if not (isinstance(p, LeastSquaresProblem) or is_scalar(p)):
            raise TypeError(
                "a user problem is a LeastSquaresProblem or a ScalarProblem, got "
                f"{type(p).__name__}"
            )
        if self.x0 is None:
            finite = np.isfinite(p.lower) & np.isfinite(p.upper)
            with np.errstate(invalid="ignore"):  # inf - inf where a side is infinite: not used
                mid = 0.5 * (p.lower + p.upper)
            self.x0 = np.where(finite, mid, np.clip(p.reference, p.lower, p.upper))
        self.x0 = np.asarray(self.x0, float).ravel()
        if self.x0.size != p.n_params or not np.all(np.isfinite(self.x0)):
            raise ValueError(f"x0 must be {p.n_params} finite values, got {self.x0.tolist()}")
        if self.x_ref is not None:
            self.x_ref = np.asarray(self.x_ref, float).ravel()
            if self.x_ref.size != p.n_params:
                raise ValueError(f"x_ref must have {p.n_params} values, got {self.x_ref.size}")
        if self.success is None:
            kind = (
                "f-target"
                if self.f_min is not None
                else ("digits" if self.x_ref is not None else "solver")
            )
            self.success = SuccessRule(kind)
        elif isinstance(self.success, dict):
            self.success = SuccessRule(**self.success)
        if self.success.kind == "f-target" and self.f_min is None:
            raise ValueError("success rule 'f-target' needs f_min")
        if self.success.kind == "digits" and self.x_ref is None:
            raise ValueError("success rule 'digits' needs x_ref")

    @property
    def kind(self) -> str:
        return "scalar" if is_scalar(self.problem) else "least-squares"

    def judge(self, x, f: float, solver_success: bool) -> dict[str, Any]:
        """The outcome of a run ending at ``x`` (physical) with best cost ``f``: ``success`` by the
        problem's rule, ``f_gap`` (f - f_min, when known) and ``digits`` (min over the
        parameters, when ``x_ref`` is known; capped at 15)."""
        out: dict[str, Any] = {}
        if self.f_min is not None:
            out["f_gap"] = float(f - self.f_min) if math.isfinite(f) else math.inf
        if self.x_ref is not None:
            out["digits"] = correct_digits(x, self.x_ref)
        kind = self.success.kind
        if kind == "f-target":
            ok = out["f_gap"] <= self.success.target
        elif kind == "digits":
            ok = out["digits"] >= self.success.digits
        else:
            ok = bool(solver_success)
        out["success"] = bool(ok)
        return out

    def describe(self) -> dict[str, Any]:
        """What a record keeps of the problem (plain data)."""
        return {
            "name": self.name,
            "kind": self.kind,
            "n_params": int(self.problem.n_params),
            "f_min": None if self.f_min is None else float(self.f_min),
            "x_ref": None if self.x_ref is None else [float(v) for v in self.x_ref],
            "success_rule": self.success.to_dict(),
            "success_text": self.success.describe(),
            "finite_box": bool(
                np.all(np.isfinite(self.problem.lower)) and np.all(np.isfinite(self.problem.upper))
            ),
        }


def correct_digits(x, x_ref) -> float:
    """Correct significant digits of ``x`` against ``x_ref``, the smallest over the parameters:
    ``-log10(|x - x_ref| / |x_ref|)`` (absolute error where ``x_ref = 0``), in [0, 15]."""
    x, ref = np.asarray(x, float), np.asarray(x_ref, float)
    if x.shape != ref.shape or not np.all(np.isfinite(x)):
        return 0.0
    err = np.abs(x - ref) / np.where(ref != 0, np.abs(ref), 1.0)
    with np.errstate(divide="ignore"):
        d = -np.log10(np.maximum(err, 1e-15))
    return float(np.clip(d.min(), 0.0, 15.0))


# --- entry points -------------------------------------------------------------------------------


def entry_point_error(entry: str) -> str | None:
    """Why ``entry`` is not of the form ``module:factory`` or ``path/file.py:factory``, or None."""
    if not isinstance(entry, str) or entry.count(":") < 1:
        return (
            f"entry point {entry!r} must be 'package.module:factory' or 'path/to/file.py:factory'"
        )
    target, _, attr = entry.rpartition(":")
    if not target or not attr.isidentifier():
        return f"entry point {entry!r}: '{attr}' is not a function name"
    return None


def load_factory(entry: str) -> Callable:
    """The callable named by ``entry`` (``module:factory`` or ``file.py:factory``); ValueError
    saying what is wrong."""
    why = entry_point_error(entry)
    if why:
        raise ValueError(why)
    target, _, attr = entry.rpartition(":")
    if target.endswith(".py"):
        path = Path(target).expanduser().resolve()
        if not path.is_file():
            raise ValueError(f"entry point {entry!r}: file {target!r} does not exist")
        name = f"femubench_user_{abs(hash(str(path))):x}"
        module = sys.modules.get(name)
        if module is None:
            spec = importlib.util.spec_from_file_location(name, path)
            module = importlib.util.module_from_spec(spec)
            sys.modules[name] = module  # picklable functions of the file resolve by this name
            spec.loader.exec_module(module)
    else:
        try:
            module = importlib.import_module(target)
        except ImportError as exc:
            raise ValueError(f"entry point {entry!r}: cannot import {target!r} ({exc})") from None
    fn = getattr(module, attr, None)
    if not callable(fn):
        raise ValueError(f"entry point {entry!r}: {target!r} has no function {attr!r}")
    return fn


def load_problem(entry: str, args: dict | None = None, *, name: str = "") -> UserProblem:
    """Call the factory ``entry`` with ``args`` and return its problem as a :class:`UserProblem`
    (a bare problem is wrapped with the defaults)."""
    fn = load_factory(entry)
    try:
        out = fn(**dict(args or {}))
    except TypeError as exc:
        raise ValueError(f"entry point {entry!r} with arguments {args or {}}: {exc}") from None
    if not isinstance(out, UserProblem):
        out = UserProblem(out)
    if name and not out.name:
        out.name = name
    out.problem.provenance = {**out.problem.provenance, "entry": entry, "args": dict(args or {})}
    return out

"""Derived material parameters in the report frames: the exponent cases' coefficient ``a``.

The exponent cases identify the hydrostatic tension strength ``pt0`` in place of ``a``
(:class:`problems.inverse.cases.ExponentStrength`); the paper's Table 1 reports ``a``. For every
case with a ``derive`` rule, :func:`add_derived` computes each derived parameter through the
case's own :meth:`~problems.inverse.case.Case.material_parameters` (the formula lives there only)
at the identified point (``runs``: ``x.a``, ``xn.a``, ``err.a``) and at every history point
(``history``: ``xn.a``, ``err.a``), with the reference ``a`` = the derived value at the case's
reference point. Cases without a rule get NaN (the parameter is not part of them).
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
import pandas as pd

from bench.store import parameter_order


@lru_cache(maxsize=None)
def _case(name: str):
    from problems.inverse.cases import all_cases

    return all_cases().get(name)


def derived_names(case: str) -> tuple[str, ...]:
    """The material parameters the case derives from its identified ones (``("a",)`` for the
    exponent cases, ``()`` otherwise or for an unknown case)."""
    c = _case(case)
    if c is None or getattr(c, "derive", None) is None:
        return ()
    mat = c.material_parameters(c.reference)
    return tuple(k for k in mat if k not in c.names and k not in c.fixed)


def derived_reference(case: str) -> dict[str, float]:
    """``{name: reference value}`` of the derived parameters of ``case``."""
    c = _case(case)
    names = derived_names(case)
    if not names:
        return {}
    mat = c.material_parameters(c.reference)
    return {n: float(mat[n]) for n in names}


def derive_points(case: str, X: np.ndarray) -> dict[str, np.ndarray]:
    """Derived parameters at the identified points ``X`` (physical, shape (n, n_params) in the
    case's parameter order); NaN rows stay NaN."""
    c = _case(case)
    names = derived_names(case)
    X = np.atleast_2d(np.asarray(X, float))
    out = {n: np.full(len(X), math.nan) for n in names}
    if not names:
        return out
    for i, x in enumerate(X):
        if x.shape[0] != len(c.names) or not np.all(np.isfinite(x)):
            continue
        try:
            mat = c.material_parameters(x)
        except (ValueError, ZeroDivisionError, OverflowError):
            continue
        for n in names:
            out[n][i] = float(mat[n])
    return out


def add_derived(runs: pd.DataFrame, history: pd.DataFrame | None = None):
    """``(runs, history)`` with the derived parameters' columns added (copies; the frames'
    ``attrs["parameters"]`` include them, in the study's order)."""
    runs = runs.copy()
    history = history.copy() if history is not None else None
    params = list(runs.attrs.get("parameters") or [])
    attrs = dict(runs.attrs)
    cases = list(runs["case"].unique()) if "case" in runs else []
    new = sorted({n for c in cases for n in derived_names(c)})
    if not new:
        return runs, history
    for n in new:
        for col in (f"x.{n}", f"xn.{n}", f"err.{n}", f"ref.{n}"):
            if col not in runs:
                runs[col] = math.nan
        if history is not None and len(history):
            for col in (f"xn.{n}", f"err.{n}"):
                if col not in history:
                    history[col] = math.nan
    for case in cases:
        names = derived_names(case)
        if not names:
            continue
        c = _case(case)
        ref = derived_reference(case)
        sel = runs["case"] == case
        cols = [f"x.{p}" for p in c.names]
        if not all(col in runs for col in cols):
            continue
        vals = derive_points(case, runs.loc[sel, cols].to_numpy(float))
        for n in names:
            runs.loc[sel, f"x.{n}"] = vals[n]
            runs.loc[sel, f"xn.{n}"] = vals[n] / ref[n]
            runs.loc[sel, f"err.{n}"] = 100.0 * (vals[n] / ref[n] - 1.0)
            runs.loc[sel, f"ref.{n}"] = ref[n]
        if history is not None and len(history) and "case" in history:
            hsel = history["case"] == case
            hcols = [f"xn.{p}" for p in c.names]
            if hsel.any() and all(col in history for col in hcols):
                X = history.loc[hsel, hcols].to_numpy(float) * np.asarray(c.reference, float)
                hv = derive_points(case, X)
                for n in names:
                    history.loc[hsel, f"xn.{n}"] = hv[n] / ref[n]
                    history.loc[hsel, f"err.{n}"] = 100.0 * (hv[n] / ref[n] - 1.0)
    attrs["parameters"] = parameter_order(params + new)
    runs.attrs = attrs
    if history is not None:
        history.attrs = dict(history.attrs) | {"parameters": attrs["parameters"]}
    return runs, history

"""Derived material parameters in the report frames: the exponent cases' coefficient ``a``.

The exponent cases identify the hydrostatic tension strength ``pt0`` in place of ``a``
(:class:`problems.inverse.cases.ExponentStrength`); the paper's Table 1 reports ``a``. For every
case with a derivation in the report's frozen table
(:meth:`bench.report.catalogue.CaseInfo.derived`, the formula as the case defined it when the
table was frozen), :func:`add_derived` computes each derived parameter at the identified point
(``runs``: ``x.a``, ``xn.a``, ``err.a``) and at every history point (``history``: ``xn.a``,
``err.a``), with the reference ``a`` = the derived value at the case's reference point. Cases
without a derivation get NaN (the parameter is not part of them).
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from bench.experiment.store import parameter_order
from bench.report.catalogue import case_info


def derived_names(case: str) -> tuple[str, ...]:
    """The material parameters the case derives from its identified ones (``("a",)`` for the
    exponent cases, ``()`` otherwise or for an unknown case)."""
    c = case_info(case)
    return () if c is None else tuple(c.derived(c.reference))


def derived_reference(case: str) -> dict[str, float]:
    """``{name: reference value}`` of the derived parameters of ``case``."""
    c = case_info(case)
    return {} if c is None else {n: float(v) for n, v in c.derived(c.reference).items()}


def derive_points(case: str, X: np.ndarray) -> dict[str, np.ndarray]:
    """Derived parameters at the identified points ``X`` (physical, shape (n, n_params) in the
    case's parameter order); NaN rows stay NaN."""
    c = case_info(case)
    names = derived_names(case)
    X = np.atleast_2d(np.asarray(X, float))
    out = {n: np.full(len(X), math.nan) for n in names}
    if not names:
        return out
    for i, x in enumerate(X):
        if x.shape[0] != len(c.names) or not np.all(np.isfinite(x)):
            continue
        try:
            mat = c.derived(x)
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
        c = case_info(case)
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

"""Posterior summaries for the report: from the posterior study's files and from MCMC run records.

Two sources, both optional, read leniently (a missing or odd key is skipped, never an error):

* ``<posterior dir>/<case>/summary.json`` (the posterior study): ``case``, ``tier``, ``names``,
  ``n_samples``, ``tau`` (per parameter), ``tau_multiple``, ``mean``, ``sd``, ``q025``, ``q975``,
  ``laplace_sd`` (and ``laplace_mean`` if given); per-parameter values as ``{name: value}`` or as
  lists in the order of ``names``. Also accepted: one summary.json per tier in sub-folders.
* records of ``mcmc`` runs: ``result.extra`` (``mean``, ``std``, ``q2.5``, ``q97.5``,
  ``autocorr_time``, ``n_steps``, ``burn``, ``n_walkers``, ``chain``). For each (case, tier, track)
  the run with the most kept samples represents the method.

The exponent cases' ``a`` is derived from the chain when the record keeps it (thinned to at most
:data:`MAX_SAMPLES` samples) through the case's own rule (:mod:`bench.report.derived`).

:func:`posterior_frame` gives one row per (case, tier, source, parameter) with everything divided
by the reference; :func:`width_table` the 95 % widths; the panel is
:func:`bench.report.figures.posterior_figure`.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd

from bench.experiment.store import parameter_order
from bench.report.catalogue import PAPER_A_ERROR, case_info, is_analytic
from bench.report.derived import derive_points, derived_reference

MAX_SAMPLES = 20_000
SUMMARY = "summary.json"


def references(case: str) -> dict[str, float]:
    """Reference values of the case's identified and derived parameters."""
    c = case_info(case)
    if c is None:
        return {}
    ref = {n: float(v) for n, v in zip(c.names, c.reference)}
    return ref | derived_reference(case)


def _num(v) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def _per_param(v, names) -> dict[str, float]:
    if isinstance(v, dict):
        return {str(k): _num(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)) and names and len(v) == len(names):
        return {n: _num(x) for n, x in zip(names, v)}
    return {}


def _first(d: dict, *keys):
    for k in keys:
        if k in d and d[k] is not None:
            return d[k]
    return None


def summary_files(folder: Path) -> list[Path]:
    """Every summary.json below ``folder`` (``<case>/summary.json`` or deeper)."""
    folder = Path(folder)
    if not folder.is_dir():
        return []
    return sorted(folder.rglob(SUMMARY))


def rows_from_summary(path: Path) -> list[dict]:
    """The rows of one posterior-study summary (empty when it cannot be read)."""
    try:
        s = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return []
    if not isinstance(s, dict):
        return []
    case = str(s.get("case") or Path(path).parent.name)
    names = list(s.get("names") or [])
    stats = {
        "mean": _per_param(s.get("mean"), names),
        "sd": _per_param(_first(s, "sd", "std"), names),
        "q025": _per_param(_first(s, "q025", "q2.5"), names),
        "q975": _per_param(_first(s, "q975", "q97.5"), names),
        "laplace_sd": _per_param(s.get("laplace_sd"), names),
        "laplace_mean": _per_param(
            _first(s, "laplace_mean", "fe_optimum", "optimum", "x_opt", "map", "x_map"), names
        ),
        "laplace_sd_inflated": _per_param(s.get("laplace_sd_inflated"), names),
        "tau": _per_param(s.get("tau"), names),
    }
    tm = s.get("tau_multiple")
    tau_mult = _per_param(tm, names) if isinstance(tm, (dict, list)) else {}
    params = list(names) + sorted({k for k in stats["mean"] if k not in names})
    out = []
    for p in params:
        row = {
            "case": case,
            "tier": str(s.get("tier") or "model-error"),
            "source": "posterior study" + (" (surrogate)" if s.get("surrogate") else ""),
            "parameter": p,
            "n_samples": _num(s.get("n_samples")),
            "tau_multiple": tau_mult.get(p, _num(tm) if not isinstance(tm, (dict, list)) else 0),
        }
        for k, d in stats.items():
            row[k] = d.get(p, math.nan)
        out.append(row)
    return out


def rows_from_records(records) -> list[dict]:
    """The rows of the MCMC run records (one representative run per case, tier and track)."""
    best: dict[tuple, tuple[float, dict]] = {}
    for rec in records:
        cfg, res = rec.get("config") or {}, rec.get("result") or {}
        if cfg.get("method") != "mcmc" or rec.get("error"):
            continue
        extra = res.get("extra") or {}
        if not isinstance(extra.get("mean"), dict):
            continue
        steps = _num(extra.get("n_steps"))
        kept = (steps - _num(extra.get("burn", 0))) * _num(extra.get("n_walkers", 1))
        key = (cfg.get("case"), cfg.get("tier", "model-error"), cfg.get("track", "fe"))
        kept = kept if math.isfinite(kept) else 0.0
        if key not in best or kept > best[key][0]:
            best[key] = (kept, rec)
    counts: dict[tuple, int] = {}
    for rec in records:
        cfg = rec.get("config") or {}
        if cfg.get("method") == "mcmc":
            k = (cfg.get("case"), cfg.get("tier", "model-error"), cfg.get("track", "fe"))
            counts[k] = counts.get(k, 0) + 1
    out = []
    for (case, tier, track), (kept, rec) in best.items():
        extra = rec["result"]["extra"]
        names = list(rec["result"].get("parameter_names") or extra["mean"].keys())
        tau = _per_param(extra.get("autocorr_time"), names)
        steps = _num(extra.get("n_steps"))
        burn = _num(extra.get("burn", 0))
        stats = {
            "mean": _per_param(extra.get("mean"), names),
            "sd": _per_param(extra.get("std"), names),
            "q025": _per_param(extra.get("q2.5"), names),
            "q975": _per_param(extra.get("q97.5"), names),
        }
        chain = extra.get("chain")
        if chain is None and extra.get("chain_path"):
            chain = _chain_from_npz(extra["chain_path"])
        derived = _derived_from_chain(case, names, chain, int(burn or 0))
        n_runs = counts[(case, tier, track)]
        src = f"mcmc run ({track}, seed {rec['config'].get('seed')}, 1 of {n_runs})"
        for p in names + list(derived):
            row = {
                "case": case,
                "tier": tier,
                "source": src,
                "parameter": p,
                "n_samples": kept,
                "tau": tau.get(p, math.nan),
                "tau_multiple": (steps - burn) / tau[p] if tau.get(p) else math.nan,
                "laplace_sd": math.nan,
                "laplace_mean": math.nan,
            }
            for k, d in stats.items():
                row[k] = d.get(p, math.nan)
            if p in derived:
                row.update(derived[p])
            out.append(row)
    return out


def _chain_from_npz(path) -> np.ndarray | None:
    """The physical chain of an MCMC run kept in an ``.npz`` file
    (:class:`solvers.npz_backend.NpzBackend`: ``chain`` x ``scale``); None when unreadable."""
    try:
        with np.load(Path(path), allow_pickle=False) as z:
            chain = np.asarray(z["chain"], float)
            scale = np.asarray(z["scale"], float) if "scale" in z.files else 1.0
        return chain * scale
    except (OSError, ValueError, KeyError):
        return None


def _derived_from_chain(case: str, names, chain, burn: int) -> dict[str, dict]:
    """``{a: {mean, sd, q025, q975}}`` from a kept chain (physical ``[step][walker][param]``)."""
    ref = derived_reference(case)
    if not ref or chain is None:
        return {}
    try:
        arr = np.asarray(chain, float)
    except (TypeError, ValueError):
        return {}
    if arr.ndim != 3 or arr.shape[2] != len(names) or arr.shape[0] <= burn:
        return {}
    c = case_info(case)
    if c is None or list(c.names) != list(names):
        return {}
    flat = arr[burn:].reshape(-1, len(names))
    if len(flat) > MAX_SAMPLES:
        flat = flat[np.linspace(0, len(flat) - 1, MAX_SAMPLES).astype(int)]
    vals = derive_points(case, flat)
    out = {}
    for n, v in vals.items():
        v = v[np.isfinite(v)]
        if len(v) < 2:
            continue
        out[n] = {
            "mean": float(v.mean()),
            "sd": float(v.std(ddof=1)),
            "q025": float(np.percentile(v, 2.5)),
            "q975": float(np.percentile(v, 97.5)),
        }
    return out


def posterior_frame(records=(), folders=()) -> pd.DataFrame:
    """One row per (case, tier, source, parameter): the posterior numbers (physical) and, divided
    by the reference, ``mean_n``, ``q025_n``, ``q975_n``, ``laplace_lo_n``/``laplace_hi_n``
    (Laplace mean ± 2 sd; the Laplace mean defaults to the posterior mean), ``width95_pct`` (the
    95 % interval in percent of the reference) and ``laplace_width_pct`` (4 Laplace sd)."""
    rows = []
    for folder in folders:
        for p in summary_files(folder):
            rows += rows_from_summary(p)
    rows += rows_from_records(records)
    df = pd.DataFrame(rows)
    if not len(df):
        return df
    analytic = {c: is_analytic(c) for c in df["case"].unique()}
    df.loc[df["case"].map(analytic), "tier"] = "analytic"  # no data tiers (as in the runs)
    refs = {c: references(c) for c in df["case"].unique()}
    df["reference"] = [refs[c].get(p, math.nan) for c, p in zip(df["case"], df["parameter"])]
    ref = df["reference"].to_numpy(float)
    for k in ("mean", "q025", "q975"):
        df[f"{k}_n"] = df[k].to_numpy(float) / ref
    lm = df["laplace_mean"].fillna(df["mean"]).to_numpy(float)
    lsd = df["laplace_sd"].to_numpy(float)
    df["laplace_lo_n"] = (lm - 2 * lsd) / ref
    df["laplace_hi_n"] = (lm + 2 * lsd) / ref
    df["width95_pct"] = 100.0 * (df["q975"] - df["q025"]).to_numpy(float) / np.abs(ref)
    df["laplace_width_pct"] = 100.0 * 4.0 * lsd / np.abs(ref)
    if "laplace_sd_inflated" not in df:
        df["laplace_sd_inflated"] = math.nan
    df["laplace_inflated_width_pct"] = (
        100.0 * 4.0 * df["laplace_sd_inflated"].to_numpy(float) / np.abs(ref)
    )
    df = df.drop_duplicates(["case", "tier", "source", "parameter"], keep="last")
    return df.reset_index(drop=True)


def width_table(post: pd.DataFrame) -> pd.DataFrame:
    """Rows = (case, tier, source), columns = parameters: the 95 % posterior width in percent of
    the reference, with the Laplace ±2 sd width in brackets (strings); plus the paper's Table-1
    error of a for the exponent cases."""
    from bench.report.tables import DASH, case_order, fmt_num

    if not len(post):
        return pd.DataFrame()
    params = parameter_order(post["parameter"].unique())
    rows = []
    for (case, tier, source), g in post.groupby(["case", "tier", "source"], sort=False):
        row = {"case": case, "tier": tier, "source": source}
        gi = g.set_index("parameter")
        for p in params:
            if p not in gi.index or not math.isfinite(gi.loc[p, "width95_pct"]):
                row[p] = DASH
                continue
            w, lw = gi.loc[p, "width95_pct"], gi.loc[p, "laplace_width_pct"]
            row[p] = fmt_num(float(w), 2) + (f" ({fmt_num(float(lw), 2)})" if lw == lw else "")
        tm = g["tau_multiple"].astype(float)
        row["chain / tau"] = fmt_num(float(tm.min()), 2) if tm.notna().any() else DASH
        row["paper: err a (%)"] = (
            f"{PAPER_A_ERROR[0]:g}–{PAPER_A_ERROR[1]:g}" if "a" in references(case) else DASH
        )
        rows.append(row)
    df = pd.DataFrame(rows)
    order = case_order(df["case"])
    df["_c"] = df["case"].map(order.index)
    return df.sort_values(["_c", "tier", "source"]).drop(columns="_c").reset_index(drop=True)

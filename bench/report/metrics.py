"""Comparison metrics on the tidy frames of :func:`bench.experiment.store.to_frames` (no I/O, no
plotting).

* :func:`prepare` — the frames the report works on: run-config columns that older records lack get
  their defaults (:data:`DEFAULTS`: ``track`` "fe", ``jacobian`` "exact", ``polish`` False, ...),
  each run gets its method ``family`` (local / global / sampling, from the report's frozen
  table, :mod:`bench.report.catalogue`), its cost in forward-equivalents (``fe_solver``,
  ``fe_charged``, ``fe_total``: measured, charges such as high-fidelity corrections, BAE
  statistics or surrogate training included), the ``objective`` it minimised (case | tier |
  treatment: runs of different objectives never share a best known cost), the derived
  parameter ``a`` of the exponent cases (:mod:`bench.report.derived`), and a ``method`` label
  that names the track and Jacobian when they are not the defaults (``"lm (consistent) [FD
  central]"``); ``label`` keeps the store's.
* :func:`ert_table` — expected running time to success per method and case (COCO): the total
  forward-equivalents spent by all runs, successful or not, over the number of successes (∞ when
  none), with a seeded bootstrap 95 % confidence interval over the runs.
* :func:`target_table` — COCO-style cost targets relative to the best known cost of each
  objective: the fraction of runs whose final cost reaches ``J_best + 10^-k (J_init - J_best)``.
* :func:`jacobian_table` — runs that differ only in ``jacobian`` side by side.
"""

from __future__ import annotations

import math
import zlib

import numpy as np
import pandas as pd

from bench.report.catalogue import family, is_analytic

#: the cost targets J_best + 10^-k (J_init - J_best) of the ERT tables and runtime ECDFs
COST_KS = (1, 2, 3, 4, 6, 8)
#: the parameter targets max_i |x_i/x_i^REF - 1| (percent) of the runtime ECDFs
ERR_TARGETS = (10.0, 1.0, 0.1)

#: Run-config columns and the value a record without them had.
DEFAULTS = {
    "track": "fe",
    "jacobian": "exact",
    "polish": False,
    "tier": "model-error",
    "treatment": "none",
    "start": "default",
}
FAMILIES = ("local", "global", "sampling")
N_BOOT = 1000
#: What identifies a run apart from its Jacobian (for :func:`jacobian_table`).
PAIR_KEYS = (
    "case",
    "solver",
    "tier",
    "treatment",
    "track",
    "polish",
    "seed",
    "start",
    "start_index",
    "budget",
    "mesh",
)


def variant_label(label: str, track: str, jacobian: str, polish: bool) -> str:
    """The store's method label plus the track and Jacobian when they are not the defaults."""
    parts = []
    if track and track != DEFAULTS["track"] and track not in label:
        parts.append(f"{track}{' + FE polish' if polish else ''}")
    if jacobian and jacobian != DEFAULTS["jacobian"] and jacobian not in label:
        parts.append(f"FD {jacobian}" if jacobian in ("forward", "central") else str(jacobian))
    return f"{label} [{', '.join(parts)}]" if parts else label


def _bool(v) -> bool:
    if isinstance(v, str):
        return v.strip().lower() in ("1", "true", "yes")
    try:
        return bool(v) and not (isinstance(v, float) and math.isnan(v))
    except (TypeError, ValueError):
        return False


def prepare(runs: pd.DataFrame, history: pd.DataFrame | None = None):
    """``(runs, history)`` ready for the report (copies; see the module docstring)."""
    from bench.report.derived import add_derived

    attrs = dict(runs.attrs)
    runs = runs.copy()
    runs.attrs = attrs
    n = len(runs)
    if "forward_equivalents_nominal" in runs:
        runs["fe_nominal"] = pd.to_numeric(runs["forward_equivalents_nominal"], errors="coerce")
    for col, d in DEFAULTS.items():
        if col not in runs:
            runs[col] = [d] * n
        else:
            runs[col] = runs[col].where(runs[col].notna(), d)
    runs["polish"] = runs["polish"].map(_bool)
    analytic = runs["case"].map(is_analytic)
    runs.loc[analytic, "tier"] = "analytic"  # analytic test problems have no data tiers
    if "solver" not in runs:
        runs["solver"] = runs["method"].map(lambda m: str(m).split(" (")[0])
    if "crashed" not in runs:
        runs["crashed"] = False
    runs["crashed"] = runs["crashed"].map(_bool)
    fams = {s: family(s) for s in runs["solver"].unique()}
    runs["family"] = runs["solver"].map(fams)
    n_evals = _col(runs, "n_evals", 0.0)
    fe = _col(runs, "forward_equivalents", math.nan)
    runs["fe_solver"] = np.where(np.isfinite(fe) & (fe > 0), fe, n_evals)
    charged = _col(runs, "charged_equivalents", 0.0)
    runs["fe_charged"] = np.where(np.isfinite(charged), charged, 0.0)
    runs["fe_total"] = runs["fe_solver"] + runs["fe_charged"]
    runs["objective"] = runs["case"].astype(str) + " | " + runs["tier"].astype(str)
    runs["objective"] += " | " + runs["treatment"].astype(str)
    runs["label"] = runs["method"]
    runs["method"] = [
        variant_label(str(m), str(t), str(j), bool(p))
        for m, t, j, p in zip(runs["method"], runs["track"], runs["jacobian"], runs["polish"])
    ]
    if history is not None:
        hattrs = dict(history.attrs)
        history = history.copy()
        if len(history) and "config_hash" in history and "n_evals" in history:
            # one run's rows in evaluation order: a history whose phases each count iterations
            # from 1 (surrogate, then FE polish) is sorted by iteration in the store
            history = history.assign(_row=np.arange(len(history)))
            history = history.sort_values(["config_hash", "n_evals", "_row"], kind="stable")
            history = history.drop(columns="_row").reset_index(drop=True)
        if len(history) and "config_hash" in history:
            keep = ["method", "track", "tier", "treatment", "family", "objective", "solver"]
            info = runs.set_index("config_hash")[keep]
            for col in keep:
                history[col] = history["config_hash"].map(info[col])
        history.attrs = hattrs
    runs, history = add_derived(runs, history)
    return runs, history


#: Charges paid once and shared by many runs (amortised in ``ert_amortised``).
SHARED_CHARGES = ("surrogate-training",)
#: Charges that are shared when the run's treatment is BAE: the high-fidelity and inverse-model
#: runs of the error statistics, computed once per case and stored with a hash
#: (a one-point, iterated or first-order correction pays its own high-fidelity runs: not shared)
SHARED_CHARGES_BAE = ("hifi", "inverse-for-correction")


def add_shared_charges(runs: pd.DataFrame, records) -> pd.DataFrame:
    """``runs`` with ``fe_shared``: the forward-equivalents of each run's charges of the kinds in
    :data:`SHARED_CHARGES` (and :data:`SHARED_CHARGES_BAE` when its provenance says the treatment
    was ``bae``; read from the records; 0 when none), and ``fe_amortised`` =
    ``fe_total - fe_shared``."""
    shared = {}
    for rec in records or ():
        result = rec.get("result") or {}
        charges = result.get("charges") or {}
        kinds = SHARED_CHARGES
        if (result.get("provenance") or {}).get("treatment") == "bae":
            kinds = SHARED_CHARGES + SHARED_CHARGES_BAE
        items = (
            charges.items()
            if isinstance(charges, dict)
            else ((c.get("kind"), c) for c in charges if isinstance(c, dict))
        )
        tot = 0.0
        for kind, c in items:
            if kind in kinds and isinstance(c, dict):
                v = pd.to_numeric(c.get("forward_equivalents"), errors="coerce")
                tot += float(v) if np.isfinite(v) else 0.0
        shared[rec.get("config_hash")] = tot
    runs = runs.copy()
    runs["fe_shared"] = runs["config_hash"].map(shared).fillna(0.0).astype(float)
    runs["fe_amortised"] = runs["fe_total"] - runs["fe_shared"]
    return runs


def add_surrogate_optimum(runs: pd.DataFrame, records) -> pd.DataFrame:
    """``runs`` with, for surrogate-track runs, ``sur_max_err``: the largest ``100 |x/x_REF - 1|``
    (%) over the identified parameters of the surrogate search's own optimum (before the FE
    polish), and ``polish_evals``: the FE evaluations of the polish (NaN for other runs)."""
    err, polish = {}, {}
    for rec in records or ():
        result = rec.get("result") or {}
        extra = result.get("extra") or {}
        x = (extra.get("surrogate") or {}).get("x") if isinstance(extra, dict) else None
        ref = result.get("reference")
        if x is None or ref is None or len(x) != len(ref):
            continue
        x, ref = np.asarray(x, float), np.asarray(ref, float)
        err[rec.get("config_hash")] = float(100.0 * np.max(np.abs(x / ref - 1.0)))
        n = (extra.get("polish") or {}).get("n_evals")
        polish[rec.get("config_hash")] = float(n) if n is not None else math.nan
    runs = runs.copy()
    runs["sur_max_err"] = runs["config_hash"].map(err).astype(float)
    runs["polish_evals"] = runs["config_hash"].map(polish).astype(float)
    return runs


def _col(df: pd.DataFrame, col: str, default: float) -> np.ndarray:
    if col not in df:
        return np.full(len(df), default, float)
    return pd.to_numeric(df[col], errors="coerce").to_numpy(float)


# --- expected running time -------------------------------------------------------------------


def ert(fe: np.ndarray, ok: np.ndarray) -> float:
    """Expected running time to success: ``sum(fe) / n_successes`` (∞ when none)."""
    fe, ok = np.asarray(fe, float), np.asarray(ok, bool)
    k = int(ok.sum())
    return float(fe.sum() / k) if k else math.inf


def bootstrap_ert(
    fe: np.ndarray, ok: np.ndarray, *, n_boot: int = N_BOOT, seed: int | str = 0, level=0.95
) -> tuple[float, float]:
    """Percentile bootstrap interval of :func:`ert` (runs resampled with replacement, seeded by
    ``seed``; a resample without success has ERT ∞)."""
    fe, ok = np.asarray(fe, float), np.asarray(ok, bool)
    if not len(fe):
        return math.nan, math.nan
    if isinstance(seed, str):
        seed = zlib.crc32(seed.encode())
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, len(fe), size=(n_boot, len(fe)))
    k = ok[idx].sum(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        e = np.where(k > 0, fe[idx].sum(axis=1) / np.maximum(k, 1), np.inf)
    e = np.sort(e)
    a = (1.0 - level) / 2.0
    lo = e[int(math.floor(a * (n_boot - 1)))]
    hi = e[int(math.ceil((1.0 - a) * (n_boot - 1)))]
    return float(lo), float(hi)


def ert_table(
    runs: pd.DataFrame,
    tol: float | None = None,
    derived_tol: dict | None = None,
    *,
    n_boot: int = N_BOOT,
    seed: int = 0,
) -> pd.DataFrame:
    """One row per (track, tier, case, method): runs, successes, success rate (%), total and
    median forward-equivalents, the median charge per run (``charged_median``: corrections,
    surrogate training, ...) and of its shared part (``shared_median``, :data:`SHARED_CHARGES`),
    ERT and its bootstrap 95 % interval, and the ERT without the shared charges
    (``ert_amortised``: what the runs cost when e.g. a surrogate's training is amortised). The
    bootstrap of a group is seeded by ``seed`` and the group's key, so adding other groups changes
    nothing."""
    from bench.report.tables import SUCCESS_TOL, case_order, method_order, success

    tol = SUCCESS_TOL if tol is None else tol
    ok_all = success(runs, tol, derived_tol)
    rows = []
    for (track, tier, case, method), g in runs.groupby(
        ["track", "tier", "case", "method"], sort=False
    ):
        fe = g["fe_total"].to_numpy(float)
        fe = np.where(np.isfinite(fe), fe, 0.0)
        fe_own = g["fe_amortised"].to_numpy(float) if "fe_amortised" in g else fe
        fe_own = np.where(np.isfinite(fe_own), fe_own, 0.0)
        ok = ok_all.loc[g.index].to_numpy(bool)
        lo, hi = bootstrap_ert(fe, ok, n_boot=n_boot, seed=f"{seed}|{case}|{method}|{track}")
        rows.append(
            {
                "track": track,
                "tier": tier,
                "case": case,
                "method": method,
                "family": g["family"].iloc[0] if "family" in g else "other",
                "runs": len(g),
                "successes": int(ok.sum()),
                "success_pct": 100.0 * float(ok.mean()),
                "fe_sum": float(fe.sum()),
                "fe_median": float(np.median(fe)),
                "max_err_median": float(g["max_abs_err"].median())
                if "max_abs_err" in g
                else math.nan,
                "charged_median": float(np.median(g["fe_charged"].to_numpy(float)))
                if "fe_charged" in g
                else 0.0,
                "shared_median": float(np.median(fe - fe_own)),
                "ert": ert(fe, ok),
                "ert_amortised": ert(fe_own, ok),
                "ert_lo": lo,
                "ert_hi": hi,
            }
        )
    df = pd.DataFrame(rows)
    if len(df):
        cases, methods = case_order(df["case"]), method_order(df["method"])
        df["_c"] = df["case"].map(cases.index)
        df["_m"] = df["method"].map(methods.index)
        df = df.sort_values(["track", "tier", "_c", "_m"]).drop(columns=["_c", "_m"])
        df = df.reset_index(drop=True)
    return df


def rank(ert_df: pd.DataFrame) -> pd.DataFrame:
    """``ert_df`` sorted best first within each (track, tier, case): highest success rate, then
    lowest ERT, then (for methods that never succeed) smallest median max |error|, then lowest
    median forward-equivalents."""
    if not len(ert_df):
        return ert_df
    d = ert_df.assign(
        _s=-ert_df["success_pct"],
        _e=ert_df["ert"].fillna(math.inf),
        _x=ert_df["max_err_median"].fillna(math.inf) if "max_err_median" in ert_df else 0.0,
    )
    d = d.sort_values(["track", "tier", "case", "_s", "_e", "_x", "fe_median"], kind="stable")
    return d.drop(columns=["_s", "_e", "_x"])


def winners(ert_df: pd.DataFrame) -> pd.DataFrame:
    """Per (track, tier, case): the first method of :func:`rank`."""
    if not len(ert_df):
        return ert_df
    return rank(ert_df).groupby(["track", "tier", "case"], sort=False).head(1)


# --- cost targets ------------------------------------------------------------------------------


def cost_targets(runs_case: pd.DataFrame, hist_case: pd.DataFrame) -> np.ndarray:
    """The cost targets of one case (empty when they cannot be defined)."""
    costs = [runs_case["cost"].to_numpy(float)]
    if len(hist_case):
        costs.append(hist_case["best_cost"].to_numpy(float))
    allc = np.concatenate(costs)
    allc = allc[np.isfinite(allc)]
    if not len(allc) or not len(hist_case):
        return np.array([])
    first = (
        hist_case.sort_values("iteration").groupby("config_hash")["cost"].first().to_numpy(float)
    )
    first = first[np.isfinite(first)]
    if not len(first):
        return np.array([])
    f_best, f_init = float(allc.min()), float(np.median(first))
    if not f_init > f_best:
        return np.array([])
    return np.array([f_best + 10.0 ** (-k) * (f_init - f_best) for k in COST_KS])


def objective_targets(runs_obj: pd.DataFrame, hist_obj: pd.DataFrame) -> np.ndarray:
    """The cost targets of one objective (:func:`cost_targets`), from the
    runs whose final cost is an FE cost (surrogate-track runs count only with their FE polish) and
    the FE-track histories (a surrogate's history costs are not FE costs)."""
    fe_final = runs_obj[(runs_obj["track"] == "fe") | runs_obj["polish"].astype(bool)]
    h = hist_obj
    if len(h) and "track" in h:
        fe_h = h[h["track"] == "fe"]
        h = fe_h if len(fe_h) else h
    return cost_targets(fe_final if len(fe_final) else runs_obj, h)


def target_table(runs: pd.DataFrame, history: pd.DataFrame) -> pd.DataFrame:
    """Per (track, tier, case, method): the percentage of runs whose final cost reaches each cost
    target ``k`` (columns ``k1``, ``k2``, ...; NaN when the objective's targets are undefined)."""
    from bench.report.tables import case_order, method_order

    rows = []
    hist_by = dict(tuple(history.groupby("objective"))) if len(history) else {}
    for obj, ro in runs.groupby("objective", sort=False):
        targets = objective_targets(ro, hist_by.get(obj, history.iloc[0:0]))
        for (track, tier, case, method), g in ro.groupby(
            ["track", "tier", "case", "method"], sort=False
        ):
            cost = g["cost"].to_numpy(float)
            cost = np.where(g["crashed"].to_numpy(bool), np.inf, cost)
            row = {"track": track, "tier": tier, "case": case, "method": method, "runs": len(g)}
            for j, k in enumerate(COST_KS):
                row[f"k{k}"] = (
                    100.0 * float(np.mean(np.nan_to_num(cost, nan=np.inf) <= targets[j]))
                    if len(targets)
                    else math.nan
                )
            rows.append(row)
    df = pd.DataFrame(rows)
    if len(df):
        cases, methods = case_order(df["case"]), method_order(df["method"])
        df["_c"] = df["case"].map(cases.index)
        df["_m"] = df["method"].map(methods.index)
        df = df.sort_values(["track", "tier", "_c", "_m"]).drop(columns=["_c", "_m"])
        df = df.reset_index(drop=True)
    return df


def fe_at(run: pd.Series, n_evals: np.ndarray) -> np.ndarray:
    """Forward-equivalents spent after ``n_evals`` evaluations of ``run``: its charges (paid
    up front) plus the evaluations at the run's measured forward-equivalents per evaluation."""
    n = float(run.get("n_evals", 0) or 0)
    per = float(run["fe_solver"]) / n if n > 0 else 1.0
    return float(run.get("fe_charged", 0.0)) + np.asarray(n_evals, float) * per


# --- FD versus exact Jacobians -----------------------------------------------------------------


def jacobian_table(runs: pd.DataFrame) -> pd.DataFrame:
    """Runs that differ only in ``jacobian``, side by side: one row per pair key (case, solver,
    tier, treatment, track, seed, start, budget, ...) with, per Jacobian, ``iterations.<j>``,
    ``evals.<j>``, ``fe.<j>`` (measured forward-equivalents of the solver) and ``max_err.<j>`` (%,
    final max |parameter error|). Empty when no such pair exists."""
    if "jacobian" not in runs or runs["jacobian"].nunique() < 2:
        return pd.DataFrame()
    keys = [k for k in PAIR_KEYS if k in runs]
    rows = []
    for key, g in runs.groupby(keys, sort=False, dropna=False):
        if g["jacobian"].nunique() < 2:
            continue
        row = dict(zip(keys, key))
        row["method"] = g["label"].iloc[0] if "label" in g else g["solver"].iloc[0]
        for _, r in g.drop_duplicates("jacobian").iterrows():
            j = r["jacobian"]
            row[f"iterations.{j}"] = int(r.get("n_iterations", 0) or 0)
            row[f"evals.{j}"] = int(r.get("n_evals", 0) or 0)
            row[f"fe.{j}"] = float(r["fe_solver"])
            if "fe_nominal" in r:
                row[f"fe_nominal.{j}"] = float(r["fe_nominal"])
            row[f"max_err.{j}"] = float(r.get("max_abs_err", math.nan))
        rows.append(row)
    return pd.DataFrame(rows)

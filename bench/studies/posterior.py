"""Posterior study on a surrogate: converged emcee chains (>= 50 integrated autocorrelation times),
posterior summaries (with the derived exponent coefficient ``a`` of the exponent cases), against
the Laplace approximation at the FE optimum (exact FE Jacobian).

Likelihood (docs/surrogate.md, "Surrogate error in the likelihood"): the objective of the case
(data tier, region, model-error correction: its shift and low-rank covariance) with the FE model
replaced by the stored surrogate restricted to the region, and the surrogate's hold-out variance
added to the noise variance: ``C = diag(sigma^2 + v) (+ V V^T of a correction)``. Prior uniform on
the case's box; points the material rule rejects have ``log p = -inf``.

Sampling (in ``u = (x - lower) / (upper - lower)``): the surrogate's MAP (trust-region least squares
from the best of a Latin hypercube), walkers started in the MAP's own Laplace ellipsoid, emcee's
differential-evolution moves (80 % DE + 20 % DE-snooker), vectorised log-probability (one surrogate
batch per half-ensemble). Chunks of steps until the kept chain (after a burn-in of
``burn_fraction`` of the steps) is at least ``min_tau_multiple`` times the largest integrated
autocorrelation time (emcee's estimator), or ``max_steps`` / ``max_minutes``.

Laplace: FE ``lm`` (exact Jacobians) from the MCMC mean (``fe_budget`` FE evaluations), then one
FE run with sensitivities at its optimum: ``cov = (J^T C^-1 J)^-1`` with the data's noise alone
(``laplace_sd``: the FE model's own posterior) and with the surrogate-inflated noise
(``laplace_sd_inflated``: what the MCMC on the surrogate should reproduce); ``a`` by the delta
method.

Files in ``results/studies/posterior/<case>/`` (``<case>__<tier>`` for other tiers than
consistent): ``summary.json`` (format below), ``chain.npz`` (kept chain, thinned, physical, with
``names``, and ``log_prob``), ``posterior.md``; :func:`render_posterior` draws ``corner.png`` and
``trace.png`` from these files alone.

``summary.json``: ``case``, ``tier``, ``treatment``, ``names`` (identified parameters, then ``a``
for the exponent cases), ``n_samples`` (kept, unthinned: steps x walkers), ``tau`` ({name: steps}),
``tau_multiple`` (kept steps / max tau), ``mean``, ``sd``, ``q025``, ``q975``, ``laplace_sd``,
``laplace_sd_inflated``, ``fe_optimum`` ({name: value}), ``map`` (surrogate MAP), plus
``n_walkers``, ``n_steps``, ``burn``, ``acceptance``, ``n_evals``, ``wall_s``, ``converged``,
``surrogate`` (name, hash, hold-out RMS/sigma), ``fe`` (polish evaluations and cost), ``a_width``
(exponent cases: sd and 95 % half-width of ``a`` in % of its mean, next to the paper's 11-46 %
Table-1 error), ``agreement`` (``max_offset_sd``, ``sd_ratio``, ``ok``: :func:`agreement`; when
not ok the surrogate, not the data, limits the posterior).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from problems.inverse.cases import PAPER_A_ERROR

SUMMARY = "summary.json"
CHAIN = "chain.npz"


@dataclass
class PosteriorResult:
    folder: Path
    summary: dict


def study_folder(case: str, tier: str, out=None) -> Path:
    from bench.studies import output_dir

    name = case if tier == "consistent" else f"{case}__{tier}"
    return output_dir("posterior", name, out)


def exponent_a(case, X: np.ndarray) -> np.ndarray | None:
    """The derived coefficient ``a`` of exponent cases at the rows of ``X`` (physical), else
    None."""
    if case.form != "exponent":
        return None
    from problems.materials.hardening import reference_test

    test = reference_test(case.hardening)
    i = {n: k for k, n in enumerate(case.names)}
    s0, pt0, b = X[:, i["sigma0"]], X[:, i["pt0"]], X[:, i["b"]]
    S = test.q_hat * s0
    return (pt0 + test.p_hat * s0) / S**b


def exponent_a_gradient(case, x: np.ndarray) -> np.ndarray:
    """d a / d x (n,) at one physical point (exponent cases)."""
    _, chain = case.derive(dict(zip(case.names, map(float, x))))
    return np.array([chain["a"].get(n, 0.0) for n in case.names])


def _objective(case, tier, treatment, surrogate, mapper=None):
    """``(evaluator, spec)``: the objective on ``surrogate`` (None: the FE model) with the
    treatment's region and correction."""
    from bench.experiment.objective import prepare
    from bench.experiment.spec import DataSpec, RunSpec, Treatment

    spec = RunSpec(case.name, "lm", data=DataSpec(tier), treatment=Treatment(treatment))
    asm = prepare(spec, mapper=mapper, forward=surrogate)
    if asm.spec.treatment.name not in ("none", "bae"):  # the default treatment resolved to either
        raise ValueError(
            f"posterior: treatment {asm.spec.treatment.name!r} is not supported (none, bae, "
            "default)"
        )
    return asm.treated(forward=surrogate), asm.spec


def inflated_problem(problem):
    """The same least-squares problem with the surrogate's hold-out variance added to the noise
    variance (``problem.model`` a restricted surrogate)."""
    from problems.inverse.problem import LeastSquaresProblem

    sigma = np.broadcast_to(np.asarray(problem.sigma, float), problem.data.shape)
    return LeastSquaresProblem(
        problem.model,
        problem.data,
        problem.lower,
        problem.upper,
        problem.reference,
        sigma=problem.model.inflated_sigma(sigma),
        covariance_factor=problem.covariance_factor,
        blocks=problem.blocks,
        provenance=problem.provenance,
    )


class LogPosterior:
    """Vectorised ``log p(U)`` over rows of ``U`` in the unit box (see the module docstring);
    counts its evaluations."""

    def __init__(self, problem):
        self.problem = problem
        self.model = problem.model
        self.lower, self.span = problem.lower, problem.upper - problem.lower
        self.n_evals = 0

    def cost(self, X) -> np.ndarray:
        values = self.model.predict(X)
        R = self.problem.whiten((self.problem.data[None, :] - values).T)
        return np.sum(R * R, axis=0)

    def __call__(self, U) -> np.ndarray:
        U = np.atleast_2d(U)
        lp = np.full(len(U), -np.inf)
        inside = np.all((U >= 0.0) & (U <= 1.0), axis=1)
        X = self.lower + U * self.span
        ok = np.array(
            [bool(inside[i]) and self.model.check(X[i]) is None for i in range(len(U))], bool
        )
        if ok.any():
            self.n_evals += int(ok.sum())
            lp[ok] = -0.5 * self.cost(X[ok])
        return lp


def surrogate_map(post: LogPosterior, seed: int, n_lhs: int = 256, n_starts: int = 4):
    """``(u_map, cov_u)``: the MAP of the surrogate posterior in the unit box and its Laplace
    covariance there (trust-region least squares with the surrogate's Jacobian)."""
    from scipy.optimize import least_squares
    from scipy.stats import qmc

    prob, model = post.problem, post.model
    U = qmc.LatinHypercube(d=post.lower.size, seed=seed).random(n_lhs)
    lp = post(U)
    best = (None, np.inf, None)

    def res(u):
        x = post.lower + u * post.span
        return prob.whiten(prob.data - model.predict(x)[0])

    def jac(u):
        x = post.lower + u * post.span
        return -prob.whiten(model(x, jacobian=True).jacobian) * post.span[None, :]

    for u0 in U[np.argsort(-lp)[:n_starts]]:
        r = least_squares(res, u0, jac=jac, bounds=(0.0, 1.0), method="trf", max_nfev=300)
        if 2 * r.cost < best[1]:
            best = (r.x, 2 * r.cost, r.jac)
    u, _, J = best
    cov = np.linalg.pinv(J.T @ J)
    return u, cov


def _laplace(problem_fe, problem_infl, x, J_model, case):
    """Laplace standard deviations at ``x`` from the model Jacobian (m, n): noise alone and
    inflated; plus those of ``a`` (delta method) for exponent cases."""
    out = {}
    for key, prob in (("laplace_sd", problem_fe), ("laplace_sd_inflated", problem_infl)):
        Jw = prob.whiten(J_model)
        cov = np.linalg.pinv(Jw.T @ Jw)
        sd = dict(zip(case.names, np.sqrt(np.maximum(np.diag(cov), 0.0))))
        if case.form == "exponent":
            g = exponent_a_gradient(case, x)
            sd["a"] = float(math.sqrt(max(g @ cov @ g, 0.0)))
        out[key] = sd
    return out


def run_posterior(
    case: str,
    *,
    tier: str = "consistent",
    treatment: str = "none",
    surrogate: str = "default",
    n_walkers: int = 32,
    seed: int = 0,
    min_tau_multiple: float = 50.0,
    burn_fraction: float = 0.3,
    chunk: int = 500,
    max_steps: int = 60_000,
    max_minutes: float = 15.0,
    fe_budget: int = 30,
    thin: int | None = None,
    out=None,
    progress: bool = False,
) -> PosteriorResult:
    """Run the study for one case and write its files (see the module docstring)."""
    import warnings

    import emcee
    from emcee.autocorr import integrated_time

    from bench.experiment.surrogate_track import load_for
    from bench.studies import write_json
    from problems.inverse.cases import get_case
    from solvers import solve

    t0 = time.perf_counter()
    case = get_case(case)
    if case.is_analytic:
        raise ValueError(f"case {case.name} is analytic: the posterior study runs on FE cases")
    sur = load_for(surrogate, case.name, "coarse")
    obj, spec = _objective(case, tier, treatment, sur)
    problem = inflated_problem(obj.problem)
    post = LogPosterior(problem)
    d = len(case.names)
    nw = max(int(n_walkers), 2 * d + 2)
    nw += nw % 2
    u_map, cov_u = surrogate_map(post, seed)
    rng = np.random.default_rng(seed)
    L = np.linalg.cholesky(cov_u + 1e-18 * np.eye(d))
    p0 = np.clip(u_map + (rng.standard_normal((nw, d)) @ L.T), 0.0, 1.0)
    moves = [(emcee.moves.DEMove(), 0.8), (emcee.moves.DESnookerMove(), 0.2)]
    sampler = emcee.EnsembleSampler(nw, d, post, vectorize=True, moves=moves)
    sampler.random_state = np.random.RandomState(seed).get_state()
    state, tau, steps, converged = p0, np.full(d, np.inf), 0, False
    while steps < max_steps:
        state = sampler.run_mcmc(state, chunk, progress=False, skip_initial_state_check=True)
        steps = sampler.iteration
        burn = int(burn_fraction * steps)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            tau = integrated_time(sampler.get_chain()[burn:], tol=0)
        kept = steps - burn
        if progress:
            print(
                f"  {case.name}: {steps} steps, tau max {np.max(tau):.1f}, kept/tau "
                f"{kept / np.max(tau):.1f}, {time.perf_counter() - t0:.0f} s",
                flush=True,
            )
        if np.all(np.isfinite(tau)) and kept >= min_tau_multiple * np.max(tau):
            converged = True
            break
        if time.perf_counter() - t0 > 60 * max_minutes:
            break
    mcmc_wall = time.perf_counter() - t0
    burn = int(burn_fraction * steps)
    chain_u = sampler.get_chain()[burn:]  # (kept, nw, d)
    logp = sampler.get_log_prob()[burn:]
    kept = chain_u.shape[0]
    flat_x = post.lower + chain_u.reshape(-1, d) * post.span
    names = list(case.names)
    cols = {n: flat_x[:, i] for i, n in enumerate(names)}
    tau_d = {n: float(t) for n, t in zip(names, tau)}
    a = exponent_a(case, flat_x)
    if a is not None:
        names.append("a")
        cols["a"] = a
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            tau_d["a"] = float(integrated_time(a.reshape(kept, nw)[:, :, None], tol=0)[0])
    summary_stats = {
        "mean": {n: float(np.mean(v)) for n, v in cols.items()},
        "sd": {n: float(np.std(v, ddof=1)) for n, v in cols.items()},
        "q025": {n: float(np.percentile(v, 2.5)) for n, v in cols.items()},
        "q975": {n: float(np.percentile(v, 97.5)) for n, v in cols.items()},
    }
    # Laplace at the FE optimum (FE lm from the posterior mean), exact FE Jacobian
    fe_obj, _ = _objective(case, tier, treatment, None)
    x_start = np.array([summary_stats["mean"][n] for n in case.names])
    fe_res = solve(fe_obj, "lm", budget=fe_budget, seed=seed, x0=x_start)
    x_fe = np.array(fe_res.x)
    jr = fe_obj.model(x_fe, jacobian=True)
    infl_fe = _inflated_like(fe_obj.problem, problem)
    lap = _laplace(fe_obj.problem, infl_fe, x_fe, jr.jacobian, case)
    fe_opt = dict(zip(case.names, map(float, x_fe)))
    if case.form == "exponent":
        fe_opt["a"] = float(exponent_a(case, x_fe[None])[0])
    tau_max = max(tau_d[n] for n in case.names)
    summary = {
        "case": case.name,
        "tier": obj.provenance.get("data_tier"),
        "treatment": spec.treatment.name,
        "plate_margin_mm": spec.treatment.plate_margin_mm,
        "names": names,
        "n_walkers": nw,
        "n_steps": int(steps),
        "burn": int(burn),
        "n_samples": int(kept * nw),
        "tau": tau_d,
        "tau_multiple": float(kept / tau_max) if tau_max > 0 else float("inf"),
        "min_tau_multiple": float(min_tau_multiple),
        "converged": bool(converged),
        **summary_stats,
        **lap,
        "fe_optimum": fe_opt,
        "map": dict(zip(case.names, map(float, post.lower + u_map * post.span))),
        "reference": dict(zip(case.names, map(float, case.reference))),
        "acceptance": float(np.mean(sampler.acceptance_fraction)),
        "n_evals": int(post.n_evals),
        "mcmc_wall_s": float(mcmc_wall),
        "wall_s": float(time.perf_counter() - t0),
        "surrogate": {
            "name": surrogate,
            "hash": sur.hash,
            "holdout_rms_sigma": {
                k: v.get("rms_sigma")
                for k, v in ((sur.info.get("validation") or {}).get("blocks") or {}).items()
            },
        },
        "fe": {
            "n_evals": fe_res.n_evals,
            "forward_equivalents": fe_res.forward_equivalents,
            "cost": fe_res.cost,
            "status": fe_res.status,
            "jacobian_wall_s": jr.wall_s,
        },
        "likelihood": "C = diag(sigma^2 + surrogate hold-out variance)"
        + (" + V V^T (BAE)" if spec.treatment.name == "bae" else ""),
    }
    summary["agreement"] = agreement(summary)
    if a is not None:
        m, sd = summary_stats["mean"]["a"], summary_stats["sd"]["a"]
        half = 0.5 * (summary_stats["q975"]["a"] - summary_stats["q025"]["a"])
        summary["a_width"] = {
            "sd_percent": 100.0 * sd / abs(m),
            "half_width_95_percent": 100.0 * half / abs(m),
            "laplace_sd_percent": 100.0 * lap["laplace_sd"]["a"] / abs(fe_opt["a"]),
            "paper_table1_error_percent": list(PAPER_A_ERROR),
        }
    folder = study_folder(case.name, summary["tier"], out)
    thin = thin or max(1, int(tau_max // 2))
    np.savez_compressed(
        folder / CHAIN,
        chain=(post.lower + chain_u[::thin] * post.span),
        log_prob=logp[::thin],
        names=np.array(list(case.names)),
        thin=thin,
    )
    summary["thin"] = thin
    write_json(folder / SUMMARY, summary)
    (folder / "posterior.md").write_text(format_summary(summary) + "\n")
    return PosteriorResult(folder, summary)


def agreement(s: dict, offset_sd: float = 3.0, ratio=(0.67, 1.5)) -> dict:
    """Does the surrogate posterior agree with the Laplace approximation at the FE optimum (with
    the inflated noise)? ``max_offset_sd``: largest |posterior mean - FE optimum| / posterior sd;
    ``sd_ratio``: range of posterior sd / inflated Laplace sd; ``ok`` when the offset is below
    ``offset_sd`` and the ratios inside ``ratio`` (else the surrogate, not the data, limits the
    posterior: its numbers should not be used)."""
    names = [n for n in s["names"] if s["sd"].get(n)]
    off = max(abs(s["mean"][n] - s["fe_optimum"][n]) / s["sd"][n] for n in names)
    r = [s["sd"][n] / s["laplace_sd_inflated"][n] for n in names if s["laplace_sd_inflated"].get(n)]
    ok = off < offset_sd and ratio[0] <= min(r) and max(r) <= ratio[1]
    return {"max_offset_sd": float(off), "sd_ratio": [float(min(r)), float(max(r))], "ok": bool(ok)}


def _inflated_like(fe_problem, sur_problem):
    """The FE problem with the surrogate problem's inflated sigma (same rows)."""
    from problems.inverse.problem import LeastSquaresProblem

    return LeastSquaresProblem(
        fe_problem.model,
        fe_problem.data,
        fe_problem.lower,
        fe_problem.upper,
        fe_problem.reference,
        sigma=np.broadcast_to(np.asarray(sur_problem.sigma, float), fe_problem.data.shape),
        covariance_factor=fe_problem.covariance_factor,
        blocks=fe_problem.blocks,
    )


def format_summary(s: dict) -> str:
    """Markdown table of one case's posterior."""
    lines = [
        f"# Posterior of {s['case']} ({s['tier']} tier, treatment {s['treatment']}) on the "
        "surrogate",
        "",
        f"{s['n_walkers']} walkers x {s['n_steps']} steps (burn-in {s['burn']}), "
        f"{s['n_samples']} kept samples, chain = {s['tau_multiple']:.1f} tau "
        f"({'converged' if s['converged'] else 'NOT converged'}: >= {s['min_tau_multiple']:g} "
        f"tau required), acceptance {s['acceptance']:.2f}, {s['n_evals']} surrogate evaluations, "
        f"{s['mcmc_wall_s']:.0f} s MCMC, {s['wall_s']:.0f} s in all.",
        "",
        "| parameter | tau | mean | sd | 2.5 % | 97.5 % | FE optimum | Laplace sd | Laplace sd "
        "(inflated) | sd / Laplace (inflated) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for n in s["names"]:
        li = s["laplace_sd_inflated"].get(n, float("nan"))
        lines.append(
            f"| {n} | {s['tau'].get(n, float('nan')):.1f} | {s['mean'][n]:.6g} | "
            f"{s['sd'][n]:.3g} | {s['q025'][n]:.6g} | {s['q975'][n]:.6g} | "
            f"{s['fe_optimum'].get(n, float('nan')):.6g} | "
            f"{s['laplace_sd'].get(n, float('nan')):.3g} | {li:.3g} | "
            f"{s['sd'][n] / li if li else float('nan'):.2f} |"
        )
    if "a_width" in s:
        w = s["a_width"]
        lines += [
            "",
            f"Exponent coefficient a: posterior sd {w['sd_percent']:.3g} % of its mean, 95 % "
            f"half-width {w['half_width_95_percent']:.3g} % (Laplace at the FE optimum, noise "
            f"alone: {w['laplace_sd_percent']:.3g} %), against the paper's Table-1 error of "
            f"{w['paper_table1_error_percent'][0]:g}-{w['paper_table1_error_percent'][1]:g} %.",
        ]
    return "\n".join(lines)


def render_posterior(folder) -> list[Path]:
    """``corner.png`` and ``trace.png`` from ``summary.json`` and ``chain.npz`` alone."""
    import corner
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from bench.plotting import save
    from bench.studies import read_json

    folder = Path(folder)
    s = read_json(folder / SUMMARY)
    with np.load(folder / CHAIN) as z:
        chain = z["chain"]
        names = [str(n) for n in z["names"]]
    flat = chain.reshape(-1, chain.shape[-1])
    labels, cols = list(names), [flat[:, i] for i in range(flat.shape[1])]
    if "a" in s["names"]:
        from problems.inverse.cases import get_case

        labels.append("a")
        cols.append(exponent_a(get_case(s["case"]), flat))
    data = np.column_stack(cols)
    truths = [s["fe_optimum"].get(n, np.nan) for n in labels]
    fig = corner.corner(
        data,
        labels=labels,
        truths=truths,
        truth_color="tab:red",
        quantiles=[0.025, 0.5, 0.975],
        show_titles=True,
        title_fmt=".4g",
    )
    fig.suptitle(
        f"{s['case']} ({s['tier']}): surrogate posterior, {s['tau_multiple']:.0f} tau; red = FE "
        "optimum",
        y=1.01,
    )
    out = [save(fig, folder / "corner.png", dpi=80)]
    fig, axes = plt.subplots(len(names), 1, figsize=(7, 1.4 * len(names)), sharex=True)
    for i, ax in enumerate(np.atleast_1d(axes)):
        ax.plot(chain[:, :, i], lw=0.3, alpha=0.5)
        ax.set_ylabel(names[i], fontsize=8)
    np.atleast_1d(axes)[-1].set_xlabel(f"kept step / {s.get('thin', 1)}")
    out.append(save(fig, folder / "trace.png", dpi=80))
    return out

"""Surrogate benchmarks (not tests): speed of one evaluation and of a batch against one FE run,
measured in the same run; surrogate search + FE polish against FE-only LM from random starts.

    OMP_NUM_THREADS=1 python -m bench.perf.surrogate speed [--cases all] [--repeat 200]
        [--rounds 3] [--json results/surrogates/speed.json]
    python -m bench.perf.surrogate table --json results/surrogates/speed.json   (markdown)
    OMP_NUM_THREADS=1 python -m bench.perf.surrogate polish [--cases all] [--starts 3]
        [--tier consistent] [--out results/surrogates/polish_vs_lm.jsonl]
    OMP_NUM_THREADS=1 python -m bench.perf.surrogate tradeoff [--cases all]
        [--json results/surrogates/tradeoff.json]

``speed``: per case, in one process, the median CPU time (``time.process_time``: on a shared
machine the wall time of a long computation mostly measures how long the process waited for a
core) of 3 plain FE runs on the coarse mesh, and on the default surrogate against the case's
consistent data:

* ``misfit``: one evaluation of the cost at a point, what replaces an FE run + residual in an
  objective (:class:`problems.surrogate.misfit.SurrogateMisfit`: box, material rule, GP mean of the
  POD coefficients, misfit in their space; one compiled call), single and per point in batches of
  32 and 1000;
* ``values`` / ``jacobian``: one call returning the 8 130 predicted values (and their Jacobian);
* ``evaluator``: one cost through the :class:`~problems.inverse.evaluator.Evaluator` a solver
  sees (counting, cache, log; every point new), single and per point in batches of 1000, and the
  same with ``cost_path=False`` (``before``: the model's call and the whole residual, the path of
  the records made before the cost path);

and the ratios FE / each: medians over ``--rounds`` rounds, each one FE run then every surrogate
timing (so that a burst of load on this shared machine falls on both). Single calls are timed
in groups of 20 (the CPU clock's resolution).

``tradeoff``: per case whose training and hold-out runs are kept (``runs_dir()`` of
:mod:`problems.surrogate.build`, matched by training hash: no new FE runs), the shipped regression
against regressions that share kernels, refitted on the same training runs and POD: one GP for all
modes, the leading mode alone plus one GP for the rest, and the cross-validated RBF. For each: the
hold-out RMS error in units of sigma (displacements, force; the same valid hold-out runs), the
CPU time of one surrogate call and of its regression alone (the POD coefficients), against one
plain FE run in the same process. It answers whether the 10^4 speed target can be bought with
fewer kernels without losing the 1 sigma accuracy target.

``polish``: per case, the FE-only LM optimum ``x_LM`` (LM from the default start, budget 200), then
from ``--starts`` seeded random starts (``start = random``, ``start_index = k``): FE-only LM
(budget 100) and ``cma`` on the default surrogate (budget 3000) + FE polish (lm, exact Jacobians,
budget 40); a run reaches the optimum when every parameter is within ``--tol`` (0.1 %) of
``x_LM``. One JSON line per run (resumable: done runs are skipped).
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

import numpy as np


def _cases(spec: str) -> list[str]:
    from problems.inverse.cases import CASES

    if spec == "all":
        return [n for n, c in CASES.items() if not c.is_analytic]
    return spec.split(",")


def _cpu(fn, items, group: int = 20) -> float:
    """Median CPU time of one ``fn(item)``, s, timed in groups of ``group`` calls after a
    warm-up call on the last item (not timed: every timed item is new to a cache)."""
    from problems.surrogate.validation import cpu_per_call

    fn(items[-1])
    return cpu_per_call(fn, items[:-1], group)


def _cpu_batch(fn, X, size: int, repeats: int = 5) -> float:
    """Median CPU time per point of ``fn(batch)`` over ``repeats`` batches of ``size`` rows, s."""
    fn(X[:size])
    times = []
    for k in range(repeats):
        batch = X[(k * size) % len(X) :][:size]
        t0 = time.process_time()
        fn(batch)
        times.append((time.process_time() - t0) / len(batch))
    return statistics.median(times)


def speed(cases, repeat: int, rounds: int = 3) -> list[dict]:
    """Per case, CPU times in one process (see the module docstring): medians over ``rounds``
    alternating rounds, and the ratios to one coarse FE run."""
    from bench.experiment.surrogate_track import load_for
    from problems.inverse.build import build_objective
    from problems.inverse.evaluator import Evaluator
    from problems.inverse.forward import FEForwardModel
    from problems.surrogate.model import VectorisedMapper

    rows = []
    for name in cases:
        sur = load_for("default", name, "coarse")
        fast = build_objective(name, tier="consistent", forward=sur, mapper=VectorisedMapper())
        plain = Evaluator(fast.problem, mapper=VectorisedMapper(), cost_path=False)
        misfit = fast._misfit
        data = fast.problem
        fe = FEForwardModel(sur.checker.case, "coarse", sur.checker.loading, sur.checker.points)
        rng = np.random.default_rng(0)
        width = sur.upper - sur.lower
        X = sur.lower + rng.random((max(1000, rounds * repeat), len(sur.names))) * width
        Z = X / data.reference

        def fresh(ev):  # a batch through an emptied cache (reset: microseconds)
            return lambda B: (ev.reset(), ev.costs(B))

        fe(X[0])  # warm-up
        times: dict[str, list[float]] = {}
        for k in range(rounds):  # alternating rounds: the machine's load falls on all alike
            t0 = time.process_time()
            fe(X[1 + k])
            one = slice(repeat * k, repeat * (k + 1))
            fast.reset(), plain.reset()  # every timed point new to the evaluators' caches
            for key, value in {
                "fe_s": time.process_time() - t0,
                "misfit_s": _cpu(misfit, X[one]),
                "misfit_batch32_s": _cpu_batch(misfit, X, 32, 10),
                "misfit_batch1000_s": _cpu_batch(misfit, X, 1000, 1),
                "values_s": _cpu(sur, X[one]),
                "jacobian_s": _cpu(lambda x: sur(x, jacobian=True), X[one][:20]),
                "evaluator_s": _cpu(fast.cost, Z[one]),
                "evaluator_batch1000_s": _cpu_batch(fresh(fast), Z, 1000, 1),
                "evaluator_before_s": _cpu(plain.cost, Z[one][::-1]),
                "evaluator_before_batch1000_s": _cpu_batch(fresh(plain), Z, 1000, 1),
            }.items():
                times.setdefault(key, []).append(value)
        row = {"case": name, **{key: statistics.median(v) for key, v in times.items()}}
        for k in [k for k in row if k.endswith("_s") and k != "fe_s"]:
            row["ratio_" + k[:-2]] = row["fe_s"] / row[k]
        rows.append(row)
        us = {k: 1e6 * v for k, v in row.items() if k.endswith("_s") and k != "fe_s"}
        print(
            f"{name:24} CPU: FE {row['fe_s']:.3f} s | misfit: one {us['misfit_s']:.1f} us "
            f"(x{row['ratio_misfit']:.3g}), batch 32 {us['misfit_batch32_s']:.1f} us/point "
            f"(x{row['ratio_misfit_batch32']:.3g}), batch 1000 {us['misfit_batch1000_s']:.1f} "
            f"(x{row['ratio_misfit_batch1000']:.3g}) | values {us['values_s']:.0f} us, +Jacobian "
            f"{us['jacobian_s']:.0f} us | evaluator: one {us['evaluator_s']:.1f} us "
            f"(x{row['ratio_evaluator']:.3g}; before {us['evaluator_before_s']:.0f} us), "
            f"batch 1000 {us['evaluator_batch1000_s']:.1f} us/point "
            f"(x{row['ratio_evaluator_batch1000']:.3g}; before "
            f"{us['evaluator_before_batch1000_s']:.0f})",
            flush=True,
        )
    return rows


def speed_table(rows) -> str:
    """The markdown table of ``speed`` rows (docs/surrogate.md section 13)."""

    def us(row, key):
        return f"{1e6 * row[key]:.1f} ({row['ratio_' + key[:-2]] / 1e4:.2f})"

    lines = [
        "| case | FE run, CPU s | misfit: one, µs (ratio / 10⁴) | batch 32, µs/point | "
        "batch 1000, µs/point | values, µs | + Jacobian, µs | evaluator: one, µs, now / before "
        "(ratio now) | evaluator: batch 1000, µs/point, now / before (ratio now) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        before = 1e6 * r["evaluator_before_s"], 1e6 * r["evaluator_before_batch1000_s"]
        lines.append(
            f"| {r['case']} | {r['fe_s']:.3f} | {us(r, 'misfit_s')} | "
            f"{us(r, 'misfit_batch32_s')} | {us(r, 'misfit_batch1000_s')} | "
            f"{1e6 * r['values_s']:.0f} | {1e6 * r['jacobian_s']:.0f} | "
            f"{1e6 * r['evaluator_s']:.1f} / {before[0]:.0f} "
            f"({r['ratio_evaluator'] / 1e4:.2f}) | "
            f"{1e6 * r['evaluator_batch1000_s']:.1f} / {before[1]:.0f} "
            f"({r['ratio_evaluator_batch1000'] / 1e4:.2f}) |"
        )
    return "\n".join(lines)


def _cpu_per_call(fn, X, repeat: int) -> float:
    """Median CPU time of one ``fn(x)`` over the first ``repeat`` rows of ``X`` after a warm-up
    call, s (groups of 20 calls)."""
    from problems.surrogate.validation import cpu_per_call

    fn(X[0])
    return cpu_per_call(fn, X[:repeat])


def tradeoff(cases, repeat: int) -> list[dict]:
    import dataclasses

    from bench.experiment.surrogate_track import load_for
    from problems.inverse import layout
    from problems.inverse.data import get_data
    from problems.inverse.forward import FEForwardModel
    from problems.surrogate.build import runs_dir
    from problems.surrogate.regression import Scorer, fit_gp, fit_rbf, select_rbf

    rows = []
    for name in cases:
        sur = load_for("default", name, "coarse")
        key = (sur.info.get("training_hash") or "")[:12]
        kept = sorted(runs_dir().glob(f"{name}__coarse__{key}.npz")) if key else []
        if not kept:
            print(f"{name:24} no kept training runs (hash {key or '?'}): skipped", flush=True)
            continue
        runs = np.load(kept[0])
        if "hold_X" not in runs:
            print(f"{name:24} no kept hold-out runs: skipped", flush=True)
            continue
        pod, width = sur.pod, sur.upper - sur.lower
        Z = (runs["X"] - sur.lower) / width
        if Z.shape != sur.train_z.shape or not np.allclose(Z, sur.train_z, rtol=0, atol=1e-12):
            print(f"{name:24} kept runs are not the surrogate's training set: skipped", flush=True)
            continue
        A = pod.coefficients(runs["Y"])
        N = int(sur.info["description"]["n_snapshots"])
        all_blocks = layout.blocks(N, (pod.mean.size - N) // (2 * N))
        report = {k: all_blocks[k] for k in ("displacement", "force")}
        scorer = Scorer(pod.modes, {k: all_blocks[k] for k in layout.BLOCK_NAMES})
        HZ = (runs["hold_X"] - sur.lower) / width
        data = get_data(name)
        fe = FEForwardModel(sur.checker.case, "coarse", data.settings.loading, data.points)
        X = sur.lower + np.random.default_rng(0).random((repeat, len(width))) * width
        fe(X[0])  # warm-up
        fe_s = []
        for k in range(3):
            t0 = time.process_time()
            fe(X[k])
            fe_s.append(time.process_time() - t0)
        fe_s = statistics.median(fe_s)
        variants = {"shipped": sur.regression}
        t0 = time.process_time()
        variants["gp, one kernel"] = fit_gp(Z, A, n_individual=0, individual=(), restarts=1)
        variants["gp, leading mode + one kernel"] = fit_gp(
            Z, A, n_individual=1, individual=(), restarts=1
        )
        cfg, _ = select_rbf(Z, A, scorer)
        variants[f"rbf ({cfg['kernel']})"] = fit_rbf(Z, A, **cfg)
        fit_s = time.process_time() - t0
        for label, reg in variants.items():
            model = dataclasses.replace(sur, regression=reg)
            E = (pod.reconstruct(reg.predict(HZ)) - runs["hold_Y"]) / pod.scale
            rms = {k: float(np.sqrt(np.mean(E[:, sl] ** 2))) for k, sl in report.items()}
            one = _cpu_per_call(model, X, repeat)
            kernels_s = _cpu_per_call(
                lambda x, reg=reg: reg.predict(model.to_scaled(x)[None]), X, repeat
            )
            n_kernels = len(getattr(reg, "components", ())) or 1
            row = {
                "case": name,
                "regression": label,
                "kernels": n_kernels,
                "holdout_rms_sigma": rms,
                "surrogate_s": one,
                "regression_s": kernels_s,
                "fe_s": fe_s,
                "ratio": fe_s / one,
            }
            rows.append(row)
            print(
                f"{name:24} {label:32} kernels {n_kernels:2d} | hold-out RMS: displacement "
                f"{rms['displacement']:.3g} sigma, force {rms['force']:.3g} sigma | one call "
                f"{1e6 * one:.0f} us (coefficients {1e6 * kernels_s:.0f} us), FE {fe_s:.3f} s: "
                f"x{fe_s / one:.3g}",
                flush=True,
            )
        print(f"{name:24} refits took {fit_s:.0f} s CPU", flush=True)
    return rows


def _within(x, ref, tol) -> tuple[bool, float]:
    dev = float(np.max(np.abs(np.asarray(x) / np.asarray(ref) - 1.0)))
    return dev <= tol, dev


def _suite_lm(case: str, tier: str) -> dict | None:
    """The default suite's FE-only LM run of ``case`` from the default start on ``tier`` (no
    treatment), if stored in results/default/runs/."""
    from bench.paths import results_root

    for f in sorted((results_root() / "default" / "runs").glob("*.json")):
        d = json.loads(f.read_text())
        r = d.get("result", d)
        p = r.get("provenance", {})
        if (
            r.get("method") == "lm"
            and p.get("case") == case
            and p.get("data_tier") == tier
            and p.get("treatment") == "none"
            and p.get("start", "default") == "default"
        ):
            keys = ("x", "cost", "n_evals", "forward_equivalents", "wall_s", "status")
            return {**{k: r[k] for k in keys}, "record": f.name}
    return None


def polish(cases, starts: int, tier: str, out: Path, tol: float) -> None:
    from bench.experiment.identify import identify
    from bench.experiment.spec import DataSpec, RunSpec

    out.parent.mkdir(parents=True, exist_ok=True)
    done = set()
    if out.exists():
        for line in out.read_text().splitlines():
            d = json.loads(line)
            done.add((d["case"], d["tier"], d["kind"], d["start_index"]))

    def record(doc):
        with out.open("a") as f:
            f.write(json.dumps(doc) + "\n")

    for name in cases:
        ref_key = (name, tier, "lm-default", -1)
        suite = _suite_lm(name, tier)
        if suite is not None and ref_key not in done:
            record({"case": name, "tier": tier, "kind": "lm-default", "start_index": -1, **suite})
            done.add(ref_key)
            print(f"{name}: FE-only LM optimum from the default suite ({suite['record']})")
        if ref_key in done:
            x_lm = next(
                json.loads(line)["x"]
                for line in out.read_text().splitlines()
                if (lambda d: (d["case"], d["tier"], d["kind"], d["start_index"]) == ref_key)(
                    json.loads(line)
                )
            )
        else:
            r = identify(RunSpec(name, "lm", budget=200, data=DataSpec(tier)))
            x_lm = r.x
            record(
                {
                    "case": name,
                    "tier": tier,
                    "kind": "lm-default",
                    "start_index": -1,
                    "x": r.x,
                    "cost": r.cost,
                    "n_evals": r.n_evals,
                    "forward_equivalents": r.forward_equivalents,
                    "wall_s": r.wall_s,
                    "status": r.status,
                }
            )
            print(f"{name}: FE-only LM optimum cost {r.cost:.6g} ({r.n_evals} evaluations)")
        for k in range(starts):
            for kind in ("lm", "cma+polish"):
                if (name, tier, kind, k) in done:
                    continue
                if kind == "lm":
                    spec = RunSpec(
                        name, "lm", start="random", start_index=k, budget=100, data=DataSpec(tier)
                    )
                else:
                    spec = RunSpec(
                        name,
                        "cma",
                        start="random",
                        start_index=k,
                        budget=3000,
                        data=DataSpec(tier),
                        surrogate="default",
                        polish_budget=40,
                    )
                t0 = time.perf_counter()
                r = identify(spec)
                ok, dev = _within(r.x, x_lm, tol)
                doc = {
                    "case": name,
                    "tier": tier,
                    "kind": kind,
                    "start_index": k,
                    "x0": r.x0,
                    "x": r.x,
                    "cost": r.cost,
                    "reached": ok,
                    "max_rel_dev": dev,
                    "n_evals": r.n_evals,
                    "forward_equivalents": r.forward_equivalents,
                    "training_runs": r.charges.get("surrogate-training", {}).get("n", 0),
                    "fe_polish_evals": (r.extra.get("polish") or {}).get("n_evals"),
                    "surrogate_evals": (r.extra.get("surrogate") or {}).get("n_evals"),
                    "surrogate_x": (r.extra.get("surrogate") or {}).get("x"),
                    "wall_s": time.perf_counter() - t0,
                    "status": r.status,
                }
                record(doc)
                print(
                    f"{name} start {k} {kind:10}: {'REACHED' if ok else 'missed '} max dev "
                    f"{100 * dev:.3g} %, cost {r.cost:.6g}, {r.n_evals} evaluations, "
                    f"{r.forward_equivalents:.1f} fe, {doc['wall_s']:.0f} s",
                    flush=True,
                )


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("what", choices=["speed", "table", "polish", "tradeoff"])
    p.add_argument("--cases", default="all")
    p.add_argument("--repeat", type=int, default=200)
    p.add_argument("--rounds", type=int, default=3, help="speed: alternating rounds (median)")
    p.add_argument("--starts", type=int, default=3)
    p.add_argument("--tier", default="consistent", choices=["consistent", "model-error"])
    p.add_argument("--tol", type=float, default=1e-3)
    p.add_argument("--out", default=None)
    p.add_argument("--json", default=None, help="speed, tradeoff: write the rows as JSON")
    a = p.parse_args(argv)
    cases = _cases(a.cases)
    if a.what == "speed":
        rows = speed(cases, a.repeat, a.rounds)
        if a.json:
            Path(a.json).write_text(json.dumps(rows, indent=1))
    elif a.what == "table":
        print(speed_table(json.loads(Path(a.json).read_text())))
    elif a.what == "tradeoff":
        rows = tradeoff(cases, a.repeat)
        if a.json:
            Path(a.json).write_text(json.dumps(rows, indent=1))
    else:
        from bench.paths import results_root

        out = Path(a.out) if a.out else results_root() / "surrogates" / "polish_vs_lm.jsonl"
        polish(cases, a.starts, a.tier, out, a.tol)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Certified nonlinear regression (NIST StRD): femubench's least-squares methods against scipy's
MINPACK wrapper called directly, same budget, 27 problems x 2 starts (not a test).

    python -m bench.perf.nist [--budget 2000] [--methods lm,trf,lm-minpack,gauss-newton]
                              [--out results/perf/nist.jsonl] [--problems Misra1a,MGH09]

Every run starts at NIST's start 1 or 2 (``problems.benchmarks.nist``: unbounded, unscaled,
sigma 1) with the same budget of evaluations, every call counted (finite-difference columns
included). The direct reference is ``scipy.optimize.least_squares(fun, b0, method='lm',
max_nfev=budget)`` with scipy's defaults (finite differences inside MINPACK), its calls counted
by a wrapper that stops it at the budget; its answer is the best point of its first ``budget``
calls. Correct digits are NIST's log relative error, the smallest over the parameters
(``problems.user.correct_digits``).

Printed: per method, the number of problem/start pairs with >= 4 correct digits (and >= 2,
median evaluations of those runs), side by side with MINPACK's; and every femubench run that
reports ``converged`` with fewer than 2 correct digits (the target is none). One line per run
goes to ``--out`` (JSON lines, appended): a rerun skips the runs already there (resumable).
The methods that need a finite box (multistart-lm, pso+lm) are refused on these unbounded
problems, and say so.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from problems.benchmarks import nist
from problems.inverse.evaluator import Evaluator
from problems.user import correct_digits
from solvers import solve

METHODS = ("lm", "trf", "lm-minpack", "gauss-newton")
DIRECT = "minpack-direct"


class _Stop(Exception):
    pass


def run_direct(name: str, start: int, budget: int) -> dict:
    """scipy least_squares(method='lm') called directly on ``name`` from NIST's ``start``."""
    from scipy.optimize import least_squares

    curve, y = nist.Curve(name), nist.response(name)
    calls, best = [0], [math.inf, None]

    def fun(b):
        if calls[0] >= budget:
            raise _Stop
        calls[0] += 1
        r = y - curve(b)
        c = float(r @ r)
        if math.isfinite(c) and c < best[0]:
            best[:] = [c, np.array(b, float)]
        return r

    status, message = None, ""
    try:
        res = least_squares(fun, nist.start(name, start), method="lm", max_nfev=budget)
        status, message = int(res.status), str(res.message)
    except _Stop:
        message = "budget"
    except Exception as exc:  # noqa: BLE001 - a failed library run is data
        message = f"{type(exc).__name__}: {exc}"
    x = best[1]
    if status is None:
        verdict = "budget" if message == "budget" else "failed"
    else:  # MINPACK's own word (scipy: status > 0 is a tolerance met)
        verdict = "converged" if status > 0 else "budget"
    return {
        "status": verdict,
        "message": message,
        "n_evals": calls[0],
        "cost": best[0],
        "digits": correct_digits(x, nist.certified(name)) if x is not None else 0.0,
    }


def run_method(method: str, name: str, start: int, budget: int) -> dict:
    """femubench's ``method`` on ``name`` from NIST's ``start``."""
    ev = Evaluator(nist.problem(name, start))
    try:
        res = solve(ev, method, budget=budget, seed=0, x0=nist.start(name, start))
    except ValueError as exc:  # refused (a method that needs a finite box)
        return {"status": "refused", "message": str(exc), "n_evals": 0, "cost": math.inf,
                "digits": 0.0}  # fmt: skip
    return {
        "status": res.status,
        "message": res.message,
        "n_evals": res.n_evals,
        "n_repeats": res.n_repeats,
        "cost": res.cost,
        "digits": correct_digits(np.array(res.x), nist.certified(name)),
    }


def _done(path: Path) -> dict:
    out = {}
    if path.exists():
        for line in path.read_text().splitlines():
            try:
                row = json.loads(line)
            except json.JSONDecodeError:
                continue  # a torn last line (interrupted): rerun it
            out[(row["method"], row["problem"], row["start"], row["budget"])] = row
    return out


def _append(path: Path, row: dict) -> None:
    with open(path, "a") as fh:  # one line per run; a torn line is rerun (see _done)
        fh.write(json.dumps(row) + "\n")
        fh.flush()
        os.fsync(fh.fileno())


def summarise(rows: list[dict], methods, budget: int) -> str:
    lines = [
        f"NIST StRD: {len(nist.NAMES)} problems x 2 starts, budget {budget} evaluations per run "
        "(every call counted)",
        "",
        f"{'method':16} {'>=4 digits':>10} {'>=2 digits':>10} {'converged':>9} "
        f"{'conv <2 dig':>11} {'median evals (>=4)':>18}",
    ]
    bad = []
    for m in (*methods, DIRECT):
        rs = [r for r in rows if r["method"] == m and r["budget"] == budget]
        if not rs:
            continue
        ok4 = [r for r in rs if r["digits"] >= 4]
        ok2 = [r for r in rs if r["digits"] >= 2]
        conv = [r for r in rs if r["status"] == "converged"]
        wrong = [r for r in conv if r["digits"] < 2]
        if m != DIRECT:
            bad += wrong
        med = statistics.median(r["n_evals"] for r in ok4) if ok4 else math.nan
        lines.append(
            f"{m:16} {len(ok4):>6}/{len(rs):<3} {len(ok2):>6}/{len(rs):<3} {len(conv):>9} "
            f"{len(wrong):>11} {med:>18.0f}"
        )
    lines.append("")
    named = [f"{r['method']} {r['problem']} s{r['start']} ({r['digits']:.1f})" for r in bad]
    lines.append(
        "femubench runs reporting converged with < 2 correct digits: "
        + (", ".join(named) or "none")
    )
    lines.append("")
    lines.append("per problem/start: correct digits (status: c converged, s stalled, b budget, "
                 "m max_iterations, f failed, r refused)")  # fmt: skip
    head = f"{'problem':10} s " + " ".join(f"{m[:12]:>14}" for m in (*methods, DIRECT))
    lines.append(head)
    table = {(r["method"], r["problem"], r["start"]): r for r in rows if r["budget"] == budget}
    for name in nist.NAMES:
        for s in (1, 2):
            cells = []
            for m in (*methods, DIRECT):
                r = table.get((m, name, s))
                cells.append(
                    ""
                    if r is None
                    else f"{r['digits']:5.1f} {r['status'][0]} {r['n_evals']:>6}"
                )
            lines.append(f"{name:10} {s} " + " ".join(f"{c:>14}" for c in cells))
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--budget", type=int, default=2000)
    ap.add_argument("--methods", default=",".join(METHODS))
    ap.add_argument("--problems", default=",".join(nist.NAMES))
    ap.add_argument("--out", type=Path, default=Path("results/perf/nist.jsonl"))
    args = ap.parse_args(argv)
    methods = [m for m in args.methods.split(",") if m]
    names = [n for n in args.problems.split(",") if n]
    for n in names:
        nist.record(n)  # unknown names: one line, exit 2 (ValueError below)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    done = _done(args.out)
    warnings.simplefilter("ignore")
    for name in names:
        for start in (1, 2):
            for m in (*methods, DIRECT):
                key = (m, name, start, args.budget)
                if key in done:
                    continue
                t0 = time.perf_counter()
                out = (
                    run_direct(name, start, args.budget)
                    if m == DIRECT
                    else run_method(m, name, start, args.budget)
                )
                row = {"method": m, "problem": name, "start": start, "budget": args.budget,
                       **out, "wall_s": time.perf_counter() - t0}  # fmt: skip
                _append(args.out, row)
                done[key] = row
                print(f"{m:14} {name:10} s{start} digits {out['digits']:5.2f} {out['status']:10} "
                      f"evals {out['n_evals']}", file=sys.stderr, flush=True)  # fmt: skip
    print(summarise(list(done.values()), methods, args.budget))
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(2)

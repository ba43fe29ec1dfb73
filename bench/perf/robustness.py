"""Robustness of the forward model over the whole box (a benchmark, not a test).

    python -m bench.perf.robustness [--mesh coarse] [--points 200] [--cases all] [--seed 0]
    [--out FILE] [--rerun-failed]

For each case, ``--points`` seeded Latin-hypercube points in the bounds; the infeasible ones (not a
well-posed material) are skipped and counted; every feasible point runs the FE model (10 snapshots
to 1.5 mm). Prints per case: feasible points, failures (with their messages), cuts, Newton
iterations and wall time; appends one JSON line per point to ``--out`` (resumable: points already
in the file are not rerun; the last line of a point counts, so ``--rerun-failed`` reruns the
failed ones and appends their new records).

A failure is counted apart (column ``exhaust``) when the model itself has no solution: the
material's strength is exhausted (the FE message says "strength exhausted": negative plastic work
under confinement lowers sigma_bar to 0 at some point, see ``docs/drucker_prager.md`` section 5);
the others are numerical failures of the solver.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

#: the FE message of a run that stopped because the material's strength is exhausted
EXHAUSTED = "strength exhausted"


def main(argv=None) -> None:
    from problems.inverse.cases import CASES
    from problems.inverse.forward import FEForwardModel

    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--mesh", default="coarse")
    ap.add_argument("--points", type=int, default=200)
    ap.add_argument("--cases", default="all")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--out", type=Path, default=None, help="JSON-lines file of the points (resumable)"
    )
    ap.add_argument(
        "--rerun-failed", action="store_true", help="rerun the points recorded as failed in --out"
    )
    args = ap.parse_args(argv)
    names = list(CASES) if args.cases == "all" else args.cases.split(",")
    done = {}
    if args.out and args.out.exists():
        for line in args.out.read_text().splitlines():
            try:
                rec = json.loads(line)
            except json.JSONDecodeError:
                continue  # a torn last line: that point is rerun
            if args.rerun_failed and rec.get("converged") is False:
                done.pop((rec["case"], rec["index"]), None)
            else:
                done[(rec["case"], rec["index"])] = rec
    print(
        f"{'case':24} {'feasible':>8} {'failed':>6} {'exhaust':>7} {'cuts':>5} {'iters/run':>9} "
        f"{'s/run':>7}"
    )
    total_failed = total_exhausted = 0
    for name in names:
        case = CASES[name]
        model = FEForwardModel(case, args.mesh)
        X = case.random_starts(args.points, seed=args.seed)
        recs = []
        for i, x in enumerate(X):
            rec = done.get((name, i))
            if rec is None:
                why = model.check(x)
                rec = {"case": name, "index": i, "x": x.tolist(), "feasible": why is None}
                if why is None:
                    t = time.perf_counter()
                    r = model.response(x)
                    rec |= {
                        "converged": bool(r.converged),
                        "message": r.message,
                        "cuts": r.cuts,
                        "iterations": r.iterations,
                        "wall_s": time.perf_counter() - t,
                    }
                if args.out:
                    with args.out.open("a") as fh:
                        fh.write(json.dumps(rec) + "\n")
            recs.append(rec)
        feas = [r for r in recs if r["feasible"]]
        failed = [r for r in feas if not r["converged"]]
        exhausted = [r for r in failed if EXHAUSTED in r["message"]]
        total_failed += len(failed)
        total_exhausted += len(exhausted)
        print(
            f"{name:24} {len(feas):8d} {len(failed):6d} {len(exhausted):7d} "
            f"{sum(r['cuts'] for r in feas):5d} "
            f"{np.mean([r['iterations'] for r in feas]):9.1f} "
            f"{np.mean([r['wall_s'] for r in feas]):7.2f}",
            flush=True,
        )
        for r in failed:
            print(f"    failed at x = {np.round(r['x'], 5).tolist()}: {r['message']}")
    print(
        f"mesh {args.mesh}: {total_failed} failures in all: {total_failed - total_exhausted} "
        f"numerical, {total_exhausted} where the model has no solution (strength exhausted)"
    )


if __name__ == "__main__":
    main()

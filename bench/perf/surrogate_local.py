"""Local hold-out of the default surrogates (not a test): ``n`` fresh FE runs (LHS, seed stream
``[0, 3]``) in the enrichment box around the data's own surrogate optimum (where identifications
and posteriors live), their error in units of sigma, and the surrogate's Jacobian against the FE
model's exact one at the box centre (relative error of each sigma-scaled column); appended to
``results/surrogates/local_holdout.json`` ({case: {...}}).

    OMP_NUM_THREADS=1 python -m bench.perf.surrogate_local [CASE ...] [--points 20]
"""

from __future__ import annotations

import argparse
import json

import numpy as np


def local_holdout(case: str, n: int) -> dict:
    from bench.experiment.surrogate_track import load_for
    from problems.inverse.data import get_data
    from problems.inverse.forward import FEForwardModel
    from problems.surrogate.design import make_design
    from problems.surrogate.training import run_points

    sur = load_for("default", case, "coarse")
    lo, hi = (np.array(b) for b in sur.info["enrichment"]["local_box"])
    design = make_design(lo, hi, n, seed=[0, 3], method="lhs")
    data = get_data(case)
    fe = FEForwardModel(sur.checker.case, "coarse", data.settings.loading, data.points)
    runs = run_points(fe, design.X)
    E = (sur.predict(runs.X) - runs.Y) / sur.pod.scale
    f, u = E[:, -len(data.snapshots_mm) :], E[:, : -len(data.snapshots_mm)]
    # the surrogate's Jacobian against the FE model's exact one at the enrichment centre
    centre = np.array(sur.info["enrichment"]["centre"])
    J_fe = fe(centre, jacobian=True).jacobian / sur.pod.scale[:, None]
    J_s = sur(centre, jacobian=True).jacobian / sur.pod.scale[:, None]
    jac_err = np.linalg.norm(J_s - J_fe, axis=0) / np.linalg.norm(J_fe, axis=0)
    return {
        "jacobian_relative_error": dict(zip(sur.names, map(float, jac_err))),
        "n_points": runs.n_ok,
        "n_failed": runs.n_failed,
        "local_box": [lo.tolist(), hi.tolist()],
        "force_rms_sigma": float(np.sqrt(np.mean(f**2))),
        "force_max_sigma": float(np.max(np.abs(f))),
        "displacement_rms_sigma": float(np.sqrt(np.mean(u**2))),
        "displacement_max_sigma": float(np.max(np.abs(u))),
        "surrogate_hash": sur.hash,
    }


def main(argv=None) -> int:
    from bench.paths import results_root
    from problems.inverse.cases import CASES

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("cases", nargs="*")
    p.add_argument("--points", type=int, default=20)
    a = p.parse_args(argv)
    cases = a.cases or [n for n, c in CASES.items() if not c.is_analytic]
    out = results_root() / "surrogates" / "local_holdout.json"
    doc = json.loads(out.read_text()) if out.exists() else {}
    for case in cases:
        doc[case] = local_holdout(case, a.points)
        r = doc[case]
        print(
            f"{case:24} local hold-out {r['n_points']} points: force RMS {r['force_rms_sigma']:.3f}"
            f" sigma (max {r['force_max_sigma']:.2f}), displacement RMS "
            f"{r['displacement_rms_sigma']:.3f} sigma (max {r['displacement_max_sigma']:.2f}); "
            "Jacobian vs FE: "
            + ", ".join(f"{k} {v:.2g}" for k, v in r["jacobian_relative_error"].items()),
            flush=True,
        )
        out.write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

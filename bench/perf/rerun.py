"""Rerun a seeded sample of shipped records from their stored configurations and compare the
answers (a benchmark of reproducibility, not a test): same status, the largest relative difference
of the parameters ``x``, of the surrogate's own optimum before an FE polish, and the difference in
evaluations.

    OMP_NUM_THREADS=1 python -m bench.perf.rerun results/comparison --where track=surrogate \\
        [--per-method 2] [--seed 0] [--json FILE]

``--where key=value`` (repeatable) selects records by their configuration; ``--per-method`` records
of each method are drawn with ``--seed``. Nothing is written to the results folder.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np


def _rel(a, b) -> float | None:
    if a is None or b is None:
        return None
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.max(np.abs(a - b) / np.maximum(np.abs(b), 1e-300)))


def _value(text: str):
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text


def sample(folder: Path, where: dict, per_method: int, seed: int) -> list[dict]:
    """Records of ``folder`` whose configuration matches ``where``, ``per_method`` of each method
    drawn with ``seed`` (sorted by file name first: the same draw on every machine)."""
    groups: dict[str, list[dict]] = {}
    for path in sorted((folder / "runs").glob("*.json")):
        rec = json.loads(path.read_text())
        if all(rec["config"].get(k) == v for k, v in where.items()) and not rec.get("error"):
            groups.setdefault(rec["config"]["method"], []).append(rec)
    rng = np.random.default_rng(seed)
    out = []
    for method in sorted(groups):
        recs = groups[method]
        for i in sorted(rng.choice(len(recs), min(per_method, len(recs)), replace=False)):
            out.append(recs[i])
    return out


def compare(rec: dict) -> dict:
    from bench.experiment.runner import run_one

    t0 = time.perf_counter()
    again = run_one(rec["config"], suite=rec.get("suite"))
    old, new = rec["result"], again["result"]
    surrogate = (old.get("extra") or {}).get("surrogate") or {}
    surrogate_new = (new.get("extra") or {}).get("surrogate") or {}
    return {
        "config_hash": rec["config_hash"],
        "case": rec["config"]["case"],
        "method": rec["config"]["method"],
        "seed": rec["config"].get("seed"),
        "same_status": new["status"] == old["status"],
        "bit_for_bit": new["x"] == old["x"],
        "x_rel": _rel(new["x"], old["x"]),
        "surrogate_x_rel": _rel(surrogate_new.get("x"), surrogate.get("x")),
        "n_evals": (old["n_evals"], new["n_evals"]),
        "wall_s": (old.get("wall_s"), new.get("wall_s")),
        "rerun_s": time.perf_counter() - t0,
        "same_arch": rec.get("machine", {}).get("arch") == again["machine"].get("arch"),
    }


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("folder")
    p.add_argument("--where", action="append", default=[], metavar="KEY=VALUE")
    p.add_argument("--per-method", type=int, default=2)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json", default=None)
    a = p.parse_args(argv)
    where = dict((k, _value(v)) for k, v in (w.split("=", 1) for w in a.where))
    rows = []
    for rec in sample(Path(a.folder), where, a.per_method, a.seed):
        row = compare(rec)
        rows.append(row)
        sx = row["surrogate_x_rel"]
        print(
            f"{row['case']:24} {row['method']:13} seed {row['seed']}: status "
            f"{'same' if row['same_status'] else 'DIFFERS'}, x {row['x_rel']:.2g}"
            + ("" if sx is None else f", surrogate's own x {sx:.2g}")
            + f", evaluations {row['n_evals'][0]} -> {row['n_evals'][1]}, wall "
            f"{row['wall_s'][0]:.1f} -> {row['wall_s'][1]:.1f} s",
            flush=True,
        )
    if rows:
        xs = [r["x_rel"] for r in rows]
        print(
            f"{len(rows)} runs: same status {sum(r['same_status'] for r in rows)}, bit for bit "
            f"{sum(r['bit_for_bit'] for r in rows)}, largest relative difference of x "
            f"{max(xs):.2g} (median {float(np.median(xs)):.2g})"
        )
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

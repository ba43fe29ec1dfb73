"""An identification on a stored surrogate, optionally polished on the FE model: loading the
surrogate by name and the honest accounting of the combined run (see docs/surrogate.md, "Identifying
on a surrogate").

Accounting of the returned :class:`~solvers.result.RunResult`:

* ``n_evals`` = surrogate evaluations + FE polish evaluations (both counted, cache hits apart);
* ``forward_equivalents`` = the surrogate evaluations' wall time over the median FE run time of
  the surrogate's own validation (``fe_eval_s``: tiny, e.g. 1e-4 per evaluation) + the polish's
  FE forward-equivalents;
* ``charges["surrogate-training"]`` = the FE runs that built the surrogate (training, enrichment
  and hold-out: ``n``, their FE ``wall_s``, ``forward_equivalents = n``), charged in full to every
  identification; ``extra["surrogate"]["amortised_forward_equivalents"]`` is the run's cost when
  the training is shared by many identifications (the training left out);
* a model-error correction's runs are charged once.
"""

from __future__ import annotations

from dataclasses import replace

#: the name that stands for the shipped surrogate of (case, mesh)
DEFAULT = "default"


def surrogate_root():
    """Root folder of named surrogates: ``$FEMUBENCH_SURROGATE_DIR``, else
    ``<results root>/surrogates``; not created."""
    from bench.paths import results_root
    from problems.surrogate.store import default_root

    return default_root() or results_root() / "surrogates"


def surrogate_folder(key: str):
    """The folder of the stored surrogate named ``key``: ``$FEMUBENCH_SURROGATE_DIR/<key>`` when
    that is set, else ``surrogates/<key>`` in the results root or the artefact directory
    (:func:`bench.artefacts.locate`, checked against the release manifest); None when absent."""
    from bench import artefacts
    from problems.surrogate.store import default_root

    env = default_root()
    if env is not None:
        return env / key if (env / key).is_dir() else None
    return artefacts.locate(f"surrogates/{key}")


def missing_default(case: str, mesh: str) -> str:
    """One line: the default surrogate of ``case`` on ``mesh`` is missing, and how to get it."""
    from bench import artefacts
    from problems.surrogate.store import default_name, default_root

    rel = f"surrogates/{default_name(case, mesh)}"
    what = f"no default surrogate of {case} on mesh {mesh}"
    if default_root() is None and artefacts.listed(rel):
        return f"{what}: {artefacts.missing(rel)}"
    build = f"femubench surrogate {case} --mesh {mesh}"
    return f"{what} in {surrogate_root()} (build it with `{build}`)"


def load_for(name: str, case: str, mesh: str):
    """The stored surrogate ``name`` (a path, a name under the surrogate root, or ``default`` =
    ``<case>__<mesh>`` there; names are found by :func:`surrogate_folder`), checked to be a
    surrogate of ``case``."""
    from pathlib import Path

    from problems.surrogate.store import default_name, load

    key = default_name(case, mesh) if name == DEFAULT else name
    folder = Path(key).expanduser() if name != DEFAULT else None
    if folder is None or not folder.exists():
        folder = surrogate_folder(key)
    if folder is None:
        if name == DEFAULT:
            raise FileNotFoundError(missing_default(case, mesh))
        raise FileNotFoundError(
            f"surrogate {name!r} is neither a folder or file nor in {surrogate_root()}"
        )
    sur = load(folder)
    got = (sur.info.get("description") or {}).get("case")
    if got is not None and got != case:
        raise ValueError(f"surrogate {name!r} is of case {got!r}, not {case!r}")
    sur.info["path"] = str(folder)
    return sur


def fe_unit_s(sur) -> float:
    """Median FE run time measured when the surrogate was built, s (its forward-equivalent)."""
    val = sur.info.get("validation") or {}
    unit = val.get("fe_eval_s") or (sur.info.get("cost") or {}).get("training", {}).get(
        "median_run_s"
    )
    return float(unit) if unit else float("nan")


def training_charge(sur) -> dict:
    """``{"n", "wall_s", "forward_equivalents"}`` of the FE runs that built the surrogate."""
    cost = sur.info.get("cost") or {}
    parts = [cost.get("training") or {}, cost.get("holdout") or {}]
    n = sum(int(p.get("n_runs", 0)) for p in parts)
    wall = sum(float(p.get("fe_wall_s", 0.0)) for p in parts)
    return {"n": n, "wall_s": wall, "forward_equivalents": float(n)}


def nominal_equivalents(sur, log) -> float:
    """Deterministic forward-equivalents of surrogate evaluations (log entries): each plain
    evaluation priced at the surrogate's stored median evaluation time over the FE run time of
    its validation, each one with a Jacobian at its stored Jacobian time over that."""
    val = sur.info.get("validation") or {}
    unit = val.get("fe_eval_s")
    if not unit:
        return float(len(log))
    plain = float(val.get("surrogate_eval_s") or 0.0) / unit
    jac = float(val.get("surrogate_jacobian_s") or val.get("surrogate_eval_s") or 0.0) / unit
    return sum(jac if e.get("kind") == "jacobian" else plain for e in log)


def combine(result, objectives, sur, name, polished=None, *, polish_charges_repeat=False):
    """The RunResult of an identification on ``sur`` (``result``, its evaluators
    ``objectives``), followed by the FE polish ``polished`` (or None); see the module docstring."""
    unit = fe_unit_s(sur)
    new = [e for obj in objectives for e in obj.log if not e["cached"]]
    sur_wall = sum(float(e["wall_s"]) for e in new)
    sur_fe = sur_wall / unit if unit == unit and unit > 0 else float(len(new))
    sur_nominal = nominal_equivalents(sur, new)
    train = training_charge(sur)
    # the surrogate-phase evaluator priced its charges in surrogate evaluations: reprice them in
    # FE runs (their wall time over the FE run time of the surrogate's validation)
    charges = {
        k: {**v, "forward_equivalents": v["wall_s"] / unit if unit == unit and unit > 0 else v["n"]}
        for k, v in result.charges.items()
    }
    if polished is not None and not polish_charges_repeat:
        for kind, c in polished.charges.items():
            total = charges.setdefault(kind, {"n": 0, "wall_s": 0.0, "forward_equivalents": 0.0})
            for key in total:
                total[key] += c.get(key, 0.0)
    charges["surrogate-training"] = train
    surrogate_info = {
        "name": name,
        "path": sur.info.get("path"),
        "hash": sur.hash,
        "training_hash": sur.info.get("training_hash"),
        "n_evals": result.n_evals,
        "wall_s": result.wall_s,
        "model_wall_s": sur_wall,
        "forward_equivalents": sur_fe,
        "forward_equivalents_nominal": sur_nominal,
        "fe_unit_s": unit,
        "x": result.x,
        "cost": result.cost,
        "status": result.status,
        "message": result.message,
        "training_runs": train["n"],
        "holdout": {
            k: (v or {}).get("rms_sigma")
            for k, v in ((sur.info.get("validation") or {}).get("blocks") or {}).items()
        },
    }
    prov = {
        **result.provenance,
        "forward": "surrogate",
        "surrogate": name,
        "surrogate_hash": sur.hash,
        "surrogate_training_hash": sur.info.get("training_hash"),
        "surrogate_mesh": (sur.info.get("description") or {}).get("mesh"),
        "polish": polished is not None,
    }
    if polished is None:
        surrogate_info["amortised_forward_equivalents"] = sur_fe + sum(
            c["forward_equivalents"] for k, c in charges.items() if k != "surrogate-training"
        )
        return replace(
            result,
            forward_equivalents=sur_fe,
            forward_equivalents_nominal=sur_nominal,
            charges=charges,
            provenance=prov,
            message=f"on the surrogate: {result.message}",
            extra={**result.extra, "surrogate": surrogate_info},
        )
    p = polished
    surrogate_info["amortised_forward_equivalents"] = (
        sur_fe
        + p.forward_equivalents
        + sum(c["forward_equivalents"] for k, c in charges.items() if k != "surrogate-training")
    )
    history = [{**row, "phase": "surrogate"} for row in result.history] + [
        {**row, "phase": "polish", "n_evals": row.get("n_evals", 0) + result.n_evals}
        for row in p.history
    ]
    polish_info = {
        "method": p.method,
        "budget": p.budget,
        "n_evals": p.n_evals,
        "forward_equivalents": p.forward_equivalents,
        "wall_s": p.wall_s,
        "x0": p.x0,
        "x": p.x,
        "cost": p.cost,
        "status": p.status,
        "message": p.message,
    }
    prov.update(
        {
            k: v
            for k, v in p.provenance.items()
            if k not in ("forward", "surrogate_hash")  # the polish's data side is the same
        }
    )
    prov.update({"forward": "surrogate+fe-polish", "polish_method": p.method})
    return replace(
        result,
        budget=result.budget + p.budget,
        x=p.x,
        x_normalised=p.x_normalised,
        cost=p.cost,
        status=p.status,
        success=p.success,
        message=f"surrogate: {result.message}; FE polish: {p.message}",
        n_evals=result.n_evals + p.n_evals,
        n_failed=result.n_failed + p.n_failed,
        n_infeasible=result.n_infeasible + p.n_infeasible,
        n_cache_hits=result.n_cache_hits + p.n_cache_hits,
        n_iterations=result.n_iterations + p.n_iterations,
        wall_s=result.wall_s + p.wall_s,
        forward_equivalents=sur_fe + p.forward_equivalents,
        forward_equivalents_nominal=sur_nominal + p.forward_equivalents_nominal,
        charges=charges,
        provenance=prov,
        history=history,
        extra={**result.extra, "surrogate": surrogate_info, "polish": polish_info},
    )

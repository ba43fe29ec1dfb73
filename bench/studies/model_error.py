"""Model-error study: how far the discretisation error pushes each case's identification, and what
each treatment buys at what cost.

For a case, every configuration ``inverse mesh x treatment x measurement region`` (and optionally
the DIC data route) gives one row:

* the *linearised bias of a perfect optimiser* at the reference, ``dz = -(J^T J)^-1 J^T r`` with
  ``J``, ``r`` the Jacobian and the whitened residual of the (treated) objective at the reference
  (in %, per parameter);
* the *LM result* from the default start: the parameter errors (%) and its cost in evaluations and
  forward-equivalents, charges (high-fidelity runs, BAE statistics) included.

:func:`run_model_error` writes one JSON file per configuration into the output folder as soon as
it is done (an interrupted study resumes where it stopped; a torn file is recomputed) and a
``summary.csv``; :func:`render_model_error` draws ``bias_vs_cost.png`` from the files alone.
"""

from __future__ import annotations

import itertools
import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from bench.studies import output_dir, write_csv
from problems.io import jsonio

TREATMENT_ORDER = ("none", "one-point", "iterated", "first-order", "bae")
#: a diagnostic, bias-only: the one-point correction made *at the reference* (not available in
#: practice). Its bias is what the high-fidelity model's own error against the data leaves: the
#: floor of every correction made with that high-fidelity mesh.
HIFI_LIMIT = "hifi-at-reference"


@dataclass(frozen=True)
class Configuration:
    """One row of the study."""

    mesh: str
    treatment: str
    plate_margin_mm: float
    route: str = "fe"
    bias_only: bool = False  # the linearised bias alone, no LM (for expensive inverse meshes)

    @property
    def key(self) -> str:
        key = f"{self.mesh}__{self.treatment}__margin{self.plate_margin_mm:g}__{self.route}"
        return key + ("__bias" if self.bias_only else "")


@dataclass
class ModelErrorRun:
    """What :func:`run_model_error` computed (rows) and where it wrote them."""

    case: str
    rows: list[dict] = field(default_factory=list)
    dir: Path | None = None


def linearised_bias(objective) -> dict[str, float]:
    """``-(J^T J)^-1 J^T r`` at the reference (z = 1) in % per parameter
    (one Jacobian, one residual)."""
    z = np.ones(objective.n_params)
    r = objective.residual(z)
    J = objective.jacobian(z, scheme="central", rel_step=1e-4)
    dz = -np.linalg.lstsq(J, r, rcond=None)[0]
    return {n: 100.0 * float(v) for n, v in zip(objective.names, dz)}


def one_row(
    case: str, cfg: Configuration, *, budget: int, mapper=None, data=None, hifi_mesh=None
) -> dict:
    """LM from the default start and the linearised bias for one configuration.

    ``data``: the model-error data set (default: the shipped one, or the DIC route's);
    ``hifi_mesh``:
    the correction's high-fidelity mesh (default: the next finer preset of the inverse mesh)."""
    from bench.experiment.identify import identify
    from bench.experiment.objective import prepare
    from bench.experiment.spec import RunSpec, Treatment
    from problems.inverse.build import hifi_mesh_for, resolve_data
    from problems.inverse.cases import get_case
    from problems.inverse.data import get_data, tier_settings

    t0 = time.perf_counter()
    c = get_case(case)
    if data is None:
        settings = tier_settings("model-error", route=cfg.route)
        data = (
            get_data(case, settings, progress=True)
            if cfg.route != "fe"
            else resolve_data(c, cfg.mesh, "model-error", None)
        )
    hifi_mesh = hifi_mesh or (hifi_mesh_for(cfg.mesh) if cfg.treatment != "none" else None)
    if cfg.treatment == HIFI_LIMIT and not cfg.bias_only:
        raise ValueError(f"treatment {HIFI_LIMIT!r} is a diagnostic of the bias alone: --bias-only")
    spec = RunSpec(
        case,
        "lm",
        budget=budget,
        mesh=cfg.mesh,
        treatment=Treatment(
            "one-point" if cfg.treatment == HIFI_LIMIT else cfg.treatment,
            cfg.plate_margin_mm,
            hifi_mesh=hifi_mesh,
        ),
    )
    asm = prepare(spec, mapper=mapper, dataset=data)
    if cfg.bias_only:
        return _bias_row(case, cfg, asm, t0)
    result = identify(spec, mapper=mapper, dataset=data)
    # the linearised bias of the correction the solver ended with: at the start (one-point), at
    # the LM solution (iterated and first-order, the fixed point), or the BAE statistics
    if cfg.treatment == "one-point":
        correction = asm.one_point(c.start)
    elif cfg.treatment == "iterated":
        correction = asm.one_point(np.asarray(result.x))
    elif cfg.treatment == "first-order":
        correction = asm.first_order(np.asarray(result.x))
    else:
        correction = asm.correction()
    objective = asm.objective(correction)
    bias = linearised_bias(objective)
    errors = result.errors_percent()
    total_fe = result.forward_equivalents + sum(
        ch["forward_equivalents"] for ch in result.charges.values()
    )
    return {
        "case": case,
        "mesh": cfg.mesh,
        "treatment": cfg.treatment,
        "plate_margin_mm": cfg.plate_margin_mm,
        "route": cfg.route,
        "lm_error_percent": errors,
        "linearised_bias_percent": bias,
        "max_abs_error_percent": max(abs(v) for v in errors.values()),
        "n_evals": result.n_evals,
        "forward_equivalents": result.forward_equivalents,
        "charges": result.charges,
        "total_forward_equivalents": total_fe,
        "status": result.status,
        "iterations": result.n_iterations,
        "x": result.x,
        "provenance": result.provenance,
        "wall_s": time.perf_counter() - t0,
    }


def _bias_row(case: str, cfg: Configuration, asm, t0: float) -> dict:
    """The linearised perfect-optimiser bias alone (one residual and one Jacobian: one run with
    sensitivities on the FE model, plus the correction's runs) of the assembly ``asm``; the
    one-point correction is made at the default start (at the reference for :data:`HIFI_LIMIT`),
    ``iterated`` and ``first-order`` need the LM solution and are refused."""
    from problems.inverse.model_error import ITERATED

    if cfg.treatment in ITERATED:
        raise ValueError(
            f"a bias-only row of treatment {cfg.treatment!r} needs the LM solution: run LM"
        )
    if cfg.treatment == HIFI_LIMIT:
        corr = asm.one_point(asm.case.reference)
        corr.treatment = HIFI_LIMIT
        objective = asm.objective(corr)
    else:
        objective = asm.treated()
    bias = linearised_bias(objective)
    charged = objective.charged_equivalents()
    charges = {k: {**c, "forward_equivalents": charged[k]} for k, c in objective.charges.items()}
    fe = objective.forward_equivalents()
    return {
        "case": case,
        "mesh": cfg.mesh,
        "treatment": cfg.treatment,
        "plate_margin_mm": cfg.plate_margin_mm,
        "route": cfg.route,
        "bias_only": True,
        "lm_error_percent": {},
        "linearised_bias_percent": bias,
        "max_abs_error_percent": float("nan"),
        "max_abs_bias_percent": max(abs(v) for v in bias.values()),
        "n_evals": objective.n_evals,
        "forward_equivalents": fe,
        "charges": charges,
        "total_forward_equivalents": fe + sum(charged.values()),
        "status": "bias only",
        "iterations": 0,
        "x": None,
        "provenance": objective.provenance,
        "wall_s": time.perf_counter() - t0,
    }


#: the DIC-route rows (on the first inverse mesh): no treatment on the full face, and the default
#: treatment (:func:`problems.inverse.cases.default_treatment`: BAE, 30 mm plate margin)
DIC_ROWS = (("none", 0.0), ("bae", 30.0))


def configurations(
    meshes, treatments, margins, dic: bool, bias_only: bool = False
) -> list[Configuration]:
    """The study's grid (``bias_only``: rows of the linearised bias alone), and with ``dic`` the
    DIC-route rows of :data:`DIC_ROWS` whose treatment is asked for."""
    grid = [
        Configuration(m, t, float(g), bias_only=bias_only)
        for m, t, g in itertools.product(meshes, treatments, margins)
    ]
    if dic:
        grid += [Configuration(meshes[0], t, g, "dic") for t, g in DIC_ROWS if t in treatments]
    return grid


def run_model_error(
    case: str,
    *,
    meshes=("coarse",),
    treatments=TREATMENT_ORDER,
    margins=(0.0, 30.0),
    dic: bool = False,
    bias_only: bool = False,
    budget: int = 200,
    mapper=None,
    out=None,
    progress=None,
    data=None,
    hifi_mesh: str | None = None,
) -> ModelErrorRun:
    """Compute (or resume) the study of ``case``; one ``<key>.json`` per configuration, then
    ``summary.csv``.
    ``data`` and ``hifi_mesh`` override the shipped model-error data and the default high-fidelity
    mesh."""
    d = output_dir("model_error", case, out)
    run = ModelErrorRun(case, dir=d)
    for cfg in configurations(meshes, treatments, margins, dic, bias_only):
        path = d / f"{cfg.key}.json"
        row = None
        if path.exists():
            try:
                row = jsonio.loads(path.read_text())
            except ValueError:
                # torn: recompute, keep it for inspection
                path.rename(path.with_suffix(".json.corrupt"))
            if (
                row is not None
                and cfg.route == "fe"
                and row["provenance"].get("data_hash") != _data_hash(case, cfg.mesh, data)
            ):
                row = None  # made with other data: stale, recompute
        if row is None:
            row = one_row(
                case,
                cfg,
                budget=budget,
                mapper=mapper,
                data=None if cfg.route == "dic" else data,
                hifi_mesh=hifi_mesh,
            )
            tmp = path.with_suffix(".json.tmp")
            tmp.write_text(jsonio.dumps(row, indent=1, sort_keys=True))
            tmp.replace(path)
            if cfg.route == "dic":
                _keep_dic_data(case, d)
        run.rows.append(row)
        if progress is not None:
            progress(cfg, row)
    write_csv(d / "summary.csv", [_flat(r) for r in run.rows])
    return run


def _keep_dic_data(case: str, folder: Path) -> None:
    """Copy the DIC-route data set (made in the data cache) beside the rows, ``dic_data.json``
    (the images stay in the cache: their settings and seed regenerate them)."""
    import shutil

    from problems.inverse.data import cached_path, tier_settings

    src = cached_path(case, tier_settings("model-error", route="dic"))
    if src.exists() and not (folder / "dic_data.json").exists():
        shutil.copyfile(src, folder / "dic_data.json")


def _data_hash(case: str, mesh: str, data) -> str:
    """Content hash of the model-error data a row of ``case`` on ``mesh`` is made with."""
    from problems.inverse.build import resolve_data
    from problems.inverse.cases import get_case

    return (
        data if data is not None else resolve_data(get_case(case), mesh, "model-error", None)
    ).hash


def _flat(row: dict) -> dict:
    out = {
        k: row[k]
        for k in (
            "case",
            "mesh",
            "treatment",
            "plate_margin_mm",
            "route",
            "n_evals",
            "forward_equivalents",
            "total_forward_equivalents",
            "max_abs_error_percent",
            "status",
            "iterations",
        )
    }
    out |= {f"err_{n}": v for n, v in row["lm_error_percent"].items()}
    out |= {f"bias_{n}": v for n, v in row["linearised_bias_percent"].items()}
    return out


def render_model_error(folder) -> Path:
    """Draw ``bias_vs_cost.png``: max |LM error| (%) against total forward-equivalents, one marker
    per treatment, filled for the full face and open with a plate margin; rewrite ``summary.csv``
    with every row in the folder (a partial run writes only its own)."""
    from bench import plotting

    folder = Path(folder)
    rows = _rows_of(folder)
    if not rows:
        raise FileNotFoundError(f"{folder}: no study files (*.json); run the study first")
    write_csv(folder / "summary.csv", [_flat(r) for r in rows])  # every row in the folder
    plt = plotting.pyplot()
    fig, ax = plt.subplots(figsize=plotting.SINGLE)
    markers = dict(zip(TREATMENT_ORDER, "osD^"))
    for r in rows:
        ax.plot(
            r["total_forward_equivalents"],
            _shown_error(r),
            _marker(r, markers),
            mfc="none" if r["plate_margin_mm"] else None,
            color="k" if r["mesh"] == "coarse" else "0.5",
            label=f"{r['mesh']}, {_label(r)}",
        )
    ax.set_xscale("log")
    ax.set_yscale("log")
    plotting.log_axis(ax, "x")
    plotting.log_axis(ax, "y")
    ax.set_xlabel("cost: forward-equivalents (identification + corrections)")
    ax.set_ylabel("max |parameter error| of LM (+: linearised bias), %")
    ax.set_title(rows[0]["case"])
    ax.legend(fontsize="x-small", ncol=1)
    return plotting.save(fig, folder / "bias_vs_cost.png")


def _rank(treatment: str) -> int:
    order = (*TREATMENT_ORDER, HIFI_LIMIT)
    return order.index(treatment) if treatment in order else len(order)


def _shown_error(row: dict) -> float:
    """The max |LM error| (%), or for a bias-only row the max |linearised bias|."""
    if row.get("bias_only"):
        return max(abs(float(v)) for v in row["linearised_bias_percent"].values())
    err = row["max_abs_error_percent"]
    return float(err) if not isinstance(err, str) else float("nan")


def _marker(row: dict, markers: dict) -> str:
    if row.get("bias_only"):
        return "+"
    return "*" if row.get("route") == "dic" else markers.get(row["treatment"], "x")


def _rows_of(folder: Path) -> list[dict]:
    return [json.loads(p.read_text()) for p in sorted(Path(folder).glob("*__*.json"))]


def _label(row: dict) -> str:
    t = {"bae": "BAE", HIFI_LIMIT: "one-point at the reference"}
    text = t.get(row["treatment"], row["treatment"])
    if row["plate_margin_mm"]:
        text += f" + {row['plate_margin_mm']:g} mm"
    text += " (DIC)" if row.get("route") == "dic" else ""
    return text + (", bias only" if row.get("bias_only") else "")


def overview_table(root) -> str:
    """A markdown table over every case folder under ``root``: per case and inverse mesh, the max
    |LM error| (%) with the worst parameter, and the total forward-equivalents of each row
    (the linearised perfect-optimiser bias in brackets)."""
    root = Path(root)
    folders = sorted(p for p in root.iterdir() if p.is_dir() and any(p.glob("*__*.json")))
    rows = [r for f in folders for r in _rows_of(f)]
    fields = ("mesh", "route", "treatment", "plate_margin_mm", "bias_only")

    def key(r):
        return tuple(bool(r.get(n)) if n == "bias_only" else r[n] for n in fields)

    order = sorted(
        {key(r) for r in rows},
        key=lambda k: (k[0] != "coarse", k[1] != "fe", k[4], _rank(k[2]), k[3]),
    )
    head = ["case", "mesh"] + [_label(dict(zip(fields, k))) for k in order]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for f in folders:
        by = {key(r): r for r in _rows_of(f)}
        for mesh in sorted({k[0] for k in by}, key=lambda m: m != "coarse"):
            cells = [f.name, mesh]
            for k in order:
                r = by.get(k) if k[0] == mesh else None
                if r is None:
                    cells.append("")
                    continue
                b = r["linearised_bias_percent"]
                bias = max(abs(v) for v in b.values())
                if r.get("bias_only"):
                    worst = max(b, key=lambda n: abs(b[n]))
                    cells.append(f"[{bias:.1f} ({worst})], {r['total_forward_equivalents']:.0f}")
                    continue
                worst = max(r["lm_error_percent"], key=lambda n: abs(r["lm_error_percent"][n]))
                cells.append(
                    f"{r['max_abs_error_percent']:.1f} % ({worst}) [{bias:.1f}], "
                    f"{r['total_forward_equivalents']:.0f}"
                )
            lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def render_overview(root) -> list[Path]:
    """``overview.md`` (:func:`overview_table`) and ``bias_vs_cost.png`` over all cases under
    ``root`` (one marker per treatment, filled without and open with a plate margin)."""
    from bench import plotting

    root = Path(root)
    folders = sorted(p for p in root.iterdir() if p.is_dir() and any(p.glob("*__*.json")))
    if not folders:
        raise FileNotFoundError(f"{root}: no study folders; run the study first")
    md = root / "overview.md"
    md.write_text(
        "# Model-error study: max |parameter error| of LM (worst parameter) [linearised "
        "perfect-optimiser bias], total forward-equivalents\n\n" + overview_table(root)
    )
    plt = plotting.pyplot()
    fig, ax = plt.subplots(figsize=plotting.DOUBLE)
    markers = dict(zip(TREATMENT_ORDER, "osD^"))
    seen = set()
    for f in folders:
        # bias-only rows are in overview.md; their cost is in runs of their own mesh
        for r in (r for r in _rows_of(f) if not r.get("bias_only")):
            key = (
                r["treatment"],
                bool(r["plate_margin_mm"]),
                r.get("route", "fe"),
                r["mesh"],
                bool(r.get("bias_only")),
            )
            label = None
            if key not in seen:
                seen.add(key)
                label = (r["mesh"] + ", " if r["mesh"] != "coarse" else "") + _label(r)
            ax.plot(
                r["total_forward_equivalents"],
                _shown_error(r),
                _marker(r, markers),
                mfc="none" if r["plate_margin_mm"] else None,
                color="k" if r["mesh"] == "coarse" else "0.5",
                label=label,
            )
    ax.axhline(2.0, **plotting.REFERENCE_LINE)
    ax.set_xscale("log")
    ax.set_yscale("log")
    plotting.log_axis(ax, "x")
    plotting.log_axis(ax, "y")
    ax.set_xlabel("cost: forward-equivalents (identification + corrections)")
    ax.set_ylabel("max |parameter error| of LM, %")
    ax.set_title(f"model-error study, {len(folders)} cases (dotted: the 2 % target)")
    handles, labels = ax.get_legend_handles_labels()
    rank = {t: i for i, t in enumerate(("none", "one-point", "iterated", "first-order", "BAE"))}
    pairs = sorted(
        zip(labels, handles),
        key=lambda p: ("DIC" in p[0], rank.get(p[0].split(" ")[0].rstrip(","), 9), p[0]),
    )
    ax.legend(
        [h for _, h in pairs],
        [lab for lab, _ in pairs],
        fontsize="x-small",
        loc="center left",
        bbox_to_anchor=(1.0, 0.5),
    )
    return [md, plotting.save(fig, root / "bias_vs_cost.png")]

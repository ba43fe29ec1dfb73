"""Mesh convergence study of one FE case: every mesh solved once at the case's reference (response
and exact Jacobian), then observed orders, Richardson extrapolation, each mesh's error in sigma
units and its linearised parameter bias (:mod:`problems.analysis.convergence`).

Meshes come in *families* (one element, one grading, refined: ``n,n,2n`` for the 8-node element,
``n/2,n/2,n`` with the same nodes for the 27-node one) and *comparison* meshes (e.g. the uniform
presets) that are judged against the extrapolation without being part of it.

Files, in ``results/studies/convergence/<case>/`` (or ``--out``):

* ``meshes/<key>.json`` — one per mesh: the measurement vector and the exact Jacobian at the
  reference, CPU and wall time; written atomically with a SHA-256 of its content, so an interrupted
  study resumes where it stopped and a torn or edited record is recomputed (not committed: ~1 MB
  each);
* ``convergence.json`` — the summary: per family the observed orders and the extrapolated force
  curve, per mesh the errors, biases and times, and, with the model-error tier's data mesh, the
  rounding floor and each mesh's bias against the rounded data (:func:`add_rounding`) and the
  plate-margin analysis (``plate_margin``: :func:`plate_margin_summary`) (small);
* ``extrapolated.json`` — the Richardson-extrapolated measurement vector (front-face fields and
  forces) the errors are measured against;
* ``convergence.md`` and ``convergence.png`` (drawn from ``convergence.json`` alone).

The overview of every study (:func:`render_overview`) is ``overview.md`` in the root, with
``plate_margin.png`` beside it when a study has the plate-margin analysis.
"""

from __future__ import annotations

import hashlib
import json
import math
import time
from pathlib import Path

import numpy as np

from bench.studies import markdown_table, output_dir, read_json
from problems.analysis import convergence as conv
from problems.fe.mesh import SIZE_MM, discretisation_key, parse_mesh_spec
from problems.io import jsonio
from problems.io.atomic import atomic_write_text

STUDY = "convergence"
SCHEMA = 1
#: default family: n = 6, 10, 14 (8-node n x n x 2n, graded with ratio 4)
DEFAULT_SIZES = (6, 10, 14)
DEFAULT_GRADING = 4.0
DEFAULT_ELEMENTS = ("hex8",)
#: uniform presets judged against the extrapolation
DEFAULT_COMPARE = ("coarse", "paper")
#: plate margins of the measurement-region analysis, mm (:func:`plate_margin_summary`): the grid
#: rows are at z = 5, 10, ... mm, so 10 mm drops the row nearest each plate, 30 mm five
DEFAULT_PLATE_MARGINS = (0.0, 10.0, 15.0, 20.0, 30.0)
#: the file name of the overview's plate-margin figure (:func:`render_overview`)
PLATE_MARGIN_FIGURE = "plate_margin.png"


def family_specs(sizes, grading: float, element: str) -> list[str]:
    """Mesh specs of a family: ``n,n,2n[:gR]`` (hex8) or ``n/2,n/2,n[:gR]:hex27`` (same nodes) for
    each n of ``sizes`` (even for hex27)."""
    tail = (f":g{grading:g}" if grading != 1.0 else "") + (":hex27" if element == "hex27" else "")
    out = []
    for n in sizes:
        m = n // 2 if element == "hex27" else n
        if element == "hex27" and n % 2:
            raise ValueError(f"size {n} is odd: hex27 families need even sizes (n/2 elements)")
        out.append(f"{m},{m},{2 * m}{tail}")
    return out


def family_label(element: str, grading: float) -> str:
    """``hex8 g4``, ``hex27 uniform``, ..."""
    return f"{element} " + (f"g{grading:g}" if grading != 1.0 else "uniform")


def record_path(folder: Path, spec: str) -> Path:
    """``<folder>/meshes/<key>.json`` with ``,`` -> ``x`` and ``:`` -> ``_`` in the key."""
    key = discretisation_key(spec).replace(",", "x").replace(":", "_")
    return Path(folder) / "meshes" / f"{key}.json"


def _digest(doc: dict) -> str:
    body = {k: v for k, v in doc.items() if k != "sha256"}
    return hashlib.sha256(jsonio.dumps(body, sort_keys=True).encode()).hexdigest()


def write_record(path: Path, doc: dict) -> Path:
    """Write a mesh record atomically with the SHA-256 of its content."""
    return atomic_write_text(path, jsonio.dumps({**doc, "sha256": _digest(doc)}) + "\n")


def read_record(path: Path, case: str, spec: str) -> dict | None:
    """The record at ``path`` if it is complete, unchanged (checksum), of this schema, ``case``
    and the discretisation of ``spec``; else None (to be recomputed)."""
    try:
        doc = jsonio.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None
    if not isinstance(doc, dict) or doc.get("sha256") != _digest(doc):
        return None
    if (
        doc.get("schema") != SCHEMA
        or doc.get("case") != case
        or doc.get("key") != discretisation_key(spec)
    ):
        return None
    return doc


def solve_mesh(case_name: str, spec: str, jacobian: bool = True) -> dict:
    """One mesh at the case's reference: measurement vector, exact Jacobian (columns the case's
    parameters, physical units), element size (mm), elements, solved dofs, CPU and wall time (s)
    of the response + Jacobian run (the discretisation is built first, not timed).

    The model-error tier's data mesh, and any mesh asked for without a Jacobian
    (``jacobian=False``: a *plain* run, ~2/3 of the cost, for the finest meshes of a study), is
    taken from :mod:`problems.inverse.response_cache`: the run ``femubench data`` makes that tier
    from (solved once for both; computed here, without a Jacobian, if missing). Without a
    Jacobian its record has ``jacobian`` None: its errors are measured, its own bias is not."""
    from bench.progress import solved_dofs
    from problems.inverse import response_cache
    from problems.inverse.cases import get_case
    from problems.inverse.data import shares_reference_solve
    from problems.inverse.forward import FEForwardModel, discretisation
    from problems.inverse.protocol import ForwardResult

    case = get_case(case_name)
    model = FEForwardModel(case, mesh=spec)
    plain = not jacobian or shares_reference_solve(spec)
    if plain:
        run = response_cache.solve(model, case.reference, jacobian=False)
        res = ForwardResult(
            run["ok"],
            run["values"],
            run["message"],
            run["wall_s"],
            run["jacobian"],
            run["plain_wall_s"],
        )
        cpu, wall = run["cpu_s"], run["wall_s"]
    else:
        discretisation(spec)  # built once per process, outside the timing
        cpu, wall = time.process_time(), time.perf_counter()
        res = model(case.reference, jacobian=True)
        cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    ms = parse_mesh_spec(spec)
    n_elements = int(np.prod(ms.shape))
    return {
        "schema": SCHEMA,
        "case": case_name,
        "mesh": spec,
        "key": discretisation_key(spec),
        "element": ms.element,
        "grading": ms.grading,
        "grading_z": ms.grading_z,
        "symmetry": ms.symmetry,
        "elements": n_elements,
        "dofs": solved_dofs(spec),
        "h_mm": conv.element_size_mm(np.prod(SIZE_MM), n_elements),
        "ok": bool(res.ok and (res.jacobian is not None or plain)),
        "message": res.message or ("" if res.jacobian is not None else "no Jacobian (a plain run)"),
        "cpu_s": cpu,
        "wall_s": wall,
        "plain_wall_s": res.plain_wall_s,
        "names": list(case.names),
        "reference": list(case.reference),
        "n_snapshots": model.loading.snapshots,
        "n_points": len(model.points),
        "values": None if res.values is None else res.values,
        "jacobian": None if res.jacobian is None else res.jacobian,
    }


def run_convergence(
    case: str,
    families: dict[str, list[str]],
    compare=(),
    out: str | Path | None = None,
    report=None,
    plate_margins=DEFAULT_PLATE_MARGINS,
    plain=(),
) -> Path:
    """Solve (or reuse) every mesh of ``families`` ({label: specs coarse to fine}) and ``compare``
    for ``case``, write the summary, the extrapolation and the markdown table; returns the output
    folder. ``report(record, reused)`` is called after each mesh; ``plate_margins`` (mm) are
    those of the plate-margin analysis (:func:`plate_margin_summary`; with the data mesh);
    ``plain``: specs (any spelling) solved without the Jacobian (:func:`solve_mesh`). A stored
    record without a Jacobian is solved again when its mesh is not plain (nor the data mesh)."""
    from problems.inverse.data import shares_reference_solve

    folder = output_dir(STUDY, case, out)
    specs = [s for fam in families.values() for s in fam] + [s for s in compare]
    plain_keys = {discretisation_key(s) for s in plain}
    records = {}
    for spec in dict.fromkeys(specs):
        jacobian = discretisation_key(spec) not in plain_keys
        path = record_path(folder, spec)
        rec = read_record(path, case, spec)
        if rec and rec["ok"] and rec["jacobian"] is None and jacobian:
            # a plain record of a mesh now asked with its Jacobian (the data mesh's has none)
            rec = rec if shares_reference_solve(spec) else None
        reused = rec is not None
        if rec is None:
            rec = solve_mesh(case, spec, jacobian)
            write_record(path, rec)
        records[spec] = rec
        if report is not None:
            report(rec, reused)
    summary, extrapolated = analyse(case, families, list(compare), records, plate_margins)
    atomic_write_text(folder / "convergence.json", jsonio.dumps(summary, indent=1) + "\n")
    atomic_write_text(
        folder / "extrapolated.json",
        jsonio.dumps(
            {
                "case": case,
                "reference_family": summary["reference_family"],
                "values": [float(f"{v:.9g}") for v in extrapolated],
            }
        )
        + "\n",
    )
    atomic_write_text(folder / "convergence.md", markdown(summary))
    return folder


def analyse(
    case: str, families: dict, compare: list, records: dict, plate_margins=DEFAULT_PLATE_MARGINS
) -> tuple[dict, np.ndarray]:
    """The summary of a study from its mesh records and the extrapolated measurement vector.

    Each family with three or more solved meshes is extrapolated from its last three; the
    reference is the extrapolation of the family whose finest mesh it moves least (the smallest
    Richardson error estimate) among the families in their asymptotic range (the last two observed
    orders agree: :func:`problems.analysis.convergence.asymptotic`), or among all when none is.
    With the model-error tier's data mesh among the records the summary has the plate-margin
    analysis for ``plate_margins`` (mm; :func:`plate_margin_summary`; none when empty).
    ValueError when no family can be extrapolated."""
    first = next(iter(records.values()))
    N, m = first["n_snapshots"], first["n_points"]
    sd = conv.noise_sd(N, m)
    fam_out = {}
    for label, specs in families.items():
        recs = [records[s] for s in specs if records[s]["ok"]]
        entry = {"meshes": list(specs), "solved": [r["mesh"] for r in recs]}
        if len(recs) >= 3:
            ex = conv.extrapolate(
                [r["h_mm"] for r in recs], np.array([r["values"] for r in recs]), N, m
            )
            entry.update({k: v for k, v in ex.items() if k != "values"})
            entry["extrapolated_force_kN"] = ex["values"][-N:].tolist()
            entry["_values"] = ex["values"]
        fam_out[label] = entry
    usable = {k: v for k, v in fam_out.items() if "_values" in v}
    if not usable:
        raise ValueError(
            f"case {case}: no family has 3 solved meshes; nothing to extrapolate (see the mesh "
            "records' messages)"
        )
    # prefer families in their asymptotic range (their estimate can be trusted)
    trusted = {k: v for k, v in usable.items() if v["asymptotic"]} or usable
    ref_label = min(trusted, key=lambda k: trusted[k]["finest_error_sigma"])
    ref = usable[ref_label]["_values"]
    for v in fam_out.values():
        v.pop("_values", None)
    data_mesh = _data_mesh([*records], records)
    rows = []
    for label, specs in [*families.items(), ("compare", compare)]:
        for spec in specs:
            r = records[spec]
            row = {
                "mesh": spec,
                "family": label,
                "element": r["element"],
                "grading": r["grading"],
                "grading_z": r.get("grading_z"),  # records before gzR have none
                "elements": r["elements"],
                "dofs": r["dofs"],
                "h_mm": r["h_mm"],
                "ok": r["ok"],
                "message": r["message"],
                "cpu_s": r["cpu_s"],
                "wall_s": r["wall_s"],
            }
            if r["ok"]:
                row.update(conv.errors(r["values"], ref, N, m))
            if r["ok"] and r["jacobian"] is not None:
                bias = conv.linearised_bias(
                    np.asarray(r["jacobian"]), np.asarray(r["values"]) - ref, sd, r["reference"]
                )
                row["bias_pct"] = {n: 100.0 * b for n, b in zip(r["names"], bias)}
                row["worst_bias"] = _worst(r["names"], bias)
                if data_mesh is not None:
                    data_bias = conv.linearised_bias(
                        np.asarray(r["jacobian"]),
                        np.asarray(r["values"]) - np.asarray(records[data_mesh]["values"]),
                        sd,
                        r["reference"],
                    )
                    row["data_bias_pct"] = {n: 100.0 * b for n, b in zip(r["names"], data_bias)}
                    row["worst_data_bias"] = _worst(r["names"], data_bias)
            rows.append(row)
    _estimate_missing_biases(rows, records, families[ref_label], ref, sd)
    summary = {
        "schema": SCHEMA,
        "case": case,
        "sigma_displacement_mm": conv.SIGMA_DISPLACEMENT_MM,
        "sigma_force_kN": conv.SIGMA_FORCE_KN,
        "n_snapshots": N,
        "n_points": m,
        "parameters": first["names"],
        "reference_family": ref_label,
        "data_mesh": data_mesh,
        "families": fam_out,
        "meshes": rows,
    }
    if data_mesh is not None:
        add_rounding(summary, records)
    if data_mesh is not None and len(plate_margins):
        summary["plate_margin"] = plate_margin_summary(records, data_mesh, plate_margins)
    return summary, ref


def add_rounding(summary: dict, records: dict) -> dict:
    """Add what the data's rounding costs to a study's ``summary`` with the model-error tier's
    data mesh (``summary["data_mesh"]``), from its mesh records ``records`` ({spec: record}).

    The data are the data mesh's response rounded as the tier rounds them
    (:func:`problems.inverse.data.rounded` with the tier's settings: displacements to 1 um,
    forces to 0.1 kN). Adds, in %, {parameter: %} of the reference:

    * per mesh row with a Jacobian ``rounded_data_bias_pct`` and ``worst_rounded_data_bias``:
      the linearised bias against the rounded data (what a fit of the model-error data with that
      mesh finds, Table 1), beside ``data_bias_pct`` (against the unrounded response);
    * ``rounding_floor_pct``: the exact data model's linearised step on its rounded data
      (:func:`problems.analysis.convergence.rounding_floor`) with the Jacobian of the solved mesh
      with the most dofs that has one (``rounding_floor_mesh``), and
      ``rounding_floor_spread_pct``: its largest difference with the Jacobian of any other mesh
      of the same element (its uncertainty from the Jacobian).

    Returns ``summary`` (changed in place); unchanged when no mesh has a Jacobian. ValueError
    when the records' layout is not the tier's (another number of front-face points)."""
    from problems.inverse.data import rounded, tier_settings

    data = records[summary["data_mesh"]]
    N, m = data["n_snapshots"], data["n_points"]
    settings = tier_settings("model-error", snapshots=N)
    if len(settings.points) != m:
        raise ValueError(
            f"the mesh records have {m} front-face points; the model-error data have "
            f"{len(settings.points)}"
        )
    exact = np.asarray(data["values"], float)
    data_values = rounded(exact, settings)
    sd = conv.noise_sd(N, m)
    names = summary["parameters"]
    for row in summary["meshes"]:
        r = records[row["mesh"]]
        if r["ok"] and r["jacobian"] is not None:
            bias = conv.linearised_bias(
                np.asarray(r["jacobian"]), np.asarray(r["values"]) - data_values, sd, r["reference"]
            )
            row["rounded_data_bias_pct"] = {n: 100.0 * b for n, b in zip(names, bias)}
            row["worst_rounded_data_bias"] = _worst(names, bias)
    with_jacobian = sorted(
        (r for r in records.values() if r["ok"] and r["jacobian"] is not None),
        key=lambda r: -r["dofs"],
    )
    if not with_jacobian:
        return summary
    # the spread over the meshes of the finest's element (an 8-node mesh of the hex27 study
    # misses the data by 60 % or more: its Jacobian is not the data model's)
    with_jacobian = [r for r in with_jacobian if r["element"] == with_jacobian[0]["element"]]
    floor, spread = conv.rounding_floor(
        [np.asarray(r["jacobian"]) for r in with_jacobian],
        exact,
        data_values,
        sd,
        data["reference"],
    )
    summary["rounding_floor_mesh"] = with_jacobian[0]["mesh"]
    summary["rounding_floor_pct"] = {n: 100.0 * float(v) for n, v in zip(names, floor)}
    summary["rounding_floor_spread_pct"] = {n: 100.0 * float(v) for n, v in zip(names, spread)}
    return summary


def plate_margin_summary(records: dict, data_mesh: str, margins_mm) -> dict:
    """The plate-margin analysis of a study (``plate_margin`` of ``convergence.json``): how the
    measurement region (:class:`problems.inverse.build.Region`) changes what each candidate
    inverse mesh meets in the model-error data, from the mesh records ``records`` ({spec:
    record}) and the data mesh ``data_mesh`` (a spec of ``records``) at plate margins
    ``margins_mm`` (mm), with :func:`problems.analysis.convergence.plate_margin_study`.

    Returns ``margins_mm``, ``points`` (front-face points kept at each margin) and ``meshes``:
    per solved mesh with a Jacobian (the data mesh aside) its ``dofs``, and per margin (lists in
    the order of ``margins_mm``; dicts {parameter: %} of the reference):

    * ``untreated_pct`` — the linearised bias against the data mesh's response;
    * ``corrected_pct`` — {finer mesh: biases}: for each solved mesh with more dofs (the data
      mesh aside) the linearised bias of the mesh's Jacobian with that mesh's response minus the
      data, the first-order limit of the iterated model-error correction with it as the
      high-fidelity model;
    * ``sd_pct`` — each parameter's noise sd under the rounding noise of the data
      (:func:`problems.analysis.convergence.noise_sd`).

    The points are the default measurement grid (:func:`problems.fe.front_face.measurement_grid`),
    the specimen the standard cube; ValueError when the records have another number of points."""
    from problems.fe.front_face import measurement_grid

    data = records[data_mesh]
    N, m = data["n_snapshots"], data["n_points"]
    points = measurement_grid()
    if len(points) != m:
        raise ValueError(
            f"the mesh records have {m} front-face points; the plate-margin analysis needs the "
            f"default measurement grid's {len(points)}"
        )
    data_values = np.asarray(data["values"], float)
    solved = {
        spec: r
        for spec, r in records.items()
        if r["ok"] and r["values"] is not None and r["key"] != data["key"]
    }
    meshes, kept = {}, None
    for spec, r in solved.items():
        if r["jacobian"] is None:
            continue
        finer = [f for f, q in solved.items() if q["dofs"] > r["dofs"]]
        residuals = {f: np.asarray(solved[f]["values"], float) - data_values for f in finer}
        residuals["untreated"] = np.asarray(r["values"], float) - data_values
        study = conv.plate_margin_study(
            r["jacobian"], residuals, r["reference"], points, margins_mm, N, SIZE_MM[2]
        )
        kept = [s["points"] for s in study]

        def pct(values, names=r["names"]):
            return {n: float(f"{100.0 * v:.5g}") for n, v in zip(names, values)}

        meshes[spec] = {
            "dofs": r["dofs"],
            "untreated_pct": [pct(s["bias"]["untreated"]) for s in study],
            "corrected_pct": {f: [pct(s["bias"][f]) for s in study] for f in finer},
            "sd_pct": [pct(s["sd"]) for s in study],
        }
    return {"margins_mm": [float(x) for x in margins_mm], "points": kept, "meshes": meshes}


def update_plate_margin(folder: str | Path, margins_mm) -> Path | None:
    """Redo the analyses of a study's folder against the model-error data from its mesh records
    (no FE solve): the rounding floor and each mesh's bias against the rounded data
    (:func:`add_rounding`) and, for ``margins_mm`` (mm; none when empty), the plate-margin
    analysis; rewrite ``convergence.json`` and ``convergence.md``. Returns the json's path, or
    None when the study has no data mesh (nothing to analyse) or, without margins, a mesh record
    is missing (the mesh records are local caches: the shipped summary stays). ValueError (one
    line) when a mesh record is missing or torn and margins are asked for."""
    folder = Path(folder)
    summary = read_json(folder / "convergence.json")
    if not summary.get("data_mesh"):
        return None
    records = {}
    for spec in (r["mesh"] for r in summary["meshes"]):
        records[spec] = read_record(record_path(folder, spec), summary["case"], spec)
        if records[spec] is None:
            if not len(margins_mm):
                return None
            raise ValueError(
                f"{record_path(folder, spec)}: the mesh record is missing or torn; the "
                "plate-margin analysis needs every mesh record (run the study without --render)"
            )
    add_rounding(summary, records)
    if len(margins_mm):
        summary["plate_margin"] = plate_margin_summary(records, summary["data_mesh"], margins_mm)
    atomic_write_text(folder / "convergence.md", markdown(summary))
    return atomic_write_text(folder / "convergence.json", jsonio.dumps(summary, indent=1) + "\n")


def _estimate_missing_biases(rows, records: dict, family, ref, sd) -> None:
    """For each solved mesh without a Jacobian (the data mesh, plain runs) its own linearised
    bias against the extrapolation ``ref`` seen through the Jacobian of the reference family's
    finest mesh that has one (``bias_est_pct``, ``worst_bias_est``, ``bias_est_via``): in the
    linearisation that mesh's bias against ``ref`` minus its bias against the mesh's response,
    i.e. an estimate, exact only when the two Jacobians agree."""
    via = next(
        (s for s in reversed(family) if records[s]["ok"] and records[s]["jacobian"] is not None),
        None,
    )
    if via is None:
        return
    J, names, reference = (
        np.asarray(records[via]["jacobian"]),
        records[via]["names"],
        records[via]["reference"],
    )
    for row in rows:
        r = records[row["mesh"]]
        if r["ok"] and r["jacobian"] is None:
            bias = conv.linearised_bias(J, np.asarray(r["values"]) - ref, sd, reference)
            row["bias_est_pct"] = {n: 100.0 * b for n, b in zip(names, bias)}
            row["worst_bias_est"] = _worst(names, bias)
            row["bias_est_via"] = via


def _data_mesh(specs, records: dict) -> str | None:
    """The spec among ``specs`` whose record is of the model-error tier's data mesh
    (:data:`problems.inverse.data.MODEL_ERROR_MESH`, any spelling: by its ``key``) and solved,
    else None."""
    from problems.inverse.data import MODEL_ERROR_MESH

    key = discretisation_key(MODEL_ERROR_MESH)
    return next((s for s in specs if records[s].get("key") == key and records[s]["ok"]), None)


def _worst(names, bias) -> dict:
    """``{"parameter", "pct"}`` of the largest |bias| (bias as fractions)."""
    worst = int(np.argmax(np.abs(bias)))
    return {"parameter": names[worst], "pct": 100.0 * float(bias[worst])}


def _bias_text(worst: dict | None) -> str:
    return "n/a" if worst is None else f"{worst['parameter']} {worst['pct']:+.2f} %"


def _fmt(value, spec: str) -> str:
    return (
        "n/a"
        if value is None or (isinstance(value, float) and not math.isfinite(value))
        else (format(value, spec))
    )


def _orders(values) -> str:
    """Observed orders of successive triples, ``0.70 -> 2.86``."""
    return " -> ".join(_fmt(v, ".2f") for v in values) if values else "n/a"


def markdown(summary: dict) -> str:
    """The study's markdown: orders per family, then one row per mesh."""
    lines = [
        f"# Mesh convergence: {summary['case']}",
        "",
        f"Errors against the Richardson extrapolation of the **{summary['reference_family']}** "
        f"family; sigma = {summary['sigma_displacement_mm'] * 1e3:.3f} um per displacement, "
        f"{summary['sigma_force_kN']:g} kN for the force; {summary['n_snapshots']} snapshots x "
        f"{summary['n_points']} front-face points. Orders: of each triple of successive meshes "
        "(the last one extrapolates; asymptotic when the last two agree within 25 %). Bias: "
        "linearised Gauss-Newton step from the reference with the mesh's exact Jacobian.",
        "",
        "| family | meshes | orders (field) | orders (force) | asymptotic | finest's error (sigma) "
        "| extrapolated force at the last snapshot (kN) |",
        "|---|---|---|---|---|---|---|",
    ]
    for label, fam in summary["families"].items():
        force = fam.get("extrapolated_force_kN")
        lines.append(
            f"| {label} | {', '.join(fam['meshes'])} | {_orders(fam.get('orders_field_all'))} | "
            f"{_orders(fam.get('orders_force_all'))} | "
            f"{'yes' if fam.get('asymptotic') else 'no'} | "
            f"{_fmt(fam.get('finest_error_sigma'), '.2f')} | "
            f"{_fmt(force[-1] if force else None, '.2f')} |"
        )
    rows = []
    for r in summary["meshes"]:
        row = {
            "mesh": r["mesh"],
            "elements": r["elements"],
            "dofs": r["dofs"],
            "RMS field error (sigma)": r.get("rms_sigma", math.nan),
            "force error (%)": r.get("force_last_pct", math.nan),
            "worst bias": (
                f"{r['worst_bias']['parameter']} {r['worst_bias']['pct']:+.2f} %"
                if "worst_bias" in r
                else f"{_bias_text(r['worst_bias_est'])} (est. via {r['bias_est_via']})"
                if "worst_bias_est" in r
                else r["message"]
            ),
            "CPU s": r["cpu_s"],
            "wall s": r["wall_s"],
        }
        if summary.get("data_mesh"):
            row["worst bias vs the data mesh"] = _bias_text(r.get("worst_data_bias"))
        if "rounding_floor_pct" in summary:
            row["worst bias vs the rounded data"] = _bias_text(r.get("worst_rounded_data_bias"))
        rows.append(row)
    table = markdown_table(
        rows,
        {
            "RMS field error (sigma)": ".2f",
            "force error (%)": "+.3f",
            "CPU s": ".1f",
            "wall s": ".1f",
        },
    )
    bias_rows = [
        {"mesh": r["mesh"], **{k: v for k, v in r["bias_pct"].items()}}
        for r in summary["meshes"]
        if "bias_pct" in r
    ]
    bias = markdown_table(bias_rows, {p: "+.2f" for p in summary["parameters"]})
    if summary.get("data_mesh"):
        lines += [
            "",
            f"The model-error tier's data mesh {summary['data_mesh']} is in the study: 'worst bias "
            "vs the data mesh' is each mesh's linearised bias against its response (what an "
            "inverse model on that mesh meets in the model-error data, rounding aside).",
        ]
        if "rounding_floor_pct" in summary:
            lines[-1] += (
                " 'worst bias vs the rounded data': against the data as the tier makes them "
                "(displacements rounded to 1 um, forces to 0.1 kN): what a fit of the "
                "model-error data with that mesh finds."
            )
    return "\n".join(
        lines
        + ["", "## Meshes", "", table, "", "## Linearised parameter bias (%)", "", bias, ""]
        + _rounding_floor_lines(summary)
    )


def _rounding_floor_lines(summary: dict) -> list[str]:
    """The case markdown's section on the rounding floor (:func:`add_rounding`; none without
    it): per parameter the floor, its spread over the Jacobians and each mesh's bias against the
    rounded data."""
    if "rounding_floor_pct" not in summary:
        return []
    floor, spread = summary["rounding_floor_pct"], summary["rounding_floor_spread_pct"]
    rows = [
        {"": "rounding floor", **floor},
        {"": "spread over the Jacobians", **spread},
    ] + [
        {"": r["mesh"], **r["rounded_data_bias_pct"]}
        for r in summary["meshes"]
        if "rounded_data_bias_pct" in r
    ]
    return [
        "## The rounding floor of the model-error data (%)",
        "",
        "The data mesh's own linearised step on its data rounded as the tier rounds them (1 um, "
        f"0.1 kN), with the Jacobian of {summary['rounding_floor_mesh']} (spread: the largest "
        "difference with another mesh's Jacobian of its element): what the exact model finds "
        "on these data (a model lands closer only where its own bias cancels part of it). "
        "Then each mesh's "
        "linearised bias against the rounded data (its bias against the unrounded response "
        "plus, to first order, the floor).",
        "",
        markdown_table(rows, {p: "+.2f" for p in summary["parameters"]}),
        "",
    ]


def render_convergence(folder: str | Path) -> Path:
    """Draw ``convergence.png`` from ``convergence.json``: RMS front-face error (sigma), force
    error (%) and worst |bias| (%) against solved dofs, one line per family, markers for the
    comparison meshes."""
    from bench.plotting import pyplot, row, save

    folder = Path(folder)
    summary = read_json(folder / "convergence.json")
    plt = pyplot()
    fig, axes = plt.subplots(1, 3, figsize=row(3))
    panels = (
        ("rms_sigma", "RMS front-face error (sigma)"),
        ("force_last_pct", "|force error| at the last snapshot (%)"),
        ("worst_bias", "worst |linearised bias| (%)"),
    )
    groups: dict[str, list[dict]] = {}
    for r in summary["meshes"]:
        if r.get("ok") and "rms_sigma" in r:
            groups.setdefault(r["family"], []).append(r)
    for ax, (key, title) in zip(axes, panels):
        for label, rs in groups.items():
            rs = [r for r in rs if key in r]  # a mesh without a Jacobian has no bias
            x = [r["dofs"] for r in rs]
            y = [abs(r["worst_bias"]["pct"] if key == "worst_bias" else r[key]) for r in rs]
            if label == "compare":
                ax.plot(x, y, "s", color="0.4", label="compare")
                for r, xi, yi in zip(rs, x, y):
                    ax.annotate(
                        r["mesh"], (xi, yi), fontsize=7, xytext=(3, 3), textcoords="offset points"
                    )
            else:
                ax.plot(x, y, marker="o", label=label)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("solved dofs")
        ax.set_title(title, fontsize=9)
    axes[0].legend(fontsize=7)
    fig.suptitle(
        f"{summary['case']}: errors against the extrapolated {summary['reference_family']}",
        fontsize=10,
    )
    return save(fig, folder / "convergence.png")


def render_overview(root: str | Path) -> Path:
    """``overview.md`` of every study under ``root``: each case folder ``root/<case>/`` and each
    folder of a further study ``root/<study>/<case>/`` (e.g. ``hex27-g8``) holding a
    ``convergence.json``. Per family the observed orders; the model-error tier's data mesh, where
    a study has it, with its error against that study's extrapolation and the other studies'
    extrapolations of the case; every other mesh's worst linearised bias against the data mesh
    (the candidates for the inverse model); per mesh the RMS error (sigma), force error (%),
    worst bias and CPU s; with the plate-margin analysis (:func:`plate_margin_summary`) a section
    on the measurement region and its figure :data:`PLATE_MARGIN_FIGURE`."""
    root = Path(root)
    studies = []  # (study label, folder, summary)
    for path in sorted(root.glob("*/convergence.json")) + sorted(root.glob("*/*/convergence.json")):
        label = root.name if path.parent.parent == root else path.parent.parent.name
        studies.append((label, path.parent, read_json(path)))
    rows, orders, references, candidates = [], [], [], {}
    for label, folder, s in studies:
        for fam_label, fam in s["families"].items():
            orders.append(
                {
                    "case": s["case"],
                    "study": label,
                    "family": fam_label
                    + (" (reference)" if fam_label == s["reference_family"] else ""),
                    "meshes": ", ".join(fam["meshes"]),
                    "orders (field)": _orders(fam.get("orders_field_all")),
                    "orders (force)": _orders(fam.get("orders_force_all")),
                    "asymptotic": "yes" if fam.get("asymptotic") else "no",
                    "finest's error (sigma)": fam.get("finest_error_sigma", math.nan),
                }
            )
        for r in s["meshes"]:
            rows.append(
                {
                    "case": s["case"],
                    "study": label,
                    "mesh": r["mesh"],
                    "dofs": r["dofs"],
                    "RMS (sigma)": r.get("rms_sigma", math.nan),
                    "force (%)": r.get("force_last_pct", math.nan),
                    "worst bias": _bias_text(r.get("worst_bias")) if r.get("ok") else "failed",
                    "CPU s": r["cpu_s"],
                }
            )
            if s.get("data_mesh") and r["mesh"] != s["data_mesh"]:
                candidates.setdefault(r["mesh"], {})[s["case"]] = r
        if s.get("data_mesh"):
            references.append(_reference_row(label, folder, s, studies))
    cases = sorted({s["case"] for _, _, s in studies if s.get("data_mesh")})
    cand_rows = [
        {
            "mesh": mesh,
            "dofs": next(iter(by_case.values()))["dofs"],
            **{
                c: _bias_text(by_case[c].get("worst_data_bias")) if c in by_case else "-"
                for c in cases
            },
            "worst |bias| (%)": max(
                (
                    abs(r["worst_data_bias"]["pct"])
                    for r in by_case.values()
                    if "worst_data_bias" in r
                ),
                default=math.nan,
            ),
            "CPU s (max)": max(r["cpu_s"] for r in by_case.values()),
        }
        for mesh, by_case in candidates.items()
        # a mesh without a Jacobian in any case (a plain run: a reference candidate) has no bias
        if any("worst_data_bias" in r for r in by_case.values())
    ]
    cand_rows.sort(key=lambda r: r["dofs"])
    parts = [
        "# Mesh convergence of every case",
        "",
        "Per case: `convergence.md` and `convergence.png` in its folder (`<case>/`, and "
        "`<study>/<case>/` for a further study). Errors against the Richardson extrapolation of "
        "each study's reference family; sigma = 1 um / sqrt(12) per displacement, 1 kN for the "
        "force. CPU s: one response + exact Jacobian at the case's reference (on a shared "
        "2-core machine: contention inflates them).",
        "",
        "## Observed orders",
        "",
        markdown_table(orders, {"finest's error (sigma)": ".2f"}),
    ]
    if references:
        parts += [
            "## The model-error tier's data mesh",
            "",
            "Its error against the extrapolation of its study's reference family (the criterion: "
            "<= 0.3 sigma RMS, <= 0.05 % in force) and, as an independent check, against the "
            "other studies' extrapolations of the case; worst linearised bias against the "
            "extrapolation (n/a when its run has no Jacobian); CPU and wall s of its run (shared "
            "with `femubench data`, which needs no Jacobian).",
            "",
            markdown_table(
                references,
                {"RMS (sigma)": ".2f", "force (%)": "+.3f", "CPU s": ".0f", "wall s": ".0f"},
            ),
            "## Candidate inverse models: worst linearised bias against the data mesh",
            "",
            "Per case the parameter with the largest linearised bias (%) of a mesh against the "
            "data mesh's response at the reference: what the inverse model meets in the "
            "model-error data, rounding aside (no correction).",
            "",
            markdown_table(cand_rows, {"worst |bias| (%)": ".2f", "CPU s (max)": ".1f"}),
        ]
    parts += _rounding_floor_section(studies)
    parts += _plate_margin_section(root, studies)
    parts += [
        "## Meshes",
        "",
        markdown_table(rows, {"RMS (sigma)": ".2f", "force (%)": "+.3f", "CPU s": ".1f"}),
    ]
    return atomic_write_text(root / "overview.md", "\n".join(parts))


#: the meshes whose bias against the rounded data the overview shows beside the unrounded one:
#: the default inverse model on the model-error tier
#: (:data:`problems.inverse.data.MODEL_ERROR_INVERSE_MESH`) and the next of its family
ROUNDING_MESHES = ("6,6,12:g8:hex27", "9,9,18:g8:hex27")


def _rounding_floor_section(studies) -> list[str]:
    """The overview's section on the data's rounding floor (:func:`add_rounding`; none without
    it): per case the worst parameter's floor, every parameter's floor and its spread, and the
    worst bias of :data:`ROUNDING_MESHES` against the rounded data beside the same parameter's
    bias against the unrounded response."""
    rows = []
    for _, _, s in studies:
        if "rounding_floor_pct" not in s:
            continue
        floor, spread = s["rounding_floor_pct"], s["rounding_floor_spread_pct"]
        worst = max(floor, key=lambda n: abs(floor[n]))
        row = {
            "case": s["case"],
            "worst floor": f"{worst} {floor[worst]:+.2f} %",
            "floor of every parameter (%)": ", ".join(f"{n} {v:+.2f}" for n, v in floor.items()),
            "spread (%)": max(spread.values()),
        }
        by_mesh = {r["mesh"]: r for r in s["meshes"]}
        for mesh in ROUNDING_MESHES:
            r = by_mesh.get(mesh, {})
            w = r.get("worst_rounded_data_bias")
            row[f"{mesh}: rounded (unrounded)"] = (
                "-"
                if w is None
                else f"{w['parameter']} {w['pct']:+.2f} % "
                f"({r['data_bias_pct'][w['parameter']]:+.2f} %)"
            )
        rows.append(row)
    if not rows:
        return []
    return [
        "## The rounding floor of the model-error data",
        "",
        "The model-error data are the data mesh's response rounded to 1 um (displacements) and "
        "0.1 kN (force). The rounding floor is the exact data model's linearised step on these "
        "data, dx / x_ref = -(J^T W J)^-1 J^T W (U_data mesh - round(U_data mesh)), with the "
        "Jacobian of the finest solved mesh that has one (spread: the largest difference with "
        "another mesh's Jacobian of its element): what the exact model would find on these "
        "data (a model lands closer only where its own bias cancels part of it). Beside it the "
        "worst linearised bias "
        "against the rounded data (what Table 1's fits find) of the default inverse model and "
        "of 9,9,18:g8:hex27, with the same parameter's bias against the unrounded response in "
        "brackets.",
        "",
        markdown_table(rows, {"spread (%)": ".2f"}),
    ]


def _plate_margin_section(root: Path, studies) -> list[str]:
    """The overview's section on the plate margin (markdown lines; none without the analysis):
    per candidate mesh in every analysed case a table case x margin of the worst untreated
    linearised bias and its parameter's noise sd, and one of the correction's limit with the
    mesh's high-fidelity model (:func:`_correction_mesh`); draws :data:`PLATE_MARGIN_FIGURE`."""
    from problems.inverse.data import MODEL_ERROR_INVERSE_MESH

    analysed = {s["case"]: s for _, _, s in studies if s.get("plate_margin")}
    if not analysed:
        return []
    cases = sorted(analysed)
    margins = sorted({x for s in analysed.values() for x in s["plate_margin"]["margins_mm"]})
    first = analysed[cases[0]]["plate_margin"]
    meshes = [
        mesh
        for mesh in sorted(first["meshes"], key=lambda k: first["meshes"][k]["dofs"])
        if all(mesh in s["plate_margin"]["meshes"] for s in analysed.values())
    ]
    if not meshes:
        return []
    shown = {}  # mesh -> case -> (correction mesh or None, {margin: cell}, {margin: cell})
    for mesh in meshes:
        for case, s in analysed.items():
            pm = s["plate_margin"]
            entry = pm["meshes"][mesh]
            hifi = _correction_mesh(s, mesh, entry["corrected_pct"])
            cells = {}
            for i, margin in enumerate(pm["margins_mm"]):
                cells[margin] = (
                    _worst_margin_cell(entry["untreated_pct"][i], entry["sd_pct"][i]),
                    _worst_margin_cell(entry["corrected_pct"][hifi][i], entry["sd_pct"][i])
                    if hifi
                    else None,
                )
            shown.setdefault(mesh, {})[case] = (hifi, cells)
    points = ", ".join(f"{x:g} mm: {n}" for x, n in zip(first["margins_mm"], first["points"]))
    parts = [
        "## Measurement region: the plate margin",
        "",
        "A plate margin leaves out the front-face points closer than it to either plate (the "
        "grid rows are at z = 5, 10, ... mm; the force is always kept). Front-face points kept: "
        f"{points}. Per mesh and case the parameter with the largest linearised bias (%) "
        "against the data mesh at each margin, untreated (the mesh's own response) and, below, "
        "the limit of the iterated model-error correction with a finer mesh (the mesh's "
        "Jacobian with the finer mesh's response minus the data, to first order), with that "
        "parameter's noise sd (% of the reference, the data's rounding: 1 um / sqrt(12), "
        f"1 kN). Last row: the largest |bias| over the cases. Figure: `{PLATE_MARGIN_FIGURE}` "
        f"({MODEL_ERROR_INVERSE_MESH}).",
        "",
    ]
    for mesh, by_case in shown.items():
        for k, what in ((0, "untreated"), (1, "corrected")):
            hifis = sorted({h for h, _ in by_case.values() if h})
            if k == 1 and not hifis:
                continue
            rows = [
                {
                    "case": case,
                    **{
                        f"{x:g} mm": (cells[x][k][0] if x in cells and cells[x][k] else "-")
                        for x in margins
                    },
                }
                for case, (_, cells) in sorted(by_case.items())
            ]
            rows.append(
                {
                    "case": "worst over the cases",
                    **{
                        f"{x:g} mm": _fmt(
                            max(
                                (c[x][k][1] for _, c in by_case.values() if x in c and c[x][k]),
                                default=None,
                            ),
                            ".2f",
                        )
                        + " %"
                        for x in margins
                    },
                }
            )
            title = f"{mesh}, {what}" + (f" (correction with {', '.join(hifis)})" if k else "")
            parts += [f"### {title}", "", markdown_table(rows)]
    _plate_margin_figure(root / PLATE_MARGIN_FIGURE, shown, MODEL_ERROR_INVERSE_MESH)
    return parts


def _worst_margin_cell(bias_pct: dict, sd_pct: dict) -> tuple[str, float]:
    """``("pt0 -8.46 % (sd 0.53 %)", 8.46)``: the worst parameter's bias and noise sd (%), and
    its |bias| (%)."""
    name = max(bias_pct, key=lambda n: abs(bias_pct[n]))
    return f"{name} {bias_pct[name]:+.2f} % (sd {sd_pct[name]:.2f} %)", abs(bias_pct[name])


def _correction_mesh(summary: dict, mesh: str, corrected: dict) -> str | None:
    """The finer mesh whose correction the overview shows for ``mesh``: its default
    high-fidelity mesh (:func:`problems.inverse.build.hifi_mesh_for`) when ``corrected`` has it,
    else the next member of its family there, else None."""
    from problems.inverse.build import hifi_mesh_for

    try:
        key = discretisation_key(hifi_mesh_for(mesh))
    except ValueError:
        key = None
    match = [f for f in corrected if discretisation_key(f) == key]
    if match:
        return match[0]
    for fam in summary["families"].values():
        if mesh in fam["meshes"]:
            later = fam["meshes"][fam["meshes"].index(mesh) + 1 :]
            return next((f for f in later if f in corrected), None)
    return None


def _plate_margin_figure(path: Path, shown: dict, mesh: str) -> Path | None:
    """Worst |linearised bias| (%, log) against the plate margin (mm) of ``mesh`` (else the
    first mesh of ``shown``) per case, untreated and corrected: two panels."""
    from bench.plotting import pyplot, row, save

    mesh = mesh if mesh in shown else next(iter(shown))
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=row(2), sharey=True)
    for k, (ax, what) in enumerate(zip(axes, ("untreated", "corrected"))):
        for case, (_, cells) in sorted(shown[mesh].items()):
            xs = [x for x in sorted(cells) if cells[x][k]]
            if xs:
                ax.plot(xs, [cells[x][k][1] for x in xs], marker="o", label=case)
        hifis = sorted({h for h, _ in shown[mesh].values() if h})
        ax.axhline(1.0, color="0.6", lw=0.8, ls="--")
        ax.set_yscale("log")
        ax.set_xlabel("plate margin (mm)")
        ax.set_title(what + (f" (limit with {', '.join(hifis)})" if k else ""), fontsize=9)
    axes[0].set_ylabel("worst |linearised bias| (%)")
    axes[1].legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0))
    fig.suptitle(f"{mesh} against the model-error data mesh", fontsize=10)
    return save(fig, path)


def _reference_row(label: str, folder: Path, summary: dict, studies) -> dict:
    """The overview's row of a study's data mesh: its errors against the study's extrapolation,
    and the RMS / force difference between that extrapolation and every other study's of the
    case (``extrapolated.json``)."""
    r = next(r for r in summary["meshes"] if r["mesh"] == summary["data_mesh"])
    own = np.asarray(read_json(folder / "extrapolated.json")["values"], float)
    N, m = summary["n_snapshots"], summary["n_points"]
    others = []
    for other_label, other_folder, other in studies:
        if other["case"] != summary["case"] or other_folder == folder:
            continue
        values = np.asarray(read_json(other_folder / "extrapolated.json")["values"], float)
        e = conv.errors(values, own, N, m)
        others.append(
            f"{other_label} {other['reference_family']}: "
            f"{e['rms_sigma']:.2f} sigma, {e['force_last_pct']:+.3f} %"
        )
    return {
        "case": summary["case"],
        "study": label,
        "mesh": r["mesh"],
        "dofs": r["dofs"],
        "RMS (sigma)": r.get("rms_sigma", math.nan),
        "force (%)": r.get("force_last_pct", math.nan),
        "worst bias": _bias_text(r.get("worst_bias")),
        "CPU s": r["cpu_s"],
        "wall s": r["wall_s"],
        "other extrapolations vs this one": "; ".join(others) or "-",
    }

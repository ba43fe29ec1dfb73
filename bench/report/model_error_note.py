"""The note under every model-error Table 1 of report.md: how many cases meet the success criterion
with the runs' treatment, the worst parameter of each case that misses, and why, with the numbers
of the shipped model-error study (``results/studies/model_error/<case>/``, see docs/objective.md)
when it is found.

Two study rows per case, matched on the runs' inverse mesh, treatment and plate margin (and on the
data hash and the high-fidelity mesh when both sides have one):

* ``<mesh>__<treatment>__margin<m>__fe[__bias].json``: the linearised bias of the same treated
  objective, −(JᵀJ)⁻¹Jᵀr at the reference (the error of a perfect optimiser);
* ``<mesh>__hifi-at-reference__margin<m>__fe__bias.json``: the one-point correction made *at the
  reference* with the high-fidelity mesh, i.e. what that mesh's own error against the model-error
  data leaves: the floor of every correction that subtracts a discretisation error computed on it.

A case the study has no rows for (another inverse mesh) takes both from the shipped hex27
convergence study instead (:func:`load_convergence`, ``results/studies/convergence/hex27-g8``):
the bias is the ``data_bias_pct`` of the inverse mesh's entry, the floor the worst
``data_bias_pct`` of the high-fidelity mesh's entry (no floor for treatment ``none``).

:func:`model_error_note` is pure; :func:`run_settings` and :func:`load_study` gather its inputs.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import NamedTuple

import pandas as pd

from bench.report import tables as T

#: the diagnostic row of the study (``bench.studies.model_error.HIFI_LIMIT``)
FLOOR_TREATMENT = "hifi-at-reference"
#: the convergence study quoted for inverse meshes the model-error study does not cover, as a
#: folder next to the model-error study's (``studies/convergence/hex27-g8``)
CONVERGENCE_STUDY = ("convergence", "hex27-g8")
DOC_ANCHORS = {
    "the model-error study": "measured-the-model-error-study-resultsstudiesmodel_error",
    "where the 2 % target is not reached": (
        "where-the-2--target-is-not-reached-model-error-tier-default-treatment"
    ),
}


class Setting(NamedTuple):
    """The model-error treatment a run used (resolved from ``default``)."""

    requested: str
    treatment: str
    mesh: str
    margin: float
    hifi_mesh: str
    data_hash: str | None = None

    def tag(self) -> str:
        """The treatment as the method label names it
        (:func:`bench.experiment.store.method_label`), e.g. ``default bae 30 mm``."""
        margin = f" {self.margin:g} mm" if self.margin else ""
        return (
            f"default {self.treatment}{margin}" if self.requested == "default" else self.requested
        )

    def describe(self) -> str:
        """E.g. ``bae on `paper` for the `coarse` inverse mesh, 30 mm plate margin``."""
        text = self.treatment
        if self.treatment != "none" and self.hifi_mesh:
            text += f" on `{self.hifi_mesh}`"
        text += f" for the `{self.mesh}` inverse mesh" if self.mesh else ""
        return text + (f", {self.margin:g} mm plate margin" if self.margin else "")


def default_model_error_dirs(out_dir: Path) -> list[Path]:
    """Where the model-error study's ``<case>/*.json`` rows are looked for, like the posterior
    study: :func:`bench.report.study_dirs` without ``DIR/model_error``, which at the results root
    holds the BAE statistics, not the study; for a study's own report
    (``results/studies/<study>``) also the sibling ``results/studies/model_error``."""
    from bench.report import study_dirs

    dirs = study_dirs(out_dir, "model_error", direct=False)
    parent = Path(out_dir).resolve().parent
    if parent.name == "studies" and (parent / "model_error").is_dir():
        dirs = list(dict.fromkeys([*dirs, parent / "model_error"]))
    return dirs


def convergence_dirs(model_error_dirs) -> list[Path]:
    """The hex27 convergence study's folders (:data:`CONVERGENCE_STUDY`) next to the existing
    model-error study folders ``model_error_dirs`` (both under the results root's studies)."""
    out = [Path(d).parent.joinpath(*CONVERGENCE_STUDY) for d in model_error_dirs or ()]
    return [p for p in dict.fromkeys(out) if p.is_dir()]


def run_settings(runs: pd.DataFrame, records=()) -> dict[str, Setting]:
    """Case -> the :class:`Setting` of its first run in ``runs``: from the record's provenance
    when there is one, else from the run's configuration (``default`` resolved through the
    report's frozen table, :data:`bench.report.catalogue.CASES`)."""
    from bench.report.catalogue import case_info

    by_hash = {r.get("config_hash"): r for r in records or () if isinstance(r, dict)}
    out: dict[str, Setting] = {}
    for _, r in runs.iterrows():
        case = str(r["case"])
        if case in out:
            continue
        rec = by_hash.get(r.get("config_hash"), {})
        cfg = rec.get("config") or {}
        prov = (rec.get("result") or {}).get("provenance") or {}
        requested = str(prov.get("treatment_requested") or r.get("treatment") or "none")
        info = case_info(case) if requested == "default" else None
        d = info.default_treatment if info else None  # (treatment, plate margin mm, hifi mesh)
        treatment = prov.get("treatment") or (d[0] if d else requested)
        margin = prov.get("region_plate_margin_mm")
        if margin is None:
            margin = d[1] if d else cfg.get("plate_margin_mm", 0.0)
        hifi = prov.get("hifi_mesh") or (d[2] if d else cfg.get("hifi_mesh") or "")
        mesh = prov.get("inverse_mesh") or r.get("mesh") or ""
        dh = prov.get("data_hash") or r.get("data_hash")
        out[case] = Setting(
            requested,
            str(treatment),
            str(mesh),
            float(margin or 0.0),
            str(hifi or ""),
            dh if isinstance(dh, str) else None,
        )
    return out


def _read(path: Path) -> dict | None:
    try:
        row = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return row if isinstance(row, dict) else None


def _biases(row: dict | None, key: str = "linearised_bias_percent") -> dict[str, float]:
    out = {}
    for p, v in ((row or {}).get(key) or {}).items():
        try:
            v = float(v)
        except (TypeError, ValueError):
            continue
        if math.isfinite(v):
            out[str(p)] = v
    return out


def load_study(dirs, settings: dict[str, Setting]) -> dict[str, dict] | None:
    """Per case of ``settings``: ``{"bias": {parameter: %}, "floor": (parameter, %) | None,
    "hifi_mesh": str, "stale": bool}`` from the first folder of ``dirs`` holding the case's rows;
    None when no folder exists at all (the study was not found). A case without rows is left out,
    and so is one whose rows name another high-fidelity mesh than its runs (a suite's
    ``hifi_mesh``; the convergence study may stand in); ``stale``: the rows were made with other
    data than the runs (their numbers are not used)."""
    dirs = [Path(d) for d in dirs or () if Path(d).is_dir()]
    if not dirs:
        return None
    out: dict[str, dict] = {}
    for case, s in settings.items():
        key = f"{s.mesh}__{{}}__margin{s.margin:g}__fe"
        for d in dirs:
            own = _read(d / case / f"{key.format(s.treatment)}.json") or _read(
                d / case / f"{key.format(s.treatment)}__bias.json"
            )
            floor = _read(d / case / f"{key.format(FLOOR_TREATMENT)}__bias.json")
            if own is None and floor is None:
                continue
            if s.hifi_mesh and s.hifi_mesh != _hifi_of(own, floor, s.hifi_mesh):
                continue  # another high-fidelity mesh: not this correction's numbers
            hashes = {(r.get("provenance") or {}).get("data_hash") for r in (own, floor) if r}
            hashes.discard(None)
            stale = bool(s.data_hash and hashes and hashes != {s.data_hash})
            fb = _biases(floor)
            worst = max(fb.items(), key=lambda kv: abs(kv[1])) if fb else None
            out[case] = {
                "bias": {} if stale else _biases(own),
                "floor": None if stale or worst is None else (worst[0], abs(worst[1])),
                "hifi_mesh": str(((floor or {}).get("provenance") or {}).get("hifi_mesh") or ""),
                "stale": stale,
                "source": "model_error",
            }
            break
    return out


def _hifi_of(own: dict | None, floor: dict | None, default: str) -> str:
    """The high-fidelity mesh the study's rows ``own`` and ``floor`` name in their provenance
    (the floor's first), ``default`` when neither names one."""
    for row in (floor, own):
        hifi = ((row or {}).get("provenance") or {}).get("hifi_mesh")
        if hifi:
            return str(hifi)
    return default


def load_convergence(dirs, settings: dict[str, Setting]) -> dict[str, dict]:
    """Per case of ``settings``, like :func:`load_study` from the first folder of ``dirs``
    holding ``<case>/convergence.json`` with the entry needed: for treatment ``none``, ``bias``
    the ``data_bias_pct`` of the inverse mesh's entry (linearised bias against the model-error
    data mesh's response, %) and no floor; for a correction, no bias (the study has no treated
    objective) and ``floor`` the worst ``data_bias_pct`` (parameter, |%|) of the high-fidelity
    mesh's entry. ``data_mesh``: the study's data mesh. Cases without that entry are left out."""
    out: dict[str, dict] = {}
    for case, s in settings.items():
        for d in dirs or ():
            conv = _read(Path(d) / case / "convergence.json") or {}
            meshes = {
                str(m.get("mesh")): m for m in conv.get("meshes") or () if isinstance(m, dict)
            }
            none = s.treatment == "none"
            own = _biases(meshes.get(s.mesh), "data_bias_pct") if none else {}
            hifi = "" if none else s.hifi_mesh
            fb = _biases(meshes.get(hifi), "data_bias_pct") if hifi else {}
            if not (own or fb):
                continue
            worst = max(fb.items(), key=lambda kv: abs(kv[1])) if fb else None
            out[case] = {
                "bias": own,
                "floor": None if worst is None else (worst[0], abs(worst[1])),
                "hifi_mesh": hifi,
                "stale": False,
                "source": "convergence",
                "data_mesh": str(conv.get("data_mesh") or ""),
            }
            break
    return out


def _case_frame(t: pd.DataFrame) -> pd.DataFrame:
    """The cases of a Table 1 that have an identification, as a runs-like frame of their median
    errors (``err.<parameter>``), for :func:`bench.report.tables.success`."""
    n_id = t.attrs.get("n_identified", {})
    cases = [c for c in t.columns if n_id.get(c, 1) > 0 and t[c].notna().any()]
    df = pd.DataFrame(
        {f"err.{p}": [float(t.loc[p, c]) for c in cases] for p in t.index}, index=cases
    )
    df.attrs["parameters"] = list(t.index)
    return df


def _cases(n: int) -> str:
    return f"{n} case" + ("" if n == 1 else "s")


def _max_identified(row: pd.Series, dt: dict) -> float:
    """The largest |error| of a case's identified parameters (derived ones such as a left out,
    as in the study's rows)."""
    vals = [abs(float(v)) for k, v in row.items() if k[4:] not in dt and math.isfinite(v)]
    return max(vals, default=math.nan)


def model_error_note(
    t: pd.DataFrame,
    settings: dict[str, Setting],
    study: dict[str, dict] | None,
    *,
    tol: float = T.SUCCESS_TOL,
    derived_tol: dict | None = None,
    doc: str | None = None,
    study_name: str = "`results/studies/model_error`",
    convergence_name: str = "`results/studies/convergence/hex27-g8`",
) -> str:
    """The Markdown note under a model-error Table 1 ``t`` (:func:`bench.report.tables.table1`).

    ``settings``: case -> :class:`Setting` of the table's runs; ``study``: :func:`load_study`
    (None: the study was not found; rows of :func:`load_convergence` may stand in for cases it
    lacks); ``doc``: the link to docs/objective.md (plain text when None); ``study_name``,
    ``convergence_name``: the model-error and convergence study folders as Markdown (name or
    link). The success criterion is
    :func:`bench.report.tables.success` applied to the table's medians."""
    dt = dict(T.DERIVED_TOL if derived_tol is None else derived_tol)
    med = _case_frame(t)
    ok = T.success(med, tol, dt)
    cases = list(med.index)
    miss = [c for c in cases if not ok[c]]
    sets = [settings[c] for c in cases if c in settings]
    tags = " / ".join(dict.fromkeys(f"`{s.tag()}`" for s in sets)) or "unknown"
    descs = "; ".join(dict.fromkeys(s.describe() for s in sets))
    head = (
        f"**Model-error tier, treatment {tags}**" + (f" ({descs})" if descs else "") + ": "
        f"**{int(ok.sum())} of {len(cases)} cases** in the table above (its medians) have "
        f"{T.success_rule(tol, dt)}."
    )
    if not miss:
        return head + "\n"
    if doc:
        ref = " and ".join(f"[{k}]({doc}#{a})" for k, a in DOC_ANCHORS.items())
        ref += " in docs/objective.md"
    else:
        ref = "docs/objective.md"

    def worst(c):
        errs = {p: float(med.loc[c, f"err.{p}"]) for p in t.index}
        errs = {p: v for p, v in errs.items() if math.isfinite(v)}
        return max(errs.items(), key=lambda kv: abs(kv[1]) / dt.get(kv[0], tol))

    def floored(c):  # treatment none has no high-fidelity model, hence no floor
        return c not in settings or settings[c].treatment != "none"

    rows = [r for r in ((study or {}).get(c) for c in miss) if r]
    conv = [r for r in rows if r.get("source") == "convergence"]
    mixed = bool(conv) and len(conv) < len(rows)
    hifi = next((r["hifi_mesh"] for r in rows if r.get("hifi_mesh")), "")
    hifi = hifi or next((s.hifi_mesh for s in sets if s.hifi_mesh), "") or "high-fidelity"
    if study is None:
        head += (
            " The cases that miss, with their worst parameter (the largest error against its "
            "tolerance):"
        )
    else:
        src_old = f"the model-error study ({study_name}; same case, data and treatment)"
        dm = next((r["data_mesh"] for r in conv if r.get("data_mesh")), "")
        conv_bias = any(r["bias"] for r in conv)
        src_conv = (
            f"the hex27 convergence study ({convergence_name}; "
            + ("the `data_bias_pct` of the inverse mesh's entry, " if conv_bias else "")
            + "against the model-error data"
            + (f" mesh `{dm}`)" if dm else ")")
        )
        how_old = (
            f"the study's `{FLOOR_TREATMENT}` row: the one-point correction made at the "
            "reference, the limit of the iterated correction"
        )
        how_conv = "the worst `data_bias_pct` of its entry in the convergence study"
        if mixed:
            src = f"{src_old} or, for the cases marked *convergence*, {src_conv}"
            how = f"{how_old}; or {how_conv}"
        elif conv:
            src, how = src_conv, how_conv + ": the limit of the iterated correction"
        else:
            src, how = src_old, how_old
        head += (
            " The cases that miss, with their worst parameter (the largest error against its "
            f"tolerance) and, from {src}, "
        )
        if conv and not conv_bias and not mixed:  # corrections: no treated objective's bias
            head += "the *floor*"
        else:
            head += (
                "the *bias*: the linearised bias of the same objective, i.e. the error of a "
                "perfect optimiser"
            )
        head += (
            (
                ("; and the *floor*" if conv_bias or not conv or mixed else "")
                + ": the largest error the high-fidelity model "
                f"`{hifi}` itself leaves against the model-error data ({how}), which limits "
                f"every correction that subtracts a discretisation error computed on `{hifi}`:"
            )
            if any(floored(c) for c in miss)
            else ":"
        )
    items, diffs, below, floors = [], [], [], []
    for c in miss:
        p, e = worst(c)
        item = f"- {c}: {p} {T.fmt_pct(e)} %"
        row = None if study is None else study.get(c)
        if study is None:
            pass
        elif row is None:
            item += " (not in the study)"
        elif row["stale"]:
            item += " (the study's rows were made with other data)"
        else:
            b = row["bias"].get(p)
            parts = [f"bias {T.fmt_pct(b)} %" if b is not None else f"bias {T.DASH}"]
            if row.get("source") == "convergence" and not row["bias"]:
                parts = []  # a correction: the convergence study gives only its floor
            if mixed and row.get("source") == "convergence":
                parts.insert(0, "*convergence*")
            if b is not None:
                diffs.append(abs(b - e))
            if row["floor"] is not None and floored(c):
                fp, fv = row["floor"]
                parts.append(f"floor {T.fmt_pct(fv)} % on {fp}")
                floors.append(fv)
                below.append(_max_identified(med.loc[c], dt) < fv)
            item += " (" + "; ".join(parts) + ")"
        items.append(item)
    out = [head, "", *items, ""]
    if study is None:
        out.append(
            f"The model-error study ({study_name}) was not found, so this report cannot say "
            "whether these misses are biases of the objective or how far the high-fidelity "
            f"model's own error is from the target; see {ref}."
        )
        return "\n".join(out) + "\n"
    why = []
    if diffs:
        n = f"all {_cases(len(diffs))}" if len(diffs) == len(miss) else _cases(len(diffs))
        why.append(
            f"The bias agrees with the table within {max(diffs):.2g} points on the worst "
            f"parameter ({n})"
            + (
                ": the misses are biases of the objective, not failures of the optimiser, so more "
                "iterations or another solver would not remove them."
                if max(diffs) <= 0.5
                else "."
            )
        )
    if floors and max(floors) <= tol:
        why.append(
            f"The floor is within {tol:g} % on all {_cases(len(floors))} "
            f"({T.fmt_pct(min(floors))}–{T.fmt_pct(max(floors))} %): the error `{hifi}` itself "
            "leaves does not keep these cases from the target; the rest of the miss is the "
            "correction's or the optimiser's."
        )
    elif floors:
        bae = any(s.treatment == "bae" for c, s in settings.items() if c in miss)
        why.append(
            f"The floor is above {tol:g} % on {sum(f > tol for f in floors)} of these "
            f"{_cases(len(floors))} ({T.fmt_pct(min(floors))}–{T.fmt_pct(max(floors))} %): "
            f"subtracting a discretisation error computed on `{hifi}` cannot reach the target "
            "there; "
            + (
                "BAE, which also takes the directions in which that error varies out of the fit, "
                if bae
                else "the identification "
            )
            + f"ends below the floor on {sum(below)} of them, but not within the target."
        )
    if not diffs and not floors:
        why.append("The study has no usable rows for these cases and this treatment.")
    out.append(" ".join(why + [f"See {ref}."]))
    return "\n".join(out) + "\n"

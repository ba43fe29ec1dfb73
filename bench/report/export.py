"""Export of run records for the community's readers: IOHanalyzer (``ioh``) and COCO (``cocopp``).

``femubench report DIR --format ioh,coco`` writes, next to report.md,

* ``ioh/<method>/IOHprofiler_f<id>_<name>.json`` and
  ``ioh/<method>/data_f<id>_<name>/IOHprofiler_f<id>_DIM<n>.dat``: the format of
  ``ioh.logger.Analyzer`` (one ``evaluations raw_y`` block per run, a line at every improvement
  and one at the run's last evaluation; ``raw_y = f - f_opt``), which IOHanalyzer reads;
* ``coco/<method>/bbobexp_f<id>.info`` and ``coco/<method>/data_f<id>/bbobexp_f<id>_DIM<n>.dat``
  (and ``.tdat``): the format of ``cocoex.Observer("bbob")`` (``bbob-new2``), which ``cocopp``
  reads (``cocopp.main("coco/<method>")``); only the runs of BBOB problems, as cocopp knows
  COCO's own suites only.

What a run contributes is its improvement trace ``[[evaluations, best f], ...]``: the result's
exact per-call ``trace`` when the record has one, else the history rows (one per iteration or
generation; the shipped FE records). The FE cases' problems are the case with its data tier and
treatment, their algorithms the solver with its track and Jacobian when not the defaults.
``f_opt`` is the problem's known ``f_min``; without one, the best cost any run of the problem
reached (FE cases: 0, a least-squares cost being >= 0). A BBOB problem (factory arguments
``function`` and ``instance``) keeps its function and instance numbers; any other problem gets the
function number of its position among the problems in alphabetical order, and instance 1 for
every run.

The report reads records only: nothing here imports problems/ or solvers/.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from pathlib import Path

#: IOH's format version this writer follows (``ioh.logger.Analyzer`` 0.4.2)
IOH_VERSION = "0.4.2"
#: COCO's data format and the cocoex version whose observer it follows
COCO_FORMAT, COCO_VERSION = "bbob-new2", "2.8.2"


@dataclass(frozen=True)
class ExportRun:
    """One run as the exports see it: problem, method, dimension, function and instance numbers,
    ``f_opt``, the improvement trace ``((evaluations, best f), ...)`` and the evaluations spent."""

    problem: str
    method: str
    dimension: int
    function: int
    instance: int
    f_opt: float
    trace: tuple
    n_evals: int
    suite: str
    x_best: tuple = ()


def _trace_of(rec) -> list[tuple[int, float]]:
    res = rec["result"]
    if res.get("trace"):  # exact per call (records since the every-call accounting)
        return [(int(n), float(f)) for n, f in res["trace"]]
    best, out = math.inf, []
    for h in res.get("history") or []:
        f = h.get("best_cost", h.get("cost"))
        n = h.get("n_evals")
        if f is None or n is None or not math.isfinite(float(f)):
            continue
        if float(f) < best:
            best = float(f)
            if out and out[-1][0] == int(n):
                out[-1] = (int(n), best)
            else:
                out.append((int(n), best))
    return out


def export_runs(records) -> list[ExportRun]:
    """The :class:`ExportRun` of every record that evaluated at least one usable point."""
    rows = []
    for rec in records:
        cfg, res = rec["config"], rec["result"]
        trace = _trace_of(rec)
        if not trace:
            continue
        prob = (res.get("extra") or {}).get("problem") or {}
        args = (cfg.get("problem") or {}).get("args") or {}
        rows.append(
            dict(
                problem=_problem_key(cfg),
                method=_method_key(cfg),
                dimension=len(res.get("parameter_names") or []) or int(prob.get("n_params", 0)),
                bbob=_bbob_numbers(cfg),
                args=args,
                f_min=prob.get("f_min"),
                user=bool(cfg.get("problem")),
                trace=tuple(trace),
                n_evals=max(int(res.get("n_evals") or 0), trace[-1][0]),
                x=tuple(float(v) for v in res.get("x") or []),
            )
        )
    names = sorted({r["problem"] for r in rows})
    best = {}
    for r in rows:
        best[r["problem"]] = min(best.get(r["problem"], math.inf), r["trace"][-1][1])
    out = []
    for r in rows:
        if r["f_min"] is not None:
            f_opt = float(r["f_min"])
        else:
            f_opt = best[r["problem"]] if r["user"] else 0.0
        fid, iid = r["bbob"] or (names.index(r["problem"]) + 1, 1)
        out.append(
            ExportRun(
                problem=r["problem"],
                method=r["method"],
                dimension=r["dimension"],
                function=fid,
                instance=iid,
                f_opt=f_opt,
                trace=r["trace"],
                n_evals=r["n_evals"],
                suite="bbob" if r["bbob"] else "femubench",
                x_best=r["x"],
            )
        )
    return out


def _problem_key(cfg) -> str:
    """A user problem's name; an FE case with its data tier and model-error treatment (they are
    different objectives)."""
    if cfg.get("problem"):
        return cfg["case"]
    treatment = cfg.get("treatment", "none")
    return f"{cfg['case']}-{cfg.get('tier', 'model-error')}" + (
        f"-{treatment}" if treatment != "none" else ""
    )


def _method_key(cfg) -> str:
    """The solver, with its track and Jacobian when not the defaults (different algorithms)."""
    return (
        cfg["method"]
        + (f"-{cfg['track']}" if cfg.get("track", "fe") != "fe" else "")
        + (f"-jac-{cfg['jacobian']}" if cfg.get("jacobian", "exact") != "exact" else "")
    )


def _bbob_numbers(cfg) -> tuple[int, int] | None:
    spec = cfg.get("problem") or {}
    args = spec.get("args") or {}
    if "bbob" in str(spec.get("entry", "")) and isinstance(args.get("function"), int):
        return int(args["function"]), int(args.get("instance", 1))
    return None


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.+-]+", "_", name)


def _atomic(path: Path, text: str) -> None:
    from bench.experiment.store import atomic_write_text  # the one atomic writer

    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, text)


def _groups(runs, key):
    out: dict = {}
    for r in runs:
        out.setdefault(key(r), []).append(r)
    return out


# --- IOHprofiler ----------------------------------------------------------------------------------


def ioh_dat_block(run: ExportRun) -> str:
    """One run's block of an IOHprofiler ``.dat`` file: a line at every improvement and at the last
    evaluation (``raw_y = best f - f_opt``), as ``ioh.logger.Analyzer`` writes it."""
    lines = ["evaluations raw_y"]
    for n, f in run.trace:
        lines.append(f"{n} {f - run.f_opt:.10f}")
    if run.trace[-1][0] < run.n_evals:
        lines.append(f"{run.n_evals} {run.trace[-1][1] - run.f_opt:.10f}")
    return "\n".join(lines) + "\n"


def write_ioh(records, dest: str | Path) -> list[Path]:
    """Write the IOHprofiler folders of ``records`` under ``dest`` (one folder per method);
    return the JSON files written."""
    dest = Path(dest)
    written = []
    for (method, fid, name), runs in sorted(
        _groups(export_runs(records), lambda r: (r.method, r.function, _fname(r))).items()
    ):
        folder = dest / _safe(method)
        scenarios = []
        for dim, rs in sorted(_groups(runs, lambda r: r.dimension).items()):
            rel = f"data_f{fid}_{name}/IOHprofiler_f{fid}_DIM{dim}.dat"
            _atomic(folder / rel, "".join(ioh_dat_block(r) for r in rs))
            scenarios.append(
                {
                    "dimension": dim,
                    "path": rel,
                    "runs": [
                        {
                            "instance": r.instance,
                            "evals": r.n_evals,
                            "best": {
                                "evals": r.trace[-1][0],
                                "y": r.trace[-1][1] - r.f_opt,
                                "x": list(r.x_best),
                            },
                        }
                        for r in rs
                    ],
                }
            )
        doc = {
            "version": IOH_VERSION,
            "suite": runs[0].suite,
            "function_id": fid,
            "function_name": name,
            "maximization": False,
            "algorithm": {"name": method, "info": "femubench"},
            "attributes": ["evaluations", "raw_y"],
            "scenarios": scenarios,
        }
        path = folder / f"IOHprofiler_f{fid}_{name}.json"
        _atomic(path, json.dumps(doc, indent=1) + "\n")
        written.append(path)
    return written


def _fname(run: ExportRun) -> str:
    if run.suite == "bbob":
        return f"bbob-f{run.function}"
    return _safe(run.problem)


# --- COCO -----------------------------------------------------------------------------------------

_COCO_HEADER = (
    "% f evaluations | g evaluations | best noise-free fitness - Fopt ({fopt:.12e}) + sum g_i+ | "
    "measured fitness | best measured fitness or single-digit g-values | x1 | x2...\n"
)


def _coco_line(n: int, f: float, f_opt: float) -> str:
    return f"{n} 0 {f - f_opt:+.9e} {f:+.9e} {f:+.9e}\n"


def coco_blocks(run: ExportRun) -> tuple[str, str]:
    """One run's blocks of the COCO ``.dat`` (a line at every improvement and at the last
    evaluation) and ``.tdat`` (the same lines: the trace is all that is known between them)."""
    head = _COCO_HEADER.format(fopt=run.f_opt)
    body = "".join(_coco_line(n, f, run.f_opt) for n, f in run.trace)
    if run.trace[-1][0] < run.n_evals:
        body += _coco_line(run.n_evals, run.trace[-1][1], run.f_opt)
    return head + body, head + body


def write_coco(records, dest: str | Path) -> tuple[list[Path], int]:
    """Write the COCO data folders of the BBOB runs among ``records`` under ``dest`` (one folder
    per method, the argument of ``cocopp.main``); return the ``.info`` files written and the
    number of runs left out: cocopp reads COCO's own suites only (its testbeds are hard-wired),
    so the runs of other problems go to the IOH export alone."""
    dest = Path(dest)
    written = []
    every = export_runs(records)
    bbob = [r for r in every if r.suite == "bbob"]
    for (method, fid), runs in sorted(_groups(bbob, lambda r: (r.method, r.function)).items()):
        folder = dest / _safe(method)
        info = []
        for dim, rs in sorted(_groups(runs, lambda r: r.dimension).items()):
            stem = f"data_f{fid}/bbobexp_f{fid}_DIM{dim}"
            dat, tdat = zip(*(coco_blocks(r) for r in rs))
            _atomic(folder / f"{stem}.dat", "".join(dat))
            _atomic(folder / f"{stem}.tdat", "".join(tdat))
            runs_txt = ", ".join(
                f"{r.instance}:{r.n_evals}|{r.trace[-1][1] - r.f_opt:.1e}" for r in rs
            )
            info.append(
                f"suite = '{rs[0].suite}', funcId = {fid}, DIM = {dim}, Precision = 1.000e-08, "
                f"algId = '{method}', coco_version = '{COCO_VERSION}', logger = 'bbob', "
                f"data_format = '{COCO_FORMAT}', settings = ''\n% {rs[0].problem}\n"
                f"{stem}.dat, {runs_txt}\n"
            )
        path = folder / f"bbobexp_f{fid}.info"
        _atomic(path, "".join(info))
        written.append(path)
    return written, len(every) - len(bbob)

"""Running suites: one identification per task, in-process or on a Dask cluster, resumable.

* :func:`run_one` runs one :class:`~bench.experiment.spec.RunSpec` and returns its record; it never
  raises — any exception becomes a record with ``status == "failed"`` and the traceback in the
  message (and in ``record["error"]``), so one crash never takes a suite down.
* :func:`run_suite` skips every run that already has a record in ``DIR/runs/`` and runs the
  rest (a record file that cannot be read, or whose content or config does not match, is moved
  into ``DIR/runs/corrupt/``, one made on other data than today's into ``DIR/runs/stale/``; both
  are logged and their runs run again); it writes ``DIR/<suite>.plan.json`` (every planned run)
  for the report. Runs go with ``workers=1`` in a plain loop in this process (debugging,
  profiling), otherwise on a Dask ``LocalCluster`` of ``workers`` single-threaded worker processes
  (default: one per core; capped at the cores and the pending runs; BLAS/OpenMP pinned to one
  thread; Ctrl-C ignored, the client handles it), or on an existing cluster given by
  ``scheduler``.
  Records are written by this process (the client) as runs complete, atomically, so a
  ``kill -9`` at any moment loses at most the runs in flight and never leaves half a record.

Inside a run the objective evaluates Jacobian columns and population batches sequentially by
default: with one run per core the cluster is already saturated. ``fan_out=True`` (CLI
``--fan-out``) hands the objective a mapper that submits those batches to the same cluster
through :func:`distributed.worker_client` — useful when there are fewer runs than cores.
"""

from __future__ import annotations

import datetime as _dt
import functools
import logging
import os
import platform
import sys
import time
import traceback
import warnings
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from bench.experiment import store
from bench.experiment.spec import RunSpec, canonical_json, config_hash
from bench.experiment.suite import Suite

# thread pinning for every worker process
from bench.parallel import SINGLE_THREAD_ENV, WorkerClientMapper, cap_workers, sigint_ignored

log = logging.getLogger("femubench.runner")

#: Distinct warnings kept per record.
MAX_WARNINGS = 20
#: Format tag of ``DIR/<suite>.plan.json`` (:func:`write_plan`).
PLAN_FORMAT = "femubench-plan/1"
#: Packages whose versions go into every record.
VERSIONED = (
    "femubench",
    "numpy",
    "scipy",
    "nlopt",
    "pymoo",
    "pyswarms",
    "emcee",
    "dask",
    "distributed",
    "pandas",
    "meshio",
    "SALib",
    "numba",
    "llvmlite",
    "kvxopt",
    "scikit-learn",
    "cma",
    "nevergrad",
    "scikit-optimize",
)


def now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="milliseconds")


@functools.lru_cache(maxsize=1)
def versions() -> dict[str, str]:
    """Versions of Python, femubench (plus its git commit when run from a checkout) and the
    numerical packages."""
    from importlib import metadata

    out = {"python": platform.python_version()}
    for name in VERSIONED:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            pass
    commit = _git_commit()
    if commit:
        out["femubench_git"] = commit
    return out


def _git_commit() -> str | None:
    """HEAD of the checkout femubench is imported from (read from .git, no subprocess)."""
    root = Path(__file__).resolve().parent.parent / ".git"
    try:
        head = (root / "HEAD").read_text().strip()
        if head.startswith("ref: "):
            ref = head[5:]
            p = root / ref
            if p.is_file():
                return p.read_text().strip()
            packed = root / "packed-refs"
            if packed.is_file():
                for line in packed.read_text().splitlines():
                    if line.endswith(" " + ref):
                        return line.split()[0]
            return None
        return head
    except OSError:
        return None


@functools.lru_cache(maxsize=1)
def machine() -> dict[str, Any]:
    """Where a run was executed."""
    try:
        affinity = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - macOS, Windows
        affinity = os.cpu_count()
    return {
        "hostname": platform.node(),
        "platform": platform.platform(),
        "machine": platform.machine(),
        "processor": platform.processor(),
        "python": sys.version.split()[0],
        "cpu_count": os.cpu_count(),
        "cpu_affinity": affinity,
        "omp_num_threads": os.environ.get("OMP_NUM_THREADS"),
        "arch": arch(),
    }


@functools.lru_cache(maxsize=1)
def arch() -> str:
    """The code paths a run's arithmetic took: the CPU that numba compiles for and the kernels
    of the BLAS numpy loaded (e.g. ``"znver4; openblas Zen"``). Two machines of one kind can
    differ here, and then floating-point results differ in the last digits."""
    import numpy  # noqa: F401  (load every BLAS the runs use: numpy's, scipy's, kvxopt's)
    import scipy.linalg  # noqa: F401

    try:
        import kvxopt  # noqa: F401
    except ImportError:  # pragma: no cover - a dependency
        pass

    parts = []
    try:
        import llvmlite.binding as llvm

        parts.append(llvm.get_host_cpu_name())
    except Exception:  # pragma: no cover - numba is a dependency
        parts.append("?")
    try:
        from threadpoolctl import threadpool_info

        blas = [
            f"{i.get('internal_api')} {i.get('architecture')}"
            for i in threadpool_info()
            if i.get("user_api") == "blas"
        ]
        parts += sorted(set(blas))
    except Exception:  # pragma: no cover - threadpoolctl comes with scikit-learn
        pass
    return "; ".join(parts)


def is_analytic(case_name: str) -> bool:
    from problems.inverse.cases import get_case

    return get_case(case_name).is_analytic


def dataset_for(spec: RunSpec, *, progress: bool = False):
    """The measured data set of a run of an FE case (:meth:`DataSpec.load
    <bench.experiment.spec.DataSpec.load>`); None for an analytic case or a user problem."""
    if spec.problem or is_analytic(spec.case):
        return None
    return spec.data.load(spec.case, spec.mesh, progress=progress)


def failed_result(config: RunSpec, message: str, *, n_evals: int = 0, wall_s: float = 0.0):
    """A RunResult for a run that crashed before (or while) its solver returned: no answer, its
    start point ``x0`` (the spec's, when the case is known)."""
    import math

    from solvers.result import RunResult

    names, ref, x0 = [], [], None
    try:  # best effort: an unknown case or start has none
        from problems.inverse.cases import get_case
        from problems.inverse.starts import start_point

        case = get_case(config.case)
        names, ref = list(case.names), [float(v) for v in case.reference]
        x0 = start_point(case, kind=config.start, seed=config.seed, index=config.start_index)
    except Exception:  # noqa: BLE001
        pass
    x0 = [float(v) for v in x0] if x0 is not None else []
    xn = [a / b if b else math.nan for a, b in zip(x0, ref)] if len(x0) == len(ref) else []
    return RunResult(
        method=config.method,
        options=dict(config.options),
        seed=config.seed,
        budget=config.budget,
        parameter_names=names,
        reference=ref,
        x0=x0,
        x=list(x0),
        x_normalised=xn,
        cost=math.nan,
        status="failed",
        success=False,
        message=message,
        n_evals=int(n_evals),
        wall_s=wall_s,
    )


def run_one(
    config: RunSpec | dict,
    *,
    mapper: Callable | None = None,
    suite: str | None = None,
    dataset=None,
) -> dict[str, Any]:
    """Run one identification and return its record (see :mod:`bench.experiment.store`); never
    raises (except KeyboardInterrupt/SystemExit).

    ``dataset``: the run's measured data (a problems.inverse.data.Dataset) when the caller prepared
    it; by default the objective assembly loads (or makes) it (:meth:`DataSpec.load
    <bench.experiment.spec.DataSpec.load>`).
    """
    if isinstance(config, dict):
        config = RunSpec.from_dict(config)
    started, t0 = now(), time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:  # kept in the record, not on the console
        warnings.simplefilter("always")
        warnings.simplefilter("ignore", DeprecationWarning)
        warnings.simplefilter("ignore", PendingDeprecationWarning)
        result, data_hash, error = _run_guarded(config, mapper, dataset, t0)
    record = make_record(
        config,
        result,
        suite=suite,
        data_hash=data_hash,
        error=error,
        started=started,
        finished=now(),
    )
    seen = []
    for w in caught:
        text = f"{w.category.__name__}: {w.message}"
        if text not in seen:
            seen.append(text)
    record["warnings"] = seen[:MAX_WARNINGS]
    return record


def _run_guarded(config: RunSpec, mapper, dataset, t0):
    error = data_hash = None
    evaluations = [0]  # the objective's counter, kept for a crash report
    try:
        if config.problem:  # a user problem (an entry point): .user_problems
            from bench.experiment.user_problems import run_user

            count = [lambda ev, _: evaluations.__setitem__(0, ev.n_evals)]
            return run_user(config, mapper=mapper, observers=count), None, None
        from bench.experiment.identify import identify

        result = identify(
            config,
            mapper=mapper,
            dataset=dataset,
            observers=[lambda ev, _: evaluations.__setitem__(0, ev.n_evals)],
        )
        data_hash = result.provenance.get("data_hash")
    except Exception as exc:  # a crash must never take a suite down
        error = "".join(traceback.format_exception(exc))
        result = failed_result(
            config,
            f"{type(exc).__name__}: {exc}\n{error}",
            n_evals=evaluations[0],
            wall_s=time.perf_counter() - t0,
        )
    return result, data_hash, error


def make_record(
    config: RunSpec,
    result,
    *,
    suite=None,
    data_hash=None,
    error=None,
    started=None,
    finished=None,
) -> dict[str, Any]:
    res = result.to_dict() if hasattr(result, "to_dict") else dict(result)
    return {
        "schema": store.RECORD_SCHEMA,
        "config_hash": config_hash(config),
        "config": config.to_dict(),
        "suite": suite,
        "result": res,
        "data_hash": data_hash,
        "error": error,
        "versions": versions(),
        "machine": machine(),
        "started": started,
        "finished": finished,
        "warnings": [],
    }


# --- inside a Dask task --------------------------------------------------------------------


def _dask_task(config: dict, suite: str | None, fan_out: bool, dataset=None) -> dict:
    """The Dask task: one identification (module-level so that it pickles by reference)."""
    return run_one(
        config, mapper=WorkerClientMapper() if fan_out else None, suite=suite, dataset=dataset
    )


# --- suites -----------------------------------------------------------------------------------


@dataclass
class SuiteSummary:
    """What :func:`run_suite` did."""

    name: str
    out_dir: Path
    total: int
    skipped: int
    ran: int = 0
    failed: int = 0
    crashed: int = 0
    wall_s: float = 0.0
    removed_tmp: int = 0
    log_file: Path | None = None
    failures: list[str] = field(default_factory=list)
    set_aside: list[Path] = field(default_factory=list)
    stale: list[Path] = field(default_factory=list)
    #: labels of the runs skipped now whose record is a crash (rerun with ``retry_failed``)
    crashed_before: list[str] = field(default_factory=list)

    def __str__(self) -> str:
        text = (
            f"suite {self.name!r}: {self.total} runs, {self.skipped} already done, {self.ran} run "
            f"now ({self.failed} not successful, {self.crashed} crashed) in {self.wall_s:.1f} s; "
            f"records in {store.runs_dir(self.out_dir)}"
        )
        if self.set_aside:
            text += (
                f"; {len(self.set_aside)} unreadable record(s) moved to "
                f"{store.corrupt_dir(self.out_dir)} (their runs were run again)"
            )
        if self.stale:
            text += (
                f"; {len(self.stale)} record(s) made on other data moved to "
                f"{store.runs_dir(self.out_dir) / store.STALE} (their runs were run again)"
            )
        return text


def default_workers() -> int:
    """One worker per core this process may use."""
    return cap_workers(None)


@contextmanager
def _dir_lock(out_dir: Path):
    """Exclusive lock on the results directory (released by the OS even on kill -9)."""
    import fcntl

    out_dir.mkdir(parents=True, exist_ok=True)
    fh = open(out_dir / ".lock", "a+")
    try:
        try:
            fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise ValueError(
                f"another 'femubench run' is writing to {out_dir}; wait for it or use another --out"
            ) from None
        yield
    finally:
        fh.close()


@contextmanager
def _suite_log(path: Path):
    logger = logging.getLogger("femubench")
    handler = logging.FileHandler(path, encoding="utf-8")
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(message)s"))
    old_level = logger.level
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    try:
        yield
    finally:
        logger.removeHandler(handler)
        logger.setLevel(old_level)
        handler.close()


def pending_runs(
    suite: Suite,
    out_dir: str | Path,
    *,
    force: bool = False,
    retry_failed: bool = False,
    records: list[dict] | None = None,
):
    """``(all_runs, pending)``: the suite's runs and those to run now (no readable record yet, or
    a record made on other data than today's (:func:`stale_records`), or all of them with
    ``force``, or also the crashed ones with ``retry_failed``). ``records``: the readable
    records of ``out_dir`` when the caller has them (default: scanned now)."""
    runs = suite.runs()
    if force:
        return runs, list(runs)
    if records is None:
        records = store.scan_records(out_dir)[0]
    done = {rec["config_hash"]: rec for rec in records}
    for rec, _ in stale_records(runs, done):
        del done[rec["config_hash"]]
    pending = [r for r in runs if config_hash(r) not in done]
    if retry_failed:
        pending += [r for r in runs if done.get(config_hash(r), {}).get("error")]
    return runs, pending


def crashed_records(runs: list[RunSpec], pending: list[RunSpec], records) -> list[str]:
    """Labels of the runs not in ``pending`` whose record (among ``records``) is a crash."""
    crashed = {r["config_hash"] for r in records if r.get("error")}
    todo = {config_hash(r) for r in pending}
    return [r.label for r in runs if config_hash(r) in crashed - todo]


def current_data_hash(config: RunSpec) -> str | None:
    """The hash of the data set ``config`` would use today (its file, which
    ``$FEMUBENCH_DATA_DIR`` may change), or None: no data set (analytic case, user problem) or
    none on disk yet (it will be made from the run's settings, as the record's was)."""
    if config.problem or is_analytic(config.case):
        return None
    from problems.inverse.data import data_path, load

    path = config.data.file or data_path(config.case, config.data.data_settings(config.mesh))
    try:
        return load(path).hash
    except (OSError, ValueError):  # missing or torn: made (or reported) when the run runs
        return None


def current_data_mesh(config: RunSpec) -> str | None:
    """The discretisation key of the mesh that makes the data set ``config`` would use today
    (None for a data file, an analytic case or a user problem)."""
    if config.data.file or config.problem or is_analytic(config.case):
        return None
    from problems.fe.mesh import discretisation_key

    return discretisation_key(config.data.data_settings(config.mesh).mesh)


def stale_records(runs: list[RunSpec], done: dict[str, dict]) -> list[tuple[dict, str]]:
    """``(record, reason)`` of every record in ``done`` (by config hash) of one of ``runs`` that
    was made on other data than the run would use today: its ``data_hash`` differs from
    :func:`current_data_hash`, or, while today's data set is not on disk yet (a non-default
    set, made when its first run runs), the data mesh in its provenance differs from
    :func:`current_data_mesh` (a re-pointed tier). A record without ``data_hash`` is accepted."""
    from problems.fe.mesh import discretisation_key

    today: dict = {}
    out = []
    for cfg in runs:
        rec = done.get(config_hash(cfg))
        if rec is None or not rec.get("data_hash"):
            continue
        key = data_key(cfg)
        if key not in today:
            today[key] = (current_data_hash(cfg), current_data_mesh(cfg))
        data_hash, data_mesh = today[key]
        if data_hash is not None and data_hash != rec["data_hash"]:
            out.append(
                (rec, f"made on data {rec['data_hash'][:12]}, today's data is {data_hash[:12]}")
            )
            continue
        made_on = ((rec.get("result") or {}).get("provenance") or {}).get("data_mesh")
        if data_hash is None and data_mesh and made_on:
            if discretisation_key(made_on) != data_mesh:
                out.append(
                    (rec, f"made on data of mesh {made_on}, today's data mesh is {data_mesh}")
                )
    return out


def set_aside_stale(runs: list[RunSpec], out_dir: Path, records: list[dict]) -> list[Path]:
    """Move the records of ``runs`` (among ``records``, the readable records of ``out_dir``) made
    on other data than today's into ``DIR/runs/stale/`` and drop them from ``records`` (logged;
    only call while holding the directory lock); return their new paths."""
    done = {rec["config_hash"]: rec for rec in records}
    moved = []
    for rec, why in stale_records(runs, done):
        new = store.set_aside(store.record_path(out_dir, rec["config_hash"]), store.STALE)
        log.warning("record %s %s: moved to %s, its run runs again", new.name, why, new.parent)
        moved.append(new)
        records.remove(rec)
    return moved


def write_plan(suite: Suite, runs: list[RunSpec], out_dir: Path) -> Path:
    """Write ``DIR/<suite>.plan.json``: the config hash and label of every planned run, so that a
    report can say which runs are missing (:mod:`bench.report.completeness`)."""
    from problems.io.jsonio import dumps

    doc = {
        "format": PLAN_FORMAT,
        "suite": suite.name,
        "runs": [{"hash": config_hash(r), "label": r.label} for r in runs],
    }
    return store.atomic_write_text(out_dir / f"{suite.name}.plan.json", dumps(doc, indent=0) + "\n")


def worker_count(workers: int | None, n_pending: int) -> int:
    """Worker processes of a local cluster: ``workers`` (default: one per core) capped at the
    cores and at the pending runs (at least 1)."""
    return max(1, min(cap_workers(workers), n_pending))


def set_aside_unreadable(out_dir: Path, unreadable=None) -> list[Path]:
    """Move the unreadable records of ``out_dir`` (``unreadable``: ``(path, reason)`` found by
    :func:`bench.experiment.store.scan_records`, default: scanned now) aside (logged); return
    their new paths."""
    moved = []
    for old, new, why in store.set_aside_unreadable(out_dir, unreadable):
        log.warning(
            "unreadable record %s (%s) moved to %s; its run counts as not done", old.name, why, new
        )
        moved.append(new)
    return moved


def run_suite(
    suite: Suite,
    out_dir: str | Path,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    force: bool = False,
    retry_failed: bool = False,
    progress: bool = True,
    fan_out: bool = False,
) -> SuiteSummary:
    """Run every run of ``suite`` that has no record in ``out_dir`` (all of them with ``force``)."""
    out_dir = Path(out_dir)
    if workers is not None and workers < 1:
        raise ValueError(f"--workers must be >= 1, got {workers}")
    if workers is not None and scheduler is not None:
        raise ValueError("give either --workers or --scheduler, not both")
    t0 = time.perf_counter()
    with _dir_lock(out_dir):
        store.runs_dir(out_dir).mkdir(parents=True, exist_ok=True)
        removed = store.clean_tmp(out_dir)
        if suite.source:
            store.atomic_write_text(out_dir / f"{suite.name}.suite.toml", suite.source)
        log_file = out_dir / f"{suite.name}.log"
        with _suite_log(log_file):
            records, unreadable = store.scan_records(out_dir)  # read once
            set_aside = set_aside_unreadable(out_dir, unreadable)
            stale = [] if force else set_aside_stale(suite.runs(), out_dir, records)
            runs, pending = pending_runs(
                suite, out_dir, force=force, retry_failed=retry_failed, records=records
            )
            write_plan(suite, runs, out_dir)
            summary = SuiteSummary(
                suite.name,
                out_dir,
                len(runs),
                len(runs) - len(pending),
                removed_tmp=removed,
                log_file=log_file,
                set_aside=set_aside,
                stale=stale,
                crashed_before=crashed_records(runs, pending, records),
            )
            if removed:
                log.warning(
                    "removed %d stray temporary file(s) left by an interrupted run", removed
                )
            n_workers = worker_count(workers, len(pending))
            if workers is not None and n_workers < workers and scheduler is None:
                log.info(
                    "--workers %d capped at %d (%d cores, %d pending runs)",
                    workers,
                    n_workers,
                    default_workers(),
                    len(pending),
                )
            where = scheduler or (
                "in-process" if n_workers == 1 else f"local cluster of {n_workers} workers"
            )
            log.info(
                "suite %s: %d runs, %d with a record, %d to run (%s)%s",
                suite.name,
                len(runs),
                summary.skipped,
                len(pending),
                where,
                ", --force" if force else "",
            )
            datasets = prepare_datasets(pending, progress=progress)
            bar = _progress(suite.name, len(runs), summary.skipped, progress)
            try:
                todo = []
                for cfg in pending:  # runs whose data could not be made fail right away
                    ds = datasets.get(data_key(cfg))
                    if isinstance(ds, BaseException):
                        msg = "".join(traceback.format_exception(ds))
                        rec = make_record(
                            cfg,
                            failed_result(cfg, f"data set: {type(ds).__name__}: {ds}\n{msg}"),
                            suite=suite.name,
                            error=msg,
                            started=now(),
                            finished=now(),
                        )
                        _finish(summary, out_dir, cfg, rec, bar)
                    else:
                        todo.append(cfg)
                if not todo:
                    pass
                elif scheduler is None and n_workers == 1:
                    for cfg in todo:
                        rec = run_one(cfg, suite=suite.name, dataset=datasets.get(data_key(cfg)))
                        _finish(summary, out_dir, cfg, rec, bar)
                else:
                    _run_dask(
                        summary,
                        out_dir,
                        todo,
                        suite.name,
                        bar,
                        n_workers=n_workers,
                        scheduler=scheduler,
                        fan_out=fan_out,
                        datasets=datasets,
                    )
            except KeyboardInterrupt:
                log.warning(
                    "interrupted: %d runs finished now, %d left for the next 'femubench run'",
                    summary.ran,
                    len(pending) - summary.ran,
                )
                raise
            finally:
                bar.close()
                summary.wall_s = time.perf_counter() - t0
            log.info("done: %s", summary)
    return summary


def data_key(config: RunSpec) -> tuple | None:
    """Runs with the same key share one data set (None: analytic, no data set): the case, the data
    tier, the inverse mesh (a consistent-tier data set is made on it), the data settings and the
    data file."""
    if config.problem or is_analytic(config.case):
        return None  # user problems and analytic cases have no data set
    d = config.data
    return config.case, d.tier, config.mesh, canonical_json(d.settings), d.file


def prepare_datasets(pending: list[RunSpec], *, progress: bool = False) -> dict:
    """Load (or make, once) the data set of every FE case x data settings among ``pending``, here
    in the client, so that workers receive the data with the task (no shared file system needed)
    and a non-default data set is computed once, not by every run. Failures are returned as the
    exception, which turns the affected runs into failed records."""
    out: dict = {}
    for cfg in pending:
        key = data_key(cfg)
        if key is None or key in out:
            continue
        t0 = time.perf_counter()
        try:
            out[key] = dataset_for(cfg, progress=progress)
            log.info(
                "data set of %s %s: hash %s (%.1f s)",
                cfg.case,
                key[1],
                getattr(out[key], "hash", "?")[:12],
                time.perf_counter() - t0,
            )
        except Exception as exc:  # noqa: BLE001 - reported per run
            out[key] = exc
            log.error("data set of %s with %s could not be made: %s", cfg.case, key[1], exc)
    return out


def _progress(name: str, total: int, initial: int, enabled: bool):
    from tqdm.auto import tqdm

    return tqdm(
        total=total,
        initial=initial,
        desc=name,
        unit="run",
        disable=not enabled,
        dynamic_ncols=True,
        smoothing=0.05,
        file=sys.stderr,
    )


def _finish(summary: SuiteSummary, out_dir: Path, cfg: RunSpec, record: dict, bar) -> None:
    store.write_record(out_dir, record)
    res = record["result"]
    summary.ran += 1
    verdict = ((res.get("extra") or {}).get("problem") or {}).get("success")  # a user problem's
    if not (res.get("success") if verdict is None else verdict):
        summary.failed += 1
    if record.get("error"):
        summary.crashed += 1
        summary.failures.append(cfg.label)
        log.error("run %s crashed:\n%s", cfg.label, record["error"])
    log.info(
        "%s: %s cost=%s n_evals=%s wall=%.2fs [%s]",
        cfg.label,
        res.get("status"),
        res.get("cost"),
        res.get("n_evals"),
        float(res.get("wall_s") or 0.0),
        record["config_hash"][:12],
    )
    for w in record.get("warnings") or []:
        log.warning("%s: %s", cfg.label, w)
    bar.update(1)
    bar.set_postfix(unsuccessful=summary.failed, crashed=summary.crashed, refresh=False)


def _run_dask(
    summary, out_dir, pending, suite_name, bar, *, n_workers, scheduler, fan_out, datasets=None
):
    import uuid

    from distributed import Client, LocalCluster, as_completed

    cluster = None
    if scheduler is None:
        with sigint_ignored():  # Ctrl-C stops this process, which closes the workers quietly
            cluster = LocalCluster(
                n_workers=n_workers,
                threads_per_worker=1,
                processes=True,
                dashboard_address=":0",
                env=dict(SINGLE_THREAD_ENV),
                silence_logs=logging.ERROR,
            )
        client = Client(cluster)
    else:
        try:
            client = Client(scheduler, timeout="20s")
        except (OSError, TimeoutError) as exc:
            raise ValueError(f"cannot reach the Dask scheduler at {scheduler!r}: {exc}") from None
    try:
        log.info("dask: %s, dashboard %s", client, getattr(client, "dashboard_link", "?"))
        tag = uuid.uuid4().hex[:8]
        scattered = {
            k: client.scatter(ds, hash=False)
            for k, ds in (datasets or {}).items()
            if not isinstance(ds, BaseException)
        }
        by_key = {}
        futures = []
        for cfg in pending:
            key = f"femubench-{config_hash(cfg)[:16]}-{tag}"
            fut = client.submit(
                _dask_task,
                cfg.to_dict(),
                suite_name,
                fan_out,
                scattered.get(data_key(cfg)),
                key=key,
                pure=False,
            )
            by_key[fut.key] = cfg
            futures.append(fut)
        for fut in as_completed(futures):
            cfg = by_key[fut.key]
            try:
                record = fut.result()
            except Exception as exc:  # worker died (KilledWorker), unpicklable result, ...
                msg = "".join(traceback.format_exception(exc))
                record = make_record(
                    cfg,
                    failed_result(cfg, f"{type(exc).__name__}: {exc}\n{msg}"),
                    suite=suite_name,
                    error=msg,
                    started=None,
                    finished=now(),
                )
            _finish(summary, out_dir, cfg, record, bar)
            fut.release()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()

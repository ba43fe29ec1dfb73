"""Suites: a TOML file describing cases x methods x seeds x starts x budgets, and its runs.

A suite is loaded with :func:`load_suite` (or :func:`parse_suite` from a dict), validated
strictly *before anything runs* — every unknown key, unknown case or method and impossible
value is reported with the allowed values — and expanded by :meth:`Suite.runs` into a list of
:class:`~bench.experiment.spec.RunSpec`, one per identification (its hash keys the run's record
in the results store).

The schema is documented in ``docs/suites.md``; in short::

    [suite]
    name = "default"                 # optional, defaults to the file name
    description = "..."              # optional
    cases = "all"                    # or a list of case names (analytic-* included)
    methods = ["lm", "gauss-newton"]
    seeds = [0]                      # optional, default [0]
    starts = ["default"]             # "default" and/or "random"; optional
    random_starts = 1                # random starts per seed when "random" is listed
    budgets = [200]                  # forward evaluations per run
    mesh = "coarse"                  # optional
    hifi_mesh = "fine"               # optional: the corrections' high-fidelity mesh

    [data]                           # optional, passed to build_objective(data=...)
    noise_um = 0.0

    [options.lm]                     # optional, per-method solver options
    xtol = 1e-10

    [problems.rosen]                 # optional: a user problem, listed in 'cases' by its name
    entry = "mypkg.mod:factory"      # or "path/to/file.py:factory" (problems.user)
    args = {n = 5}                   # keyword arguments of the factory (optional)
    grid = {seed = [1, 2]}           # optional: one problem per combination, named
                                     # rosen-seed1, rosen-seed2
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from bench.experiment.spec import (
    DEFAULT_SURROGATE,
    JACOBIANS,
    START_KINDS,
    TRACKS,
    DataSpec,
    RunSpec,
    Treatment,
)
from problems.inverse.build import PLATE_MARGIN_TEXT, Region
from problems.inverse.evaluator import BUDGET_UNITS
from problems.inverse.model_error import TREATMENTS
from problems.io.tomlio import read_toml

SUITE_KEYS = {
    "name": "suite name (string; default: the file name without .toml)",
    "description": "free text",
    "cases": '"all" or a list of case names',
    "methods": "list of method names",
    "seeds": "list of non-negative integers (default [0])",
    "starts": 'list of "default" and/or "random" (default ["default"])',
    "random_starts": "random starts per seed when 'random' is listed (integer >= 1, default 1)",
    "budgets": "list of positive integers: forward evaluations per run",
    "mesh": "FE mesh name (default 'coarse')",
    "tiers": 'list of data tiers, "model-error" and/or "consistent" (default ["model-error"])',
    "treatments": (
        'list of model-error treatments: "none", "one-point", "iterated", "first-order", "bae" '
        '(default ["none"])'
    ),
    "plate_margin_mm": f"{PLATE_MARGIN_TEXT} (default 0)",
    "hifi_mesh": (
        "high-fidelity mesh spec of the correction treatments (one-point, iterated, first-order, "
        "bae), finer than mesh and not the data's; none runs unchanged; not with default (it sets "
        "its own) (default: problems.inverse.build.hifi_mesh_for(mesh))"
    ),
    "tracks": (
        'list of "fe" (the solver on the FE model) and/or "surrogate" (the solver on the stored '
        'default surrogate, then an FE polish) (default ["fe"])'
    ),
    "jacobians": (
        'list of "exact" (the model\'s own Jacobian), "forward", "central" (finite differences); '
        'only methods that use a Jacobian are run with each (default ["exact"])'
    ),
    "budget_unit": '"evaluations" or "forward-equivalents" (nominal; default "evaluations")',
    "polish_budget": "FE evaluations of the polish after a surrogate-track run (default 100)",
    "free_repeats": (
        "true: repeated points are free (FE economy); default false: every call counts, repeats "
        "included (COCO's rule)"
    ),
}
#: treatments that a suite's ``hifi_mesh`` does not apply to: ``none`` has no high-fidelity
#: model, ``default`` sets its own (:meth:`~bench.experiment.spec.Treatment.resolved`; refused
#: with the key)
NO_HIFI = ("none", "default")
PART_KEYS = tuple(k for k in SUITE_KEYS if k not in ("name", "description"))
TOP_KEYS = ("suite", "part", "data", "options", "problems")
PROBLEM_KEYS = {
    "entry": "'package.module:factory' or 'path/to/file.py:factory' (problems.user)",
    "args": "table of keyword arguments of the factory (optional)",
    "grid": "table of lists: one problem per combination of these arguments (optional)",
}


@dataclass(frozen=True)
class Part:
    """One product of run dimensions of a suite (the [suite] table, or one [[part]] over it)."""

    cases: tuple[str, ...]
    methods: tuple[str, ...]
    seeds: tuple[int, ...] = (0,)
    starts: tuple[str, ...] = ("default",)
    random_starts: int = 1
    budgets: tuple[int, ...] = (200,)
    mesh: str = "coarse"
    tiers: tuple[str, ...] = ("model-error",)
    treatments: tuple[str, ...] = ("none",)
    plate_margin_mm: float = 0.0
    hifi_mesh: str | None = None
    tracks: tuple[str, ...] = ("fe",)
    jacobians: tuple[str, ...] = ("exact",)
    budget_unit: str = "evaluations"
    polish_budget: int = 100
    free_repeats: bool = False

    def runs(self, data: dict, options: dict, problems: dict | None = None) -> list[RunSpec]:
        """All runs, ordered track, tier, treatment, case, method, Jacobian, budget, seed, start,
        start index. The consistent tier is never corrected (it runs once, untreated, whatever
        the treatments); ``hifi_mesh`` reaches the corrections only (not ``none`` nor ``default``:
        :data:`NO_HIFI`); the Jacobian choice only multiplies the methods that use one; a
        deterministic method runs once from the default start (under the first seed)."""
        out = []
        for track, tier, treatment, case, method, jac, budget, seed, start in itertools.product(
            self.tracks,
            self.tiers,
            self.treatments,
            self.cases,
            self.methods,
            self.jacobians,
            self.budgets,
            self.seeds,
            self.starts,
        ):
            if tier == "consistent" and treatment != self.treatments[0]:
                continue  # nothing to correct: the data come from the inverse model itself
            if tier == "consistent":
                treatment = "none"
            if jac != "exact" and not uses_jacobian(method):
                continue
            if start == "default" and seed != self.seeds[0] and not is_stochastic(method):
                continue  # a deterministic method from the default start gives one answer
            n = 1 if start == "default" else self.random_starts
            for i in range(n):
                out.append(
                    RunSpec(
                        case,
                        method,
                        seed,
                        start,
                        i,
                        budget,
                        self.mesh,
                        dict(options.get(method, {})),
                        DataSpec(tier, dict(data)),
                        Treatment(
                            treatment,
                            self.plate_margin_mm,
                            None if treatment in NO_HIFI else self.hifi_mesh,
                        ),
                        surrogate=DEFAULT_SURROGATE if track == "surrogate" else None,
                        polish_budget=self.polish_budget if track == "surrogate" else 0,
                        jacobian=jac,
                        budget_unit=self.budget_unit,
                        free_repeats=self.free_repeats,
                        problem=dict((problems or {}).get(case, {})),
                    )
                )
        return out


@dataclass(frozen=True)
class Suite:
    """A validated suite: its parts (products of run dimensions) and the shared settings."""

    name: str
    parts: tuple[Part, ...]
    data: dict = field(default_factory=dict)
    options: dict = field(default_factory=dict)  # method -> {option: value}
    description: str = ""
    source: str | None = None  # the TOML text it was read from, if any
    problems: dict = field(default_factory=dict)  # name -> {"entry": ..., "args": {...}}

    def runs(self) -> list[RunSpec]:
        """All runs of all parts, each once (in part order)."""
        seen, out = set(), []
        for part in self.parts:
            for r in part.runs(self.data, self.options, self.problems):
                if r.hash not in seen:
                    seen.add(r.hash)
                    out.append(r)
        return out

    def with_problem(self, name: str, spec: dict) -> "Suite":
        """This suite's methods, budgets, seeds and starts on the user problem ``spec``
        (``{"entry", "args"}``) alone, as the suite ``<name of this suite>-<name>``; ValueError
        when the entry point cannot be loaded."""
        from problems.user import load_factory

        load_factory(spec["entry"])
        parts = tuple(dataclasses.replace(p, cases=(name,)) for p in self.parts)
        return dataclasses.replace(
            self,
            name=f"{self.name}-{name}",
            parts=parts,
            problems={name: dict(spec)},
            source=None,
        )

    def _union(self, attr: str) -> tuple:
        return tuple(dict.fromkeys(v for p in self.parts for v in getattr(p, attr)))

    @property
    def cases(self) -> tuple[str, ...]:
        return self._union("cases")

    @property
    def methods(self) -> tuple[str, ...]:
        return self._union("methods")

    @property
    def seeds(self) -> tuple[int, ...]:
        return self._union("seeds")

    @property
    def starts(self) -> tuple[str, ...]:
        return self._union("starts")

    @property
    def budgets(self) -> tuple[int, ...]:
        return self._union("budgets")

    @property
    def tiers(self) -> tuple[str, ...]:
        return self._union("tiers")

    @property
    def treatments(self) -> tuple[str, ...]:
        return self._union("treatments")

    @property
    def random_starts(self) -> int:
        return max(p.random_starts for p in self.parts)

    @property
    def mesh(self) -> str:
        """The inverse mesh (of the first part; parts may differ)."""
        return self.parts[0].mesh

    def __len__(self) -> int:
        return len(self.runs())

    @property
    def total_budget(self) -> int:
        """Upper bound on the evaluations of the whole suite (solver budget plus FE polish)."""
        return sum(r.budget + r.polish_budget for r in self.runs())


def is_stochastic(method: str) -> bool:
    """Whether ``method`` draws random numbers (so that its seeds give different runs)."""
    from solvers import find_method

    info = find_method(method)
    return info is None or bool(info.stochastic)


def uses_jacobian(method: str) -> bool:
    """Whether ``method`` asks the objective for Jacobians (so that exact and finite-difference
    Jacobians are two different runs of it)."""
    from solvers import find_method

    info = find_method(method)
    return info is not None and "scheme" in (info.options or {})


# --- what is allowed ------------------------------------------------------------------------


def _mesh_error(mesh) -> str | None:
    """Why ``mesh`` is not a valid mesh spec (``coarse``, ``NX,NY,NZ``, optionally ``:quarter``), or
    None."""
    from problems.fe.mesh import parse_mesh_spec

    if not isinstance(mesh, str):
        return f"mesh must be a string, got {mesh!r}"
    from bench.resources import check_mesh_memory

    try:
        parse_mesh_spec(mesh)
        check_mesh_memory(mesh)
    except ValueError as exc:
        return str(exc)
    return None


def _data_settings() -> dict[str, tuple]:
    """Allowed [data] keys (the fields of problems.inverse.data.DataSettings) -> accepted Python
    types."""
    from problems.inverse.data import DataSettings

    return {
        f.name: _types_like(f.default) for f in dataclasses.fields(DataSettings) if f.name != "tier"
    }  # the tier is a suite dimension: [suite] tiers


#: [data] keys checked together when levels_mm is given (it must end at displacement_mm and have
#: snapshots values)
_JOINT_DATA_KEYS = ("levels_mm", "snapshots", "displacement_mm")


def _data_settings_errors(data: dict) -> list[str]:
    """Every reason ``data`` does not make valid DataSettings (each key alone, the machine log's
    keys together), or []."""
    from problems.inverse.data import DataSettings

    def why(values: dict) -> str | None:
        try:
            DataSettings(**values)
        except (ValueError, TypeError) as exc:
            return str(exc)
        return None

    joint = _JOINT_DATA_KEYS if "levels_mm" in data else ()
    alone = [why({k: v}) for k, v in data.items() if k not in joint]
    errors = [e for e in alone if e]
    together = {k: v for k, v in data.items() if k in joint}
    if together and why(together):
        errors.append(why(together))
    if not errors and why(data):  # the combination of individually valid values
        errors.append(why(data))
    return errors


def method_options(method: str) -> dict | None:
    """The declared options ``{name: solvers.options.Option}`` of a method, None if unknown."""
    from solvers import find_method

    info = find_method(method)
    return None if info is None else dict(info.options or {})


def _types_like(default) -> tuple:
    if isinstance(default, bool):
        return (bool,)
    if isinstance(default, int):
        return (int,)
    if isinstance(default, float):
        return (float,)
    if isinstance(default, str):
        return (str,)
    if default is None:
        return (bool, int, float, str)
    if isinstance(default, (list, tuple)):
        return (list,)
    return (object,)


# --- loading and validation -----------------------------------------------------------------


def load_suite(path: str | Path) -> Suite:
    """Read and validate a suite TOML file; raise ValueError naming every problem."""
    path = Path(path)
    raw, text = read_toml(path, "suite")
    return parse_suite(raw, name=path.stem, source=text, where=str(path))


def missing_surrogates(runs) -> list[str]:
    """One line per default surrogate that the surrogate-track runs among ``runs`` need and
    that is nowhere to be found (:func:`bench.experiment.surrogate_track.surrogate_folder`),
    saying how to get it. ``femubench run`` asks this of its pending runs only: a suite whose
    surrogate-track runs all have their records needs no surrogate."""
    from bench.experiment.surrogate_track import missing_default, surrogate_folder
    from problems.surrogate.store import JSON_NAME, NPZ_NAME, default_name

    missing = []
    for case, mesh in dict.fromkeys((r.case, r.mesh) for r in runs if r.track == "surrogate"):
        folder = surrogate_folder(default_name(case, mesh))
        if folder is None or not all((folder / n).is_file() for n in (JSON_NAME, NPZ_NAME)):
            missing.append(missing_default(case, mesh))
    return missing


def parse_suite(
    raw: dict, *, name: str = "suite", source: str | None = None, where: str = "suite"
) -> Suite:
    """Validate a suite given as a dict (the parsed TOML); raise ValueError listing all errors."""
    errors: list[str] = []

    def err(msg):
        errors.append(msg)

    if not isinstance(raw, dict):
        raise ValueError(f"{where}: a suite is a TOML table")
    for key in raw:
        if key not in TOP_KEYS:
            err(
                f"unknown top-level table [{key}]; allowed: "
                f"{', '.join('[[part]]' if k == 'part' else '[' + k + ']' for k in TOP_KEYS)}"
            )
    s = raw.get("suite")
    if s is None:
        err("missing table [suite] (with at least 'cases', 'methods' and 'budgets')")
        s = {}
    elif not isinstance(s, dict):
        err("'suite' must be a table: [suite]")
        s = {}
    for key in s:
        if key not in SUITE_KEYS:
            hint = _did_you_mean(key, SUITE_KEYS)
            err(f"[suite] unknown key {key!r}{hint}; allowed: {', '.join(SUITE_KEYS)}")

    # name / description
    sname = s.get("name", name)
    if not isinstance(sname, str) or not sname.strip():
        err(f"[suite] name must be a non-empty string, got {sname!r}")
        sname = name
    elif not all(c.isalnum() or c in "-_." for c in sname):
        err(f"[suite] name {sname!r} may contain only letters, digits, '-', '_' and '.'")
    description = s.get("description", "")
    if not isinstance(description, str):
        err(f"[suite] description must be a string, got {description!r}")
        description = ""

    problems = _parse_problems(raw.get("problems", {}), err)

    parts_raw = raw.get("part", [])
    if not isinstance(parts_raw, list) or not all(isinstance(p, dict) for p in parts_raw):
        err("'part' must be an array of tables: [[part]]")
        parts_raw = []
    specs, spec_errs = [], []  # each part's clean values and where its errors go
    if not parts_raw:
        specs.append(_parse_spec(s, err, problems))
        spec_errs.append(err)
    else:
        for i, part in enumerate(parts_raw, 1):
            for key in part:
                if key not in SUITE_KEYS or key in ("name", "description"):
                    hint = _did_you_mean(key, SUITE_KEYS)
                    err(f"[[part]] {i}: unknown key {key!r}{hint}; allowed: {', '.join(PART_KEYS)}")
            merged = {k: v for k, v in s.items() if k not in ("name", "description")} | part

            def part_err(msg, i=i):
                errors.append(msg.replace("[suite]", f"[[part]] {i}:", 1))

            specs.append(_parse_spec(merged, part_err, problems))
            spec_errs.append(part_err)
    methods = list(dict.fromkeys(m for sp in specs for m in sp["methods"] if isinstance(m, str)))

    # [data]
    raw_data = raw.get("data", {})
    if not isinstance(raw_data, dict):
        err("'data' must be a table: [data]")
        raw_data = {}
    data: dict[str, Any] = {}
    allowed_data = _data_settings()
    for key, value in raw_data.items():
        if key not in allowed_data:
            err(
                f"[data] unknown key {key!r}{_did_you_mean(key, allowed_data)}; allowed: "
                f"{', '.join(allowed_data)}"
            )
            continue
        types = allowed_data[key]
        ok, value = _coerce(value, types)
        if not ok:
            err(
                f"[data] {key} must be of type {'/'.join(t.__name__ for t in types)}, got "
                f"{raw_data[key]!r}"
            )
        elif isinstance(value, float) and not math.isfinite(value):
            err(f"[data] {key} must be finite, got {value!r}")
        data[key] = value
    if data and not any(e.startswith("[data]") for e in errors):
        for reason in _data_settings_errors(data):
            err(f"[data] {reason}")
    if not any(e.startswith("[data]") for e in errors):
        for spec, spec_err in zip(specs, spec_errs):
            for reason in _honesty_errors(spec, data):
                spec_err(reason)

    # [options.<method>]
    options = raw.get("options", {})
    if not isinstance(options, dict):
        err("'options' must be a table of per-method tables: [options.<method>]")
        options = {}
    clean_options: dict[str, dict] = {}
    for m, opts in options.items():
        if m not in methods:
            err(
                f"[options.{_q(m)}] is for method {m!r}, which the suite does not run; "
                f"the suite's methods: {', '.join(map(str, methods)) or '(none)'}"
            )
            continue
        if not isinstance(opts, dict):
            err(f"[options.{_q(m)}] must be a table of option = value")
            continue
        table = method_options(m)
        clean = {}
        for key, value in opts.items():
            if table is not None and key not in table:
                allowed = ", ".join(table) or "(this method takes no options)"
                err(
                    f"[options.{_q(m)}] unknown option {key!r}{_did_you_mean(key, table)}; "
                    f"allowed: {allowed}"
                )
                continue
            if table is not None:
                default = table[key].default
                ok, value2 = _coerce(value, _types_like(default))
                if not ok:
                    err(
                        f"[options.{_q(m)}] {key} must be like its default {default!r} "
                        f"({type(default).__name__}), got {value!r}"
                    )
                    continue
                value = value2
                why = table[key].error(value)
                if why:
                    err(f"[options.{_q(m)}] {key} = {why}; allowed: {table[key].range_text()}")
                    continue
            if isinstance(value, float) and not math.isfinite(value):
                err(
                    f"[options.{_q(m)}] {key} must be finite (leave it out to use its default), "
                    f"got {value!r}"
                )
                continue
            clean[key] = value
        if clean:
            clean_options[m] = clean

    if errors:
        raise ValueError(f"{where}: invalid suite:\n  - " + "\n  - ".join(errors))

    return Suite(
        name=sname,
        parts=tuple(Part(**spec) for spec in specs),
        data=dict(data),
        options=clean_options,
        description=description,
        source=source,
        problems=problems,
    )


def _parse_problems(raw, err) -> dict[str, dict]:
    """Validate the ``[problems.<name>]`` tables; return ``name -> {"entry", "args"}`` with every
    grid combination expanded (``<name>-<key><value>...``; a string value without its key)."""
    from problems.user import entry_point_error, load_factory

    if not isinstance(raw, dict):
        err("'problems' must be a table of [problems.<name>] tables")
        return {}
    out: dict[str, dict] = {}
    for name, table in raw.items():
        where = f"[problems.{_q(name)}]"
        if not isinstance(table, dict):
            err(f"{where} must be a table with 'entry' (and optionally 'args', 'grid')")
            continue
        for key in table:
            if key not in PROBLEM_KEYS:
                err(
                    f"{where} unknown key {key!r}{_did_you_mean(key, PROBLEM_KEYS)}; allowed: "
                    f"{', '.join(PROBLEM_KEYS)}"
                )
        entry = table.get("entry")
        why = entry_point_error(entry) if entry is not None else f"{where} missing key 'entry'"
        if why is None:
            try:
                load_factory(entry)
            except ValueError as exc:
                why = str(exc)
        if why:
            err(f"{where} {why}" if not why.startswith(where) else why)
            continue
        args, grid = table.get("args", {}), table.get("grid", {})
        if not isinstance(args, dict):
            err(f"{where} args must be a table of keyword arguments, got {args!r}")
            continue
        if not isinstance(grid, dict) or not all(isinstance(v, list) and v for v in grid.values()):
            err(f"{where} grid must be a table of non-empty lists, got {grid!r}")
            continue
        keys = list(grid)
        for combo in itertools.product(*(grid[k] for k in keys)):
            full = name + "".join(
                f"-{v}" if isinstance(v, str) else f"-{k}{v}" for k, v in zip(keys, combo)
            )
            out[full] = {
                "entry": entry,
                "args": dict(sorted((args | dict(zip(keys, combo))).items())),
            }
    return out


def _parse_spec(s: dict, err, problems: dict | None = None) -> dict:
    """Validate the run dimensions of a [suite] table (or a [[part]] merged over it); returns
    them as a dict of clean values (errors go to ``err``). ``problems``: the suite's user
    problems (names allowed in ``cases``; the default ``cases`` when there are any)."""
    # cases
    from problems.inverse.cases import CASES, all_cases
    from solvers import METHODS, find_method

    problems = problems or {}
    known_cases = list(all_cases()) + list(problems)
    cases = s.get("cases", list(problems) or None)
    if cases is None:
        err("[suite] missing key 'cases' (\"all\" or a list of case names)")
        cases = []
    elif cases == "all":
        cases = list(CASES)
    elif not isinstance(cases, list) or not cases:
        err(f'[suite] cases must be "all" or a non-empty list of case names, got {cases!r}')
        cases = []
    else:
        for c in cases:
            if not isinstance(c, str) or c not in known_cases:
                err(
                    f'[suite] cases: case {c!r} is unknown; allowed: "all" or '
                    f"{', '.join(known_cases)}"
                )
        _no_duplicates("cases", cases, err)

    # methods
    methods = s.get("methods")
    if methods is None:
        err("[suite] missing key 'methods' (a list of method names)")
        methods = []
    elif not isinstance(methods, list) or not methods:
        err(f"[suite] methods must be a non-empty list of method names, got {methods!r}")
        methods = []
    else:
        allowed = list(METHODS)
        for m in methods:
            if not isinstance(m, str) or find_method(m) is None:
                hint = _did_you_mean(m, allowed) if isinstance(m, str) else ""
                err(
                    f"[suite] methods: method {m!r} is unknown{hint}; allowed: {', '.join(allowed)}"
                    " (or nlopt:<ALGORITHM>)"
                )
        _no_duplicates("methods", methods, err)

    seeds = _int_list(s, "seeds", [0], minimum=0, err=err)
    budgets = _int_list(s, "budgets", None, minimum=1, err=err)

    starts = s.get("starts", ["default"])
    if not isinstance(starts, list) or not starts:
        err(f'[suite] starts must be a non-empty list of "default" and/or "random", got {starts!r}')
        starts = ["default"]
    else:
        for st in starts:
            if st not in START_KINDS:
                err(
                    f"[suite] starts: {st!r} is not a start kind; allowed: {', '.join(START_KINDS)}"
                )
        _no_duplicates("starts", starts, err)
        starts = [st for st in START_KINDS if st in starts]  # canonical order

    random_starts = s.get("random_starts", 1)
    if isinstance(random_starts, bool) or not isinstance(random_starts, int) or random_starts < 1:
        err(f"[suite] random_starts must be an integer >= 1, got {random_starts!r}")
        random_starts = 1
    elif "random_starts" in s and "random" not in starts:
        err('[suite] random_starts is set but starts does not list "random"')

    mesh = s.get("mesh", "coarse")
    why = _mesh_error(mesh)
    if why:
        err(f"[suite] {why}")

    from problems.inverse.data import TIERS

    tiers = _choice_list(s, "tiers", ["model-error"], TIERS, err)
    treatments = _choice_list(s, "treatments", ["none"], TREATMENTS, err)
    plate_margin = s.get("plate_margin_mm", 0.0)
    why = Region.range_error(plate_margin)
    if why:
        err(f"[suite] {why}")
        plate_margin = 0.0
    hifi_mesh = _parse_hifi_mesh(s, mesh, tiers, treatments, err)

    tracks = _choice_list(s, "tracks", ["fe"], TRACKS, err)
    if "surrogate" in tracks:
        from problems.inverse.cases import ANALYTIC_CASES

        no_surrogate = [c for c in cases if c in ANALYTIC_CASES or c in problems]
        if no_surrogate:
            err(
                f"[suite] tracks: the surrogate track is for the FE cases; "
                f"{', '.join(map(str, no_surrogate))} cannot have one (run them in a [[part]] "
                'with tracks = ["fe"])'
            )
    jacobians = _choice_list(s, "jacobians", ["exact"], JACOBIANS, err)
    budget_unit = s.get("budget_unit", "evaluations")
    if budget_unit not in BUDGET_UNITS:
        err(f"[suite] budget_unit = {budget_unit!r} is unknown; allowed: {', '.join(BUDGET_UNITS)}")
        budget_unit = "evaluations"
    polish_budget = s.get("polish_budget", 100)
    if isinstance(polish_budget, bool) or not isinstance(polish_budget, int) or polish_budget < 1:
        err(f"[suite] polish_budget = {polish_budget!r} is out of range: a whole number >= 1")
        polish_budget = 100
    free_repeats = s.get("free_repeats", False)
    if not isinstance(free_repeats, bool):
        err(f"[suite] free_repeats = {free_repeats!r} is not true/false")
        free_repeats = False
    return dict(
        cases=tuple(cases),
        methods=tuple(methods),
        seeds=tuple(seeds),
        starts=tuple(starts),
        random_starts=random_starts,
        budgets=tuple(budgets),
        mesh=mesh,
        tiers=tuple(tiers),
        treatments=tuple(treatments),
        plate_margin_mm=float(plate_margin),
        hifi_mesh=hifi_mesh,
        tracks=tuple(tracks),
        jacobians=tuple(jacobians),
        budget_unit=budget_unit,
        polish_budget=int(polish_budget),
        free_repeats=free_repeats,
    )


def _parse_hifi_mesh(s: dict, mesh, tiers: list, treatments: list, err) -> str | None:
    """The part's ``hifi_mesh`` (None when not given or refused): a valid mesh spec
    (:func:`_mesh_error`), finer than the inverse ``mesh``
    (:func:`problems.inverse.build.check_finer`, as ``identify --hifi-mesh``), with a correction
    to apply to and without ``default`` (which sets its own). Whether it is the data's
    discretisation is checked with the ``[data]`` table (:func:`_honesty_errors`)."""
    if "hifi_mesh" not in s:
        return None
    hifi_mesh = s["hifi_mesh"]
    why = _mesh_error(hifi_mesh)
    if why:
        err(f"[suite] hifi_mesh: {why}")
        return None
    corrections = [t for t in TREATMENTS if t not in NO_HIFI]
    if "default" in treatments:
        err(
            f'[suite] hifi_mesh = {hifi_mesh!r} is set but treatments lists "default", which sets '
            "its own high-fidelity mesh (femubench cases); allowed: hifi_mesh with "
            f"{', '.join(corrections)} only (run default in a [[part]] without hifi_mesh)"
        )
        return None
    if all(t in NO_HIFI for t in treatments) or "model-error" not in tiers:
        err(
            f"[suite] hifi_mesh = {hifi_mesh!r} applies to no run: it is the high-fidelity mesh "
            f"of the treatments {', '.join(corrections)} on the model-error tier; allowed: "
            "leave it out, or list one of them"
        )
        return None
    if not _mesh_error(mesh):
        from problems.inverse.build import check_finer

        try:
            check_finer(hifi_mesh, mesh, "[suite] hifi_mesh =")
        except ValueError as exc:
            err(str(exc))
            return None
    return hifi_mesh


def _honesty_errors(spec: dict, data: dict) -> list[str]:
    """Why the part ``spec``'s ``hifi_mesh`` may not be used on the model-error data of the
    ``[data]`` table ``data`` (the honesty rule,
    :func:`problems.inverse.model_error.check_honest`: never the discretisation that made the
    data), or []."""
    from problems.fe.mesh import discretisation_key
    from problems.inverse.data import tier_settings
    from problems.inverse.model_error import check_honest

    hifi_mesh = spec.get("hifi_mesh")
    if hifi_mesh is None or "model-error" not in spec["tiers"]:
        return []
    data_mesh = tier_settings("model-error", inverse_mesh=spec["mesh"], **data).mesh
    try:
        check_honest(
            discretisation_key(data_mesh), "model-error", hifi=discretisation_key(hifi_mesh)
        )
    except ValueError as exc:
        return [f"[suite] hifi_mesh = {hifi_mesh!r}: {exc}"]
    return []


def _q(m: str) -> str:
    return m if m.replace("-", "").replace("_", "").isalnum() else f'"{m}"'


def _choice_list(s: dict, key: str, default: list[str], allowed, err) -> list[str]:
    """A non-empty list of distinct names from ``allowed`` (in the order of ``allowed``)."""
    value = s.get(key, default)
    if not isinstance(value, list) or not value:
        err(
            f"[suite] {key} must be a non-empty list of {', '.join(map(repr, allowed))}, got "
            f"{value!r}"
        )
        return list(default)
    bad = [v for v in value if v not in allowed]
    if bad:
        err(f"[suite] {key}: {', '.join(map(repr, bad))} unknown; allowed: {', '.join(allowed)}")
        return list(default)
    _no_duplicates(key, value, err)
    return [a for a in allowed if a in value]


def _int_list(s: dict, key: str, default, *, minimum: int, err) -> list[int]:
    if key not in s:
        if default is None:
            err(f"[suite] missing key {key!r} ({SUITE_KEYS[key]})")
            return []
        return list(default)
    value = s[key]
    if not isinstance(value, list) or not value:
        err(f"[suite] {key} must be a non-empty list of integers, got {value!r}")
        return list(default or [])
    bad = [v for v in value if isinstance(v, bool) or not isinstance(v, int) or v < minimum]
    if bad:
        what = "positive integers" if minimum == 1 else f"integers >= {minimum}"
        err(f"[suite] {key} must be {what}; invalid: {', '.join(map(repr, bad))}")
        return []
    _no_duplicates(key, value, err)
    return list(value)


def _no_duplicates(key: str, values: list, err) -> None:
    seen, dup = set(), []
    for v in values:
        hv = repr(v)
        if hv in seen and hv not in dup:
            dup.append(hv)
        seen.add(hv)
    if dup:
        err(f"[suite] {key} lists {', '.join(dup)} more than once")


def _coerce(value, types: tuple) -> tuple[bool, Any]:
    """Accept ``value`` for ``types`` (ints where floats are expected become floats)."""
    if object in types:
        return True, value
    if isinstance(value, bool):
        return (bool in types), value
    if isinstance(value, int) and int not in types and float in types:
        return True, float(value)
    if isinstance(value, list) and list in types:
        return True, value
    return isinstance(value, tuple(t for t in types if t is not list)), value


def _did_you_mean(key: str, allowed) -> str:
    import difflib

    close = difflib.get_close_matches(str(key), list(allowed), n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""

"""Rules of the code's structure, checked on the sources (ast; nothing is imported):

* a numba kernel compiled with ``cache=True`` calls no numba kernel defined in another file
  (numba's cache is invalidated only when the caller's own file changes, so it would keep
  running stale machine code of the callee);
* the report (bench/report/, and bench/plotting.py it draws with) imports nothing from problems/
  or solvers/, at module level or inside functions: it reads records (and its frozen table,
  bench/report/catalogue.py), so the report of a results folder does not change with the code;
* every floor imports only the floors below it (problems -> nothing above; solvers -> problems;
  the experiment side of bench -> neither the report nor the commands; :data:`FLOOR_RULES`);
* no import circles among the modules of problems/, solvers/ and bench/ (module-level imports);
  imports deferred into functions hide a circle from Python but not from the reader, so their
  circles may only shrink (:data:`DEFERRED_CIRCLES`).
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("problems", "solvers", "bench")


def source_modules(root: Path = ROOT, packages=PACKAGES) -> dict[str, Path]:
    """Dotted module name -> file of every module under ``packages``."""
    out = {}
    for pkg in packages:
        for path in sorted((root / pkg).rglob("*.py")):
            parts = list(path.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            out[".".join(parts)] = path
    return out


def _module_body(tree: ast.Module):
    """The statements run at import (module level, through if/try blocks; ``if
    TYPE_CHECKING:`` blocks left out)."""
    stack = list(tree.body)
    while stack:
        node = stack.pop(0)
        if isinstance(node, ast.If):
            test = node.test
            name = test.id if isinstance(test, ast.Name) else getattr(test, "attr", None)
            if name != "TYPE_CHECKING":
                stack[:0] = node.body + node.orelse
        elif isinstance(node, ast.Try):
            stack[:0] = node.body + node.orelse + node.finalbody
            for h in node.handlers:
                stack[:0] = h.body
        else:
            yield node


def _bindings(tree: ast.Module, modules) -> tuple[dict, dict]:
    """Module-level import bindings: (local name -> module, local name -> (module, name))."""
    mods, names = {}, {}
    for node in _module_body(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.asname:
                    mods[a.asname] = a.name
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            for a in node.names:
                local = a.asname or a.name
                if f"{node.module}.{a.name}" in modules:
                    mods[local] = f"{node.module}.{a.name}"
                else:
                    names[local] = (node.module, a.name)
    return mods, names


def _cache_dicts(tree: ast.Module) -> set[str]:
    """Names of module-level dicts of jit options that set ``cache=True``."""
    out = set()
    for node in _module_body(tree):
        if isinstance(node, ast.Assign) and len(node.targets) == 1:
            target, v = node.targets[0], node.value
            if not isinstance(target, ast.Name):
                continue
            if isinstance(v, ast.Call) and getattr(v.func, "id", None) == "dict":
                if any(_is_true(k.value) for k in v.keywords if k.arg == "cache"):
                    out.add(target.id)
            elif isinstance(v, ast.Dict):
                for k, val in zip(v.keys, v.values):
                    if isinstance(k, ast.Constant) and k.value == "cache" and _is_true(val):
                        out.add(target.id)
    return out


def _is_true(node) -> bool:
    return isinstance(node, ast.Constant) and node.value is True


def _jit_kind(dec, cache_dicts) -> str | None:
    """'cached', 'jit' or None for a decorator (numba's njit/jit/vectorize/guvectorize)."""
    call = dec if isinstance(dec, ast.Call) else None
    f = call.func if call else dec
    name = f.id if isinstance(f, ast.Name) else getattr(f, "attr", None)
    if name not in ("njit", "jit", "vectorize", "guvectorize", "generated_jit"):
        return None
    if call is None:
        return "jit"
    for k in call.keywords:
        if (k.arg == "cache" and _is_true(k.value)) or (
            k.arg is None and isinstance(k.value, ast.Name) and k.value.id in cache_dicts
        ):
            return "cached"
    return "jit"


def jit_functions(tree: ast.Module) -> dict[str, tuple[str, ast.FunctionDef]]:
    """Module-level numba functions of a module: name -> (kind, node)."""
    dicts = _cache_dicts(tree)
    out = {}
    for node in tree.body:
        if isinstance(node, ast.FunctionDef):
            kinds = [k for k in (_jit_kind(d, dicts) for d in node.decorator_list) if k]
            if kinds:
                out[node.name] = ("cached" if "cached" in kinds else "jit", node)
    return out


def cross_file_kernel_calls(sources: dict[str, str]) -> list[str]:
    """Calls from a cached numba kernel to a numba kernel of another module; ``sources``:
    dotted module name -> source text. One line per call: ``caller -> callee``."""
    trees = {m: ast.parse(s) for m, s in sources.items()}
    kernels = {m: jit_functions(t) for m, t in trees.items()}
    found = []
    for mod, tree in trees.items():
        mods, names = _bindings(tree, sources)
        for fname, (kind, node) in kernels[mod].items():
            if kind != "cached":
                continue
            for call in (n for n in ast.walk(node) if isinstance(n, ast.Call)):
                f, target = call.func, None
                if isinstance(f, ast.Name) and f.id in names:
                    target = names[f.id]
                elif (
                    isinstance(f, ast.Attribute)
                    and isinstance(f.value, ast.Name)
                    and f.value.id in mods
                ):
                    target = (mods[f.value.id], f.attr)
                if target and target[0] != mod and target[1] in kernels.get(target[0], {}):
                    found.append(f"{mod}.{fname} -> {target[0]}.{target[1]}")
    return sorted(set(found))


def import_graph(sources: dict[str, str], deferred: bool = False) -> dict[str, set[str]]:
    """Module -> the modules of ``sources`` it imports at module level, with ``deferred`` also
    inside functions (``from pkg import
    name`` counts as importing ``pkg.name`` when that is a module, else ``pkg``; importing a
    module runs its parent packages too; a module's own parent packages are left out)."""
    graph = {}
    for mod, src in sources.items():
        deps = set()
        tree = ast.parse(src)
        for node in ast.walk(tree) if deferred else _module_body(tree):
            if isinstance(node, ast.Import):
                deps |= {a.name for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
                for a in node.names:
                    sub = f"{node.module}.{a.name}"
                    deps.add(sub if sub in sources else node.module)
        deps |= {p for d in deps for p in _parents(d)}
        parents = _parents(mod)
        graph[mod] = {d for d in deps if d in sources and d != mod and d not in parents}
    return graph


def _parents(mod: str) -> set[str]:
    return {mod.rsplit(".", i)[0] for i in range(1, mod.count(".") + 1)}


def import_circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(out)


def _sources() -> dict[str, str]:
    return {m: p.read_text(encoding="utf-8") for m, p in source_modules().items()}


# --- the rules on this tree -------------------------------------------------------------------


def test_cached_kernels_call_no_kernel_of_another_file():
    assert cross_file_kernel_calls(_sources()) == []


#: circles that close only through an import inside a function (the mesh spec and the 27-node
#: mesh)
DEFERRED_CIRCLES = [
    # a mesh spec's 27-node mesh is built from its 8-node mesh by mesh_quadratic (MeshSpec.build)
    ["problems.fe.mesh", "problems.fe.mesh_quadratic"],
]


def test_no_import_circles():
    assert import_circles(import_graph(_sources())) == []


def test_no_new_circles_through_deferred_imports():
    found = import_circles(import_graph(_sources(), deferred=True))
    assert [c for c in found if c not in DEFERRED_CIRCLES] == []


def imports_of(src: str) -> set[str]:
    """Every module named by an import statement of ``src`` (module level and in functions)."""
    out = set()
    for node in ast.walk(ast.parse(src)):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            out.add(node.module)
    return out


def test_the_report_imports_nothing_from_problems_or_solvers():
    found = {
        f"{mod} imports {name}"
        for mod, src in _sources().items()
        if mod.startswith("bench.report") or mod == "bench.plotting"  # the report draws with it
        for name in imports_of(src)
        if name.split(".")[0] in ("problems", "solvers")
    }
    assert sorted(found) == []


#: the floors, top to bottom, and what a floor may not import (module prefixes)
FLOOR_RULES = {
    "problems": ("solvers", "bench"),
    "solvers": ("bench",),
    # the experiment side, studies, perf scripts: neither the commands nor the report
    "bench": ("bench.commands", "bench.cli", "bench.report"),
}
#: the modules above the experiment side (they may import everything below)
TOP = ("bench.commands", "bench.cli", "bench.__main__", "bench.report")


def floor_breaches(sources: dict[str, str]) -> list[str]:
    """``"module imports name"`` for every import (module level or in a function) that reaches
    up a floor (:data:`FLOOR_RULES`)."""
    out = []
    for mod, src in sources.items():
        if mod.startswith(TOP):
            continue
        banned = FLOOR_RULES[mod.split(".")[0]]
        out += [
            f"{mod} imports {name}"
            for name in sorted(imports_of(src))
            if any(name == b or name.startswith(b + ".") for b in banned)
        ]
    return out


def test_every_floor_imports_only_the_floors_below():
    assert floor_breaches(_sources()) == []


#: the bench modules outside bench/experiment/ that the experiment side may use (helpers with no
#: run logic of their own)
EXPERIMENT_HELPERS = ("bench.paths", "bench.parallel", "bench.resources", "bench.artefacts")


def experiment_breaches(sources: dict[str, str]) -> list[str]:
    """``"module imports name"`` for every import (module level or in a function) by which
    bench/experiment/ reaches a bench module other than itself and :data:`EXPERIMENT_HELPERS`,
    or by which the report reaches the experiment side other than through its store."""
    graph = import_graph(sources, deferred=True)
    out = []
    for mod, deps in sorted(graph.items()):
        for d in sorted(deps):
            if d == "bench.experiment" or not d.startswith("bench."):
                continue
            if mod.startswith("bench.experiment."):
                bad = not d.startswith("bench.experiment.") and d not in EXPERIMENT_HELPERS
            elif mod == "bench.report" or mod.startswith("bench.report."):
                bad = d.startswith("bench.experiment.") and d != "bench.experiment.store"
            else:
                bad = False
            if bad:
                out.append(f"{mod} imports {d}")
    return out


def test_the_experiment_side_is_one_group():
    """bench/experiment/ (spec, objective, identify, suite, runner, store, surrogate track, user
    problems) imports itself and a few helpers, never a study, a calibration or the report; the
    report reaches it only through the store (reading records)."""
    assert experiment_breaches(_sources()) == []


# --- the checks themselves --------------------------------------------------------------------

_KERNELS = """
from numba import njit
_JIT = dict(cache=True, nogil=True)

@njit(cache=True)
def leaf(x):
    return x

@njit(inline="always")
def inlined(x):
    return x
"""

_CALLER = """
from numba import njit
from pkg import kernels as K
from pkg.kernels import leaf
_JIT = dict(cache=True)

@njit(**_JIT)
def bad_attribute(x):
    return K.inlined(x)

@njit(cache=True)
def bad_name(x):
    return leaf(x)

@njit
def uncached(x):
    return leaf(x)

@njit(cache=True)
def own(x):
    return uncached(x) + K.helper(x)
"""


def test_cross_file_calls_found_through_names_and_module_aliases():
    found = cross_file_kernel_calls({"pkg.kernels": _KERNELS, "pkg.caller": _CALLER})
    assert found == [
        "pkg.caller.bad_attribute -> pkg.kernels.inlined",
        "pkg.caller.bad_name -> pkg.kernels.leaf",
    ]


def test_floor_breaches_are_found():
    sources = {
        "problems.a": "def f():\n    from bench.experiment.store import x\n",
        "bench.experiment.runner": "import bench.report.tables\n",
        "bench.commands.run": "import bench.report\n",  # the top may
        "bench.experiment.store": "from bench.reporting import y\n",  # only a prefix of a name
    }
    assert floor_breaches(sources) == [
        "problems.a imports bench.experiment.store",
        "bench.experiment.runner imports bench.report.tables",
    ]


def test_experiment_breaches_are_found():
    sources = {
        "bench.paths": "",
        "bench.studies.x": "",
        "bench.experiment.store": "",
        "bench.experiment.runner": "from bench import paths\ndef f():\n import bench.studies.x\n",
        "bench.report.tables": "from bench.experiment import store\nimport bench.experiment.runner",
        "bench.commands.run": "import bench.experiment.runner\n",  # the top may
    }
    assert experiment_breaches(sources) == [
        "bench.experiment.runner imports bench.studies.x",
        "bench.report.tables imports bench.experiment.runner",
    ]


def test_imports_found_in_functions_too():
    src = "import os\nfrom problems.inverse import cases\ndef f():\n    from solvers import x\n"
    assert imports_of(src) == {"os", "problems.inverse", "solvers"}


def test_import_circles_found_at_module_level_only():
    sources = {
        "a": "from b import f\n",
        "b": "import c\n",
        "c": "from a import g\n",
        "d": "def late():\n    import a\n",
        "e": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import d\n",
    }
    assert import_circles(import_graph(sources)) == [["a", "b", "c"]]
    sources["c"] = "def late():\n    from a import g\n"
    assert import_circles(import_graph(sources)) == []

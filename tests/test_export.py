"""Exports (IOHprofiler, COCO) read back by ioh's own writer and cocopp, and the statistics of
the user-problem report (fixed target, fixed budget, rank tests with Holm's correction)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from bench.experiment import store
from bench.experiment.runner import run_suite
from bench.experiment.suite import parse_suite
from bench.report import statistics as S
from bench.report.export import export_runs, write_coco, write_ioh


@pytest.fixture(scope="module")
def bbob_dir(tmp_path_factory):
    """A tiny BBOB run: f1 and f3 in 2-D, instances 1-2, cma and de, two seeds, 120 evaluations."""
    out = tmp_path_factory.mktemp("bbob")
    raw = {
        "suite": {"name": "tiny", "methods": ["cma", "de"], "seeds": [0, 1], "budgets": [120]},
        "problems": {
            "bbob": {
                "entry": "problems.benchmarks.bbob:problem",
                "args": {"dimension": 2},
                "grid": {"function": [1, 3], "instance": [1, 2]},
            }
        },
    }
    run_suite(parse_suite(raw), out, workers=1, progress=False)
    return out


def test_coco_export_is_read_by_cocopp(bbob_dir, tmp_path):
    pytest.importorskip("cocopp")
    import matplotlib

    matplotlib.use("Agg")
    import cocopp

    records = store.load_records(bbob_dir)
    assert write_coco(records, tmp_path / "coco")[1] == 0
    ds = cocopp.load(str(tmp_path / "coco" / "cma"))
    assert sorted((d.funcId, d.dim) for d in ds) == [(1, 2), (3, 2)]
    runs = [r for r in export_runs(records) if r.method == "cma" and r.function == 3]
    d3 = next(d for d in ds if d.funcId == 3)
    assert sorted(d3.instancenumbers) == [1, 1, 2, 2]
    assert list(d3.maxevals) == [120.0] * 4
    # cocopp's ERT to a target equals the one of the traces
    target = 10.0
    hits = [S.evals_to([(n, f - r.f_opt) for n, f in r.trace], target) for r in runs]
    spent = sum(h if math.isfinite(h) else r.n_evals for h, r in zip(hits, runs))
    n_ok = sum(math.isfinite(h) for h in hits)
    assert n_ok > 0
    assert d3.detERT([target])[0] == pytest.approx(spent / n_ok)


@pytest.mark.slow
def test_cocopp_main_postprocesses_the_export(bbob_dir, tmp_path):
    """cocopp's whole post-processing (figures, tables, HTML) on the exported folder."""
    pytest.importorskip("cocopp")
    import matplotlib

    matplotlib.use("Agg")
    import cocopp

    write_coco(store.load_records(bbob_dir), tmp_path / "coco")
    cocopp.main(f"-o {tmp_path / 'pp'} {tmp_path / 'coco' / 'cma'}")
    assert (tmp_path / "pp" / "index.html").is_file()


def _read_ioh(folder: Path):
    docs = {p.name: json.loads(p.read_text()) for p in folder.glob("*.json")}
    dats = {p.relative_to(folder).as_posix(): p.read_text() for p in folder.rglob("*.dat")}
    return docs, dats


def _blocks(text):
    out = []
    for line in text.splitlines():
        if line.startswith("evaluations"):
            out.append([])
        else:
            n, y = line.split()
            out[-1].append((int(n), float(y)))
    return out


def test_ioh_export_matches_ioh_analyzer(bbob_dir, tmp_path):
    """The same runs replayed through ioh.logger.Analyzer give the same files (same names, same
    run blocks, same JSON runs)."""
    ioh = pytest.importorskip("ioh")
    records = [r for r in store.load_records(bbob_dir) if r["config"]["method"] == "de"]
    write_ioh(records, tmp_path / "ours")
    runs = [r for r in export_runs(records) if r.function == 1]
    lg = ioh.logger.Analyzer(
        root=str(tmp_path),
        folder_name="theirs",
        algorithm_name="de",
        algorithm_info="femubench",
        store_positions=False,
    )
    for r in runs:  # replay: the trace's gaps at its evaluations, a worse value elsewhere
        values = {n: f - r.f_opt for n, f in r.trace}
        best = [math.inf]

        def f(x, values=values, best=best):
            n = int(round(x[0]))
            y = values.get(n, best[0] if n == r.n_evals else best[0] + 1.0)
            best[0] = min(best[0], y)
            return y

        prob = ioh.wrap_problem(
            f, name="bbob-f1", dimension=2, instance=r.instance, lb=-1e9, ub=1e9
        )
        pid = prob.meta_data.problem_id  # ioh numbers wrapped problems itself
        prob.attach_logger(lg)
        for n in range(1, r.n_evals + 1):
            prob([float(n), 0.0])
        prob.reset()
    lg.close()
    ours, ours_dat = _read_ioh(tmp_path / "ours" / "de")
    theirs, theirs_dat = _read_ioh(tmp_path / "theirs")
    renumber = lambda s: s.replace(f"f{pid}_", "f1_")  # noqa: E731
    theirs = {renumber(k): json.loads(renumber(json.dumps(v))) for k, v in theirs.items()}
    theirs_dat = {renumber(k): v for k, v in theirs_dat.items()}
    name = "IOHprofiler_f1_bbob-f1.json"
    assert name in ours and name in theirs
    o, t = ours[name]["scenarios"][0], theirs[name]["scenarios"][0]
    assert o["path"] == t["path"] and o["dimension"] == t["dimension"] == 2
    strip = lambda rs: [(x["instance"], x["evals"], x["best"]["evals"]) for x in rs]  # noqa: E731
    assert strip(o["runs"]) == strip(t["runs"])
    for a, b in zip(o["runs"], t["runs"]):
        assert a["best"]["y"] == pytest.approx(b["best"]["y"], rel=1e-9, abs=1e-12)
    bo, bt = _blocks(ours_dat[o["path"]]), _blocks(theirs_dat[t["path"]])
    assert [[n for n, _ in b] for b in bo] == [[n for n, _ in b] for b in bt]
    assert np.allclose([y for b in bo for _, y in b], [y for b in bt for _, y in b], rtol=1e-9)
    for key in ("function_name", "maximization", "attributes"):
        assert ours[name][key] == theirs[name][key]


def test_report_formats_write_the_exports(bbob_dir, tmp_path):
    from bench.report import write_report

    md = write_report(bbob_dir, ["md", "csv", "ioh", "coco"], dest=tmp_path / "rep").read_text()
    assert "forward-equivalents" not in md and "Table 1" not in md
    assert "f − f_min ≤ 1e-08" in md and "ERT to success in evaluations" in md
    assert (tmp_path / "rep" / "coco" / "cma" / "bbobexp_f1.info").is_file()
    assert (tmp_path / "rep" / "ioh" / "de" / "IOHprofiler_f3_bbob-f3.json").is_file()
    assert (tmp_path / "rep" / "figures" / "user_ecdf.png").is_file()


# --- statistics ---
def test_holm_matches_hand_computation():
    assert np.allclose(S.holm([0.01, 0.04, 0.03, 0.2]), [0.04, 0.09, 0.09, 0.2])


def test_fixed_target_and_budget_views():
    runs = pd.DataFrame(
        {
            "method": ["a", "a", "b"],
            "problem": ["p", "p", "p"],
            "budget": [100, 100, 100],
            "n_evals": [100, 100, 80],
            "trace": [[(1, 10.0), (40, 0.5)], [(1, 5.0), (90, 2.0)], [(1, 0.1)]],
        }
    )
    ft = S.fixed_target(runs, targets=(1.0,)).set_index("method")
    assert ft.loc["a", "reached"] == 1 and ft.loc["a", "ert"] == pytest.approx((40 + 100) / 1)
    assert ft.loc["b", "ert"] == 1.0
    fb = S.fixed_budget(runs, fractions=(0.5, 1.0)).set_index("method")
    assert fb.loc["a", "gap@0.5"] == pytest.approx(np.median([0.5, 5.0]))
    assert fb.loc["a", "gap@1"] == pytest.approx(np.median([0.5, 2.0]))


def test_pairwise_tests_find_a_clear_difference_and_not_a_null_one():
    rng = np.random.default_rng(0)
    rows = []
    for p in range(8):
        for _ in range(5):
            rows.append({"method": "good", "problem": f"p{p}", "gap": 10 ** rng.uniform(-8, -6)})
            rows.append({"method": "bad", "problem": f"p{p}", "gap": 10 ** rng.uniform(-1, 1)})
            rows.append({"method": "bad2", "problem": f"p{p}", "gap": 10 ** rng.uniform(-1, 1)})
    t = S.pairwise_tests(pd.DataFrame(rows))
    over = t[t["scope"] == "all problems"].set_index(["a", "b"])
    assert over.loc[("bad", "good"), "verdict"] == "b better"
    assert over.loc[("bad", "good"), "p_holm"] < 0.05
    assert over.loc[("bad", "bad2"), "verdict"] == "no difference"
    per = t[(t["scope"] != "all problems") & (t["a"] == "bad") & (t["b"] == "good")]
    assert len(per) == 8 and (per["verdict"] == "b better").all()


def test_stats_format_adds_the_fe_statistics(tmp_path):
    """--format stats on FE records: rank tests and fixed views of the relative cost; without it
    nothing is added (the shipped report test covers that)."""
    from bench.report.user_problems import fe_frame

    raw = {
        "suite": {
            "name": "s",
            "cases": ["analytic-smooth", "analytic-linear"],
            "methods": ["lm", "de"],
            "seeds": [0, 1, 2],
            "starts": ["random"],
            "budgets": [60],
        }
    }
    out = tmp_path / "res"
    run_suite(parse_suite(raw), out, workers=1, progress=False)
    recs = store.load_records(out)
    df = fe_frame(recs)
    assert len(df) == 12 and set(df["problem"]) == {
        "analytic-smooth-model-error",
        "analytic-linear-model-error",
    }
    assert all(t[0][1] >= t[-1][1] >= 0 for t in df["trace"]) and df["gap"].min() == 0.0
    from bench.report import write_report

    md = write_report(out, ["md", "csv", "stats"], dest=tmp_path / "rep", figures=False)
    text = md.read_text()
    assert "## Statistics of the FE runs" in text and "Fixed budget" in text
    assert (tmp_path / "rep" / "tables" / "fe_rank_tests.csv").is_file()

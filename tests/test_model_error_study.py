"""The model-error study on tiny meshes: rows, resumption, torn files, the figure."""

import json

import numpy as np
import pytest

from bench.studies.model_error import render_model_error, run_model_error


@pytest.fixture(scope="module")
def data():
    from problems.inverse.data import make_data

    return make_data("linear-compression", mesh="2,2,4", snapshots=2)


def test_study_rows_resume_and_render(tmp_path, data):
    seen = []
    run = run_model_error(
        "linear-compression",
        meshes=("1,1,2",),
        treatments=("none", "one-point"),
        margins=(0.0, 40.0),
        budget=40,
        out=tmp_path,
        data=data,
        hifi_mesh="1,1,4",
        progress=lambda cfg, row: seen.append(cfg.key),
    )
    assert len(run.rows) == 4 and len(seen) == 4
    none = next(r for r in run.rows if r["treatment"] == "none" and r["plate_margin_mm"] == 0)
    point = next(r for r in run.rows if r["treatment"] == "one-point" and r["plate_margin_mm"] == 0)
    assert set(none["lm_error_percent"]) == {"E", "beta", "K", "psi", "sigma0", "H"}
    assert point["charges"]["hifi"]["n"] == 1 and "hifi" not in none["charges"]
    assert point["total_forward_equivalents"] > point["forward_equivalents"]
    assert np.isfinite(list(none["linearised_bias_percent"].values())).all()
    # resumption: nothing recomputed; a torn file is recomputed and kept aside
    torn = tmp_path / f"{run.rows[0]['mesh']}__none__margin0__fe.json"
    torn.write_text('{"case": "linear-comp')
    again = run_model_error(
        "linear-compression",
        meshes=("1,1,2",),
        treatments=("none", "one-point"),
        margins=(0.0, 40.0),
        budget=40,
        out=tmp_path,
        data=data,
        hifi_mesh="1,1,4",
    )
    assert json.loads(torn.read_text())["treatment"] == "none"
    assert (tmp_path / f"{torn.stem}.json.corrupt").exists() and len(again.rows) == 4
    assert (tmp_path / "summary.csv").read_text().count("\n") == 5
    assert render_model_error(tmp_path).stat().st_size > 1000


def test_rows_made_with_other_data_are_recomputed(tmp_path, data):
    from problems.inverse.data import make_data

    run_model_error(
        "linear-compression",
        meshes=("1,1,2",),
        treatments=("none",),
        margins=(0.0,),
        budget=20,
        out=tmp_path,
        data=data,
    )
    other = make_data("linear-compression", mesh="2,2,4", snapshots=2, resolution_um=2.0)
    run = run_model_error(
        "linear-compression",
        meshes=("1,1,2",),
        treatments=("none",),
        margins=(0.0,),
        budget=20,
        out=tmp_path,
        data=other,
    )
    assert run.rows[0]["provenance"]["data_hash"] == other.hash != data.hash


def test_overview_over_the_case_folders(tmp_path):
    from bench.studies.model_error import render_overview

    for case, err in (("linear-compression", 3.0), ("linear-shear", 40.0)):
        d = tmp_path / case
        d.mkdir()
        for t, g, fe in (("none", 0.0, 30.0), ("bae", 30.0, 900.0)):
            row = {
                "case": case,
                "mesh": "coarse",
                "route": "fe",
                "treatment": t,
                "plate_margin_mm": g,
                "lm_error_percent": {"E": err / (1 + (t == "bae")), "beta": 0.5},
                "linearised_bias_percent": {"E": err, "beta": 0.4},
                "max_abs_error_percent": err / (1 + (t == "bae")),
                "total_forward_equivalents": fe,
            }
            (d / f"coarse__{t}__margin{g:g}__fe.json").write_text(json.dumps(row))
    md, png = render_overview(tmp_path)
    text = md.read_text()
    assert "| case | mesh | none | BAE + 30 mm |" in text
    assert "| linear-shear | coarse | 40.0 % (E) [40.0], 30 | 20.0 % (E) [40.0], 900 |" in text
    assert png.stat().st_size > 1000


def test_bias_only_rows(tmp_path, data):
    run = run_model_error(
        "linear-compression",
        meshes=("1,1,2",),
        treatments=("none", "one-point"),
        margins=(0.0,),
        bias_only=True,
        out=tmp_path,
        data=data,
        hifi_mesh="1,1,4",
    )
    assert [p.name for p in sorted(tmp_path.glob("*__bias.json"))] == [
        "1,1,2__none__margin0__fe__bias.json",
        "1,1,2__one-point__margin0__fe__bias.json",
    ]
    none, point = run.rows
    assert none["bias_only"] and none["lm_error_percent"] == {} and none["n_evals"] <= 2
    assert np.isfinite(list(point["linearised_bias_percent"].values())).all()
    assert point["charges"]["hifi"]["n"] == 1
    assert point["total_forward_equivalents"] > point["forward_equivalents"]
    with pytest.raises(ValueError, match="needs the LM solution"):
        run_model_error(
            "linear-compression",
            meshes=("1,1,2",),
            treatments=("iterated",),
            margins=(0.0,),
            bias_only=True,
            out=tmp_path,
            data=data,
            hifi_mesh="1,1,4",
        )
    render_model_error(tmp_path)  # bias-only rows are drawn at their bias
    from bench.studies.model_error import HIFI_LIMIT

    limit = run_model_error(
        "linear-compression",
        meshes=("1,1,2",),
        treatments=(HIFI_LIMIT,),
        margins=(0.0,),
        bias_only=True,
        out=tmp_path,
        data=data,
        hifi_mesh="1,1,4",
    ).rows[0]
    assert limit["treatment"] == HIFI_LIMIT and limit["charges"]["hifi"]["n"] == 1
    assert limit["provenance"]["treatment"] == HIFI_LIMIT

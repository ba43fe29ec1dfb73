"""Mesh-spec lists of the benchmark scripts (bench/perf): NX,NY,NZ triples keep all their tokens."""

import pytest

from bench.perf.inverse_meshes import MESHES
from bench.perf.linear_solvers import split_specs
from problems.fe.mesh import parse_mesh_spec


def test_split_specs_keeps_grading_and_element_tokens():
    assert split_specs("coarse,paper:quarter,10,10,20:eighth,4,4,8:g1.5:hex27,6,6,12:g4") == [
        "coarse",
        "paper:quarter",
        "10,10,20:eighth",
        "4,4,8:g1.5:hex27",
        "6,6,12:g4",
    ]
    specs = split_specs(MESHES)
    assert len(specs) == 8 and specs[0] == "3,3,6:g4:hex27" and "coarse" in specs
    for s in specs:
        parse_mesh_spec(s)  # every default candidate is a valid spec
    with pytest.raises(SystemExit, match="no mesh spec"):
        split_specs(",,")

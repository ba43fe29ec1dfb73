"""The one JSON encoding: numpy to Python, non-finite floats as strings, exact round trip."""

import math

import numpy as np
import pytest

from problems.io import jsonio


def test_round_trip_of_numpy_and_non_finite_values():
    doc = {
        "a": np.array([1.5, np.nan, np.inf]),
        "b": np.float32(2.0),
        "c": (np.int64(3), -math.inf),
        4: [True, None, "text"],
    }
    text = jsonio.dumps(doc, sort_keys=True)
    assert "NaN" not in text and "Infinity" not in text  # strict JSON
    back = jsonio.loads(text)
    assert back["a"][0] == 1.5 and math.isnan(back["a"][1]) and back["a"][2] == math.inf
    assert back["b"] == 2.0 and back["c"] == [3, -math.inf]
    assert back["4"] == [True, None, "text"]


def test_plain_json_is_unchanged():
    doc = {"x": [1, 2.5, "s"], "y": {"z": False}}
    assert jsonio.encode(doc) == doc
    with pytest.raises(ValueError):
        jsonio.loads("{not json")


def test_plain_keeps_non_finite_floats():
    out = jsonio.plain({"a": np.array([np.nan, 1.0]), "b": (np.float64(np.inf),)})
    assert math.isnan(out["a"][0]) and out["b"] == [math.inf] and type(out["a"][1]) is float

"""JSON-ready conversion shared by every result."""

import json
import math

import numpy as np

from fpm_sim.results import to_jsonable


def test_numpy_values_tuples_and_non_finite_floats_become_standard_json():
    value = {
        1: (np.float64(1.5), np.int64(3)),
        "a": np.array([[1.0, math.inf], [math.nan, -2.0]]),
        "b": [np.float32(0.25), "text", None],
    }
    out = to_jsonable(value)
    assert out == {"1": [1.5, 3], "a": [[1.0, "inf"], ["nan", -2.0]], "b": [0.25, "text", None]}
    assert json.loads(json.dumps(out, allow_nan=False)) == out  # standard JSON: no NaN/Infinity tokens

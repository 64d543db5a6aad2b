"""io.files: write_json is strict JSON (no NaN); json_safe maps non-finite floats to null."""

import json
import math

import numpy as np
import pytest

from vesicle_opt.io.files import json_safe, write_json


def test_json_safe_writes_nan_as_null_and_keeps_the_rest(tmp_path):
    data = {"a": math.nan, "b": [1.5, np.float64(np.inf), {"c": np.float64(2.0)}], "d": "x", "e": 3}
    with pytest.raises(ValueError):
        write_json(tmp_path / "raw.json", data)  # strict: NaN is not JSON
    write_json(tmp_path / "safe.json", json_safe(data))
    assert json.loads((tmp_path / "safe.json").read_text()) == {"a": None, "b": [1.5, None, {"c": 2.0}],
                                                                "d": "x", "e": 3}

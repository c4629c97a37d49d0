"""anisosample.io: strict JSON (no NaN tokens), atomic writers that refuse to overwrite."""

import json

import numpy as np
import pytest

from anisosample import io


def _strict_loads(text):
    def refuse(token):
        raise ValueError(f"non-standard JSON token {token}")

    return json.loads(text, parse_constant=refuse)


def test_save_json_writes_strict_json_for_numpy_nan_and_inf(tmp_path):
    # np.float64 is a subclass of float: it used to pass through as NaN/Infinity tokens.
    data = {"a": np.float64(np.nan), "b": np.float32(np.inf), "c": np.array([1.0, -np.inf])}
    path = io.save_json(tmp_path / "x.json", data)
    got = _strict_loads(path.read_text())
    assert got == {"a": None, "b": "inf", "c": [1.0, "-inf"]}


def test_save_npz_metadata_is_strict_json_and_round_trips(tmp_path):
    pts = np.array([[0.25, 0.5]], np.float32)
    path = io.save_npz(tmp_path / "p.npz", {"points": pts}, {"loss": np.float64(np.nan), "n": 1})
    arrays, meta = io.load_npz(path)
    np.testing.assert_array_equal(arrays["points"], pts)
    assert meta["loss"] is None and meta["n"] == 1 and "jax_version" in meta
    np.testing.assert_array_equal(io.load_points(path), pts)


def test_writers_refuse_to_overwrite(tmp_path):
    path = io.save_json(tmp_path / "x.json", {"a": 1})
    with pytest.raises(FileExistsError, match="overwrite=True"):
        io.save_json(path, {"a": 2})
    io.save_json(path, {"a": 2}, overwrite=True)
    assert io.load_json(path) == {"a": 2}

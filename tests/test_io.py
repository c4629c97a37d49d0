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


def test_a_damaged_exr_is_one_error_and_no_stray_output(tmp_path, capfd):
    """OpenEXR prints its complaint about a damaged chunk to the C streams; read_exr folds it
    into the one ValueError naming the file, so the CLI's one-line message stays one line."""
    good = io.write_exr(tmp_path / "g.exr", np.arange(64, dtype=np.float32).reshape(8, 8))
    blob = good.read_bytes()
    bad = tmp_path / "bad.exr"
    bad.write_bytes(blob[: len(blob) - 40])
    capfd.readouterr()
    with pytest.raises(ValueError, match=r"bad\.exr is a damaged or truncated OpenEXR image"):
        io.read_exr(bad)
    out, err = capfd.readouterr()
    assert out == "" and err == ""
    np.testing.assert_array_equal(io.read_exr(good), np.arange(64).reshape(8, 8))


def test_load_npz_reads_file_objects_and_names_damaged_ones(tmp_path):
    import io as std_io

    path = io.save_npz(tmp_path / "p.npz", {"points": np.zeros((2, 2), np.float32)}, {"n": 2})
    arrays, meta = io.load_npz(std_io.BytesIO(path.read_bytes()))
    assert arrays["points"].shape == (2, 2) and meta["n"] == 2
    path.write_bytes(path.read_bytes()[:-30])
    with pytest.raises(ValueError, match=r"p\.npz is a damaged or truncated NumPy \.npz"):
        io.load_npz(path)


def test_points_round_trip_through_every_format_bit_for_bit(tmp_path):
    pts = np.random.default_rng(1).random((33, 2)).astype(np.float32)
    for suffix in io.POINT_SUFFIXES:
        p = io.save_points(tmp_path / f"p{suffix}", pts, {"sampler": "test"})
        np.testing.assert_array_equal(io.load_points(p).view(np.uint32), pts.view(np.uint32))
    with pytest.raises(ValueError, match=r"must end in \.npy or \.npz or \.txt or \.csv"):
        io.save_points(tmp_path / "p.bin", pts)

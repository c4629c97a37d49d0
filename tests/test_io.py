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
        io.save_points(tmp_path / "p.bmp", pts)


# --- point files of every format, UTK's included (issue 27) ------------------------------------


def _sets():
    rng = np.random.default_rng(7)
    return [rng.random((13, 2)).astype(np.float32), rng.random((5, 2)).astype(np.float32)]


@pytest.mark.parametrize("name,fmt", [("s.npz", None), ("s.txt", None), ("s.dat", None),
                                      ("s.txt", "utk"), ("s.bin", None)])
def test_several_sets_and_metadata_round_trip_bit_for_bit(tmp_path, name, fmt):
    sets, meta = _sets(), {"sampler": "test", "directions_deg": [0, 90, 30], "loss": np.nan}
    path = io.save_points(tmp_path / name, sets, meta, format=fmt)
    got, back = io.load_point_sets(path, format=fmt, metadata=True)
    assert [g.dtype for g in got] == [np.float32] * 2
    for g, s in zip(got, sets, strict=True):
        np.testing.assert_array_equal(g.view(np.uint32), s.view(np.uint32))
    assert back["sampler"] == "test" and back["directions_deg"] == [0, 90, 30]
    assert back["loss"] is None
    with pytest.raises(ValueError, match=r"holds 2 point sets \(n = 13, 5\).*load_point_sets"):
        io.load_points(path, format=fmt)
    with pytest.raises(FileExistsError):
        io.save_points(path, sets, meta, format=fmt)


@pytest.mark.parametrize("name", ["p.npy", "p.csv", "p.bin", "p.txt", "p.npz"])
def test_one_set_and_its_metadata_round_trip(tmp_path, name):
    pts = _sets()[0]
    path = io.save_points(tmp_path / name, pts, {"n": 13, "seed": 4})
    got, meta = io.load_points(path, metadata=True)
    np.testing.assert_array_equal(got.view(np.uint32), pts.view(np.uint32))
    assert meta["n"] == 13 and meta["seed"] == 4
    # formats with no place for metadata keep it beside the file, never drop it
    assert (tmp_path / f"{name}.json").exists() == name.endswith((".npy", ".csv", ".bin"))


def test_a_stack_of_equal_sizes_is_one_npy_and_reads_back_as_sets(tmp_path):
    stack = np.random.default_rng(3).random((4, 8, 2)).astype(np.float32)
    for name in ("k.npy", "k.npz"):
        got = io.load_point_sets(io.save_points(tmp_path / name, stack))
        np.testing.assert_array_equal(np.stack(got), stack)
    with pytest.raises(ValueError, match=r"\.npy file holds sets of one size"):
        io.save_points(tmp_path / "mixed.npy", _sets())
    with pytest.raises(ValueError, match=r"\.csv file holds one point set"):
        io.save_points(tmp_path / "mixed.csv", _sets())


def test_a_hand_written_utk_text_file_reads_as_utk_means_it(tmp_path):
    """UTK's text format (utk-team/utk PointsetIO.hpp): whitespace-separated coordinates (tabs in
    UTK 1), sets separated by a '#' line; fixed notation with 16 digits as UTK writes."""
    f = tmp_path / "utk.dat"
    f.write_text("0.1250000000000000\t0.5000000000000000\n0.75 0.25\n#\n"
                 "0.0000000000000000 0.9999\n0.5 0.5\n0.375  0.125\n")
    sets = io.load_point_sets(f)
    assert [s.shape for s in sets] == [(2, 2), (3, 2)]
    np.testing.assert_array_equal(sets[0], np.float32([[0.125, 0.5], [0.75, 0.25]]))
    np.testing.assert_array_equal(sets[1], np.float32([[0, 0.9999], [0.5, 0.5], [0.375, 0.125]]))


def test_utk_text_output_is_what_utk_reads(tmp_path):
    """What UTK's readers see: nothing before the first point (UTK 1's reader stops at a leading
    '#'), two numbers a line, a '#' line between sets, the metadata on one last '#' line."""
    a, b = _sets()
    path = io.save_points(tmp_path / "set.txt", [a, b], {"n": 13}, format="utk")
    lines = path.read_text().splitlines()
    assert len(lines) == 13 + 1 + 5 + 1
    assert lines[13] == "#" and lines[-1].startswith("# {") and not lines[0].startswith("#")
    data = [ln for ln in lines if not ln.startswith("#")]
    np.testing.assert_array_equal(np.float32([ln.split() for ln in data]), np.concatenate([a, b]))


def test_a_hand_built_utk_binary_file_reads_back(tmp_path):
    """UTK 1's PointsetWriter_BIN (src/io/fileIO_bin.hpp): per set a uint32 count, then the
    points as (x, y) float64 pairs, no header; built here with struct, independently of io."""
    import struct

    blob = struct.pack("<I4d", 2, 0.125, 0.5, 0.75, 0.25) + struct.pack("<I2d", 1, 0.5, 0.0)
    f = tmp_path / "u.bin"
    f.write_bytes(blob)
    sets = io.load_point_sets(f)
    np.testing.assert_array_equal(sets[0], np.float32([[0.125, 0.5], [0.75, 0.25]]))
    np.testing.assert_array_equal(sets[1], np.float32([[0.5, 0.0]]))
    # and what io writes is that layout, byte for byte
    out = io.save_points(tmp_path / "w.bin", [np.float32([[0.125, 0.5], [0.75, 0.25]]),
                                              np.float32([[0.5, 0.0]])])
    assert out.read_bytes() == blob
    f.write_bytes(blob[:-3])
    with pytest.raises(ValueError, match=r"u\.bin is not a UTK binary .*set 1 promises 1 points"):
        io.load_point_sets(f)


@pytest.mark.parametrize("text,match", [
    ("0.1 0.2\n#\n0.3 1.5\n", r"must lie in \[0, 1\)\^2.*\[0\.3, 1\.5\] \(line 3, set 1\)"),
    ("0.1 0.2\n0.3 nan\n", r"contains NaN or Inf: point \[0\.3, nan\] \(line 2\)"),
    ("0.1 0.2\n0.3 0.4 0.5\n", r"is not a text file of points.*line 2: '0\.3 0\.4 0\.5'"),
    ("0.1 0.2\n0.3 0.99999999\n", r"must lie in \[0, 1\)\^2 \(as float32\)"),
    ("# only a comment\n", r"holds no points"),
])
def test_bad_text_points_name_the_file_and_line(tmp_path, text, match):
    f = tmp_path / "bad.txt"
    f.write_text(text)
    with pytest.raises(ValueError, match=r"bad\.txt") as err:
        io.load_point_sets(f)
    assert err.match(match)


def test_bad_points_are_not_written(tmp_path):
    with pytest.raises(ValueError, match=r"points must lie in \[0, 1\)\^2.*\(set 1, point 0\)"):
        io.save_points(tmp_path / "x.txt", [np.full((2, 2), 0.5), np.full((2, 2), 1.0)])
    with pytest.raises(ValueError, match=r"format must be one of npy, npz, txt, csv, utk"):
        io.save_points(tmp_path / "x.txt", np.full((2, 2), 0.5), format="utk-text")
    with pytest.raises(ValueError, match=r"a utk-bin points file name must end in \.bin"):
        io.save_points(tmp_path / "x.txt", np.full((2, 2), 0.5), format="utk-bin")
    assert not list(tmp_path.iterdir())


def test_exr_keeps_rows_and_metadata(tmp_path):
    img = np.arange(12, dtype=np.float32).reshape(3, 4)
    path = io.write_exr(tmp_path / "g.exr", img, {"n": 5, "note": "rows bottom-up", "v": [1, 2]})
    back, meta = io.read_exr(path, metadata=True)
    np.testing.assert_array_equal(back, img)
    np.testing.assert_array_equal(io.load_grid(path), img)
    assert meta == {"n": 5, "note": "rows bottom-up", "v": [1, 2]}


def test_spectrum_exr_keeps_a_30_degree_line_at_30_degrees(tmp_path):
    """Issue 27: the spectrum EXR came back flipped, a 30-degree line at 150 degrees. Energy put
    along 30 degrees in a power_spectrum_grid-shaped grid comes back from io at 30."""
    from anisosample import metrics, plot

    r = 24
    k = np.arange(-r, r + 1)
    vx, vy = np.meshgrid(k, k, indexing="xy")  # grid[i, j] = P(v_x = j - r, v_y = i - r)
    angle = np.degrees(np.arctan2(vy, vx)) % 180
    grid = ((np.abs(angle - 30) < 3) & (np.hypot(vx, vy) > 4)).astype(np.float64)
    path = plot.save_spectrum_image(tmp_path / "s.exr", grid, n=64)
    for back in (io.read_exr(path), io.load_grid(path)):
        centers, profile = metrics.angular_profile(back, bins=36)
        assert abs(centers[np.argmax(profile)] - 30) <= 5

"""The user's own point files on the command line, and UTK export (issue 27): points --format,
spectrum --points, variance --points with -o .json/.png, tables export, synthesize to UTK."""

import json
import struct

import numpy as np
import pytest

from anisosample import cli, io, metrics


def _grid_set(m: int) -> np.ndarray:
    return metrics.midpoint_grid(m).reshape(-1, 2)


def test_points_writes_utk_text_and_binary_as_utk_lays_them_out(tmp_path):
    txt, binary = tmp_path / "set.txt", tmp_path / "set.bin"
    assert cli.main(["points", "pmj02bn", "-n", "64", "-o", str(txt), "--format", "utk"]) == 0
    assert cli.main(["points", "pmj02bn", "-n", "64", "-o", str(binary)]) == 0
    lines = txt.read_text().splitlines()
    data = [ln.split() for ln in lines if not ln.startswith("#")]
    assert not lines[0].startswith("#") and len(data) == 64 and {len(d) for d in data} == {2}
    assert json.loads(lines[-1][1:])["sampler"] == "pmj02bn"  # the record, after the set
    blob = binary.read_bytes()
    assert len(blob) == 4 + 64 * 16 and struct.unpack("<I", blob[:4]) == (64,)
    from_bin = np.frombuffer(blob[4:], "<f8").reshape(64, 2)
    np.testing.assert_array_equal(np.float32(data), from_bin.astype(np.float32))
    assert io.load_points(binary, metadata=True)[1]["n"] == 64  # set.bin.json beside it
    assert cli.main(["points", "random", "-n", "8", "-o", str(tmp_path / "x.csv"),
                     "--format", "utk"]) == 2


def test_spectrum_takes_points_of_any_format(tmp_path):
    from anisosample import spectrum

    pts = _grid_set(6)
    src = io.save_points(tmp_path / "p.bin", pts)
    exr = tmp_path / "s.exr"
    assert cli.main(["spectrum", "--points", str(src), "-o", str(exr), "--radius", "5"]) == 0
    np.testing.assert_allclose(io.read_exr(exr), spectrum.power_spectrum_grid(pts, 5),
                               rtol=1e-5, atol=1e-7)
    two = io.save_points(tmp_path / "two.dat", [pts, _grid_set(4)])
    assert cli.main(["spectrum", "--points", str(two), "-o", str(tmp_path / "t.exr")]) == 2


def test_variance_of_the_users_sets_writes_only_what_is_asked(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    mine = io.save_points(tmp_path / "my.dat", [_grid_set(4), _grid_set(8), _grid_set(16)])
    argv = ["variance", "--integrand", "edges:30", "--points", str(mine), "--realizations",
            "64"]
    assert cli.main(argv) == 0  # prints the table, writes nothing
    text = capsys.readouterr().out
    assert "my.dat" in text and "slope" in text and list(tmp_path.iterdir()) == [mine]
    png, rec = tmp_path / "var.png", tmp_path / "var.json"
    assert cli.main([*argv, "--sampler", "random", "-o", str(png), "-o", str(rec)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    got = json.loads(rec.read_text())
    assert got["ns"] == [16, 64, 256] and set(got["samplers"]) == {"random", "my.dat"}
    assert got["samplers"]["my.dat"]["randomization"] == "shift"
    assert got["samplers"]["my.dat"]["fit"]["ci_low"] < got["samplers"]["my.dat"]["fit"]["slope"]
    assert cli.main([*argv, "-o", str(png)]) == 2  # an existing output is refused
    assert "exists; pass --force" in capsys.readouterr().err
    assert cli.main([*argv, "-o", str(png), "--force"]) == 0
    assert cli.main([*argv, "--n", "16,32"]) == 2  # sizes the file does not hold
    assert "none of n = [32]" in capsys.readouterr().err


def test_tables_export_writes_the_looked_up_sets(tmp_path):
    from anisosample import tables

    out = tmp_path / "t.bin"
    assert cli.main(["tables", "export", "--n", "256", "--sets", "30,120", "--no-build",
                     "-o", str(out)]) == 0
    sets, meta = io.load_point_sets(out, metadata=True)
    assert meta["directions_deg"] == [[0, 90, 30], [0, 90, 120]]
    for s, d in zip(sets, meta["directions_deg"], strict=True):
        np.testing.assert_array_equal(s, np.asarray(tables.lookup(d, 256)))
    every = tmp_path / "all.dat"
    assert cli.main(["tables", "export", "--n", "256", "-o", str(every)]) == 0
    assert len(io.load_point_sets(every)) == len(tables.canonical_sets(3))


@pytest.mark.parametrize("name,fmt", [("s.dat", None), ("s.txt", "utk")])
def test_synthesize_writes_utk_text(tmp_path, name, fmt):
    out = tmp_path / name
    argv = ["synthesize", "-n", "32", "--directions", "0,90,30", "--steps", "2", "-o", str(out)]
    assert cli.main(argv + (["--format", fmt] if fmt else [])) == 0
    pts, meta = io.load_points(out, metadata=True)
    assert pts.shape == (32, 2) and meta["seed"] == 0 and len(meta["history"]) == 3

"""The command line: happy paths write what they say; bad input is one line and exit status 2."""

import subprocess
import sys

import numpy as np
import pytest

from anisosample import cli, io


def run(*args):
    return subprocess.run(
        [sys.executable, "-m", "anisosample.cli", *args],
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_points_and_spectrum(tmp_path, capsys):
    out = tmp_path / "pts.npy"
    assert cli.main(["points", "pmj02bn", "-n", "256", "--seed", "3", "-o", str(out)]) == 0
    pts = np.load(out)
    assert pts.shape == (256, 2) and pts.dtype == np.float32 and pts.max() < 1
    npz = tmp_path / "pts.npz"
    assert cli.main(["points", "sobol-owen", "-n", "64", "--shift", "-o", str(npz)]) == 0
    arrays, meta = io.load_npz(npz)
    assert arrays["points"].shape == (64, 2) and meta["sampler"] == "sobol-owen"
    png = tmp_path / "spec.png"
    exr = tmp_path / "spec.exr"
    assert cli.main(["spectrum", str(out), "-o", str(png)]) == 0
    assert cli.main(["spectrum", str(npz), "-o", str(exr), "--radius", "10"]) == 0
    assert png.stat().st_size > 0 and io.read_exr(exr).shape == (21, 21)
    # refuses to overwrite without --force
    assert cli.main(["points", "random", "-n", "8", "-o", str(out)]) == 2
    assert "exists" in capsys.readouterr().err
    assert cli.main(["points", "random", "-n", "8", "-o", str(out), "--force"]) == 0


@pytest.mark.parametrize(
    "args,needle",
    [
        (["points", "halton", "-n", "8", "-o", "x.npy"], "unknown sampler 'halton'"),
        (["points", "random", "-n", "0", "-o", "x.npy"], "n must be >= 1"),
        (["points", "random", "-n", "8", "-o", "x.bmp"], "--output must end in .npy, .npz"),
        (["spectrum", "missing.npy", "-o", "s.png"], "no such file"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(tmp_path, args, needle):
    args = [a if not a.endswith((".npy", ".bmp", ".png")) else str(tmp_path / a) for a in args]
    r = run(*args)
    assert r.returncode == 2
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and needle in lines[0], r.stderr


def test_spectrum_rejects_points_outside_the_square(tmp_path):
    bad = tmp_path / "bad.npy"
    np.save(bad, np.full((4, 2), 1.5, np.float32))
    r = run("spectrum", str(bad), "-o", str(tmp_path / "s.png"))
    assert r.returncode == 2 and f"points in {bad} must lie in [0, 1)^2" in r.stderr


def test_help_lists_commands():
    r = run("--help")
    assert r.returncode == 0 and "points" in r.stdout and "spectrum" in r.stdout


def test_points_and_spectrum_files_hold_what_the_library_computes(tmp_path):
    """The written points are the library's set for key(seed) (split: points, shift) bit for bit,
    and the EXR spectrum is power_spectrum_grid of those points, upright (v_y grows upwards)."""
    import jax

    from anisosample import samplers, spectrum

    npz = tmp_path / "p.npz"
    assert cli.main(["points", "cmj", "-n", "100", "--seed", "5", "--shift", "-o", str(npz)]) == 0
    k_pts, k_shift = jax.random.split(jax.random.key(5))
    want = np.asarray(samplers.toroidal_shift(k_shift, samplers.get("cmj")(k_pts, 100)))
    got = io.load_points(npz)
    np.testing.assert_array_equal(got.view(np.uint32), want.view(np.uint32))
    exr = tmp_path / "s.exr"
    assert cli.main(["spectrum", str(npz), "-o", str(exr), "--radius", "6"]) == 0
    grid = np.asarray(spectrum.power_spectrum_grid(got, 6))
    np.testing.assert_allclose(io.read_exr(exr)[::-1], grid, rtol=1e-6, atol=1e-9)
    # upright: the top-left pixel of the file is v = (-6, +6)
    v = np.array([[-6, 6]])
    ref = np.abs(np.exp(-2j * np.pi * (got.astype(np.float64) @ v.T)).mean()) ** 2
    assert io.read_exr(exr)[0, 0] == pytest.approx(ref, rel=1e-4, abs=1e-7)

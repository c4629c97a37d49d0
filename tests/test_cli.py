"""The command line: happy paths write what they say; bad input is one line and exit status 2."""

import subprocess
import sys

import numpy as np
import pytest

from anisosample import cli, io, scenes


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
    and the EXR spectrum read back by io is power_spectrum_grid of those points, unflipped (DESIGN
    grid: row 0 is v_y = -r; issue 27: it came back upside down, a 30-degree line at 150)."""
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
    np.testing.assert_allclose(io.read_exr(exr), grid, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(io.load_grid(exr), grid, rtol=1e-6, atol=1e-9)
    # a grid: row 0, column 0 of the file is v = (-6, -6), by an independent direct sum
    v = np.array([[-6, -6]])
    ref = np.abs(np.exp(-2j * np.pi * (got.astype(np.float64) @ v.T)).mean()) ** 2
    assert io.read_exr(exr)[0, 0] == pytest.approx(ref, rel=1e-4, abs=1e-7)


def test_help_does_not_import_jax():
    """``anisosample --help`` and every subcommand's ``--help`` answer without loading JAX or
    NumPy (the parser takes its names from anisosample._names)."""
    code = (
        "import sys\n"
        "from anisosample import cli\n"
        "p = cli.build_parser()\n"
        "sub = next(a for a in p._actions if a.dest == 'command')\n"
        "texts = [p.format_help()] + [s.format_help() for s in sub.choices.values()]\n"
        "tables = sub.choices['tables']\n"
        "act = next(a for a in tables._actions if a.dest == 'tables_command')\n"
        "texts += [s.format_help() for s in act.choices.values()]\n"
        "print(len(texts), 'jax' in sys.modules, 'numpy' in sys.modules)\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    count, jax_loaded, numpy_loaded = r.stdout.split()
    assert int(count) >= 10 and jax_loaded == "False" and numpy_loaded == "False"


def test_help_lists_every_builtin_sampler():
    from anisosample import _names, samplers

    # every built-in is registered (users, and the guide's example, may register more)
    assert set(_names.BASELINES + _names.DIRECTIONAL_SAMPLERS) <= set(samplers.names())
    assert samplers.BASELINES == _names.BASELINES
    text = cli.build_parser().format_help()
    assert "points" in text and "render" in text


def test_python_dash_m_runs_the_command_line(tmp_path):
    from anisosample import __version__

    r = subprocess.run([sys.executable, "-m", "anisosample", "--version"], capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 0 and r.stdout.strip() == f"anisosample {__version__}"
    r = subprocess.run([sys.executable, "-m", "anisosample", "points", "random", "-n", "0",
                        "-o", str(tmp_path / "p.npy")], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 2 and r.stderr.strip() == (
        "anisosample points: error: n must be >= 1, got 0")


def test_argparse_errors_are_one_line_and_exit_2(capsys):
    assert cli.main(["points", "random", "-n", "x", "-o", "p.npy"]) == 2
    err = capsys.readouterr().err
    assert err == ("anisosample points: error: argument -n: invalid int value: 'x' "
                   "(see anisosample points --help)\n")
    assert cli.main([]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
    assert cli.main(["--help"]) == 0


@pytest.mark.parametrize("umask,mode", [(0o022, 0o644), (0o027, 0o640), (0o002, 0o664)])
def test_outputs_respect_the_umask(tmp_path, umask, mode, capsys):
    """Every writer goes through io.atomic_path; files get 0o666 less the umask, as open()
    would (tempfile.mkstemp made them 0o600)."""
    import os

    old = os.umask(umask)
    try:
        out = tmp_path / "p.npz"
        assert cli.main(["points", "random", "-n", "16", "-o", str(out)]) == 0
        png = tmp_path / "s.png"
        assert cli.main(["spectrum", str(out), "-o", str(png), "--radius", "4"]) == 0
        json_path = io.save_json(tmp_path / "x.json", {"a": 1})
        exr = io.write_exr(tmp_path / "x.exr", np.ones((2, 2), np.float32))
    finally:
        os.umask(old)
    for p in (out, png, json_path, exr):
        assert p.stat().st_mode & 0o777 == mode, (p, oct(p.stat().st_mode))
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporaries left


def test_points_exported_as_text_and_drawn_as_png(tmp_path):
    """.txt and .csv hold every float32 bit of the .npy set; -o pts.png draws it."""
    npy, txt, csv, png = (tmp_path / f"p.{s}" for s in ("npy", "txt", "csv", "png"))
    for out in (npy, txt, csv, png):
        assert cli.main(["points", "pmj02bn", "-n", "64", "--seed", "2", "-o", str(out)]) == 0
    want = np.load(npy)
    for out in (txt, csv):
        got = io.load_points(out)
        np.testing.assert_array_equal(got.view(np.uint32), want.view(np.uint32))
    assert csv.read_text().splitlines()[0] == "x,y"
    assert txt.read_text().startswith('# {"sampler": "pmj02bn"')
    from matplotlib.image import imread

    img = imread(png)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and img.shape[0] > 100
    # the dots are there: a scatter of 64 points leaves dark pixels inside the square
    assert (img[..., :3].mean(axis=-1) < 0.5).sum() > 64


def test_points_aligned_and_sheared_take_their_directions(tmp_path):
    """``points aligned --directions`` and ``points sheared --direction`` write the library's
    sets for key(seed) bit for bit; without their directions they are a one-line error."""
    import jax

    from anisosample import samplers

    k_pts, _ = jax.random.split(jax.random.key(4))
    a = tmp_path / "a.npz"
    assert cli.main(["points", "aligned", "-n", "256", "--seed", "4", "--directions",
                     "0,90,30", "-o", str(a)]) == 0
    want = samplers.get("aligned", directions_deg=[0, 90, 30])(k_pts, 256)
    got, meta = io.load_npz(a)
    np.testing.assert_array_equal(got["points"], np.asarray(want))
    assert meta["directions_deg"] == [0, 90, 30] and meta["name"] == "aligned[30]"
    s = tmp_path / "s.npy"
    assert cli.main(["points", "sheared", "-n", "64", "--seed", "4", "--direction", "30",
                     "--base", "sobol-owen", "-o", str(s)]) == 0
    want = samplers.shear(samplers.get("sobol-owen")(k_pts, 64), 30.0)
    np.testing.assert_array_equal(np.load(s), np.asarray(want))


def test_variance_with_aligned_and_sheared_samplers(tmp_path, capsys):
    out = tmp_path / "v.json"
    assert cli.main(["variance", "--integrand", "edges:30", "--sampler", "aligned,sheared",
                     "--directions", "0,90,30", "--direction", "30", "--n", "256,4096",
                     "--realizations", "16", "-o", str(out)]) == 0
    rec = io.load_json(out)
    assert rec["sampler_options"] == {"aligned": {"directions_deg": [0.0, 90.0, 30.0]},
                                      "sheared": {"direction_deg": 30.0, "base": "pmj02bn"}}
    assert set(rec["samplers"]) == {"aligned", "sheared"}


CORNELL = scenes.path("cornell")
_ALIGNED = ["--sampler", "aligned", "--spp", "256", "--pixel-center", "--block", "8",
            "--estimation-samples", "48", "--set", "width=16", "--set", "height=16"]


def test_render_aligned_k_and_gate_flags(tmp_path, capsys):
    """``--k 1`` (3-direction sets only: the shipped n = 256 table, nothing to build) and
    ``--no-gate`` reach ``render(sampler="aligned", sampler_options={"k": .., "gate": ..})``:
    the same key gives the same image bit for bit, and the summary says what ran."""
    import jax

    from anisosample import render as R

    scene = R.load_xml(CORNELL, width=16, height=16)
    for flags, opts, said in [(["--k", "1"], dict(k=1), "(k = 1); per-pixel gate on: "),
                              (["--k", "1", "--no-gate"], dict(k=1, gate=False),
                               "(k = 1); per-pixel gate off")]:
        out = tmp_path / f"{len(flags)}.exr"
        assert cli.main(["render", str(CORNELL), *_ALIGNED, *flags, "-o", str(out)]) == 0
        assert said in capsys.readouterr().out
        ref = R.render(scene, jax.random.key(0), spp=256, pixel_center=True, sampler="aligned",
                       sampler_options=dict(block_px=8, samples=48, **opts), progress=False)
        np.testing.assert_array_equal(io.read_exr(out)[..., :3], ref.mean)
        assert ref.settings["blocks"]["k"] == 1
        assert ref.settings["blocks"]["gate"] is opts.get("gate", True)


@pytest.mark.parametrize("extra, needle", [
    (["--k", "3"], "argument --k: invalid choice: 3 (choose from 1, 2)"),
    (["--k", "two"], "argument --k: invalid int value: 'two'"),
    (["--sampler", "random", "--k", "1"], "--k, --no-gate and --direction-map need --sampler"),
    (["--sampler", "pmj02bn", "--no-gate"], "--no-gate and --direction-map need --sampler"),
    (["--spp", "1"], "--sampler aligned needs --spp >= 2"),
])
def test_render_aligned_flags_refuse_bad_input(tmp_path, capsys, extra, needle):
    args = ["render", str(CORNELL), *_ALIGNED, *extra, "-o", str(tmp_path / "x.exr")]
    assert cli.main(args) == 2
    err = capsys.readouterr().err
    assert needle in err and len([ln for ln in err.splitlines() if ln.strip()]) == 1, err
    assert not (tmp_path / "x.exr").exists()


def test_help_shows_every_default(capsys):
    """``--help`` of every command states each option's default (issue 27: ``render --help``
    hid that ``--sampler`` defaults to ``random``): every option with a default other than
    None (the help says what happens) and flags shows ``default`` in its help, read back from
    the printed text."""
    import argparse
    import re

    parser = cli.build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    commands = [([name], p) for name, p in sub.choices.items()]
    commands += [(["tables", name], p) for name, p in sub.choices["tables"]._actions[-1]
                 .choices.items()]
    seen = 0
    for argv, p in commands:
        assert cli.main([*argv, "--help"]) == 0
        text = re.sub(r"\s+", "", capsys.readouterr().out)  # wrapping differs by width
        for a in p._actions:
            if (not a.option_strings or a.default is None or isinstance(a.default, bool)
                    or a.default == argparse.SUPPRESS or a.default == []):
                continue
            entry = re.sub(r"\s+", "", p._get_formatter()._format_action(a))
            assert entry in text and "default" in entry.lower(), (argv, entry)
            seen += 1
    assert seen >= 20
    assert cli.main(["render", "--help"]) == 0
    assert "(default:random)" in re.sub(r"\s+", "", capsys.readouterr().out)

"""The bad-input catalogue: every way a user can hand the library or the command line something
wrong, in one place, each case with the outcome it must have.

Each case is a small record (:class:`Case`): an id, the call (a Python call on prepared files, or
a command line), the exception type the API must raise (``ValueError``/``TypeError`` naming the
parameter or the file and what is allowed; ``FileNotFoundError``/``FileExistsError`` for files)
or, for the command line, exit status 2 with one line on stderr, and a regex that message must
match. Command lines run in-process through ``cli.main(argv)`` (fast); the cases that once
crashed the interpreter (XLA aborts, segfaults) or allocate run in a subprocess, so that a
regression fails the test instead of killing the run. No case may crash, hang, print a traceback,
or return a value (a NaN or a silently "fixed" result) instead of the error.

``python tests/test_bad_input.py`` runs the whole catalogue without pytest and prints its count
and outcome table (cases, clear errors, crashes, accepted silently) for the issue's closing note.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import os
import re
import shlex
import shutil
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
SCENES = ROOT / "anisosample" / "scenes"
TABLE_256 = ROOT / "anisosample" / "data" / "tables" / "d3_n256"

# The catalogue is what a user sees: the library's own errors, without jaxtyping's run-time
# checks (on for the rest of the suite), which would refuse a wrongly typed argument first.
pytestmark = pytest.mark.library_errors


@dataclasses.dataclass(frozen=True)
class Case:
    """One bad input and its required outcome.

    ``call(d)``: the API call on the prepared folder ``d`` (must raise ``error`` matching
    ``match``); ``argv``: a command line (``{d}`` is the folder) that must exit 2 with one line
    on stderr matching ``match``; ``code``: Python source run in a subprocess that must print a
    line matching ``match`` and exit 0 (for calls that used to crash the interpreter).
    ``report``: the command succeeds but must say what is wrong (``match`` on its output).
    ``setup(d)`` prepares extra files; ``subprocess`` runs ``argv`` as a real process.
    """

    id: str
    call: Callable | None = None
    argv: str | None = None
    code: str | None = None
    error: type | tuple = ValueError
    match: str = ""
    setup: Callable | None = None
    subprocess: bool = False
    report: bool = False
    xfail: str | None = None
    owner: str = ""  # the module whose guard this case checks (for the table)


CASES: list[Case] = []


def api(id, call, error, match, **kw):
    CASES.append(Case(id=f"api-{id}", call=call, error=error, match=match, **kw))


def cli(id, argv, match, **kw):
    CASES.append(Case(id=f"cli-{id}", argv=argv, match=match, owner="cli", **kw))


def proc(id, code, match, **kw):
    CASES.append(Case(id=f"proc-{id}", code=code, match=match, subprocess=True, **kw))


# --- prepared files ------------------------------------------------------------------------------


def _points(n=64, seed=0):
    return np.random.default_rng(seed).random((n, 2)).astype(np.float32)


def prepare(d: Path) -> None:
    """Write every file the cases read into ``d`` (cheap: no JAX, NumPy and copies only)."""
    from anisosample import io

    d.mkdir(parents=True, exist_ok=True)
    pts = _points()
    io.save_points(d / "pts.npy", pts, overwrite=True)
    np.savez(d / "raw.npz", points=pts)  # what a user's own np.savez writes: no metadata
    io.save_points(d / "pts.txt", pts, overwrite=True)
    bad = pts.copy()
    bad[3, 1] = np.nan
    np.save(d / "nan.npy", bad)
    bad = pts.copy()
    bad[0, 0] = np.inf
    np.savez(d / "inf.npz", points=bad)
    np.save(d / "outside.npy", np.full((4, 2), 1.5, np.float32))
    np.save(d / "negative.npy", -pts)
    np.save(d / "one.npy", np.ones((4, 2), np.float32))
    np.save(d / "ints.npy", np.zeros((4, 2), np.int32))
    np.save(d / "three.npy", np.zeros((4, 3), np.float32))
    np.save(d / "flat.npy", np.zeros(8, np.float32))
    np.save(d / "empty.npy", np.zeros((0, 2), np.float32))
    np.savez(d / "nopoints.npz", x=pts)
    (d / "nan.csv").write_text("x,y\n0.1,0.2\nnan,0.5\n")
    (d / "letters.txt").write_text("0.1 0.2\nabc def\n")
    (d / "ragged.csv").write_text("0.1,0.2\n0.3\n")
    good = (d / "pts.npz")
    io.save_points(good, pts, {"sampler": "random"}, overwrite=True)
    blob = good.read_bytes()
    (d / "trunc.npz").write_bytes(blob[: len(blob) // 2])
    flipped = bytearray(blob)
    flipped[len(blob) // 2] ^= 0xFF
    (d / "flip.npz").write_bytes(bytes(flipped))
    (d / "text.npz").write_text("these are not points\n")
    (d / "zero.npz").write_bytes(b"")
    (d / "foreign.npy").write_bytes(os.urandom(256))
    import pickle

    (d / "pickle.npy").write_bytes(pickle.dumps({"points": [[0.1, 0.2]]}))
    npy = (d / "pts.npy").read_bytes()
    (d / "trunc.npy").write_bytes(npy[: len(npy) - 100])
    (d / "dir.npy").mkdir(exist_ok=True)
    # grids of integrand samples
    yy, xx = np.mgrid[0:64, 0:64]
    grid = (xx * np.cos(0.5) + yy * np.sin(0.5) > 40).astype(np.float32)
    np.save(d / "grid.npy", grid)
    g = grid.copy()
    g[5, 5] = np.nan
    np.save(d / "nangrid.npy", g)
    g = grid.copy()
    g[0, 0] = np.inf
    np.save(d / "infgrid.npy", g)
    np.save(d / "grid3d.npy", np.zeros((4, 4, 4), np.float32))
    np.save(d / "grid0.npy", np.zeros((0, 5), np.float32))
    io.write_exr(d / "grid.exr", grid, overwrite=True)
    exr = (d / "grid.exr").read_bytes()
    (d / "trunc.exr").write_bytes(exr[: len(exr) // 2])
    (d / "junk.exr").write_bytes(b"\x76\x2f\x31\x01" + os.urandom(64))
    (d / "text.exr").write_text("not an image\n")
    # scenes
    for name in ("triangle_light.xml", "triangle_light.obj", "cornell.xml"):
        shutil.copy(SCENES / name, d / name)
    (d / "collinear.obj").write_text("v -0.6 1.2 -0.3\nv 0.0 1.2 -0.3\nv 0.6 1.2 -0.3\nf 1 2 3\n")
    xml = (SCENES / "triangle_light.xml").read_text()
    (d / "collinear.xml").write_text(xml.replace("triangle_light.obj", "collinear.obj"))
    (d / "nanlight.xml").write_text(xml.replace('value="10, 10, 10"', 'value="nan, 10, 10"'))
    (d / "negfov.xml").write_text(xml.replace('name="fov" value="45"', 'name="fov" value="-45"'))
    (d / "unknown_shape.xml").write_text(xml.replace('<shape type="cube">', '<shape type="torus">'))
    (d / "missing_obj.xml").write_text(xml.replace("triangle_light.obj", "nosuch.obj"))
    (d / "notxml.xml").write_text("this is not XML <scene\n")
    (d / "truncated.xml").write_text(xml[: len(xml) // 2])
    # a copy of the shipped 256-point table, then three damaged copies
    if not (d / "table").exists():
        shutil.copytree(TABLE_256, d / "table")
    for name in ("table_missing", "table_damaged", "table_flipped", "table_json"):
        if (d / name).exists():
            shutil.rmtree(d / name)
        shutil.copytree(TABLE_256, d / name)
    (d / "table_missing" / "psi_030.npz").unlink()
    s = (d / "table_damaged" / "psi_030.npz").read_bytes()
    (d / "table_damaged" / "psi_030.npz").write_bytes(s[: len(s) // 2])
    s = bytearray((d / "table_flipped" / "psi_045.npz").read_bytes())
    s[len(s) // 2] ^= 0x01
    (d / "table_flipped" / "psi_045.npz").write_bytes(bytes(s))
    (d / "table_json" / "table.json").write_text('{"kind": 3, "n": ')
    (d / "not_a_table").mkdir(exist_ok=True)


_CHECKPOINT_SETTINGS = dict(n=16, directions=(0, 90, 30), steps=4)


def _checkpoint(d: Path) -> Path:
    """A real synthesis checkpoint (n = 16, 4 steps, interrupted after 2), made once."""
    path = d / "ckpt_base.npz"
    if path.exists():
        return path
    import jax

    from anisosample import synthesis

    def stop(done, loss):
        raise KeyboardInterrupt

    s = _CHECKPOINT_SETTINGS
    try:
        synthesis.synthesize(jax.random.key(0), s["n"], list(s["directions"]), steps=s["steps"],
                             checkpoint=str(path), checkpoint_every=2, callback=stop,
                             show_progress=False)
    except KeyboardInterrupt:
        pass
    assert path.exists()
    return path


def _edited_checkpoint(name, edit):
    """``setup``: a copy of the real checkpoint with ``edit(arrays)`` applied to its arrays."""

    def setup(d):
        from anisosample import io

        arrays, meta = io.load_npz(_checkpoint(d))
        edit(arrays)
        io.save_npz(d / name, arrays, meta, overwrite=True)

    return setup


def _damaged_checkpoint(d):
    blob = _checkpoint(d).read_bytes()
    (d / "ckpt_trunc.npz").write_bytes(blob[: len(blob) // 3])


def _nan_x(a):
    a["x"] = a["x"].copy()
    a["x"][2, 0] = np.nan


def _small_x(a):
    a["x"], a["m"], a["v"] = a["x"][:8], a["m"][:8], a["v"][:8]


def _late_step(a):
    a["step"] = np.asarray(1000, np.int64)


def _synth_argv(ckpt, out="synth_out.npz"):
    s = _CHECKPOINT_SETTINGS
    return (f"synthesize -n {s['n']} --directions {','.join(map(str, s['directions']))} "
            f"--steps {s['steps']} --checkpoint {{d}}/{ckpt} -o {{o}}/{out}")


# --- shorthand for API calls ------------------------------------------------------------------


def key():
    import jax

    return jax.random.key(0)


def a_device():
    import jax

    return jax.devices()[0]


def A():  # the package, imported when a case runs
    import anisosample

    return anisosample


def tri():
    return A().warps.SphericalTriangle([[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]],
                                       [0.0, 0.0, 0.0])


def f_edge():
    return A().integrands.edges([30.0])


def scene(d):
    return A().render.load_xml(d / "triangle_light.xml", width=8, height=8, spp=4)


NAN = float("nan")
INF = float("inf")
F = [[1, 0], [3, 4]]
PTS = _points(16)
SYNTH_OWNER = "synthesis"
RENDER_OWNER = "render"

# --- samplers ---------------------------------------------------------------------------------

api("samplers-unknown-name", lambda d: A().samplers.get("halton"), ValueError,
    r"unknown sampler 'halton'.*pmj02bn", owner="samplers")
api("samplers-baseline-takes-no-options", lambda d: A().samplers.get("random", n=3), TypeError,
    r"'random' takes no options", owner="samplers")
api("samplers-n-zero", lambda d: A().samplers.get("random")(key(), 0), ValueError,
    r"n must be >= 1", owner="samplers")
api("samplers-n-negative", lambda d: A().samplers.get("jittered")(key(), -4), ValueError,
    r"n must be >= 1", owner="samplers")
api("samplers-n-huge", lambda d: A().samplers.get("random")(key(), 2**40), ValueError,
    r"n must be <= 16777216", owner="samplers")
api("samplers-n-float", lambda d: A().samplers.get("cmj")(key(), 64.0), TypeError,
    r"n must be an integer", owner="samplers")
api("samplers-n-string", lambda d: A().samplers.get("random")(key(), "64"), TypeError,
    r"n must be an integer", owner="samplers")
api("samplers-key-int", lambda d: A().samplers.get("random")(0, 16), TypeError,
    r"key must be a single JAX PRNG key", owner="samplers")
api("samplers-key-batch", lambda d: A().samplers.get("random")(
    __import__("jax").random.split(key(), 3), 16), TypeError, r"key must be a single",
    owner="samplers")
api("samplers-shift-nan", lambda d: A().samplers.toroidal_shift(key(), np.load(d / "nan.npy")),
    ValueError, r"points contains NaN or Inf", owner="samplers")
api("samplers-shift-outside", lambda d: A().samplers.toroidal_shift(key(), np.load(
    d / "outside.npy")), ValueError, r"points must lie in \[0, 1\)\^2", owner="samplers")
api("samplers-shift-shape", lambda d: A().samplers.toroidal_shift(key(), np.zeros((4, 3))),
    ValueError, r"points must have shape \(n, 2\)", owner="samplers")
api("samplers-shift-empty", lambda d: A().samplers.toroidal_shift(key(), np.zeros((0, 2))),
    ValueError, r"points must have shape \(n, 2\) with n >= 1", owner="samplers")
api("samplers-shear-180", lambda d: A().samplers.shear(PTS, 180.0), ValueError,
    r"direction_deg must lie in \[0, 180\)", owner="samplers")
api("samplers-shear-nan", lambda d: A().samplers.shear(PTS, NAN), ValueError,
    r"direction_deg must lie in \[0, 180\)", owner="samplers")
api("samplers-shear-string", lambda d: A().samplers.shear(PTS, "30"), TypeError,
    r"direction_deg must be a number", owner="samplers")
api("samplers-sheared-no-direction", lambda d: A().samplers.get("sheared"), TypeError,
    r"direction_deg", owner="samplers")
api("samplers-sheared-bad-base", lambda d: A().samplers.get("sheared", base="aligned",
    direction_deg=30.0), ValueError, r"base must be one of", owner="samplers")
api("samplers-sheared-inf", lambda d: A().samplers.get("sheared", direction_deg=INF),
    ValueError, r"direction_deg must lie in \[0, 180\)", owner="samplers")
api("samplers-aligned-nothing", lambda d: A().samplers.get("aligned"), ValueError,
    r"exactly one of integrand=, values= or directions_deg=", owner="selection")
api("samplers-aligned-200", lambda d: A().samplers.get("aligned", directions_deg=[200.0]),
    ValueError, r"directions_deg must lie in \[0, 180\)", owner="selection")
api("samplers-aligned-nan", lambda d: A().samplers.get("aligned", directions_deg=[NAN]),
    ValueError, r"directions_deg must lie in \[0, 180\)", owner="selection")
api("samplers-aligned-integrand-not-callable", lambda d: A().samplers.get(
    "aligned", integrand=3.0), TypeError, r"integrand must be a callable", owner="selection")
api("samplers-register-empty-name", lambda d: A().samplers.register("", lambda **k: None),
    ValueError, r"name must be a non-empty string", owner="samplers")
api("samplers-register-taken", lambda d: A().samplers.register("random", lambda **k: None),
    ValueError, r"'random' is already registered", owner="samplers")

# --- spectrum ----------------------------------------------------------------------------------

api("spectrum-nan-points", lambda d: A().spectrum.power_spectrum(np.load(d / "nan.npy"), F),
    ValueError, r"points contains NaN or Inf", owner="spectrum")
api("spectrum-inf-points", lambda d: A().spectrum.power_spectrum(
    A().io.load_npz(d / "inf.npz")[0]["points"], F), ValueError, r"NaN or Inf", owner="spectrum")
api("spectrum-outside", lambda d: A().spectrum.power_spectrum(np.load(d / "outside.npy"), F),
    ValueError, r"points must lie in \[0, 1\)\^2", owner="spectrum")
api("spectrum-shape", lambda d: A().spectrum.power_spectrum(np.zeros((4, 3)), F), ValueError,
    r"points must have shape \(n, 2\)", owner="spectrum")
api("spectrum-empty-points", lambda d: A().spectrum.power_spectrum(np.zeros((0, 2)), F),
    ValueError, r"points must have shape \(n, 2\) with n >= 1", owner="spectrum")
api("spectrum-int-points", lambda d: A().spectrum.power_spectrum(np.zeros((4, 2), np.int32), F),
    TypeError, r"points must be a floating-point array", owner="spectrum")
api("spectrum-freqs-fractional", lambda d: A().spectrum.power_spectrum(PTS, [[0.5, 1.0]]),
    ValueError, r"freqs must hold integer frequency vectors", owner="spectrum")
api("spectrum-freqs-nan", lambda d: A().spectrum.power_spectrum(PTS, [[NAN, 1.0]]), ValueError,
    r"freqs must hold integer", owner="spectrum")
api("spectrum-freqs-shape", lambda d: A().spectrum.power_spectrum(PTS, [[1, 2, 3]]), ValueError,
    r"freqs must have shape \(m, 2\)", owner="spectrum")
api("spectrum-freqs-empty", lambda d: A().spectrum.power_spectrum(PTS, np.zeros((0, 2), int)),
    ValueError, r"freqs must hold at least one frequency", owner="spectrum")
api("spectrum-freqs-overflow", lambda d: A().spectrum.power_spectrum(PTS, [[2.0**40, 0.0]]),
    ValueError, r"freqs must fit in int32", owner="spectrum")
api("spectrum-method-unknown", lambda d: A().spectrum.power_spectrum(PTS, F, method="fft"),
    ValueError, r"method must be one of", owner="spectrum")
api("spectrum-grid-radius-zero", lambda d: A().spectrum.power_spectrum_grid(PTS, 0), ValueError,
    r"radius must be >= 1", owner="spectrum")
api("spectrum-grid-radius-negative", lambda d: A().spectrum.power_spectrum_grid(PTS, -3),
    ValueError, r"radius must be >= 1", owner="spectrum")
api("spectrum-grid-radius-float", lambda d: A().spectrum.power_spectrum_grid(PTS, 2.5),
    TypeError, r"radius must be an integer", owner="spectrum")
api("plot-save-spectrum-image-wrong-suffix", lambda d: A().plot.save_spectrum_image(
    d / "s.jpg", np.ones((5, 5)), n=16), ValueError, r"\.png|\.exr", owner="plot")
api("metrics-radial-profile-nan", lambda d: A().metrics.radial_profile(
    np.full((5, 5), NAN)), ValueError, r"grid.*(NaN|finite)", owner="metrics")
api("spectrum-grid-radius-huge", lambda d: A().spectrum.power_spectrum_grid(PTS, 100000),
    ValueError, r"radius.*(GB|GiB|MB|MiB|bytes|memory)", owner="spectrum")

# --- losses ------------------------------------------------------------------------------------

api("losses-spectrum-nan-point", lambda d: A().losses.spectrum_loss(np.load(d / "nan.npy"), F),
    ValueError, r"points contains NaN or Inf", owner="losses")
api("losses-spectrum-shape", lambda d: A().losses.spectrum_loss(np.zeros((4, 3)), F),
    ValueError, r"points must have shape", owner="losses")
api("losses-spectrum-weights-nan", lambda d: A().losses.spectrum_loss(PTS, F,
    weights=np.array([1.0, NAN])), ValueError, r"weights", owner="losses")
api("losses-spectrum-weights-shape", lambda d: A().losses.spectrum_loss(PTS, F,
    weights=np.ones(5)), ValueError, r"weights", owner="losses")
api("losses-sw-nan-point", lambda d: A().losses.sliced_wasserstein_loss(np.load(d / "nan.npy"),
    [0.0, 90.0]), ValueError, r"points contains NaN or Inf", owner="losses")
api("losses-sw-direction-200", lambda d: A().losses.sliced_wasserstein_loss(PTS, [200.0]),
    ValueError, r"directions_deg must lie in \[0, 180\)", owner="losses")
api("losses-quantile-u-outside", lambda d: A().losses.square_projection_quantile(30.0,
    np.array([1.5])), ValueError, r"u must lie in \[-1/2, 1/2\]", owner="losses")
proc("losses-grad-nan-point",
     "import jax, numpy as np, anisosample as a\n"
     "p = np.random.default_rng(0).random((16, 2)).astype(np.float32); p[3, 0] = np.nan\n"
     "try:\n    g = jax.grad(lambda x: a.losses.spectrum_loss(x, [[1, 0], [3, 4]]))(p)\n"
     "    print('RETURNED', np.asarray(g).ravel()[:4])\n"
     "except (ValueError, RuntimeError) as e:\n    print('REFUSED', ' '.join(str(e).split()))\n",
     r"REFUSED .*(NaN|finite)", owner="losses")
api("losses-jit-grad-nan-point", lambda d: __import__("jax").jit(__import__("jax").grad(
    lambda x: A().losses.spectrum_loss(x, F)))(np.load(d / "nan.npy")), (ValueError, RuntimeError),
    r"(NaN|finite)", owner="losses")

# --- frequencies, diagnostics, selection --------------------------------------------------------

Q = "frequencies"
api("frequencies-design-n-zero", lambda d: A().frequencies.design(0, [0, 90]), ValueError,
    r"n must be >= ", owner=Q)
api("frequencies-design-direction-200", lambda d: A().frequencies.design(64, [200]), ValueError,
    r"directions_deg must lie in \[0, 180\)", owner=Q)
api("frequencies-design-name", lambda d: A().frequencies.design(64, [0, 90], name="x"),
    ValueError, r"name must be one of", owner=Q)
api("frequencies-design-old-kind-keyword", lambda d: A().frequencies.design(64, [0, 90],
    kind="paper"), TypeError, r"design\(\) takes name= where it took kind=", owner=Q)
api("frequencies-design-robust-axis-weight-zero", lambda d: A().frequencies.design(
    1024, [0, 90, 30], robust_axis_weight=0.0), ValueError, r"robust_axis_weight must be", owner=Q)
api("frequencies-design-robust-axis-weight-text", lambda d: A().frequencies.design(
    1024, [0, 90, 30], robust_axis_weight="3"), TypeError, r"robust_axis_weight", owner=Q)
api("frequencies-disk-negative", lambda d: A().frequencies.disk(-1.0), ValueError,
    r"radius must be finite and > 0", owner=Q)
api("frequencies-disk-nan", lambda d: A().frequencies.disk(NAN), ValueError,
    r"radius must be finite and > 0", owner=Q)
api("frequencies-wedge-length-nan", lambda d: A().frequencies.wedge(30.0, NAN), ValueError,
    r"length must be finite and > 0", owner=Q)
api("frequencies-wedge-direction-200", lambda d: A().frequencies.wedge(200.0, 10.0), ValueError,
    r"direction_deg must lie in \[0, 180\)", owner=Q)
api("frequencies-custom-fractional", lambda d: A().frequencies.custom_set([[0.5, 1.0]], [30.0]),
    ValueError, r"freqs must hold integer", owner=Q)
api("frequencies-custom-weights-nan", lambda d: A().frequencies.custom_set([[1, 1]], [30.0],
    weights=[NAN]), ValueError, r"weights must be finite", owner=Q)
api("frequencies-edge-weights-negative-spread", lambda d: A().frequencies.edge_weights(
    [[1, 1]], [30.0], spread_deg=-1.0), ValueError, r"spread_deg must be", owner=Q)
api("diagnostics-nan-points", lambda d: A().diagnostics.variance_decomposition(
    np.load(d / "nan.npy"), f_edge()), ValueError, r"points contains NaN or Inf",
    owner="diagnostics")
api("diagnostics-plain-function", lambda d: A().diagnostics.variance_decomposition(
    PTS, lambda x: x[..., 0]), (TypeError, ValueError), r"integrand", owner="diagnostics")
api("diagnostics-band-negative", lambda d: A().diagnostics.variance_decomposition(
    PTS, f_edge(), band=-1.0), ValueError, r"band must be finite and > 0", owner="diagnostics")
api("selection-table-directions-nan", lambda d: A().selection.table_directions([NAN]),
    ValueError, r"directions_deg must be finite", owner="selection")
api("selection-table-directions-k-zero", lambda d: A().selection.table_directions([30.0], k=0),
    ValueError, r"k must be >= 1", owner="selection")
api("selection-table-directions-near-axis-big", lambda d: A().selection.table_directions(
    [30.0], near_axis_deg=60), ValueError, r"near_axis_deg must be in \[0, 45\]", owner="selection")
api("selection-table-directions-near-axis-str", lambda d: A().selection.table_directions(
    [30.0], near_axis_deg="5"), TypeError, r"near_axis_deg must be a number", owner="selection")
api("pixel-sampler-near-axis-nan", lambda d: A().render.render(
    scene(d), key(), sampler="aligned-pixel", sampler_options={"near_axis_deg": NAN},
    progress=False), ValueError, r"near_axis_deg must be in \[0, 45\]", owner=RENDER_OWNER)
api("selection-table-directions-axis-snap-int", lambda d: A().selection.table_directions(
    [30.0], axis_snap=1), TypeError, r"axis_snap must be True or False", owner="selection")
api("pixel-sampler-axis-snap-str", lambda d: A().render.render(
    scene(d), key(), sampler="aligned-pixel", sampler_options={"axis_snap": "yes"},
    progress=False), TypeError, r"axis_snap must be True or False", owner=RENDER_OWNER)
api("pixel-sampler-reuse-str", lambda d: A().render.render(
    scene(d), key(), sampler="aligned-pixel", sampler_options={"reuse": "no"},
    progress=False), TypeError, r"reuse must be True or False", owner=RENDER_OWNER)
api("pixel-sampler-neighbours-negative", lambda d: A().render.render(
    scene(d), key(), sampler="aligned-pixel", sampler_options={"neighbours": -1},
    progress=False), ValueError, r"neighbours must be >= 0", owner=RENDER_OWNER)
api("neighbour-consensus-shape", lambda d: A().render.pixel_aligned.neighbour_consensus(
    np.zeros((4, 4)), np.zeros((4, 4), int)), ValueError, r"directions_deg must have shape "
    r"\(h, w, 2\)", owner=RENDER_OWNER)
api("neighbour-consensus-count-float", lambda d: A().render.pixel_aligned.neighbour_consensus(
    np.zeros((4, 4, 2)), np.zeros((4, 4))), ValueError, r"count must be integers of shape",
    owner=RENDER_OWNER)
api("neighbour-consensus-tolerance-90", lambda d: A().render.pixel_aligned.neighbour_consensus(
    np.zeros((4, 4, 2)), np.zeros((4, 4), int), tolerance_deg=90), ValueError,
    r"tolerance_deg must be below 90", owner=RENDER_OWNER)
api("neighbour-consensus-relative-big", lambda d: A().render.pixel_aligned.neighbour_consensus(
    np.zeros((4, 4, 2)), np.zeros((4, 4), int), relative_support=2), ValueError,
    r"relative_support must be in \[0, 1\]", owner=RENDER_OWNER)
api("selection-aligned-set-n-zero", lambda d: A().selection.aligned_set((30,), 0), ValueError,
    r"n must be >= ", owner="selection")
api("selection-aligned-values-nan", lambda d: A().samplers.get("aligned",
    values=np.full((32, 32), NAN)), ValueError, r"values contains NaN or Inf", owner="selection")
api("selection-aligned-k-three", lambda d: A().samplers.get("aligned", directions_deg=[30.0],
    k=3), ValueError, r"k must be <= 2", owner="selection")
api("selection-aligned-fallback", lambda d: A().samplers.get("aligned", directions_deg=[30.0],
    fallback="aligned"), ValueError, r"fallback must be one of", owner="selection")
api("metrics-angular-bins-zero", lambda d: A().metrics.angular_profile(np.ones((5, 5)),
    bins=0), ValueError, r"bins must be >= 1", owner="metrics")
api("metrics-angular-r-min-negative", lambda d: A().metrics.angular_profile(np.ones((5, 5)),
    r_min=-1.0), ValueError, r"r_min", owner="metrics")
api("metrics-radial-3d", lambda d: A().metrics.radial_profile(np.ones((5, 5, 5))), ValueError,
    r"grid must be a square centred spectrum", owner="metrics")
api("metrics-expected-spectrum-one-set", lambda d: A().metrics.expected_power_spectrum(PTS, F),
    ValueError, r"sets must be a stack of point sets of shape \(R, n, 2\)", owner="metrics")
api("plot-save-spectrum-image-nan-grid", lambda d: A().plot.save_spectrum_image(
    d / "o_nan.png", np.full((5, 5), NAN), n=16), ValueError, r"NaN or Inf", owner="plot")
api("plot-save-spectrum-image-n-zero", lambda d: A().plot.save_spectrum_image(d / "o_n0.png",
    np.ones((5, 5)), n=0), ValueError, r"n must be >= 1", owner="plot")

# --- synthesis ---------------------------------------------------------------------------------

S = SYNTH_OWNER
api("synthesize-n-zero", lambda d: A().synthesize(key(), 0, [0, 90, 30]), ValueError,
    r"n must be >= ", owner=S)
api("synthesize-n-float", lambda d: A().synthesize(key(), 64.5, [0, 90, 30]), TypeError,
    r"n must be an integer", owner=S)
api("synthesize-direction-200", lambda d: A().synthesize(key(), 64, [0, 90, 200]), ValueError,
    r"directions_deg must lie in \[0, 180\)", owner=S)
api("synthesize-direction-nan", lambda d: A().synthesize(key(), 64, [0, NAN]), ValueError,
    r"directions_deg must lie in \[0, 180\)", owner=S)
api("synthesize-directions-empty", lambda d: A().synthesize(key(), 64, []), ValueError,
    r"directions_deg must hold at least one direction", owner=S)
api("synthesize-directions-repeated", lambda d: A().synthesize(key(), 64, [0, 90, 90]),
    ValueError, r"directions_deg must not repeat", owner=S)
api("synthesize-36-directions-at-64", lambda d: A().synthesize(key(), 64, list(range(0, 180, 5))),
    ValueError, r"(directions|too many).*(n|points)", owner=S)
api("synthesize-prefix-unknown", lambda d: A().synthesize(key(), 64, [0, 90], prefix="sobol-8"),
    ValueError, r"prefix must be 'none', 'dihedral-<m>'", owner=S)
api("synthesize-prefix-dihedral-12", lambda d: A().synthesize(key(), 64, [0, 90],
    prefix="dihedral-12"), ValueError, r"prefix must be .*multiple of 8", owner=S)
api("synthesize-prefix-over-n-4", lambda d: A().synthesize(key(), 64, [0, 90],
    prefix="dihedral-24"), ValueError, r"prefix has 24 points, more than n/4", owner=S)
api("synthesize-prefix-nan-points", lambda d: A().synthesize(key(), 64, [0, 90],
    prefix=np.full((4, 2), NAN)), ValueError, r"prefix contains NaN", owner=S)
api("synthesize-prefix-int", lambda d: A().synthesize(key(), 64, [0, 90], prefix=np.ones(3)),
    ValueError, r"prefix must have shape \(n, 2\)", owner=S)
api("synthesize-sequence-from-48", lambda d: A().synthesis.synthesize_sequence(key(), 256,
    [0, 90, 30], sequence_from=48), ValueError, r"sequence_from must be 0 .* power of two",
    owner=S)
api("synthesize-sequence-from-over-n", lambda d: A().synthesis.synthesize_sequence(key(), 64,
    [0, 90, 30], sequence_from=128), ValueError, r"sequence_from must be at most n=64", owner=S)
api("synthesize-sequence-weights", lambda d: A().synthesis.synthesize_sequence(key(), 64,
    [0, 90, 30], sequence_from=16, sequence_weights="heavy"), ValueError,
    r"sequence_weights must be one of", owner=S)
api("tables-prefix-asymmetric", lambda d: A().tables.lookup([0, 90, 30], 256,
    prefix="pmj02bn-32"), ValueError, r"prefix 'pmj02bn-32' cannot be held by a table",
    owner="tables")
api("selection-aligned-sets-three-extras", lambda d: A().selection.aligned_sets(
    [(30,), (10, 20, 40)], 256), ValueError, r"at most two directions besides 0 and 90",
    owner="selection")
api("tables-lookup-many-as-numpy-str", lambda d: A().tables.lookup_many([(30,)], 256,
    as_numpy="yes"), TypeError, r"as_numpy must be True or False", owner="tables")
api("selection-aligned-sets-as-numpy-int", lambda d: A().selection.aligned_sets([(30,)], 256,
    as_numpy=1), TypeError, r"as_numpy must be True or False", owner="selection")
api("tables-lookup-many-n-1", lambda d: A().tables.lookup_many([(30,)], 1), ValueError,
    r"n must be >= 2", owner="tables")
api("tables-lookup-many-request-180", lambda d: A().tables.lookup_many([(30,), (180,)], 256),
    ValueError, r"directions_deg must lie in \[0, 180\)", owner="tables")
api("tables-missing-prefix-asymmetric", lambda d: A().tables.missing([(30,)], 256,
    prefix="pmj02bn-32"), ValueError, r"prefix 'pmj02bn-32' cannot be held by a table",
    owner="tables")
api("tables-missing-sequence-from-negative", lambda d: A().tables.missing([(30,)], 256,
    sequence_from=-1), ValueError, r"sequence_from must be >= 0", owner="tables")
api("sampler-aligned-sequence-n-over-length", lambda d: A().samplers.get("aligned-sequence",
    directions_deg=[30], length=64, sequence_from=16)(key(), 65), ValueError,
    r"n must be at most the sequence length 64", owner="selection")
api("sampler-aligned-sequence-from-over-length", lambda d: A().samplers.get("aligned-sequence",
    directions_deg=[30], length=64, sequence_from=128), ValueError,
    r"sequence_from must be at most length=64", owner="selection")
api("optimizer-recipe-name", lambda d: A().optimizer.objective(64, [0, 90, 30], "rate"),
    TypeError, r"recipe must be a synthesis Recipe", owner="optimizer")
api("optimizer-adam-boundary", lambda d: A().optimizer.Adam(0.5, 0.01, 64, 10,
    boundary="reflect"), ValueError, r"boundary must be one of", owner="optimizer")
api("optimizer-x0-outside", lambda d: A().optimizer.minimize(
    A().optimizer.objective(16, [0, 90], A().synthesis.make_recipe()),
    A().optimizer.Adam(0.5, 0.01, 16, 2), np.full((16, 2), 1.5)), ValueError,
    r"x0 must lie in \[0, 1\)\^2", owner="optimizer")
api("synthesize-steps-zero", lambda d: A().synthesize(key(), 64, [0, 90], steps=0), ValueError,
    r"steps must be >= 1", owner=S)
api("synthesize-steps-negative", lambda d: A().synthesize(key(), 64, [0, 90], steps=-5),
    ValueError, r"steps must be >= 1", owner=S)
api("synthesize-c-nan", lambda d: A().synthesize(key(), 64, [0, 90], c=NAN), ValueError,
    r"\bc must be finite", owner=S)
api("synthesize-lr-negative", lambda d: A().synthesize(key(), 64, [0, 90], learning_rate=-1.0),
    ValueError, r"learning_rate must be finite and > 0", owner=S)
api("synthesize-recipe-unknown", lambda d: A().synthesize(key(), 64, [0, 90], recipe="fast"),
    ValueError, r"recipe must be one of", owner=S)
api("synthesize-init-unknown", lambda d: A().synthesize(key(), 64, [0, 90], init="halton"),
    ValueError, r"init must be one of", owner=S)
api("synthesize-method-unknown", lambda d: A().synthesize(key(), 64, [0, 90], method="fft"),
    ValueError, r"method must be one of", owner=S)
api("synthesize-unknown-adam-option", lambda d: A().synthesize(key(), 64, [0, 90], beta=3),
    (TypeError, ValueError), r"beta", owner=S)
api("synthesize-key-int", lambda d: A().synthesize(0, 64, [0, 90]), TypeError,
    r"key must be a single JAX PRNG key", owner=S)
api("synthesize-checkpoint-every-zero", lambda d: A().synthesize(key(), 64, [0, 90],
    checkpoint_every=0), ValueError, r"checkpoint_every must be >= 1", owner=S)
api("synthesize-checkpoint-damaged", lambda d: A().synthesize(
    key(), 16, [0, 90, 30], steps=4, checkpoint=str(d / "ckpt_trunc.npz"), show_progress=False),
    ValueError, r"ckpt_trunc\.npz.*(damaged|truncated)", setup=_damaged_checkpoint, owner=S)
api("synthesize-checkpoint-text", lambda d: A().synthesize(
    key(), 16, [0, 90, 30], steps=4, checkpoint=str(d / "text.npz"), show_progress=False),
    ValueError, r"text\.npz is not a NumPy \.npz archive", owner=S)
api("synthesize-checkpoint-wrong-shape", lambda d: A().synthesize(
    key(), 16, [0, 90, 30], steps=4, checkpoint=str(d / "ckpt_small.npz"), show_progress=False),
    ValueError, r"ckpt_small\.npz.*(shape|16)",
    setup=_edited_checkpoint("ckpt_small.npz", _small_x), owner=S)
api("synthesize-checkpoint-step-beyond-steps", lambda d: A().synthesize(
    key(), 16, [0, 90, 30], steps=4, checkpoint=str(d / "ckpt_late.npz"), show_progress=False),
    ValueError, r"ckpt_late\.npz.*step", setup=_edited_checkpoint("ckpt_late.npz", _late_step),
    owner=S)
api("synthesis-load-result-damaged", lambda d: A().synthesis.load_result(d / "trunc.npz"),
    ValueError, r"trunc\.npz is a damaged or truncated", owner=S)
api("synthesis-load-result-no-points", lambda d: A().synthesis.load_result(d / "nopoints.npz"),
    ValueError, r"nopoints\.npz.*points", owner=S)
api("synthesis-save-result-wrong-suffix", lambda d: A().synthesis.save_result(
    d / "set.txt", PTS, {}), ValueError, r"must end in \.npz", owner=S)
api("synthesize-batch-sets-mismatched", lambda d: A().synthesis.synthesize_batch(
    key(), 64, [[0, 90, 30], [0, 90]]), ValueError, r"direction_sets", owner=S)
api("synthesize-n-huge", lambda d: A().synthesize(key(), 100_000_000, [0, 90, 30],
    show_progress=False), ValueError, r"(GB|GiB|MB|MiB|bytes|memory)", owner=S)
cli("synthesize-checkpoint-nan", _synth_argv("ckpt_nan.npz"), r"ckpt_nan\.npz.*(NaN|finite)",
    setup=_edited_checkpoint("ckpt_nan.npz", _nan_x), subprocess=True)
cli("synthesize-checkpoint-wrong-shape", _synth_argv("ckpt_small.npz"),
    r"ckpt_small\.npz.*(shape|16)", setup=_edited_checkpoint("ckpt_small.npz", _small_x))
cli("synthesize-checkpoint-step-beyond-steps", _synth_argv("ckpt_late.npz"),
    r"ckpt_late\.npz.*step", setup=_edited_checkpoint("ckpt_late.npz", _late_step))
cli("synthesize-checkpoint-damaged", _synth_argv("ckpt_trunc.npz"),
    r"ckpt_trunc\.npz is a damaged or truncated", setup=_damaged_checkpoint)
cli("synthesize-n-huge", "synthesize -n 100000000 --directions 0,90,30 -o {o}/huge.npz",
    r"(GB|GiB|TB|TiB|MB|MiB|bytes|memory)")

# --- tables ------------------------------------------------------------------------------------

T = "tables"
api("tables-lookup-200", lambda d: A().tables.lookup([200], 256), ValueError,
    r"directions_deg must lie in \[0, 180\)", owner=T)
api("tables-lookup-nan", lambda d: A().tables.lookup([NAN], 256), ValueError,
    r"directions_deg must lie in \[0, 180\)", owner=T)
api("tables-lookup-n-zero", lambda d: A().tables.lookup([30], 0), ValueError, r"n must be >= ",
    owner=T)
api("tables-lookup-missing-n", lambda d: A().tables.lookup([30], 100),
    FileNotFoundError,
    r"no 3-direction table for n=100.*tables\.ensure.*tables build --n 100", owner=T)
api("tables-ensure-refused", lambda d: A().tables.ensure([[30]], 100, build_missing=False),
    FileNotFoundError,
    r"no 3-direction table for n=100.*tables build --n 100", owner=T)
api("tables-lookup-builds-nothing", lambda d: A().tables.lookup([30], 100, build_missing=True),
    TypeError, r"pure lookup and takes no \['build_missing'\].*tables\.ensure", owner=T)
api("tables-lookup-three-extra", lambda d: A().tables.lookup([10, 20, 30], 256), ValueError,
    r"at most two directions besides 0 and 90", owner=T)
api("tables-open-missing", lambda d: A().tables.open_table(d / "nosuch"), FileNotFoundError,
    r"nosuch", owner=T)
api("tables-open-not-a-table", lambda d: A().tables.open_table(d / "not_a_table"),
    (FileNotFoundError, ValueError), r"not_a_table.*table\.json", owner=T)
api("tables-open-damaged-json", lambda d: A().tables.open_table(d / "table_json"), ValueError,
    r"table_json.*table\.json", owner=T)
api("tables-load-damaged-set", lambda d: A().tables.lookup([30], 256, table=d / "table_damaged"),
    ValueError, r"psi_030\.npz.*damaged", owner=T)
api("tables-load-deleted-set", lambda d: A().tables.lookup([30], 256, table=d / "table_missing"),
    FileNotFoundError, r"psi_030", owner=T)
api("tables-deleted-set-not-complete", lambda d: _assert_incomplete(d / "table_missing"),
    (), r"", owner=T, report=True)
api("tables-canonical-direction-count-5", lambda d: A().tables.canonical_sets(5), ValueError,
    r"direction_count must be", owner=T)
api("tables-lookup-old-kind-keyword", lambda d: A().tables.lookup([0, 90, 30], 64, kind=3),
    TypeError, r"lookup\(\) takes direction_count= where it took kind=", owner=T)
api("tables-build-n-zero", lambda d: A().tables.build(0, 3, out=d / "t0"), ValueError,
    r"n must be >= ", owner=T)
api("tables-build-direction-count-5", lambda d: A().tables.build(64, 5, out=d / "t5"),
    ValueError, r"direction_count must be", owner=T)
api("tables-canonicalize-nan", lambda d: A().tables.canonicalize([NAN]), ValueError,
    r"directions_deg", owner=T)


def _assert_incomplete(path):
    """``report`` case: a table with a deleted set must not call itself complete."""
    tab = A().tables.open_table(path)
    if tab.complete:
        raise RuntimeError(f"table {path} with a deleted set reports complete=True")


# --- directions --------------------------------------------------------------------------------

D = "directions"
api("directions-nan-grid", lambda d: A().directions.estimate(np.load(d / "nangrid.npy")),
    ValueError, r"values.*(NaN|finite)", owner=D)
api("directions-inf-grid", lambda d: A().directions.estimate(np.load(d / "infgrid.npy")),
    ValueError, r"values.*(NaN|finite)", owner=D)
api("directions-1d-grid", lambda d: A().directions.estimate(np.zeros(16)), ValueError,
    r"values must .*\(h, w\)", owner=D)
api("directions-3d-grid", lambda d: A().directions.estimate(np.zeros((4, 4, 4))), ValueError,
    r"values must .*\(h, w\)", owner=D)
api("directions-empty-grid", lambda d: A().directions.estimate(np.zeros((0, 5))), ValueError,
    r"values", owner=D)
api("directions-k-negative", lambda d: A().directions.estimate(np.load(d / "grid.npy"), k=-1),
    ValueError, r"k must be >= 0", owner=D)
api("directions-complex-grid", lambda d: A().directions.estimate(np.zeros((32, 32), complex)),
    TypeError, r"values must be a real-valued array, got dtype complex128", owner=D)
api("directions-bool-grid", lambda d: A().directions.estimate(np.zeros((32, 32), bool)),
    TypeError, r"values must be a real-valued array, got dtype bool", owner=D)
api("directions-k-float", lambda d: A().directions.estimate(np.load(d / "grid.npy"), k=1.5),
    TypeError, r"k must be an integer", owner=D)
api("directions-estimator-unknown", lambda d: A().directions.estimate(np.load(d / "grid.npy"),
    estimator="hough"), ValueError, r"estimator must be one of", owner=D)
api("directions-old-method-keyword", lambda d: A().directions.estimate(np.load(d / "grid.npy"),
    method="gradient"), TypeError, r"estimator= where it took method=", owner=D)
api("directions-kappa-negative", lambda d: A().directions.estimate(np.load(d / "grid.npy"),
    kappa=-1.0), ValueError, r"kappa must be finite and > 0", owner=D)
api("directions-sigma-nan", lambda d: A().directions.estimate(np.load(d / "grid.npy"),
    sigma_px=NAN), ValueError, r"sigma_px must be finite", owner=D)
api("directions-threshold-nan", lambda d: A().directions.estimate(np.load(d / "grid.npy"),
    threshold=NAN), ValueError, r"threshold", owner=D)
api("directions-unknown-option", lambda d: A().directions.estimate(np.load(d / "grid.npy"),
    kapa=3.0), TypeError, r"kapa", owner=D)
api("directions-blocks-zero", lambda d: A().directions.estimate_blocks(np.load(d / "grid.npy"),
    samples_per_block=0), ValueError, r"samples_per_block must be >= ", owner=D)
api("directions-blocks-larger-than-grid", lambda d: A().directions.estimate_blocks(
    np.load(d / "grid.npy"), samples_per_block=128), ValueError, r"samples_per_block", owner=D)
api("directions-histogram-bin-zero", lambda d: A().directions.orientation_histogram(
    np.load(d / "grid.npy"), bin_deg=0.0), ValueError, r"bin_deg must be", owner=D)
api("directions-histogram-nan", lambda d: A().directions.orientation_histogram(
    np.load(d / "nangrid.npy")), ValueError, r"values.*(NaN|finite)", owner=D)

E = "edges"
api("edges-unknown-option", lambda d: A().edges.edge_search(f_edge(), _points(64), stepz=3),
    TypeError, r"unknown edge-search option", owner=E)
api("edges-steps-zero", lambda d: A().edges.edge_search(f_edge(), _points(64), steps=0),
    ValueError, r"steps must be >= 1", owner=E)
api("edges-too-few-points", lambda d: A().edges.edge_search(f_edge(), _points(4)),
    ValueError, r"points must hold at least", owner=E)
api("edges-nan-values", lambda d: A().edges.edge_search(f_edge(), _points(64),
    np.full(64, NAN, np.float32)), ValueError, r"values must be finite", owner=E)

# --- vmf ---------------------------------------------------------------------------------------

V = "vmf"
api("vmf-pdf-negative-kappa", lambda d: A().vmf.pdf(0.0, 0.0, -1.0), ValueError,
    r"kappa must be finite and >= 0", owner=V)
api("vmf-pdf-nan-kappa", lambda d: A().vmf.pdf(0.0, 0.0, NAN), ValueError,
    r"kappa must be finite", owner=V)
api("vmf-pdf-nan-x", lambda d: A().vmf.pdf(NAN, 0.0, 1.0), ValueError, r"x must be finite",
    owner=V)
api("vmf-bin-masses-negative-kappa", lambda d: A().vmf.bin_masses(0.0, -2.0, 180), ValueError,
    r"kappa must be finite and >= 0", owner=V)
api("vmf-bin-masses-inf-kappa", lambda d: A().vmf.bin_masses(0.0, INF, 180), ValueError,
    r"kappa must be finite", owner=V)
api("vmf-bin-masses-nbins-zero", lambda d: A().vmf.bin_masses(0.0, 2.0, 0), ValueError,
    r"nbins must be >= 1", owner=V)
api("vmf-bin-masses-nan-mu", lambda d: A().vmf.bin_masses(NAN, 2.0, 18), ValueError,
    r"mu must be finite", owner=V)
api("vmf-reverse-kl-negative-hist", lambda d: A().vmf.reverse_kl(-np.ones(18), 0.0, 2.0),
    ValueError, r"hist must hold finite, non-negative", owner=V)
api("vmf-reverse-kl-nan-hist", lambda d: A().vmf.reverse_kl(np.full(18, NAN), 0.0, 2.0),
    ValueError, r"hist must hold finite", owner=V)
api("vmf-reverse-kl-zero-hist", lambda d: A().vmf.reverse_kl(np.zeros(18), 0.0, 2.0),
    ValueError, r"positive total weight", owner=V)
api("vmf-reverse-kl-one-bin", lambda d: A().vmf.reverse_kl(np.ones(1), 0.0, 2.0), ValueError,
    r"K >= 2 bins", owner=V)
api("vmf-reverse-kl-zero-kappa", lambda d: A().vmf.reverse_kl(np.ones(18), 0.0, 0.0),
    ValueError, r"kappa must be finite and > 0", owner=V)
api("vmf-reverse-kl-mask-shape", lambda d: A().vmf.reverse_kl(np.ones(18), 0.0, 2.0,
    mask=np.ones(5, bool)), ValueError, r"mask must be a boolean array of shape \(18,\)", owner=V)
api("vmf-reverse-kl-mask-empty", lambda d: A().vmf.reverse_kl(np.ones(18), 0.0, 2.0,
    mask=np.zeros(18, bool)), ValueError, r"mask must mark at least one bin", owner=V)
api("vmf-fit-kappa-range", lambda d: A().vmf.fit_reverse_kl(np.ones(18), 0.0, 2.0,
    kappa_min=5.0, kappa_max=1.0), ValueError, r"kappa_min must be < kappa_max", owner=V)
api("vmf-fit-mu0-nan", lambda d: A().vmf.fit_reverse_kl(np.ones(18), NAN, 2.0), ValueError,
    r"mu0 must be finite", owner=V)
api("vmf-kappa-max-negative", lambda d: A().vmf.kappa_from_resultant(0.5, kappa_max=-1.0),
    ValueError, r"kappa_max must be finite and > 0", owner=V)

# --- integrands --------------------------------------------------------------------------------

I = "integrands"
api("integrands-spec-unknown", lambda d: A().integrands.from_spec("torus:1"), ValueError,
    r"torus", owner=I)
api("integrands-spec-empty", lambda d: A().integrands.from_spec(""), ValueError,
    r"integrand spec must be a non-empty string", owner=I)
api("integrands-spec-not-numbers", lambda d: A().integrands.from_spec("edges:a,b"), ValueError,
    r"expected numbers after ':'", owner=I)
api("integrands-spec-edges-none", lambda d: A().integrands.from_spec("edges:"), ValueError,
    r"edges takes 1 to 4", owner=I)
api("integrands-spec-edges-five", lambda d: A().integrands.from_spec("edges:1,2,3,4,5"),
    ValueError, r"edges takes 1 to 4", owner=I)
api("integrands-spec-edges-200", lambda d: A().integrands.from_spec("edges:200"), ValueError,
    r"\[0, 180\)", owner=I)
api("integrands-spec-edges-nan", lambda d: A().integrands.from_spec("edges:nan"), ValueError,
    r"(finite|\[0, 180\))", owner=I)
api("integrands-spec-halfplane-one-number", lambda d: A().integrands.from_spec("halfplane:30"),
    ValueError, r"halfplane takes", owner=I)
api("integrands-spec-polygon-odd", lambda d: A().integrands.from_spec("polygon:0,0,1,0,1"),
    ValueError, r"polygon takes", owner=I)
api("integrands-spec-disk-negative-radius", lambda d: A().integrands.from_spec(
    "disk:0.5,0.5,-0.1"), ValueError, r"radius must be finite and > 0", owner=I)
api("integrands-spec-bump-zero-sigma", lambda d: A().integrands.from_spec("bump:0.5,0.5,0"),
    ValueError, r"sigma must be finite and > 0", owner=I)
api("integrands-spec-inf", lambda d: A().integrands.from_spec("smoothed:30,inf"), ValueError,
    r"(finite|inf)", owner=I)
api("integrands-edges-empty", lambda d: A().integrands.edges([]), ValueError,
    r"directions_deg must hold at least one direction", owner=I)
api("integrands-polygon-two-vertices", lambda d: A().integrands.Polygon([[0, 0], [1, 1]]),
    ValueError, r"(vertices|at least 3)", owner=I)
api("integrands-polygon-nan-vertex", lambda d: A().integrands.Polygon([[0, 0], [1, NAN],
    [0, 1]]), ValueError, r"(finite|NaN)", owner=I)
api("integrands-disk-nan-centre", lambda d: A().integrands.Disk((NAN, 0.5), 0.2), ValueError,
    r"(finite|NaN)", owner=I)
api("integrands-halfplane-nan", lambda d: A().integrands.HalfPlane(NAN, 0.5), ValueError,
    r"(finite|NaN)", owner=I)

# --- variance ----------------------------------------------------------------------------------

R = "variance"
api("variance-f-not-callable", lambda d: A().variance.estimator_variance(3.0, "random", 64,
    key(), 16), TypeError, r"f must be a callable", owner=R)
api("variance-sampler-unknown", lambda d: A().variance.estimator_variance(f_edge(), "halton", 64,
    key(), 16), ValueError, r"unknown sampler 'halton'", owner=R)
api("variance-n-zero", lambda d: A().variance.estimator_variance(f_edge(), "random", 0, key(),
    16), ValueError, r"n must be >= 1", owner=R)
api("variance-realizations-one", lambda d: A().variance.estimator_variance(f_edge(), "random",
    64, key(), 1), ValueError, r"realizations must be >= 2", owner=R)
api("variance-key-int", lambda d: A().variance.estimator_variance(f_edge(), "random", 64, 7, 16),
    TypeError, r"key must be a single JAX PRNG key", owner=R)
api("variance-exact-nan", lambda d: A().variance.estimator_variance(f_edge(), "random", 64,
    key(), 16, exact=NAN), ValueError, r"exact must be finite", owner=R)
api("variance-randomization-unknown", lambda d: A().variance.estimator_variance(
    f_edge(), "random", 64, key(), 16, randomization="owen"), ValueError,
    r"randomization must be one of", owner=R)
api("variance-nan-integrand", lambda d: A().variance.estimator_variance(
    lambda x: x[..., 0] * np.float32(NAN), "random", 64, key(), 16), ValueError,
    r"(NaN|finite)", owner=R)
api("variance-user-sampler-outside", lambda d: A().variance.estimator_variance(
    f_edge(), lambda k, n: np.full((n, 2), 2.0, np.float32), 64, key(), 16), ValueError,
    r"the sampler's points must lie in \[0, 1\)\^2", owner=R)
api("variance-user-sampler-nan", lambda d: A().variance.estimator_variance(
    f_edge(), lambda k, n: np.full((n, 2), NAN, np.float32), 64, key(), 16), ValueError,
    r"the sampler's points contains NaN or Inf", owner=R)
api("variance-user-sampler-shape", lambda d: A().variance.estimator_variance(
    f_edge(), lambda k, n: np.zeros((n, 3), np.float32), 64, key(), 16), ValueError,
    r"the sampler's points must have shape \(n, 2\)", owner=R)
api("variance-user-sampler-wrong-n", lambda d: A().variance.estimator_variance(
    f_edge(), lambda k, n: np.zeros((n + 1, 2), np.float32), 64, key(), 16), ValueError,
    r"the sampler must return \(n, 2\) = \(64, 2\) points, got shape \(65, 2\)", owner=R)
api("variance-devices-one-device", lambda d: A().variance.estimator_variance(
    f_edge(), "random", 64, key(), 16, devices=a_device()), TypeError,
    r"devices must be a sequence of jax.Device .*pass \[", owner=R)
api("variance-devices-empty", lambda d: A().variance.estimate_variance(
    f_edge(), "random", 64, key(), 16, devices=[]), ValueError,
    r"devices must hold at least one device", owner=R)
api("variance-devices-not-devices", lambda d: A().variance.convergence(
    f_edge(), ["random"], [16, 64], key(), 16, devices=["cpu"]), TypeError,
    r"devices\[0\] must be a jax.Device", owner=R)
api("variance-realizations-huge", lambda d: A().variance.estimator_variance(
    f_edge(), "random", 64, key(), 10**12), ValueError, r"realizations must be <= 1073741824",
    owner=R)
api("variance-convergence-one-size", lambda d: A().variance.convergence(f_edge(), ["random"],
    [64], key(), 16), ValueError, r"ns must hold at least 2 sizes", owner=R)
api("variance-convergence-size-zero", lambda d: A().variance.convergence(f_edge(), ["random"],
    [0, 64], key(), 16), ValueError, r"(ns|n) must be >= 1", owner=R)
api("variance-convergence-no-samplers", lambda d: A().variance.convergence(f_edge(), [],
    [16, 64], key(), 16), ValueError, r"samplers", owner=R)
api("variance-fit-slope-nan", lambda d: A().variance.fit_slope([16, 64, 256], [1e-3, NAN, 1e-5]),
    ValueError, r"variances must be finite", owner=R)
api("variance-fit-slope-lengths", lambda d: A().variance.fit_slope([16, 64, 256], [1e-3, 1e-4]),
    ValueError, r"(same length|lengths|shape)", owner=R)
api("variance-fit-slope-negative", lambda d: A().variance.fit_slope([16, 64], [1e-3, -1e-4]),
    ValueError, r"ns and variances must be positive", owner=R)
api("variance-fit-slope-confidence", lambda d: A().variance.fit_slope([16, 64, 256],
    [1e-3, 1e-4, 1e-5], confidence=1.5), ValueError, r"confidence must lie in \(0, 1\)", owner=R)
api("variance-from-estimates-nan", lambda d: A().variance.variance_from_estimates(
    np.array([0.1, NAN, 0.3])), ValueError, r"NaN or Inf estimates", owner=R)
api("metrics-predicted-variance-shapes", lambda d: A().metrics.predicted_variance(np.ones(4),
    np.ones(5)), ValueError, r"(shape|same)", owner="metrics")

# --- warps -------------------------------------------------------------------------------------

W = "warps"
api("warps-bilinear-shape", lambda d: A().warps.Bilinear(np.ones((3, 3))), ValueError,
    r"values must have shape \(2, 2\)", owner=W)
api("warps-bilinear-negative", lambda d: A().warps.Bilinear([[1.0, -1.0], [1.0, 1.0]]),
    ValueError, r"values must be (finite and )?(>= 0|non-negative)", owner=W)
api("warps-bilinear-nan", lambda d: A().warps.Bilinear([[1.0, NAN], [1.0, 1.0]]), ValueError,
    r"values must be finite", owner=W)
api("warps-bilinear-all-zero", lambda d: A().warps.Bilinear(np.zeros((2, 2))), ValueError,
    r"(positive|> 0|zero)", owner=W)
api("warps-biquadratic-shape", lambda d: A().warps.Biquadratic(np.ones((2, 2))), ValueError,
    r"values must have shape \(3, 3\)", owner=W)
api("warps-biquadratic-inf", lambda d: A().warps.Biquadratic(np.full((3, 3), INF)), ValueError,
    r"values must be finite", owner=W)
api("warps-triangle-collinear", lambda d: A().warps.SphericalTriangle(
    [[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [2.0, 0.0, 1.0]], [0.0, 0.0, 0.0]), ValueError,
    r"(collinear|degenerate|area)", owner=W)
api("warps-triangle-nan-vertex", lambda d: A().warps.SphericalTriangle(
    [[0.0, 0.0, 1.0], [NAN, 0.0, 1.0], [0.0, 1.0, 1.0]], [0.0, 0.0, 0.0]), ValueError,
    r"vertices must be finite", owner=W)
api("warps-triangle-shape", lambda d: A().warps.SphericalTriangle(np.ones((2, 3)), np.zeros(3)),
    ValueError, r"vertices must have shape \(3, 3\)", owner=W)
api("warps-triangle-origin-shape", lambda d: A().warps.SphericalTriangle(
    [[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]], [0.0, 0.0]), ValueError,
    r"origin must have shape \(3,\)", owner=W)
api("warps-polygon-shape", lambda d: A().warps.ProjectedSphericalPolygon(np.ones((2, 3)),
    np.zeros(3), [0.0, 0.0, 1.0]), ValueError, r"vertices must have shape \(k, 3\)", owner=W)
api("warps-polygon-nan", lambda d: A().warps.ProjectedSphericalPolygon(
    [[0.0, 0.0, 1.0], [NAN, 0.0, 1.0], [0.0, 1.0, 1.0]], np.zeros(3), [0.0, 0.0, 1.0]),
    ValueError, r"vertices must be finite", owner=W)
api("warps-polygon-collinear", lambda d: A().warps.ProjectedSphericalPolygon(
    [[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [2.0, 0.0, 1.0]], np.zeros(3), [0.0, 0.0, 1.0]),
    ValueError, r"non-zero area", owner=W)
api("warps-polygon-not-planar", lambda d: A().warps.ProjectedSphericalPolygon(
    [[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [1.0, 1.0, 1.5], [0.0, 1.0, 1.0]], np.zeros(3),
    [0.0, 0.0, 1.0]), ValueError, r"coplanar", owner=W)
api("warps-polygon-not-convex", lambda d: A().warps.ProjectedSphericalPolygon(
    [[0.0, 0.0, 1.0], [1.0, 1.0, 1.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]], np.zeros(3),
    [0.0, 0.0, 1.0]), ValueError, r"convex", owner=W)
api("warps-polygon-zero-normal", lambda d: A().warps.ProjectedSphericalPolygon(
    [[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]], np.zeros(3), np.zeros(3)),
    ValueError, r"normal must be a non-zero vector", owner=W)
api("warps-rectangle-zero-edge", lambda d: A().warps.SphericalRectangle(
    [0.0, 0.0, 1.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]), ValueError,
    r"(edge|degenerate|area)", owner=W)
api("warps-rectangle-nan", lambda d: A().warps.SphericalRectangle(
    [0.0, 0.0, NAN], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]), ValueError,
    r"finite", owner=W)
api("warps-compose-empty", lambda d: A().warps.compose(), ValueError, r"(at least one|warps)",
    owner=W)
api("warps-compose-not-a-warp", lambda d: A().warps.compose(A().warps.Bilinear(np.ones((2, 2))),
    lambda u: u), TypeError, r"(warp|AbstractWarp)", owner=W)
api("warps-fit-pointwise-negative-factor", lambda d: A().warps.fit_pointwise(
    A().warps.Bilinear, lambda x: -x[2], [tri()]), ValueError,
    r"factor must be >= 0 .*negative at every one", owner=W)
api("warps-fit-pointwise-nan-factor", lambda d: A().warps.fit_pointwise(
    A().warps.Bilinear, lambda x: x[2] * np.float32(NAN), [tri()]), ValueError,
    r"factor must be finite", owner=W)
api("warps-fit-pointwise-not-callable", lambda d: A().warps.fit_pointwise(
    A().warps.Bilinear, 3.0, [tri()]), TypeError, r"factor must be a callable", owner=W)
api("warps-fit-pointwise-family", lambda d: A().warps.fit_pointwise(A().warps.Tabulated,
    lambda x: x[2], [tri()]), ValueError, r"family must be Bilinear or Biquadratic", owner=W)
api("warps-fit-pointwise-old-kind-keyword", lambda d: A().warps.fit_pointwise(
    kind=A().warps.Bilinear, factor=lambda x: x[2], later=[tri()]), TypeError,
    r"fit_pointwise\(\) takes family= where it took kind=", owner=W)
api("warps-sample-batch-u-above-one", lambda d: A().warps.sample_batch(tri(),
    np.array([[0.5, 1.5]], np.float32)), ValueError, r"u must lie in \[0, 1\]\^2", owner=W)
api("warps-sample-batch-u-negative", lambda d: A().warps.sample_batch(tri(),
    np.array([[-0.25, 0.5]], np.float32)), ValueError, r"u must lie in \[0, 1\]\^2", owner=W)
api("warps-sample-batch-u-nan", lambda d: A().warps.sample_batch(tri(),
    np.array([[NAN, 0.5]], np.float32)), ValueError, r"u contains NaN or Inf", owner=W)
api("warps-sample-batch-u-shape", lambda d: A().warps.sample_batch(tri(),
    np.zeros((4, 3), np.float32)), ValueError, r"u must have shape \(n, 2\)", owner=W)
api("warps-sample-batch-not-a-warp", lambda d: A().warps.sample_batch(
    lambda u: u, np.zeros((4, 2), np.float32)), TypeError, r"warp must be a warp", owner=W)

# --- render ------------------------------------------------------------------------------------

G = RENDER_OWNER
api("render-tile-classes-granule",
    lambda d: A().render.culling.tile_classes(scene(d), 0), ValueError, "granule",
    owner=RENDER_OWNER)
api("render-tile-classes-max-classes",
    lambda d: A().render.culling.tile_classes(scene(d), 64, max_classes=0), ValueError,
    "max_classes", owner=RENDER_OWNER)
api("render-tile-classes-curved-everywhere",
    lambda d: A().render.culling.tile_classes(scene(d), 64, curved_everywhere="yes"), TypeError,
    "curved_everywhere", owner=RENDER_OWNER)
api("render-load-missing", lambda d: A().render.load_xml(d / "nosuch.xml"), FileNotFoundError,
    r"nosuch\.xml", owner=G)
api("render-load-not-xml", lambda d: A().render.load_xml(d / "notxml.xml"), ValueError,
    r"notxml\.xml", owner=G)
api("render-load-truncated-xml", lambda d: A().render.load_xml(d / "truncated.xml"), ValueError,
    r"truncated\.xml", owner=G)
api("render-load-unknown-override", lambda d: A().render.load_xml(d / "triangle_light.xml",
    nosuch=3), ValueError, r"nosuch.*(spp|width|height)", owner=G)
api("render-load-unknown-shape", lambda d: A().render.load_xml(d / "unknown_shape.xml"),
    ValueError, r"torus", owner=G)
api("render-load-missing-mesh", lambda d: A().render.load_xml(d / "missing_obj.xml"),
    (FileNotFoundError, ValueError), r"missing_obj\.xml.*file not found: .*nosuch\.obj",
    owner=G)
api("render-collinear-triangle-light", lambda d: A().render.load_xml(d / "collinear.xml"),
    ValueError, r"(collinear|degenerate|zero area|area)", owner=G)
api("render-nan-radiance", lambda d: A().render.load_xml(d / "nanlight.xml"), ValueError,
    r"(radiance|finite|nan)", owner=G)
api("render-negative-fov", lambda d: A().render.load_xml(d / "negfov.xml"), ValueError,
    r"fov", owner=G)
api("render-spp-zero", lambda d: A().render.render(scene(d), key(), spp=0), ValueError,
    r"spp must be >= 1", owner=G)
api("render-spp-float", lambda d: A().render.render(scene(d), key(), spp=2.5), TypeError,
    r"spp must be an integer", owner=G)
api("render-realizations-zero", lambda d: A().render.render(scene(d), key(), realizations=0),
    ValueError, r"realizations must be >= 1", owner=G)
api("render-technique-unknown", lambda d: A().render.render(scene(d), key(), technique="cosine"),
    ValueError, r"technique must be one of", owner=G)
api("render-light-warp-unknown", lambda d: A().render.render(scene(d), key(),
    light_warp="nosuch"), ValueError, r"light_warp.*(arvo2001|cosine-bilinear)", owner=G)
api("render-light-warp-psa-on-a-patch", lambda d: A().render.render(
    A().render.load_xml(SCENES / "patch_light.xml", width=4, height=4), key(), spp=1,
    light_warp="projected-solid-angle"), ValueError,
    r"projected-solid-angle.*applies to triangle and parallelogram lights only.*bilinear patch",
    owner=G)
api("render-sampler-unknown", lambda d: A().render.render(scene(d), key(), sampler="halton"),
    ValueError, r"halton", owner=G)
api("render-dimension-unknown", lambda d: A().render.render(scene(d), key(), dimension="time"),
    ValueError, r"dimension must be one of", owner=G)
api("render-key-int", lambda d: A().render.render(scene(d), 3), TypeError,
    r"key must be a single JAX PRNG key", owner=G)
proc("render-huge-image",
     "import jax, anisosample as a\n"
     "s = a.render.load_xml('triangle_light.xml', width=100000, height=100000, spp=1)\n"
     "try:\n    a.render.render(s, jax.random.key(0), progress=False)\n"
     "except (ValueError, MemoryError) as e:\n    print('REFUSED', type(e).__name__, e)\n",
     r"REFUSED ValueError .*(GB|GiB|TB|TiB|bytes|memory)", owner=G)
api("render-pixel-out-of-range", lambda d: A().render.pixel_integrand(scene(d), (8, 0)),
    ValueError, r"pixel", owner=G)
api("render-pixel-negative", lambda d: A().render.pixel_integrand(scene(d), (-1, 0)),
    ValueError, r"pixel", owner=G)
api("render-save-wrong-suffix", lambda d: A().render.save_result(d / "img.png", None),
    ValueError, r"must end in \.exr", owner=G)
api("render-tonemap-exposure-nan", lambda d: A().render.tonemap(np.ones((2, 2, 3)),
    exposure=NAN), ValueError, r"exposure must be finite", owner=G)
api("render-tonemap-nan-image", lambda d: A().render.tonemap(np.full((2, 2, 3), NAN)),
    ValueError, r"(NaN|finite)", owner=G)

# --- io ----------------------------------------------------------------------------------------

O = "io"
for name, pattern in [
    ("trunc.npz", r"trunc\.npz is a damaged or truncated NumPy \.npz archive"),
    ("flip.npz", r"flip\.npz is a damaged or truncated NumPy \.npz archive"),
    ("text.npz", r"text\.npz is not a NumPy \.npz archive \(the file is of another format\)"),
    ("zero.npz", r"zero\.npz is not a NumPy \.npz archive \(the file is empty\)"),
    ("foreign.npy", r"foreign\.npy is not a NumPy \.npy array"),
    ("pickle.npy", r"pickle\.npy is not a NumPy \.npy array"),
    ("trunc.npy", r"trunc\.npy is a damaged or truncated NumPy \.npy array"),
    ("nan.npy", r"points in .*nan\.npy contains NaN or Inf"),
    ("inf.npz", r"points in .*inf\.npz contains NaN or Inf"),
    ("outside.npy", r"points in .*outside\.npy must lie in \[0, 1\)\^2"),
    ("negative.npy", r"points in .*negative\.npy must lie in \[0, 1\)\^2"),
    ("one.npy", r"points in .*one\.npy must lie in \[0, 1\)\^2"),
    ("three.npy", r"points in .*three\.npy must have shape \(n, 2\)"),
    ("flat.npy", r"points in .*flat\.npy must have shape \(n, 2\)"),
    ("empty.npy", r"points in .*empty\.npy must have shape \(n, 2\) with n >= 1"),
    ("nopoints.npz", r"nopoints\.npz holds no array named 'points'"),
    ("nan.csv", r"points in .*nan\.csv contains NaN or Inf"),
    ("letters.txt", r"letters\.txt is not a text file of points"),
    ("ragged.csv", r"ragged\.csv is not a text file of points"),
]:
    api(f"io-load-points-{name}", lambda d, name=name: A().io.load_points(d / name), ValueError,
        pattern, owner=O)
api("io-load-points-ints", lambda d: A().io.load_points(d / "ints.npy"), TypeError,
    r"points in .*ints\.npy must be a floating-point array", owner=O)
api("io-load-points-missing", lambda d: A().io.load_points(d / "nosuch.npy"), FileNotFoundError,
    r"no such file: .*nosuch\.npy", owner=O)
api("io-load-points-directory", lambda d: A().io.load_points(d / "dir.npy"), IsADirectoryError,
    r"dir\.npy is a directory", owner=O)
api("io-load-points-suffix", lambda d: A().io.load_points(d / "pts.bmp"), ValueError,
    r"points file name must end in \.npy or \.npz or \.txt or \.csv or \.dat or \.bin, "
    r"got pts\.bmp", owner=O)
api("io-load-npz-damaged", lambda d: A().io.load_npz(d / "flip.npz"), ValueError,
    r"flip\.npz is a damaged", owner=O)
api("io-read-exr-junk", lambda d: A().io.read_exr(d / "junk.exr"), ValueError,
    r"junk\.exr is a damaged or truncated OpenEXR image", owner=O)
api("io-read-exr-truncated", lambda d: A().io.read_exr(d / "trunc.exr"), ValueError,
    r"trunc\.exr is a damaged or truncated OpenEXR image", owner=O)
api("io-read-exr-text", lambda d: A().io.read_exr(d / "text.exr"), ValueError,
    r"text\.exr is not an OpenEXR image", owner=O)
api("io-read-exr-missing", lambda d: A().io.read_exr(d / "nosuch.exr"), FileNotFoundError,
    r"nosuch\.exr", owner=O)
api("io-write-exr-txt", lambda d: A().io.write_exr(d / "x.txt", np.ones((2, 2))), ValueError,
    r"EXR file name must end in \.exr, got x\.txt", owner=O)
api("io-write-exr-shape", lambda d: A().io.write_exr(d / "x.exr", np.ones((2, 2, 2))),
    ValueError, r"image must have shape \(h, w\), \(h, w, 3\) or \(h, w, 4\)", owner=O)
api("io-write-refuses-overwrite", lambda d: A().io.save_points(d / "pts.npy", PTS),
    FileExistsError, r"pts\.npy exists; pass overwrite=True", owner=O)
api("io-save-npz-reserved", lambda d: A().io.save_npz(d / "r.npz", {"__metadata__": PTS}),
    ValueError, r"reserved name '__metadata__'", owner=O)
api("io-save-npz-suffix", lambda d: A().io.save_npz(d / "r.zip", {"points": PTS}), ValueError,
    r"\.npz file name must end in \.npz, got r\.zip", owner=O)
api("io-save-npy-suffix", lambda d: A().io.save_npy(d / "r.dat", PTS), ValueError,
    r"must end in \.npy, got r\.dat", owner=O)
api("io-save-png-nan", lambda d: A().io.save_png(d / "nan.png", np.full((2, 2), NAN)),
    ValueError, r"contains NaN or Inf", owner=O)
api("io-save-png-suffix", lambda d: A().io.save_png(d / "x.jpg", np.ones((2, 2))), ValueError,
    r"PNG file name must end in \.png, got x\.jpg", owner=O)
api("io-save-json-suffix", lambda d: A().io.save_json(d / "x.txt", {}), ValueError,
    r"JSON file name must end in \.json", owner=O)
api("io-load-json-damaged", lambda d: A().io.load_json(d / "table_json" / "table.json"),
    ValueError, r"table\.json is not a readable JSON file", owner=O)
api("io-save-into-directory", lambda d: A().io.save_npy(d / "dir.npy", PTS, overwrite=True),
    IsADirectoryError, r"dir\.npy is a directory", owner=O)
api("io-load-grid-suffix", lambda d: A().io.load_grid(d / "grid.txt"), ValueError,
    r"grid file name must end in \.npy or \.exr", owner=O)
api("io-load-grid-3d", lambda d: A().io.load_grid(d / "grid3d.npy"), ValueError,
    r"grid in .*grid3d\.npy must be 2D", owner=O)
api("io-load-grid-empty", lambda d: A().io.load_grid(d / "grid0.npy"), ValueError,
    r"grid in .*grid0\.npy must be 2D \(h, w\) and not empty", owner=O)
api("io-load-grid-nan", lambda d: A().io.load_grid(d / "nangrid.npy"), ValueError,
    r"grid in .*nangrid\.npy contains NaN or Inf", owner=O)
api("io-load-grid-bad-exr", lambda d: A().io.load_grid(d / "junk.exr"), ValueError,
    r"junk\.exr is a damaged", owner=O)
api("plot-points-panel-shape", lambda d: A().plot.points_panel(None, np.zeros((4, 3))),
    ValueError, r"points must have shape \(n, 2\)", owner="plot")
api("plot-points-nan", lambda d: A().plot.save_points_figure(d / "o_pts_nan.png",
    np.load(d / "nan.npy")), ValueError, r"points contains NaN or Inf", owner="plot")
api("plot-save-points-figure-suffix", lambda d: A().plot.save_points_figure(d / "p.bmp", PTS),
    ValueError, r"must end in \.png, \.pdf or \.svg", owner="plot")
api("plot-spectrum-scale-unknown", lambda d: A().plot.spectrum_image(np.ones((5, 5)), n=4,
    scale="cubic"), ValueError, r"scale must be one of \['linear', 'log'\]", owner="plot")
api("plot-spectrum-clip-negative", lambda d: A().plot.spectrum_image(np.ones((5, 5)), n=4,
    clip=-1.0), ValueError, r"clip must be None \(no clipping\) or a finite multiple",
    owner="plot")
api("plot-spectrum-clip-nan", lambda d: A().plot.spectrum_image(np.ones((5, 5)), n=4, clip=NAN),
    ValueError, r"clip must be None", owner="plot")
api("plot-spectrum-grid-nan", lambda d: A().plot.spectrum_image(np.full((5, 5), NAN), n=4),
    ValueError, r"grid contains NaN or Inf", owner="plot")
api("plot-spectrum-grid-even", lambda d: A().plot.spectrum_image(np.ones((4, 4)), n=4),
    ValueError, r"grid must be a square centred spectrum of odd side", owner="plot")
api("plot-spectrum-directions-200", lambda d: A().plot.save_spectrum_figure(d / "o_sp.png",
    np.ones((5, 5)), n=4, directions_deg=[200.0]), ValueError,
    r"directions_deg must lie in \[0, 180\)", owner="plot")
api("plot-direction-map-k-zero", lambda d: A().plot.save_direction_map(d / "o_dm.png",
    A().directions.Estimate(np.zeros((2, 2, 0)), np.zeros((2, 2, 0), bool), np.zeros((2, 2, 0)),
                            np.zeros((2, 2, 0))), block=4, shape=(8, 8)), ValueError,
    r"no direction slots \(k = 0\)", owner="plot")
api("plot-direction-map-shape", lambda d: A().plot.direction_map_rgb(np.zeros((2, 2)),
    np.ones((2, 2), bool), block=4, shape=(8, 20)), ValueError,
    r"shape \(8, 20\) does not fit 2x2 blocks of 4", owner="plot")
api("plot-direction-rgb-nan", lambda d: A().plot.direction_rgb(NAN, True), ValueError,
    r"directions_deg holds NaN or Inf where valid is true", owner="plot")

# --- the command line ---------------------------------------------------------------------------

cli("no-command", "", r"anisosample: error: the following arguments are required: COMMAND")
cli("unknown-command", "frobnicate", r"invalid choice: 'frobnicate'")
cli("unknown-option", "points random -n 8 -o {o}/a.npy --nosuch", r"unrecognized arguments")
cli("points-n-zero", "points random -n 0 -o {o}/a.npy", r"n must be >= 1")
cli("points-n-negative", "points random -n -3 -o {o}/a.npy", r"n must be >= 1")
cli("points-n-text", "points random -n many -o {o}/a.npy", r"argument -n: invalid int value")
cli("points-n-huge", "points random -n 100000000000 -o {o}/a.npy", r"n must be <= 16777216")
cli("points-unknown-sampler", "points halton -n 8 -o {o}/a.npy", r"unknown sampler 'halton'")
cli("points-wrong-suffix", "points random -n 8 -o {o}/a.bmp", r"--output must end in \.npy")
cli("points-exists", "points random -n 8 -o {d}/pts.npy", r"pts\.npy exists; pass --force")
cli("points-seed-negative", "points random -n 8 --seed -1 -o {o}/a.npy",
    r"seeds must lie in \[0, 2\^32\)")
cli("points-seed-huge", "points random -n 8 --seed 4294967296 -o {o}/a.npy",
    r"seeds must lie in \[0, 2\^32\)")
cli("points-aligned-without-directions", "points aligned -n 256 -o {o}/a.npz",
    r"points aligned needs --directions")
cli("points-sheared-without-direction", "points sheared -n 256 -o {o}/a.npz",
    r"points sheared needs --direction")
cli("points-sheared-direction-200", "points sheared -n 64 --direction 200 -o {o}/a.npz",
    r"direction_deg must lie in \[0, 180\)")
cli("points-sheared-direction-nan", "points sheared -n 64 --direction nan -o {o}/a.npz",
    r"argument --direction: expected a finite number")
cli("points-sheared-bad-base", "points sheared -n 64 --direction 30 --base halton -o {o}/a.npz",
    r"base must be one of")
cli("points-aligned-direction-nan", "points aligned -n 256 --directions 0,nan -o {o}/a.npz",
    r"argument --directions: expected finite numbers")
cli("points-aligned-direction-200", "points aligned -n 256 --directions 0,90,200 -o {o}/a.npz",
    r"directions_deg must lie in \[0, 180\)")
cli("points-directions-for-baseline", "points random -n 8 --directions 30 -o {o}/a.npz",
    r"--directions applies to the aligned or sheared sampler, not to 'random'")
cli("points-base-for-baseline", "points random -n 8 --base cmj -o {o}/a.npz",
    r"--base applies to the sheared sampler")
cli("spectrum-missing", "spectrum {d}/nosuch.npy -o {o}/s.png", r"no such file: .*nosuch\.npy")
cli("spectrum-truncated-npz", "spectrum {d}/trunc.npz -o {o}/s.png",
    r"trunc\.npz is a damaged or truncated")
cli("spectrum-bitflip-npz", "spectrum {d}/flip.npz -o {o}/s.png", r"flip\.npz is a damaged")
cli("spectrum-text-npz", "spectrum {d}/text.npz -o {o}/s.png", r"text\.npz is not a NumPy")
cli("spectrum-foreign-npy", "spectrum {d}/pickle.npy -o {o}/s.png",
    r"pickle\.npy is not a NumPy \.npy array")
cli("spectrum-nan-points", "spectrum {d}/nan.npy -o {o}/s.png", r"nan\.npy contains NaN or Inf")
cli("spectrum-radius-zero", "spectrum {d}/pts.npy -o {o}/s.png --radius 0", r"radius must be >= 1")
cli("spectrum-radius-negative", "spectrum {d}/pts.npy -o {o}/s.png --radius -4",
    r"radius must be >= 1")
cli("spectrum-radius-huge", "spectrum {d}/pts.npy -o {o}/s.png --radius 100000",
    r"radius.*(GB|GiB|MB|MiB|bytes|memory)", subprocess=True)
cli("spectrum-method-unknown", "spectrum {d}/pts.npy -o {o}/s.png --method fft",
    r"argument --method: invalid choice: 'fft'")
cli("spectrum-wrong-suffix", "spectrum {d}/pts.npy -o {o}/s.jpg", r"--output must end in \.png")
cli("spectrum-clip-negative", "spectrum {d}/pts.npy -o {o}/s.png --clip -1",
    r"argument --clip: expected a number > 0 or 'none'")
cli("spectrum-clip-nan", "spectrum {d}/pts.npy -o {o}/s.png --clip nan",
    r"argument --clip: expected a finite number")
cli("spectrum-scale-unknown", "spectrum {d}/pts.npy -o {o}/s.png --scale cubic",
    r"argument --scale: invalid choice: 'cubic'")
cli("spectrum-mark-directions-200", "spectrum {d}/pts.npy -o {o}/s.png --mark-directions 0,200",
    r"--mark-directions must lie in \[0, 180\) degrees")
cli("spectrum-mark-directions-text", "spectrum {d}/pts.npy -o {o}/s.png --mark-directions 3x",
    r"argument --mark-directions: expected comma-separated numbers")
cli("spectrum-picture-options-for-exr", "spectrum {d}/pts.npy -o {o}/s.exr --scale log",
    r"--scale shape the PNG picture; the \.exr output holds the raw P_S grid")
cli("synthesize-n-zero", "synthesize -n 0 --directions 0,90,30 -o {o}/o.npz", r"n must be >= ")
cli("synthesize-direction-200", "synthesize -n 64 --directions 0,90,200 -o {o}/o.npz",
    r"directions_deg must lie in \[0, 180\)")
cli("synthesize-direction-inf", "synthesize -n 64 --directions 0,inf -o {o}/o.npz",
    r"argument --directions: expected finite numbers")
cli("synthesize-steps-zero", "synthesize -n 64 --directions 0,90 --steps 0 -o {o}/o.npz",
    r"steps must be >= 1")
cli("synthesize-c-nan", "synthesize -n 64 --directions 0,90 --c nan -o {o}/o.npz",
    r"argument --c: expected a finite number")
cli("synthesize-wrong-suffix", "synthesize -n 64 --directions 0,90 -o {o}/o.bmp",
    r"points file name must end in \.npy or \.npz")
cli("synthesize-recipe-unknown", "synthesize -n 64 --directions 0,90 --recipe x -o {o}/o.npz",
    r"argument --recipe: invalid choice")
cli("tables-build-prefix-asymmetric", "tables build --n 64 --prefix pmj02bn-16 --sets 30",
    r"prefix 'pmj02bn-16' cannot be held by a table")
cli("tables-build-sequence-from-48", "tables build --n 64 --sequence-from 48 --sets 30",
    r"sequence_from must be 0 .* power of two")
cli("synthesize-36-directions-at-64",
    "synthesize -n 64 --directions " + ",".join(str(a) for a in range(0, 180, 5))
    + " -o {o}/o.npz", r"(directions|too many).*(n|points)")
cli("directions-missing", "directions {d}/nosuch.npy", r"no such file: .*nosuch\.npy")
cli("directions-nan-grid", "directions {d}/nangrid.npy", r"nangrid\.npy contains NaN or Inf")
cli("directions-bad-exr", "directions {d}/junk.exr", r"junk\.exr is a damaged")
cli("directions-text-exr", "directions {d}/text.exr", r"text\.exr is not an OpenEXR image")
cli("directions-3d-grid", "directions {d}/grid3d.npy", r"grid3d\.npy must be 2D")
cli("directions-k-negative", "directions {d}/grid.npy -k -1", r"k must be >= 0")
cli("directions-block-zero", "directions {d}/grid.npy --block 0", r"samples_per_block must be")
cli("directions-kappa-negative", "directions {d}/grid.npy --kappa -1",
    r"kappa must be finite and > 0")
cli("directions-old-method-option", "directions {d}/grid.npy --method gradient",
    r"--method is now --estimator")
cli("directions-estimator-unknown", "directions {d}/grid.npy --estimator hough",
    r"argument --estimator: invalid choice: 'hough'")
cli("directions-sigma-inf", "directions {d}/grid.npy --sigma inf",
    r"argument --sigma: expected a finite number")
cli("directions-output-without-block", "directions {d}/grid.npy -o {o}/m.png",
    r"--output \(per-block maps\) needs --block")
cli("directions-output-k-zero", "directions {d}/grid.npy --block 48 -k 0 -o {o}/m.png",
    r"--output \(per-block maps\) needs -k >= 1, got 0")
cli("directions-output-wrong-suffix", "directions {d}/grid.npy --block 48 -o {o}/m.jpg",
    r"--output must end in \.png")
cli("tables-no-action", "tables", r"required: ACTION")
cli("tables-info-missing", "tables info {d}/nosuch", r"nosuch")
cli("tables-info-not-a-table", "tables info {d}/not_a_table", r"not_a_table.*table\.json")
cli("tables-info-damaged-json", "tables info {d}/table_json", r"table_json.*table\.json")
cli("tables-info-damaged-set", "tables info {d}/table_damaged", r"psi_030\.npz.*damaged")
cli("tables-info-bitflipped-set", "tables info {d}/table_flipped", r"psi_045\.npz.*damaged")
cli("tables-info-deleted-set", "tables info {d}/table_missing",
    r"(45/46|missing).*psi_030|psi_030.*(missing|incomplete)", report=True)
cli("tables-build-n-zero", "tables build --n 0 --out {o}/t0", r"n must be >= ")
cli("tables-build-direction-count-5", "tables build --n 64 --direction-count 5 --out {o}/t5",
    r"argument --direction-count: invalid choice: 5")
cli("tables-build-old-directions-option", "tables build --n 64 --directions 4 --out {o}/t4",
    r"--directions is now --direction-count")
cli("tables-export-old-directions-option", "tables export --n 64 --directions 4 -o {o}/t.npz",
    r"--directions is now --direction-count")
cli("tables-build-bad-sets", "tables build --n 64 --sets 1:2:x --out {o}/tb",
    r"--sets must look like")
cli("tables-build-process-without-distributed", "tables build --n 64 --process-id 1 --out {o}/t",
    r"need --distributed")
cli("tables-build-processes-beyond-cores", "tables build --n 64 --processes 999 --out {o}/t",
    r"--processes must be at most the \d+ usable cores, got 999")
cli("tables-build-processes-damaged-table",
    "tables build --n 64 --processes 2 --out {d}/table_json", r"table_json.*table\.json")
cli("tables-build-processes-and-distributed",
    "tables build --n 64 --processes 2 --distributed --out {o}/t", r"does not go with")
cli("variance-integrand-unknown", "variance --integrand torus:1 -o {o}/v.json", r"torus")
cli("variance-integrand-bad-number", "variance --integrand edges:a -o {o}/v.json",
    r"expected numbers after ':'")
cli("variance-n-text", "variance --integrand edges:30 --n 64,x -o {o}/v.json",
    r"argument --n: expected comma-separated integers")
cli("variance-n-zero", "variance --integrand edges:30 --n 0,64 -o {o}/v.json",
    r"(ns|n) must be >= 1")
cli("variance-output-suffix", "variance --integrand edges:30 --n 64 -o {o}/v.txt",
    r"--output must end in \.json or \.png, got v\.txt")
cli("variance-points-missing-size", "variance --integrand edges:30 --points {d}/pts.txt "
    "--n 64,128", r"--points pts\.txt holds sets of n = \[64\], none of n = \[128\]")
cli("variance-realizations-one", "variance --integrand edges:30 --realizations 1 -o {o}/v.json",
    r"realizations must be >= 2")
cli("variance-sampler-unknown", "variance --integrand edges:30 --sampler halton -o {o}/v.json",
    r"unknown sampler 'halton'")
cli("variance-sampler-empty", "variance --integrand edges:30 --sampler , -o {o}/v.json",
    r"--sampler must name at least one sampler")
cli("variance-aligned-without-directions",
    "variance --integrand edges:30 --sampler aligned -o {o}/v.json",
    r"--sampler aligned needs --directions")
cli("variance-sheared-without-direction",
    "variance --integrand edges:30 --sampler sheared,random -o {o}/v.json",
    r"--sampler sheared needs --direction")
cli("variance-directions-unused",
    "variance --integrand edges:30 --sampler random --directions 0,90,30 -o {o}/v.json",
    r"--directions given but --sampler names neither aligned nor sheared")
cli("variance-wrong-suffix", "variance --integrand edges:30 -o {o}/v.txt",
    r"--output must end in \.json")
cli("variance-randomization-unknown",
    "variance --integrand edges:30 --randomization owen -o {o}/v.json",
    r"argument --randomization: invalid choice")
cli("render-missing-scene", "render {d}/nosuch.xml -o {o}/i.exr", r"nosuch\.xml")
cli("render-not-xml", "render {d}/notxml.xml -o {o}/i.exr", r"notxml\.xml")
cli("render-unknown-override", "render {d}/triangle_light.xml --set nosuch=1 -o {o}/i.exr",
    r"nosuch")
cli("render-override-without-equals", "render {d}/triangle_light.xml --set spp -o {o}/i.exr",
    r"--set expects NAME=VALUE")
cli("render-spp-zero", "render {d}/triangle_light.xml --spp 0 -o {o}/i.exr", r"spp must be >= 1")
cli("render-exposure-nan", "render {d}/triangle_light.xml --exposure nan -o {o}/i.exr",
    r"argument --exposure: expected a finite number")
cli("render-exposure-inf", "render {d}/triangle_light.xml --exposure=-inf -o {o}/i.exr",
    r"argument --exposure: expected a finite number")
cli("render-technique-unknown", "render {d}/triangle_light.xml --technique cosine -o {o}/i.exr",
    r"argument --technique: invalid choice")
cli("render-light-warp-unknown", "render {d}/triangle_light.xml --light-warp nosuch "
    "-o {o}/i.exr", r"(--light-warp|light_warp).*(invalid choice|arvo2001)")
cli("render-wrong-suffix", "render {d}/triangle_light.xml -o {o}/i.png",
    r"--output must end in \.exr")
cli("render-collinear-light", "render {d}/collinear.xml --spp 1 -o {o}/i.exr",
    r"(collinear|degenerate|zero area|area)")
cli("render-bad-reference", "render {d}/triangle_light.xml --set width=8 --set height=8 "
    "--spp 1 --reference {d}/junk.exr -o {o}/i.exr", r"junk\.exr is a damaged")
cli("render-block-without-aligned", "render {d}/triangle_light.xml --block 16 -o {o}/i.exr",
    r"--block, --estimation-samples, --k, --no-gate and --direction-map need --sampler")
cli("render-no-gate-without-aligned", "render {d}/triangle_light.xml --no-gate -o {o}/i.exr",
    r"--no-gate and --direction-map need --sampler aligned or sheared")
cli("render-aligned-k-3", "render {d}/triangle_light.xml --sampler aligned --k 3 -o {o}/i.exr",
    r"argument --k: invalid choice: 3 \(choose from 1, 2\)")
cli("render-huge-image", "render {d}/triangle_light.xml --set width=100000 --set height=100000 "
    "--spp 1 -o {o}/huge.exr", r"(GB|GiB|TB|TiB|bytes|memory)", subprocess=True)
cli("render-realizations-zero", "render {d}/triangle_light.xml --realizations 0 -o {o}/i.exr",
    r"realizations must be >= 1")
cli("points-subprocess-sheared", "points sheared -n 64 -o {o}/a.npz",
    r"points sheared needs --direction", subprocess=True)


# --- running a case ------------------------------------------------------------------------------

IDS = [c.id for c in CASES]
assert len(IDS) == len(set(IDS)), "case ids must be unique"


def _argv(case: Case, d: Path) -> list[str]:
    """The case's command line: ``{d}`` is the prepared folder, ``{o}`` a fresh folder for the
    case's outputs (so that no case trips over another's files)."""
    out = d / "out" / case.id
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    return [a.replace("{d}", str(d)).replace("{o}", str(out)) for a in shlex.split(case.argv)]


def _subprocess_env():
    env = dict(os.environ, PYTHONWARNINGS="ignore", JAX_PLATFORMS="cpu")
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
    return env


def run_case(case: Case, d: Path) -> tuple[str, str]:
    """Run one case; return ``(outcome, detail)`` with outcome ``"error"`` (the required clear
    error), ``"crash"`` (the process died or printed a traceback), ``"silent"`` (accepted or
    returned a value), or ``"wrong"`` (an error, but not the one required)."""
    if case.setup is not None:
        case.setup(d)
    if case.code is not None or (case.argv is not None and case.subprocess):
        cmd = ([sys.executable, "-c", case.code] if case.code is not None
               else [sys.executable, "-m", "anisosample", *_argv(case, d)])
        try:
            r = subprocess.run(cmd, capture_output=True, text=True, timeout=240, cwd=d,
                               env=_subprocess_env())
        except subprocess.TimeoutExpired:
            return "crash", "timed out after 240 s"
        if r.returncode < 0 or r.returncode in (134, 139):
            return "crash", f"exit {r.returncode}: {r.stderr.strip()[-600:]}"
        if case.code is None and "Traceback" in r.stderr:  # the CLI prints one line, no more
            return "crash", f"exit {r.returncode}: {r.stderr.strip()[-600:]}"
        if case.code is not None:
            ok = r.returncode == 0 and re.search(case.match, r.stdout)
            return ("error", r.stdout.strip()) if ok else ("silent" if "RETURNED" in r.stdout
                                                           else "wrong", r.stdout + r.stderr)
        return _judge_cli(case, r.returncode, r.stdout, r.stderr)
    if case.argv is not None:
        from anisosample import cli

        out, err = io.StringIO(), io.StringIO()
        try:
            with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
                rc = cli.main(_argv(case, d))
        except SystemExit as exc:  # pragma: no cover - main() returns instead
            rc = exc.code
        except Exception as exc:  # noqa: BLE001 - a traceback is the failure we look for
            return "crash", f"{type(exc).__name__}: {exc}"
        return _judge_cli(case, rc, out.getvalue(), err.getvalue())
    try:
        result = case.call(d)
    except case.error as exc:
        text = str(exc.args[0]) if isinstance(exc, KeyError) and exc.args else str(exc)
        if re.search(case.match, text):
            return "error", f"{type(exc).__name__}: {text}"
        return "wrong", f"{type(exc).__name__} without /{case.match}/: {text}"
    except Exception as exc:  # noqa: BLE001
        return "wrong", f"{type(exc).__name__} instead of {case.error}: {exc}"
    if case.report:
        return "error", "reported"
    return "silent", f"returned {_short(result)} instead of raising"


def _short(value) -> str:
    text = repr(value)
    return text if len(text) < 200 else text[:197] + "..."


def _judge_cli(case, rc, out, err):
    if "Traceback" in err:
        return "crash", err.strip()[-600:]
    lines = [ln for ln in re.split(r"[\r\n]", err) if ln.strip().startswith("anisosample")]
    if case.report:
        text = out + err
        return ("error", text.strip()) if re.search(case.match, text) else (
            "silent", f"exit {rc}, output without /{case.match}/: {text.strip()[-400:]}")
    if rc == 0:
        return "silent", f"exit 0: {out.strip()[-300:]}"
    if rc != 2 or len(lines) != 1 or not re.search(case.match, lines[0]):
        return "wrong", f"exit {rc}, stderr: {err.strip()[-600:]}"
    return "error", lines[0]


@pytest.fixture(scope="module")
def d(tmp_path_factory):
    folder = tmp_path_factory.mktemp("bad_input")
    prepare(folder)
    return folder


PENDING = {
    # case id -> the guard that is still missing (strict: the mark must go once it is there)
}


ISSUE_EXAMPLES = {
    # every example issue 17 lists -> the case that holds it
    "spectrum --radius 100000 aborts inside XLA": "cli-spectrum-radius-huge",
    "a NaN in a synthesis checkpoint segfaults synthesize": "cli-synthesize-checkpoint-nan",
    "jax.grad of spectrum_loss with one NaN point segfaults": "proc-losses-grad-nan-point",
    "... also under jit": "api-losses-jit-grad-nan-point",
    "truncated .npz (points)": "cli-spectrum-truncated-npz",
    "bit-flipped .npz (points)": "cli-spectrum-bitflip-npz",
    "truncated .npz (checkpoints)": "cli-synthesize-checkpoint-damaged",
    "truncated .npz (table sets)": "cli-tables-info-damaged-set",
    "bit-flipped .npz (table sets)": "cli-tables-info-bitflipped-set",
    "a non-numpy file is 'pickled (object) data'": "cli-spectrum-foreign-npy",
    "a checkpoint of the wrong shape": "cli-synthesize-checkpoint-wrong-shape",
    "synthesize -n 100000000 MemoryError": "cli-synthesize-n-huge",
    "a 100000x100000 render MemoryError": "cli-render-huge-image",
    "a bad EXR raises RuntimeError": "cli-directions-bad-exr",
    "points sheared fails with a signature error": "cli-points-sheared-without-direction",
    "a table with a set file deleted is reported complete": "cli-tables-info-deleted-set",
    "render --set nosuch=1 ignores the override": "cli-render-unknown-override",
    "load_xml(path, nosuch=3) ignores the override": "api-render-load-unknown-override",
    "--exposure nan writes a black PNG": "cli-render-exposure-nan",
    "a collinear triangle light renders black": "cli-render-collinear-light",
    "vmf.pdf takes a negative kappa": "api-vmf-pdf-negative-kappa",
    "vmf.bin_masses takes a negative kappa": "api-vmf-bin-masses-negative-kappa",
    "fit_pointwise with a negative factor becomes uniform":
        "api-warps-fit-pointwise-negative-factor",
    "fit_pointwise with a NaN factor becomes uniform": "api-warps-fit-pointwise-nan-factor",
    "sample_batch clamps u outside [0, 1]": "api-warps-sample-batch-u-above-one",
    "sample_batch maps NaN u to a finite direction": "api-warps-sample-batch-u-nan",
    "a checkpoint step beyond --steps is written as optimized":
        "cli-synthesize-checkpoint-step-beyond-steps",
    "write_exr('x.txt') writes an EXR named .txt": "api-io-write-exr-txt",
    "36 directions at n = 64 are accepted": "cli-synthesize-36-directions-at-64",
    "an unknown light_warp lists the allowed names (issue 14)": "cli-render-light-warp-unknown",
    "aligned/sheared without directions (issue 14)": "cli-points-aligned-without-directions",
}


def _marks(case):
    reason = case.xfail or PENDING.get(case.id)
    return [pytest.mark.xfail(strict=True, reason=reason)] if reason else []


@pytest.mark.parametrize("case", [pytest.param(c, id=c.id, marks=_marks(c)) for c in CASES])
def test_bad_input(case, d):
    outcome, detail = run_case(case, d)
    assert outcome == "error", f"{case.id}: {outcome}: {detail}"


def test_the_catalogue_is_large_and_covers_every_subcommand():
    assert len(CASES) >= 150
    commands = {shlex.split(c.argv)[0] for c in CASES if c.argv}
    assert {"points", "spectrum", "synthesize", "directions", "tables", "variance",
            "render"} <= commands
    assert sum(c.subprocess for c in CASES) <= 6  # the catalogue stays fast
    assert set(PENDING) <= {c.id for c in CASES}


def test_every_example_of_the_issue_has_its_case():
    ids = {c.id for c in CASES}
    assert not [c for c in ISSUE_EXAMPLES.values() if c not in ids]


def main() -> int:
    """Run every case without pytest and print the outcome table."""
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        prepare(folder)

        rows = []
        for case in CASES:
            outcome, detail = run_case(case, folder)
            rows.append((case, outcome, detail))
            print(f"{outcome:6s} {case.id}" + ("" if outcome == "error" else f"  -- {detail}"),
                  flush=True)
    kinds = {"API (in-process)": lambda c: c.call is not None,
             "CLI (in-process cli.main)": lambda c: c.argv is not None and not c.subprocess,
             "subprocess": lambda c: c.subprocess}
    print()
    print(f"{'':28s}{'cases':>7s}{'clear error':>13s}{'crash':>7s}{'silent':>8s}{'wrong':>7s}")
    for label, pick in [*kinds.items(), ("all", lambda c: True)]:
        sel = [o for c, o, _ in rows if pick(c)]
        print(f"{label:28s}{len(sel):7d}{sel.count('error'):13d}{sel.count('crash'):7d}"
              f"{sel.count('silent'):8d}{sel.count('wrong'):7d}")
    return 0 if all(o == "error" for _, o, _ in rows) else 1


if __name__ == "__main__":
    sys.exit(main())

"""The pictures a person reads (issue 27): spectrum figures and per-block direction maps.

Truth is computed a second way: spectra from the direct sum ``|sum exp(-2 pi i v.x)|^2 / n^2``
in NumPy float64 and a rank-1 lattice whose peaks are known in closed form; orientation from the
pixels of the drawn canvas (where a frequency or a block lands on screen); colours from the hue
circle (``matplotlib.colors.rgb_to_hsv``).
"""

from __future__ import annotations

import jax
import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import LogNorm, rgb_to_hsv
from matplotlib.figure import Figure
from matplotlib.image import imread

from anisosample import cli, directions, plot, samplers, spectrum

# Rank-1 lattice x_k = (k / 13, 5 k / 13 mod 1): P_S(v) = 1 where v_x + 5 v_y = 0 (mod 13), else
# 0. Within |v| <= 4 that is v = 0, +-(3, 2) and +-(2, -3): (3, 2) is bright while its transpose
# (2, 3) and its mirror (3, -2) are dark, so a transposed or flipped picture fails.
N_LAT, G_LAT, R_LAT = 13, 5, 4
LATTICE = np.stack([np.arange(N_LAT) / N_LAT, (G_LAT * np.arange(N_LAT) % N_LAT) / N_LAT],
                   axis=-1).astype(np.float32)


def _direct_grid(points, r):
    """``P_S`` on the centred grid by the direct sum in float64, ``[i, j] = P_S(j - r, i - r)``."""
    p = np.asarray(points, np.float64)
    v = np.arange(-r, r + 1)
    vx, vy = np.meshgrid(v, v, indexing="xy")  # [i, j] -> (v_x = j - r, v_y = i - r)
    phase = np.exp(-2j * np.pi * (vx[..., None] * p[:, 0] + vy[..., None] * p[:, 1]))
    return np.abs(phase.mean(axis=-1)) ** 2


def _canvas(fig):
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].astype(float) / 255.0


def _pixel(img, ax, x, y):
    """The canvas colour at data point ``(x, y)`` of ``ax`` (display y counts from the bottom)."""
    px, py = ax.transData.transform((x, y))
    return img[img.shape[0] - 1 - int(round(py)), int(round(px))]


def test_spectrum_image_is_power_spectrum_grid():
    grid = np.asarray(spectrum.power_spectrum_grid(LATTICE, R_LAT))
    truth = _direct_grid(LATTICE, R_LAT)
    img = plot.spectrum_image(grid, n=N_LAT, clip=None)
    np.testing.assert_allclose(img, N_LAT * truth, atol=1e-5)
    c = R_LAT
    assert img[c + 2, c + 3] == pytest.approx(N_LAT, rel=1e-5)  # v = (3, 2): row v_y, col v_x
    assert img[c - 2, c - 3] == pytest.approx(N_LAT, rel=1e-5)  # -(3, 2)
    assert img[c + 3, c + 2] < 1e-4 and img[c - 2, c + 3] < 1e-4  # (2, 3) and (3, -2) dark
    # white noise is 1: the default clip at 2 caps the peaks, leaves the rest as it was
    clipped = plot.spectrum_image(grid, n=N_LAT)
    np.testing.assert_allclose(clipped, np.minimum(N_LAT * grid, 2.0))


def test_spectrum_panel_shows_frequency_a_b_at_x_a_y_b():
    grid = np.asarray(spectrum.power_spectrum_grid(LATTICE, R_LAT))
    fig = Figure(figsize=(4, 4), dpi=100)
    ax = fig.add_subplot()
    im = plot.spectrum_panel(ax, grid, n=N_LAT, directions_deg=[30.0])
    img = _canvas(fig)
    bright, dark = _pixel(img, ax, 3, 2), [_pixel(img, ax, *v) for v in ((2, 3), (3, -2), (1, 1))]
    assert bright.min() > 0.95, bright
    assert all(d.max() < 0.05 for d in dark), dark
    assert im.origin == "lower" and ax.get_xlim() == ax.get_ylim() == (-4.5, 4.5)
    # integer frequency ticks centred at 0
    ticks = [t for t in ax.get_xticks() if -4.5 <= t <= 4.5]
    assert 0 in ticks and all(float(t).is_integer() for t in ticks)
    # the marked direction is a line through the origin along (cos 30, sin 30)
    (line,) = ax.lines
    x, y = line.get_data()
    assert np.degrees(np.arctan2(y[1] - y[0], x[1] - x[0])) % 180 == pytest.approx(30.0)
    assert abs((x[1] - x[0]) * y[0] - (y[1] - y[0]) * x[0]) < 1e-9  # passes through (0, 0)
    assert len(fig.axes) == 2  # the panel and its colour bar


def test_dark_direction_of_an_aligned_set_shows_at_30_degrees():
    """A table set dark along 30 deg: on screen, the pixels along 30 deg from +x towards +y are
    darker than along 150 deg (its mirror under a vertical flip) at the same radii."""
    import jax

    from anisosample import samplers

    pts = samplers.get("aligned", directions_deg=[0.0, 90.0, 30.0])(jax.random.key(0), 256)
    grid = np.asarray(spectrum.power_spectrum_grid(pts, 24))
    fig = Figure(figsize=(5, 5), dpi=100)
    ax = fig.add_subplot()
    plot.spectrum_panel(ax, grid, n=256, colorbar=False)
    img = _canvas(fig).mean(axis=-1)
    radii = np.arange(6, 22)

    def along(t):
        return np.mean([_pixel(img[..., None], ax, r * np.cos(np.radians(t)),
                               r * np.sin(np.radians(t)))[0] for r in radii])

    assert along(30.0) < 0.15 < along(150.0), (along(30.0), along(150.0))


def test_log_scale_and_clip_as_documented():
    grid = np.asarray(spectrum.power_spectrum_grid(LATTICE, R_LAT))
    img = plot.spectrum_image(grid, n=N_LAT, scale="log", clip=None, log_floor=1e-2)
    np.testing.assert_allclose(img, np.maximum(N_LAT * grid, 1e-2))
    assert img.min() == pytest.approx(1e-2)
    fig = Figure()
    ax = fig.add_subplot()
    im = plot.spectrum_panel(ax, grid, n=N_LAT, scale="log", clip=5.0, log_floor=1e-2)
    np.testing.assert_allclose(im.get_array(), np.clip(N_LAT * grid, 1e-2, 5.0))
    assert isinstance(im.norm, LogNorm) and (im.norm.vmin, im.norm.vmax) == (1e-2, 5.0)
    assert "clipped at 5" in fig.axes[1].get_ylabel()
    # clip=None: the colour range ends at the largest value away from v = 0 (N P_S(0) = N)
    rng = np.random.default_rng(1)
    pts = rng.random((64, 2)).astype(np.float32)
    g = np.asarray(spectrum.power_spectrum_grid(pts, 6))
    im = plot.spectrum_panel(Figure().add_subplot(), g, n=64, clip=None)
    away = 64 * g.copy()
    away[6, 6] = 0
    assert im.norm.vmin == 0 and im.norm.vmax == pytest.approx(away.max())
    np.testing.assert_allclose(im.get_array(), 64 * g)  # nothing clipped


@pytest.mark.library_errors
@pytest.mark.parametrize("kw, error, match", [
    ({"scale": "cubic"}, ValueError, r"scale must be one of \['linear', 'log'\]"),
    ({"clip": -1.0}, ValueError, r"clip must be None \(no clipping\) or a finite multiple"),
    ({"clip": 0.0}, ValueError, r"clip must be None"),
    ({"clip": float("nan")}, ValueError, r"clip must be None"),
    ({"clip": "2"}, TypeError, r"clip must be None \(no clipping\) or a number"),
    ({"scale": "log", "log_floor": 0.0}, ValueError, r"log_floor must be finite and > 0"),
    ({"scale": "log", "clip": 1.0, "log_floor": 2.0}, ValueError, r"log_floor must be below"),
    ({"directions_deg": [200.0]}, ValueError, r"directions_deg must lie in \[0, 180\)"),
    ({"directions_deg": [float("nan")]}, ValueError, r"directions_deg must lie in \[0, 180\)"),
    ({"n": 0}, ValueError, r"n must be >= 1"),
])
def test_spectrum_panel_bad_arguments(kw, error, match):
    args = {"n": 4, **kw}
    with pytest.raises(error, match=match):
        plot.spectrum_panel(Figure().add_subplot(), np.ones((5, 5)), **args)


def test_save_spectrum_figure_refuses_to_overwrite(tmp_path):
    grid = np.asarray(spectrum.power_spectrum_grid(LATTICE, R_LAT))
    path = plot.save_spectrum_figure(tmp_path / "s.png", grid, n=N_LAT)
    assert imread(path).shape[2] in (3, 4)
    with pytest.raises(FileExistsError, match="s.png exists"):
        plot.save_spectrum_figure(path, grid, n=N_LAT)
    with pytest.raises(ValueError, match=r"must end in \.png, \.pdf or \.svg"):
        plot.save_spectrum_figure(tmp_path / "s.jpg", grid, n=N_LAT)


# --- direction maps ------------------------------------------------------------------------------


def _hue(rgb):
    return float(rgb_to_hsv(np.asarray(rgb, float))[0])


def test_direction_colours_are_axial():
    ok = np.array(True)
    red, also_red = plot.direction_rgb(0.0, ok), plot.direction_rgb(180.0, ok)
    np.testing.assert_allclose(red, also_red, atol=1e-12)  # 0 and 180: one axial direction
    np.testing.assert_allclose(red, [1.0, 0.0, 0.0])
    for t in (0.0, 30.0, 45.0, 100.0):  # perpendicular directions: opposite hues
        a, b = plot.direction_rgb(t, ok), plot.direction_rgb(t + 90.0, ok)
        assert abs(_hue(a) - _hue(b)) == pytest.approx(0.5, abs=1e-9)
    assert _hue(plot.direction_rgb(45.0, ok)) == pytest.approx(0.25)  # hue = 2 theta
    # unestimated: the neutral colour, whatever the (placeholder) direction; never NaN
    none = plot.direction_rgb(np.array([-1.0, np.nan]), np.array([False, False]))
    np.testing.assert_allclose(none, [plot.NO_ESTIMATE_RGB] * 2)
    assert np.ptp(plot.NO_ESTIMATE_RGB) == 0  # grey: no saturated hue is grey
    with pytest.raises(ValueError, match="directions_deg holds NaN"):
        plot.direction_rgb(np.nan, True)


# 2 x 3 blocks of 4 px over a 8 x 11 image (the last column of blocks cropped to 3 px)
DIRS = np.array([[0.0, 45.0, 90.0], [135.0, -1.0, 30.0]])
VALID = DIRS >= 0


def test_direction_map_rgb_paints_each_block_over_its_pixels():
    (rgb,) = plot.direction_map_rgb(DIRS, VALID, block=4, shape=(8, 11))
    assert rgb.shape == (8, 11, 3)
    for a in range(2):
        for b in range(3):
            tile = rgb[4 * a:4 * a + 4, 4 * b:min(4 * b + 4, 11)]
            want = plot.direction_rgb(DIRS[a, b], VALID[a, b])
            np.testing.assert_array_equal(tile, np.broadcast_to(want, tile.shape))
    with pytest.raises(ValueError, match="does not fit 2x3 blocks of 4"):
        plot.direction_map_rgb(DIRS, VALID, block=4, shape=(8, 13))


@pytest.mark.parametrize("origin", ["lower", "upper"])
def test_direction_map_panel_orientation(origin):
    """Row 0 of the blocks sits at the bottom for DESIGN's grids, at the top for images; the
    unestimated block reads grey under its hatching."""
    fig = Figure(figsize=(4, 3.5), dpi=100)
    ax = fig.add_subplot()
    plot.direction_map_panel(ax, DIRS, VALID, block=4, shape=(8, 11), origin=origin)
    img = _canvas(fig)
    for a, b in ((0, 0), (0, 1), (0, 2), (1, 0), (1, 2)):
        got = _pixel(img, ax, 4 * b + 1.5, 4 * a + 2)
        np.testing.assert_allclose(got, plot.direction_rgb(DIRS[a, b], True), atol=0.02)
    px0 = ax.transData.transform((1.5, 2.0))[1]  # display y of block row 0 (from the bottom)
    px1 = ax.transData.transform((1.5, 6.0))[1]
    assert (px0 < px1) == (origin == "lower")
    x0, y0 = ax.transData.transform((4, 4))  # the unestimated block (1, 1), hatched grey
    x1, y1 = ax.transData.transform((8, 8))
    rows = slice(img.shape[0] - int(max(y0, y1)) + 2, img.shape[0] - int(min(y0, y1)) - 2)
    tile = img[rows, int(x0) + 2:int(x1) - 2]
    assert np.ptp(tile, axis=-1).max() < 0.05  # grey levels only: no hue
    assert tile.std() > 0.02  # hatched, not a flat fill


def test_save_direction_map_from_estimate_blocks(tmp_path):
    est = directions.Estimate(DIRS[..., None], VALID[..., None], np.zeros((2, 3, 1)),
                              np.zeros((2, 3, 1)))
    path = plot.save_direction_map(tmp_path / "m.png", est, block=4, shape=(8, 11))
    h, w = imread(path).shape[:2]
    assert 300 < h < 1500 and 600 < w < 3000  # a figure, not one pixel per block
    with pytest.raises(FileExistsError, match="m.png exists"):
        plot.save_direction_map(path, est, block=4, shape=(8, 11))
    with pytest.raises(ValueError, match="needs block= .* and shape="):
        plot.save_direction_map(tmp_path / "n.png", est)
    z = np.zeros((2, 3, 0))
    empty = directions.Estimate(z, z.astype(bool), z, z)
    with pytest.raises(ValueError, match=r"no direction slots \(k = 0\)"):
        plot.save_direction_map(tmp_path / "n.png", empty, block=4, shape=(8, 11))
    with pytest.raises(TypeError, match="estimate must be a render BlockEstimate"):
        plot.save_direction_map(tmp_path / "n.png", object())
    assert not (tmp_path / "n.png").exists()


def test_save_direction_map_from_a_render_block_estimate(tmp_path):
    from anisosample.render.estimation import BlockEstimate

    inner = directions.Estimate(DIRS[..., None], VALID[..., None], np.zeros((2, 3, 1)),
                                np.zeros((2, 3, 1)))
    est = BlockEstimate(inner, None, block_px=4, samples=8, width=11, height=8, seconds=0.0,
                        integrand_samples=0)
    path = plot.save_direction_map(tmp_path / "r.png", est)
    assert imread(path).shape[0] > 300


# --- command line --------------------------------------------------------------------------------


def test_cli_spectrum_png_is_a_figure(tmp_path, capsys):
    pts = tmp_path / "lat.npy"
    np.save(pts, LATTICE)
    png = tmp_path / "s.png"
    assert cli.main(["spectrum", str(pts), "-o", str(png), "--radius", "4", "--scale", "log",
                     "--clip", "none", "--mark-directions", "30,120"]) == 0
    h, w = imread(png).shape[:2]
    assert 400 < h < 1500 and 400 < w < 1500  # not the old 9x9 pixels
    assert cli.main(["spectrum", str(pts), "-o", str(png), "--radius", "4"]) == 2
    assert "exists; pass --force" in capsys.readouterr().err


def test_cli_directions_map_is_image_sized_with_a_key(tmp_path):
    h, w = 96, 144
    ys, xs = np.meshgrid((np.arange(h) + 0.5) / h, (np.arange(w) + 0.5) / w, indexing="ij")
    grid = tmp_path / "g.npy"
    np.save(grid, (ys > 0.2 + 0.5 * xs).astype(np.float32))  # one edge, gradient at 116.6 deg
    png = tmp_path / "maps.png"
    assert cli.main(["directions", str(grid), "--block", "48", "-k", "1", "-o", str(png)]) == 0
    img = imread(png)
    assert 300 < img.shape[0] < 1500 and 600 < img.shape[1] < 3000


def test_spectrum_images(tmp_path):
    pts4096 = samplers.get("pmj02bn")(jax.random.key(21), 4096)
    g = spectrum.power_spectrum_grid(pts4096, 32)
    png = plot.save_spectrum_image(tmp_path / "s.png", g, n=4096)
    exr = plot.save_spectrum_image(tmp_path / "s.exr", g, n=4096)
    assert png.stat().st_size > 0
    from anisosample import io

    back, meta = io.read_exr(exr, metadata=True)
    np.testing.assert_allclose(back, np.asarray(g), rtol=1e-6)  # the grid, no flip (issue 27)
    assert meta["n"] == 4096 and meta["radius"] == 32
    with pytest.raises(FileExistsError):
        plot.save_spectrum_image(tmp_path / "s.png", g, n=4096)


def test_spectrum_image_rejects_bad_vmax(tmp_path):
    g = np.ones((5, 5))
    for vmax in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="vmax must be finite and > 0"):
            plot.save_spectrum_image(tmp_path / "s.png", g, n=4, vmax=vmax)
    assert not (tmp_path / "s.png").exists()


def test_save_spectrum_image_png_is_upright_and_clipped(tmp_path):
    """The PNG is ``N P_S`` clipped to ``[0, vmax]`` in grey with ``v_y`` growing upwards: the
    rank-1 lattice's bright ``(3, 2)`` lands right of and above the centre, its dark mirror
    ``(3, -2)`` below."""
    g = _direct_grid(LATTICE, R_LAT)
    path = plot.save_spectrum_image(tmp_path / "lat.png", g, n=N_LAT, vmax=2.0)
    img = imread(path)
    grey = img[..., 0] if img.ndim == 3 else img
    c = R_LAT
    assert grey.shape == (2 * R_LAT + 1, 2 * R_LAT + 1)
    assert grey[c - 2, c + 3] == pytest.approx(1.0)  # N P_S = 13, clipped to vmax: white
    assert grey[c + 2, c + 3] == pytest.approx(0.0)

"""Principal-direction estimation (anisosample.directions): conventions, accuracy, bad input."""

import math

import jax.numpy as jnp
import numpy as np
import pytest
from helpers import assert_pytree_round_trips

from anisosample import directions, integrands
from anisosample.metrics import axial_distance_deg


def grid(f, n=96):
    """DESIGN's grid convention: values[i, j] = f((j + .5)/n, (i + .5)/n)."""
    return np.asarray(f(directions.block_grid(n)), np.float32)


def step(phi_deg, p=(0.5, 0.5)):
    """Indicator of x.(cos phi, sin phi) > p.(cos phi, sin phi): an edge whose normal (spectral
    direction) is phi; written independently of anisosample.integrands."""
    t = math.radians(phi_deg)
    n = jnp.asarray([math.cos(t), math.sin(t)], jnp.float32)
    c = float(np.dot(p, [math.cos(t), math.sin(t)]))
    return lambda x: (x @ n > c).astype(jnp.float32)


def doubled_angle_mean_deg(hist):
    """The weighted axial mean of a histogram (fact sheet Sec. 1): a second estimator."""
    h = np.asarray(hist, np.float64)
    a = np.radians(2 * np.arange(len(h)) * 180.0 / len(h))
    return math.degrees(math.atan2((h * np.sin(a)).sum(), (h * np.cos(a)).sum())) / 2 % 180


@pytest.mark.parametrize("phi", [17.0, 30.0, 60.0, 100.0, 134.3, 150.0, 170.0])
def test_histogram_convention_matches_edge_normal(phi):
    # y grows with the row index and angles run from +x to +y: 30 and 150 must not be confused
    hist = directions.orientation_histogram(grid(step(phi)))
    assert hist.shape == (180,) and bool(jnp.all(hist >= 0))
    assert axial_distance_deg(doubled_angle_mean_deg(hist), phi) < 1.0


def _filter_axis(v, taps, axis):
    """Correlate ``v`` with 1D ``taps`` along ``axis``, replicate borders (float64 reference)."""
    r = (len(taps) - 1) // 2
    pad = [(0, 0)] * v.ndim
    pad[axis] = (r, r)
    vp = np.pad(v, pad, mode="edge")
    n = v.shape[axis]
    return sum(t * np.take(vp, np.arange(k, k + n), axis=axis) for k, t in enumerate(taps))


def _gradients_by_slices(values, sigma):
    """Gaussian smoothing then Sobel by shifted slices: the readable definition."""
    r = max(1, math.ceil(3.0 * sigma))
    g = np.exp(-0.5 * (np.arange(-r, r + 1) / sigma) ** 2)
    g /= g.sum()
    smooth, diff = np.array([0.25, 0.5, 0.25]), np.array([-0.5, 0.0, 0.5])
    s = _filter_axis(_filter_axis(np.asarray(values, np.float64), g, -1), g, -2)
    return (_filter_axis(_filter_axis(s, diff, -1), smooth, -2),
            _filter_axis(_filter_axis(s, smooth, -1), diff, -2))


def test_matrix_filters_equal_shifted_slice_filters():
    rng = np.random.default_rng(0)
    for shape, sigma in [((40, 56), 2.0), ((17, 17), 1.0), ((96, 96), 1.5)]:
        v = jnp.asarray(rng.uniform(size=shape), jnp.float32)
        ref = _gradients_by_slices(v, sigma)
        for a, b in zip(directions.gradients(v, sigma_px=sigma), ref, strict=True):
            np.testing.assert_allclose(a, b, atol=2e-6)


def test_histogram_bins_are_centred_and_configurable():
    h2 = directions.orientation_histogram(grid(step(40.0)), bin_deg=2.0)
    assert h2.shape == (90,)
    assert axial_distance_deg(doubled_angle_mean_deg(h2), 40.0) < 1.0
    h = directions.orientation_histogram(grid(step(0.0)))
    assert int(jnp.argmax(h)) == 0  # an edge at exactly 0 lands in the bin centred on 0
    assert float(jnp.sum(directions.orientation_histogram(np.ones((32, 32), np.float32)))) == 0


@pytest.mark.parametrize("phi", [9.0, 23.0, 45.0, 71.5, 100.0, 134.3, 160.0, 171.0])
def test_single_edge_found_within_1p5_degrees(phi):
    got = directions.estimate(grid(step(phi, (0.47, 0.53))), k=2)
    assert len(got) == 1, got
    assert axial_distance_deg(got[0], phi) <= 1.5


def test_near_axis_edges_are_pushed_away_from_the_axis_but_found():
    # documented limitation: the zeroed +-3 deg window truncates the mode of a near-axis edge
    for phi in [4.0, 86.0, 95.0, 175.0]:
        got = directions.estimate(grid(step(phi, (0.47, 0.53))), k=1)
        assert len(got) == 1 and float(axial_distance_deg(got[0], phi)) <= 5.0


def test_axis_aligned_curved_smooth_and_constant_give_no_direction():
    assert directions.estimate(grid(step(0.0, (0.4, 0.4)))) == ()
    assert directions.estimate(grid(step(90.0, (0.6, 0.6)))) == ()
    rect = integrands.Polygon([(0.2, 0.3), (0.7, 0.3), (0.7, 0.8), (0.2, 0.8)])
    assert directions.estimate(grid(rect)) == ()
    assert directions.estimate(grid(integrands.Disk((0.45, 0.55), 0.3))) == ()
    assert directions.estimate(grid(integrands.GaussianBump((0.4, 0.6), 0.1))) == ()
    assert directions.estimate(np.full((40, 50), 3.0, np.float32)) == ()


def test_two_edges_both_found():
    f = integrands.edges([35.0, 125.0], center=(0.5, 0.5), radius=0.2)
    got = directions.estimate(grid(f), k=2)
    assert len(got) == 2
    for t in (35.0, 125.0):
        assert min(float(axial_distance_deg(g, t)) for g in got) <= 1.5
    # k = 1 keeps the strongest only; k = 0 returns nothing
    assert len(directions.estimate(grid(f), k=1)) == 1
    assert directions.estimate(grid(f), k=0) == ()


def test_gradient_estimator_agrees_with_fixed_kappa_search():
    f = integrands.edges([55.0, 150.0], center=(0.48, 0.52), radius=0.22)
    fixed = directions.estimate(grid(f), k=2, details=True)
    grad = directions.estimate(grid(f), k=2, estimator="gradient", details=True)
    assert bool(jnp.all(fixed.valid)) and bool(jnp.all(grad.valid))
    for a, b in zip(np.sort(fixed.directions_deg), np.sort(grad.directions_deg), strict=True):
        assert float(axial_distance_deg(a, b)) <= 1.5
    assert bool(jnp.all(jnp.isfinite(grad.kappa))) and bool(jnp.all(grad.kappa > 0))


def test_details_never_contain_nan():
    for f in [step(33.0), integrands.Disk(), lambda x: jnp.zeros(x.shape[:-1])]:
        est = directions.estimate(grid(f, 64), k=3, details=True)
        for a in (est.directions_deg, est.valid, est.confidence, est.kappa):
            assert bool(jnp.all(jnp.isfinite(a)))
        d = est.directions_deg
        assert bool(jnp.all(jnp.where(est.valid, d >= 0, d == -1)))


def test_estimate_is_a_pytree():
    """Per grid and per block (leading axes), fixed and gradient: jit/vmap/flatten round trips."""
    assert_pytree_round_trips(directions.estimate(grid(step(33.0), 48), k=2, details=True))
    assert_pytree_round_trips(directions.estimate(grid(step(33.0), 48), k=2, details=True,
                                                  estimator="gradient"))
    assert_pytree_round_trips(directions.estimate_blocks(grid(step(70.0), 96), k=1,
                                                         samples_per_block=48))


def test_estimate_from_histogram_uses_same_path():
    values = grid(step(64.0))
    hist = directions.orientation_histogram(values)
    a = directions.estimate_from_histogram(hist, k=2)
    b = directions.estimate(values, k=2, details=True)
    np.testing.assert_array_equal(a.directions_deg, b.directions_deg)
    batched = directions.estimate_from_histogram(jnp.stack([hist, hist]), k=2)
    assert batched.directions_deg.shape == (2, 2)


def test_blocks_array_and_callable_agree_with_per_block_estimates():
    s = 48
    phis = np.array([[25.0, 70.0, 0.0], [115.0, 160.0, 45.0]], np.float32)
    # one half-plane per block with its own angle; the last column of row 0 is axis-aligned
    samples = np.zeros((2 * s, 3 * s), np.float32)
    for a in range(2):
        for b in range(3):
            samples[a * s:(a + 1) * s, b * s:(b + 1) * s] = grid(step(float(phis[a, b])), s)
    est = directions.estimate_blocks(samples, k=2, samples_per_block=s)
    assert est.directions_deg.shape == (2, 3, 2)
    for a in range(2):
        for b in range(3):
            single = directions.estimate(samples[a * s:(a + 1) * s, b * s:(b + 1) * s], k=2,
                                         details=True)
            np.testing.assert_allclose(est.directions_deg[a, b], single.directions_deg)
            if phis[a, b] == 0.0:
                assert not bool(jnp.any(est.valid[a, b]))
            else:
                assert bool(est.valid[a, b, 0])
                assert float(axial_distance_deg(est.directions_deg[a, b, 0],
                                                           phis[a, b])) <= 2.0
    table = jnp.asarray(phis)

    def per_block(idx, x):
        t = jnp.radians(table[idx[0], idx[1]])
        n = jnp.stack([jnp.cos(t), jnp.sin(t)])
        return ((x - 0.5) @ n > 0).astype(jnp.float32)

    est2 = directions.estimate_blocks(per_block, k=2, samples_per_block=s, blocks=(2, 3))
    np.testing.assert_array_equal(est2.valid, est.valid)
    np.testing.assert_allclose(
        jnp.where(est.valid, est2.directions_deg - est.directions_deg, 0.0), 0.0, atol=1.0
    )


@pytest.mark.library_errors
def test_bad_input_raises_value_errors():
    ok = grid(step(30.0), 32)
    with pytest.raises(ValueError, match="k must be >= 0"):
        directions.estimate(ok, k=-1)
    with pytest.raises(TypeError, match="k must be an integer"):
        directions.estimate(ok, k=1.5)
    bad = ok.copy()
    bad[3, 4] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        directions.estimate(bad)
    with pytest.raises(ValueError, match="at least 15x15"):
        directions.estimate(np.zeros((10, 40), np.float32))
    with pytest.raises(ValueError, match="2D"):
        directions.estimate(np.zeros((4, 40, 40), np.float32))
    for kappa in [0.0, -3.0]:
        with pytest.raises(ValueError, match="kappa"):
            directions.estimate(ok, kappa=kappa)
    with pytest.raises(ValueError, match="all-zero"):
        directions.estimate_from_histogram(jnp.zeros(180))
    with pytest.raises(ValueError, match="K >= 2"):
        directions.estimate_from_histogram(jnp.zeros((0,)))
    with pytest.raises(ValueError, match="bins"):
        directions.estimate_from_histogram(jnp.ones(90))
    with pytest.raises(ValueError, match="estimator"):
        directions.estimate(ok, estimator="argmax")
    with pytest.raises(ValueError, match="bin_deg"):
        directions.orientation_histogram(ok, bin_deg=7.0)
    with pytest.raises(ValueError, match="multiples of samples_per_block"):
        directions.estimate_blocks(np.zeros((100, 96), np.float32))
    with pytest.raises(ValueError, match="blocks="):
        directions.estimate_blocks(lambda i, x: x[..., 0])
    with pytest.raises(ValueError, match="NaN"):
        directions.estimate_blocks(lambda i, x: jnp.log(x[..., 0] - 0.5), samples_per_block=32,
                                   blocks=(1, 2))
    with pytest.raises(ValueError, match="must return shape"):
        directions.estimate_blocks(lambda i, x: x, samples_per_block=32, blocks=(1, 1))


def test_cli_directions_per_grid_and_per_block(tmp_path, capsys):
    from anisosample import cli

    g = grid(step(40.0), 32)
    np.save(tmp_path / "g.npy", g)
    np.save(tmp_path / "big.npy", np.concatenate([g, grid(step(130.0), 32)], axis=1))
    assert cli.main(["directions", str(tmp_path / "g.npy")]) == 0
    out = capsys.readouterr().out
    got = float(out.split(" deg")[0])
    assert float(axial_distance_deg(got, 40.0)) <= 2.0
    png = tmp_path / "maps.png"
    assert cli.main(["directions", str(tmp_path / "big.npy"), "--block", "32", "-o",
                     str(png)]) == 0
    assert png.exists() and "[0, 2, 0]" in capsys.readouterr().out
    assert cli.main(["directions", str(tmp_path / "g.npy"), "-k", "-1"]) == 2
    assert "k must be >= 0" in capsys.readouterr().err


def test_zeroed_windows_are_filled_from_kept_neighbours_for_the_objective():
    keep = np.asarray(directions.zero_axes(np.ones(180, np.float32), zero_window_deg=2.0)) > 0
    idx = np.arange(180, dtype=np.float32)
    filled = np.asarray(directions.fill_zeroed_bins(idx, zero_window_deg=2.0))
    assert np.all(filled[keep] == idx[keep])
    assert (filled[1], filled[2], filled[179]) == (3, 3, 177)
    assert filled[0] == (3 + 177) / 2 and filled[90] == (87 + 93) / 2
    assert set(filled[~keep]) <= set(idx[keep]) | {90.0}


def test_misspelled_options_raise_instead_of_falling_back_to_defaults():
    ok = grid(step(30.0), 32)
    with pytest.raises(TypeError, match=r"unknown option\(s\) \['kapa'\]"):
        directions.estimate(ok, kapa=5.0)
    with pytest.raises(TypeError, match="known options"):
        directions.estimate_from_histogram(np.ones(180, np.float32), treshold=0.5)
    with pytest.raises(TypeError, match="unknown option"):
        directions.estimate_blocks(np.zeros((32, 32), np.float32), samples_per_block=32, sigma=1.0)

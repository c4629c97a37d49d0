"""anisosample.metrics against closed forms and brute force."""

import itertools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import assert_pytree_round_trips, brute_force_spectrum

from anisosample import directions, metrics, samplers, spectrum


def test_axial_distance_closed_forms():
    a = np.array([0.0, 10.0, 170.0, 350.0, 90.0, -30.0, 725.0])
    b = np.array([0.0, 170.0, 10.0, 10.0, 0.0, 30.0, 0.0])
    want = np.array([0.0, 20.0, 20.0, 20.0, 90.0, 60.0, 5.0])
    np.testing.assert_allclose(metrics.axial_distance_deg(a, b, xp=np), want, atol=1e-12)
    np.testing.assert_allclose(np.asarray(metrics.axial_distance_deg(a, b)), want, atol=1e-4)


def test_axial_distance_is_symmetric_in_range_and_periodic():
    rng = np.random.default_rng(0)
    a, b = rng.uniform(-360, 360, (2, 1000))
    d = metrics.axial_distance_deg(a, b, xp=np)
    assert np.all((d >= 0) & (d <= 90))
    np.testing.assert_allclose(d, metrics.axial_distance_deg(b, a, xp=np), atol=1e-12)
    np.testing.assert_allclose(d, metrics.axial_distance_deg(a + 180.0, b, xp=np), atol=1e-9)
    # brute force: the smallest |a - b + 180 k|
    brute = np.min(np.abs(a[:, None] - b[:, None] + 180.0 * np.arange(-5, 6)), axis=1)
    np.testing.assert_allclose(d, brute, atol=1e-9)


def test_axial_distance_namespaces_and_precision():
    assert isinstance(metrics.axial_distance_deg(10.0, 20.0), jax.Array)
    assert metrics.axial_distance_deg(1.0, 2.0 + 1e-12, xp=np) == abs(1.0 - (2.0 + 1e-12))
    assert float(jax.jit(metrics.axial_distance_deg)(jnp.float32(5.0), 175.0)) == 10.0
    assert directions.axial_distance_deg is metrics.axial_distance_deg  # the old home still works
    with pytest.raises(ValueError, match="xp"):
        metrics.axial_distance_deg(1.0, 2.0, xp=None)


def test_nearest_neighbour_distance_brute_force_on_the_torus():
    p = np.random.default_rng(1).random((200, 2))
    diff = np.abs(p[:, None] - p[None])
    diff = np.minimum(diff, 1.0 - diff)
    d2 = (diff**2).sum(-1)
    np.fill_diagonal(d2, np.inf)
    np.testing.assert_allclose(metrics.nearest_neighbour_distance(p), np.sqrt(d2.min(1)),
                               rtol=1e-12)


def test_nearest_neighbour_distance_of_a_grid_and_across_the_seam():
    g = metrics.midpoint_grid(8, dtype=np.float64).reshape(-1, 2)
    np.testing.assert_allclose(metrics.nearest_neighbour_distance(g), 1 / 8, rtol=1e-12)
    d = metrics.nearest_neighbour_distance(np.array([[0.01, 0.5], [0.99, 0.5], [0.5, 0.5]]))
    np.testing.assert_allclose(d, [0.02, 0.02, 0.49], rtol=1e-9)


@pytest.mark.parametrize("bad", [np.zeros((1, 2)), np.zeros((3, 3)), np.full((2, 2), 1.5)])
def test_nearest_neighbour_distance_rejects_bad_points(bad):
    with pytest.raises(ValueError, match="points"):
        metrics.nearest_neighbour_distance(bad)


def test_midpoint_grid_closed_form_and_orders():
    n = 5
    xy = metrics.midpoint_grid(n, dtype=np.float64)
    ij = metrics.midpoint_grid(n, indexing="ij", dtype=np.float64)
    assert xy.shape == ij.shape == (n, n, 2)
    for i, j in itertools.product(range(n), repeat=2):
        assert tuple(xy[i, j]) == ((j + 0.5) / n, (i + 0.5) / n)
        assert tuple(ij[i, j]) == ((i + 0.5) / n, (j + 0.5) / n)
    assert metrics.midpoint_grid(n).dtype == np.float32
    assert metrics.midpoint_grid(n).reshape(-1, 2).mean() == pytest.approx(0.5)


@pytest.mark.parametrize("n", [1, 3, 7, 10, 33, 96, 255, 256, 1000, 4097])
def test_midpoint_grid_is_the_float32_quotient(n):
    """float64 rounded to float32 equals the float32 division the copies it replaced did."""
    g = (np.arange(n, dtype=np.float32) + 0.5) / n
    want = np.stack(np.meshgrid(g, g, indexing="xy"), -1)
    np.testing.assert_array_equal(metrics.midpoint_grid(n).view(np.uint32), want.view(np.uint32))


def test_midpoint_grid_in_jax_is_the_jax_quotient():
    c = (jnp.arange(96, dtype=jnp.float32) + 0.5) / 96
    want = jnp.stack(jnp.meshgrid(c, c, indexing="ij"), axis=-1)
    got = metrics.midpoint_grid(96, indexing="ij", xp=jnp)
    assert isinstance(got, jax.Array)
    np.testing.assert_array_equal(np.asarray(got), np.asarray(want))


@pytest.mark.parametrize("kw, name", [(dict(n=0), "n"), (dict(n=4, indexing="yx"), "indexing"),
                                      (dict(n=4, xp=None), "xp")])
def test_midpoint_grid_rejects_bad_parameters(kw, name):
    with pytest.raises(ValueError, match=name):
        metrics.midpoint_grid(**kw)


# --- image errors and efficiency, off_axis_deg, grid_values (issue 26) ----------------------------


def test_off_axis_distance_brute_force():
    d = np.random.default_rng(1).uniform(-400, 400, 500)
    brute = np.min(np.abs(d[:, None] - 90.0 * np.arange(-6, 7)), axis=1)
    np.testing.assert_allclose(metrics.off_axis_deg(d), brute, atol=1e-9)
    assert metrics.off_axis_deg(45.0) == 45.0 and metrics.off_axis_deg(179.0) == 1.0


def test_grid_values_is_the_convention_point_by_point():
    f = lambda x: x[..., 0] + 10.0 * x[..., 1] ** 2  # noqa: E731
    n = 5
    v = metrics.grid_values(f, n)
    assert v.shape == (n, n) and isinstance(v, np.ndarray)
    for i, j in itertools.product(range(n), repeat=2):
        x, y = np.float32((j + 0.5) / n), np.float32((i + 0.5) / n)
        assert v[i, j] == pytest.approx(float(x) + 10.0 * float(y) ** 2, rel=1e-6)


def test_image_error_closed_forms():
    ref = np.array([1.0, 2.0, 0.0])
    est = np.array([[1.5, 2.0, 1.0],    # errors 0.5, 0, 1
                    [0.5, 3.0, -1.0]])  # errors -0.5, 1, -1
    e = metrics.image_error(est, ref)
    np.testing.assert_allclose(e.image, [0.25, 0.5, 1.0])
    np.testing.assert_allclose(e.per_realization, [1.25 / 3, 2.25 / 3])
    assert e.mse == pytest.approx(1.75 / 3)
    assert e.mse_stderr == pytest.approx(np.sqrt(2 * (0.5 / 3) ** 2) / np.sqrt(2))  # |a-b|/2
    # variance (ddof 1) per pixel: 0.5, 0.5, 2
    assert e.mse_from_variance == pytest.approx(1.0)
    assert e.mean_error == pytest.approx((0.5 + 0 + 1 - 0.5 + 1 - 1) / 6)
    assert e.mean_error_stderr == pytest.approx(abs(1.5 / 3 - (-0.5 / 3)) / 2)
    r = metrics.image_error(est, ref, relative=True)
    denom = ref**2 + 0.01
    np.testing.assert_allclose(r.image, [0.25, 0.5, 1.0] / denom)
    assert r.mse == pytest.approx(np.mean([0.25, 0.5, 1.0] / denom))
    assert set(e.as_dict()) == {"mse", "mse_stderr", "mse_from_variance", "mean_error",
                                "mean_error_stderr"}
    assert_pytree_round_trips(e)


def test_image_error_standard_errors_match_the_spread_over_experiments():
    """Gaussian pixel noise of known sigma: mse and mse_from_variance estimate sigma^2, and each
    standard error is the spread of its estimate over independent experiments (to 20 %)."""
    rng = np.random.default_rng(2)
    sigma, r, p, trials = 0.3, 16, 8, 400
    ref = rng.uniform(0, 1, p)
    runs = [metrics.image_error(ref + rng.normal(0, sigma, (r, p)), ref) for _ in range(trials)]
    mse = np.array([e.mse for e in runs])
    assert mse.mean() == pytest.approx(sigma**2, rel=0.02)
    assert np.mean([e.mse_from_variance for e in runs]) == pytest.approx(sigma**2, rel=0.02)
    assert np.mean([e.mse_stderr for e in runs]) == pytest.approx(mse.std(ddof=1), rel=0.2)
    me = np.array([e.mean_error for e in runs])
    assert np.mean([e.mean_error_stderr for e in runs]) == pytest.approx(me.std(ddof=1), rel=0.2)
    assert abs(me.mean()) < 4 * me.std(ddof=1) / np.sqrt(trials)


def test_mse_ratio_paired_and_its_standard_error():
    rng = np.random.default_rng(3)
    ref = rng.uniform(0, 1, 6)
    noise = rng.normal(0, 0.2, (12, 6))
    base = metrics.image_error(ref + noise, ref)
    half = metrics.image_error(ref + noise / np.sqrt(2), ref)  # the same realizations, scaled
    ratio, se = metrics.mse_ratio(half, base)
    assert ratio == pytest.approx(0.5) and se == pytest.approx(0.0, abs=1e-12)
    # Spread of the ratio over independent paired experiments (delta method, to 25 %).
    ratios, ses = [], []
    for _ in range(300):
        n1 = rng.normal(0, 0.2, (24, 6))
        n2 = 0.7 * n1 + rng.normal(0, 0.1, (24, 6))
        a, b = metrics.image_error(ref + n2, ref), metrics.image_error(ref + n1, ref)
        q, s = metrics.mse_ratio(a, b)
        ratios.append(q)
        ses.append(s)
    assert np.mean(ses) == pytest.approx(np.std(ratios, ddof=1), rel=0.25)
    with pytest.raises(ValueError, match="paired"):
        metrics.mse_ratio(metrics.image_error(ref + noise[:3], ref), base)


def test_efficiency_and_its_standard_error():
    assert metrics.efficiency(0.25, 2.0) == pytest.approx(2.0)
    eff, se = metrics.efficiency(0.25, 2.0, mse_stderr=0.025)
    assert eff == pytest.approx(2.0) and se == pytest.approx(0.2)  # 10 % of the MSE -> 10 %


def test_image_error_rejects_bad_shapes():
    with pytest.raises(ValueError, match="estimates"):
        metrics.image_error(np.zeros((1, 3)), np.zeros(3))
    with pytest.raises(ValueError, match="estimates"):
        metrics.image_error(np.zeros((4, 3)), np.zeros(2))


def test_profiles():
    r = 10
    f = spectrum.frequency_grid(r).reshape(2 * r + 1, 2 * r + 1, 2)
    grid = np.hypot(f[..., 0], f[..., 1])  # P = |v|
    radii, prof = metrics.radial_profile(grid)
    np.testing.assert_allclose(prof, radii, atol=0.5)
    # energy only along the 30-degree ray -> angular profile peaks there
    ang = np.degrees(np.arctan2(f[..., 1], f[..., 0])) % 180
    grid2 = (np.abs(ang - 30) < 2).astype(float)
    c, a = metrics.angular_profile(grid2, bins=36)
    assert abs(c[np.argmax(a)] - 30) <= 5


def test_profiles_of_a_centred_grid_closed_forms():
    """Rings and directions of a grid known in closed form: ``P = |v|^2`` has ring means within
    the rounding of ``|v|`` to its ring; a grid that is ``theta`` at direction ``theta`` has an
    angular profile equal to its bin centres to within half a bin."""
    r = 12
    k = np.arange(-r, r + 1)
    vx, vy = np.meshgrid(k, k, indexing="xy")
    radii, means = metrics.radial_profile(vx**2 + vy**2)
    want = [np.mean((vx**2 + vy**2)[np.rint(np.hypot(vx, vy)) == q]) for q in radii]
    np.testing.assert_allclose(means, want, rtol=1e-12)
    ang = np.degrees(np.arctan2(vy, vx)) % 180.0
    centres, a = metrics.angular_profile(ang, bins=18)
    assert np.max(np.abs(a - centres)) <= 5.0 + 1e-9
    with pytest.raises(ValueError, match="grid must be a square centred spectrum"):
        metrics.radial_profile(np.ones((4, 4)))
    with pytest.raises(ValueError, match="grid contains NaN or Inf"):
        metrics.angular_profile(np.full((5, 5), np.nan))


def test_expected_spectrum_of_a_stack_is_the_mean_of_its_sets():
    """``<P_S>`` of a stack ``(R, n, 2)``: the mean of the sets' own spectra (brute force, float64),
    on frequencies and on the centred grid; one set gives its own spectrum."""
    sets = jnp.stack([samplers.get("jittered")(jax.random.key(i), 64) for i in range(5)])
    f = np.array([[1, 0], [0, 1], [3, -2], [7, 5], [0, 12]])
    want = np.mean([brute_force_spectrum(s, f) for s in sets], axis=0)
    got = np.asarray(metrics.expected_power_spectrum(sets, f))
    assert np.max(np.abs(got - want)) * 64 < 1e-4
    grid = np.asarray(metrics.expected_power_spectrum_grid(np.asarray(sets), 3))
    v = spectrum.frequency_grid(3)
    want_grid = np.mean([brute_force_spectrum(s, v) for s in sets], axis=0).reshape(7, 7)
    assert np.max(np.abs(grid - want_grid)) * 64 < 1e-4
    assert grid[3, 3] == pytest.approx(1.0, abs=1e-5)  # P_S(0) = 1
    one = np.asarray(metrics.expected_power_spectrum(sets[:1], f))
    np.testing.assert_array_equal(one, np.asarray(spectrum.power_spectrum(sets[0], f)))
    with pytest.raises(ValueError, match=r"sets must be a stack .* \(R, n, 2\)"):
        metrics.expected_power_spectrum(sets[0], f)
    with pytest.raises(ValueError, match="radius must be >= 1"):
        metrics.expected_power_spectrum_grid(sets, 0)
    with pytest.raises(ValueError, match="'nufft' is now called 'nufft1'"):
        metrics.expected_power_spectrum(sets, f, method="nufft")


def _trig_texture():
    """``f(x) = sum_k a_k cos(2 pi v_k . x + phi_k)``: ``P_f(+-v_k) = a_k^2 / 4``."""
    v = np.array([[1, 0], [2, 3], [-4, 1]])
    a = np.array([0.7, 0.4, 1.1])
    phi = np.array([0.3, 1.9, -0.8])

    def f(x):
        return np.sum(a * np.cos(2 * np.pi * (x @ v.T) + phi), axis=-1)

    return f, v, a


def test_eq5_is_the_variance_over_every_shift_of_a_fixed_set():
    """W Eq. 5 for a trigonometric polynomial and a fixed set of 10 points: the variance of the
    shifted estimator averaged over an M x M grid of shifts (exact for the polynomial's degree,
    M > 2 max |v|) equals ``sum_{v != 0} P_S(v) P_f(v)`` to float64 rounding."""
    f, v, a = _trig_texture()
    pts = np.random.default_rng(5).uniform(0, 1, (10, 2))
    m = 16
    t = (np.arange(m) + 0.25) / m
    shifts = np.stack(np.meshgrid(t, t, indexing="ij"), -1).reshape(-1, 2)
    est = np.array([f(np.mod(pts + s, 1.0)).mean() for s in shifts])
    measured = np.mean((est - est.mean()) ** 2)
    freqs = np.concatenate([v, -v, [[0, 0]]])
    ps = brute_force_spectrum(pts, freqs)
    pf = np.concatenate([a**2 / 4, a**2 / 4, [0.0]])
    predicted = metrics.predicted_variance(ps, pf, freqs=freqs)
    assert predicted == pytest.approx(measured, rel=1e-10)
    terms = metrics.variance_terms(ps, pf, freqs=freqs)
    assert terms.shape == (6,) and float(np.sum(terms)) == predicted


def test_predicted_variance_drops_zero_frequency():
    v = np.array([[0, 0], [1, 0], [0, 1]])
    assert metrics.predicted_variance([1.0, 0.5, 0.25], [9.0, 2.0, 4.0], freqs=v) == 2.0
    with pytest.raises(ValueError, match="same shape"):
        metrics.predicted_variance([1.0], [1.0, 2.0])
    with pytest.raises(ValueError, match="non-negative"):
        metrics.predicted_variance([-1.0], [1.0])
    with pytest.raises(ValueError, match="xp must be"):
        metrics.predicted_variance([1.0], [1.0], xp=jax)


def test_predicted_variance_in_jax_is_traceable_and_agrees():
    """``xp=jax.numpy``: the same sum, under ``jit`` and ``grad`` (d/dP_S = P_f), the zero
    frequency's term set to 0."""
    ps = np.array([1.0, 0.5, 0.25, 0.125], np.float32)
    pf = np.array([9.0, 2.0, 4.0, 8.0], np.float32)
    v = np.array([[0, 0], [1, 0], [0, 1], [2, 2]])
    want = metrics.predicted_variance(ps, pf, freqs=v)
    got = jax.jit(lambda p: metrics.predicted_variance(p, pf, freqs=v, xp=jnp))(ps)
    assert float(got) == pytest.approx(want, rel=1e-6)
    g = jax.grad(lambda p: metrics.predicted_variance(p, pf, freqs=v, xp=jnp))(jnp.asarray(ps))
    np.testing.assert_allclose(np.asarray(g), [0.0, 2.0, 4.0, 8.0])


def test_wraparound_discrepancy_closed_forms_and_spectral_form():
    """One point: ``WD^2 = 9/4 - 16/9 = 17/36``. Shift-invariant. Equal to its spectral form
    ``sum_{v != 0} P_S(v) c(v_x) c(v_y)`` (``c(0) = 4/3``, ``c(k) = 1/(2 pi^2 k^2)``), summed by
    brute force out to |v_x|, |v_y| <= 300: below it by the tail, which is positive and at most
    ``3 / (pi^2 r)`` (``P_S <= 1``; about ``3 / (pi^2 r n)`` = 1.3e-4 for these 8 points)."""
    assert metrics.wraparound_discrepancy(np.array([[0.3, 0.8]])) == pytest.approx(
        math.sqrt(17 / 36), rel=1e-14)
    pts = np.random.default_rng(2).uniform(0, 1, (8, 2))
    wd = metrics.wraparound_discrepancy(pts)
    shifted = np.mod(pts + [0.37, 0.91], 1.0)
    assert metrics.wraparound_discrepancy(shifted, block=3) == pytest.approx(wd, rel=1e-12)
    r = 300
    v = spectrum.frequency_grid(r)
    v = v[np.any(v != 0, axis=1)]
    k = v.astype(np.float64)
    c = np.where(k == 0, 4.0 / 3.0, 1.0 / (2 * np.pi**2 * np.where(k == 0, 1.0, k) ** 2))
    spectral = metrics.predicted_variance(brute_force_spectrum(pts, v), c[:, 0] * c[:, 1])
    assert 0 < wd**2 - spectral < 3 / (np.pi**2 * r)
    assert wd**2 - spectral == pytest.approx(3 / (np.pi**2 * r * 8), rel=0.3)
    with pytest.raises(ValueError, match="points must lie"):
        metrics.wraparound_discrepancy(np.array([[0.5, 1.5]]))


def test_geometric_mean_closed_form_and_bad_input():
    """(2, 8): g = 4, sd(log r) = log(4) / sqrt(2), so the standard error is 4 log(4) / 2; a
    constant list has no spread; fewer than two, non-positive or non-finite ratios are refused."""
    g, se = metrics.geometric_mean([2.0, 8.0])
    assert g == pytest.approx(4.0, rel=1e-15) and se == pytest.approx(2 * np.log(4.0), rel=1e-14)
    assert metrics.geometric_mean([0.5] * 7) == pytest.approx((0.5, 0.0), abs=1e-16)
    for bad in ([1.0], [1.0, 0.0], [1.0, -2.0], [1.0, np.nan], [1.0, np.inf], [[1.0, 2.0]]):
        with pytest.raises(ValueError, match="ratios"):
            metrics.geometric_mean(bad)

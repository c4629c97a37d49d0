"""Losses of W Sec. 4: Eq. 15 against the square's projection, the terms' float32 transforms
against float64, gradients against finite differences (the engine's own values:
test_spectrum.py)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import anisosample as asp
from anisosample import frequencies as fr
from anisosample import losses as L


def _trapezoid(theta_deg):
    th = np.deg2rad(theta_deg)
    c, s = abs(np.cos(th)), abs(np.sin(th))
    return max(c, s), min(c, s)


def _row_cdf(theta_deg, t, rows=2000):
    """CDF of d.(p - 1/2) for p uniform on a fine grid of *rows* of the square: midpoint rule in
    one coordinate, exact in the other (error O(rows^-2))."""
    th = np.deg2rad(theta_deg)
    c, s = np.cos(th), np.sin(th)
    y = (np.arange(rows) + 0.5) / rows - 0.5
    # along one row the projection is uniform on the segment between x = -1/2 and x = +1/2
    if abs(c) >= abs(s):
        a0, a1 = -0.5 * c + y[:, None] * s, 0.5 * c + y[:, None] * s
    else:
        a0, a1 = -0.5 * s + y[:, None] * c, 0.5 * s + y[:, None] * c
    lo, hi = np.minimum(a0, a1), np.maximum(a0, a1)
    frac = np.clip((t[None, :] - lo) / (hi - lo), 0.0, 1.0)
    return frac.mean(axis=0)


def test_quantile_matches_fine_grid_every_integer_degree():
    u = np.linspace(-0.49, 0.49, 99)
    worst = 0.0
    with jax.enable_x64(True):
        for deg in range(180):
            q = np.asarray(L.square_projection_quantile(float(deg), jnp.asarray(u)))
            cdf = _row_cdf(deg, q)
            a, b = _trapezoid(deg)
            # exact trapezoid density at q converts the CDF error into a quantile error
            dens = np.where(np.abs(q) <= (a - b) / 2, 1 / a,
                            ((a + b) / 2 - np.abs(q)) / (a * b + 1e-300))
            dens = np.where(b < 1e-12, 1.0, dens)
            err = np.abs(cdf - (u + 0.5)) / dens
            worst = max(worst, err.max())
    assert worst < 1e-5, worst


@pytest.mark.parametrize("deg", [0.0, 30.0, 60.0, 100.0, 135.0, 170.0])
def test_quantile_matches_sorted_grid_projection(deg):
    m = 600
    g = (np.stack(np.meshgrid(np.arange(m), np.arange(m)), -1).reshape(-1, 2) + 0.5) / m - 0.5
    th = np.deg2rad(deg)
    proj = np.sort(g @ np.array([np.cos(th), np.sin(th)]))
    idx = np.arange(m * m // 40, m * m, m * m // 20)
    u = (idx + 0.5) / (m * m) - 0.5
    q = np.asarray(L.square_projection_quantile(deg, jnp.asarray(u, jnp.float32)))
    np.testing.assert_allclose(q, proj[idx], atol=2.0 / m)


def test_quantile_fact_sheet_values():
    u = jnp.asarray([0.0, 0.1, 0.2, 0.3, 0.4, 0.45, 0.5, -0.4], jnp.float32)
    want = [0, 0.08660254, 0.17320508, 0.26683356, 0.38872961, 0.47492313, 0.68301270,
            -0.38872961]
    np.testing.assert_allclose(L.square_projection_quantile(30.0, u), want, atol=2e-7)
    u45 = jnp.asarray([0.25, 0.4, 0.5], jnp.float32)
    np.testing.assert_allclose(L.square_projection_quantile(45.0, u45),
                               [0.20710678, 0.39087902, 0.70710678], atol=2e-7)
    u8 = jnp.asarray((np.arange(8) + 0.5) / 8 - 0.5, jnp.float32)
    np.testing.assert_allclose(
        L.square_projection_quantile(30.0, u8),
        [-0.450361, -0.280049, -0.162380, -0.054127, 0.054127, 0.162380, 0.280049, 0.450361],
        atol=2e-6)


def test_sw_loss_fact_sheet_examples():
    g = jnp.asarray([[0.25, 0.25], [0.25, 0.75], [0.75, 0.25], [0.75, 0.75]], jnp.float32)
    # our scaling is n * Eq. 13
    np.testing.assert_allclose(L.sliced_wasserstein_loss(g, [45.0]) / 4, 0.0044873, rtol=1e-4)
    np.testing.assert_allclose(L.sliced_wasserstein_loss(g, [0.0]) / 4, 0.015625, rtol=1e-6)
    np.testing.assert_allclose(L.sliced_wasserstein_loss(g, [0.0, 45.0]) / 4,
                               (0.015625 + 0.0044873) / 2, rtol=1e-4)


def test_sw_loss_scale_independent_of_n(getkey):
    # i.i.d. points: E[n L_SW1D] ~ 1/6 whatever n (point_synthesis.md Sec. 3)
    vals = []
    for n in (64, 1024):
        x = jax.random.uniform(getkey(), (n, 2), jnp.float32)
        vals.append(float(L.sliced_wasserstein_loss(x, [0.0, 30.0, 90.0])))
    for v in vals:
        assert 0.05 < v < 0.5, vals


def test_single_precision_terms_agree_with_double():
    """``spectrum_terms(precision='single')``: the type-1 boxes' transforms in float32 (eps
    1e-6) against float64, n = 4096, four directions, uniform points. Rounding the box points
    to float32 moves each phase by up to ``2 pi |u| 2^-24`` (about 3e-4 for the boxes' |u| <= 800),
    so the loss and its gradient agree to a few 1e-4 relative, not to float64's 1e-10."""
    with jax.enable_x64(True):
        n = 4096
        fset = fr.design(n, [0.0, 90.0, 16.0, 146.0], "rate")
        x = jax.random.uniform(jax.random.key(3), (n, 2), jnp.float64)
        out = {}
        for prec in L.PRECISIONS:
            terms = L.linear_spectrum_loss_terms(fset, n, eps=1e-7, precision=prec)
            assert all(isinstance(t, L.GridTerm) for t in terms)
            assert all(t.single == (prec == "single") for t in terms)
            assert all(t.eps == (1e-6 if prec == "single" else 1e-7) for t in terms)
            out[prec] = jax.jit(jax.value_and_grad(lambda y, t=terms: L.terms_value(y, t)))(x)
        (v64, g64), (v32, g32) = out["double"], out["single"]
        assert g32.dtype == jnp.float64
        assert abs(float(v32 - v64)) < 1e-3 * float(v64)
        assert float(jnp.max(jnp.abs(g32 - g64))) < 3e-3 * float(jnp.max(jnp.abs(g64)))
        with pytest.raises(ValueError, match="precision"):
            L.spectrum_terms(fset, n, precision="half")


def _fd_check(f, x, coords, h):
    f = jax.jit(f)
    g = jax.jit(jax.grad(f))(x)
    for j, k in coords:
        e = jnp.zeros_like(x).at[j, k].set(h)
        fd = (f(x + e) - f(x - e)) / (2 * h)
        np.testing.assert_allclose(float(g[j, k]), float(fd), rtol=1e-5,
                                   atol=1e-7 * float(jnp.max(jnp.abs(g))))


@pytest.mark.parametrize("method", ["direct", "nufft1", "nufft3"])
def test_loss_gradients_finite_differences(getkey, method):
    with jax.enable_x64(True):
        n = 128
        x = jax.random.uniform(getkey(), (n, 2), jnp.float64)
        fset = fr.design(n, [0.0, 90.0, 30.0], "rate")
        coords = [(0, 0), (17, 1), (99, 0)]
        _fd_check(lambda y: L.linear_spectrum_loss(y, fset, method=method, eps=1e-13), x,
                  coords, 1e-6)
        _fd_check(lambda y: L.spectrum_loss(y, fset, method=method, eps=1e-13), x, coords, 1e-6)
        tgt = jnp.full((len(fset),), 0.5 / n, jnp.float64)
        _fd_check(lambda y: L.spectrum_loss(y, fset, tgt, method=method, eps=1e-13), x,
                  coords, 1e-6)


@pytest.mark.parametrize("method", ["direct", "nufft1"])
def test_spectrum_loss_takes_a_target_traced_under_jit(getkey, method):
    """W Eq. 11 with a target computed under jit (scalar and per frequency): the same value as
    the concrete target, and its gradient in the target is the closed form
    ``-2 n^2 w_v (P_S(v) - t_v) / sum w``."""
    with jax.enable_x64(True):
        n = 64
        x = jax.random.uniform(getkey(), (n, 2), jnp.float64)
        fset = fr.design(n, [0.0, 90.0, 30.0], "paper")
        tgt = jnp.linspace(0.0, 2.0 / n, len(fset))
        for t in (tgt, jnp.asarray(0.7 / n)):
            # the concrete target: a constant of the program (jitted: op by op it compiles
            # ~100 small programs)
            fixed = np.asarray(t)
            want = jax.jit(lambda y, t=fixed: L.spectrum_loss(y, fset, t, method=method,
                                                              eps=1e-13))(x)
            got = jax.jit(lambda y, t: L.spectrum_loss(y, fset, t, method=method, eps=1e-13))(
                x, t)
            np.testing.assert_allclose(float(got), float(want), rtol=1e-12)
        g = jax.jit(jax.grad(lambda t: L.spectrum_loss(x, fset, t, method=method,
                                                       eps=1e-13)))(tgt)
        p = jax.jit(lambda y: asp.spectrum.grouped_power_spectrum(y, fset, method="direct"))(x)
        w = fset.weights
        np.testing.assert_allclose(np.asarray(g), -2 * n * n * w * (np.asarray(p) - tgt)
                                   / np.sum(w), rtol=1e-9, atol=1e-12)


def test_sw_gradient_finite_differences(getkey):
    with jax.enable_x64(True):
        x = jax.random.uniform(getkey(), (64, 2), jnp.float64)
        _fd_check(lambda y: L.sliced_wasserstein_loss(y, [0.0, 90.0, 67.0]), x,
                  [(3, 0), (40, 1)], 1e-7)
        _fd_check(lambda y: L.combined_loss(y, fr.design(64, [0.0, 90.0], "paper"),
                                            [0.0, 90.0], c=0.3, method="direct"), x,
                  [(5, 1)], 1e-7)


@pytest.mark.slow
def test_white_noise_scales(getkey):
    """Loss magnitudes do not depend on n: white noise gives ~1 (linear), ~2 (squared)."""
    for n in (256, 2048):
        x = jax.random.uniform(getkey(), (n, 2), jnp.float32)
        fset = fr.design(n, [0.0, 90.0, 45.0], "paper")
        lin = float(L.linear_spectrum_loss(x, fset))
        sq = float(L.spectrum_loss(x, fset))
        assert 0.8 < lin < 1.2, (n, lin)
        assert 1.5 < sq < 2.5, (n, sq)


def test_bad_input(getkey):
    x = jax.random.uniform(getkey(), (16, 2), jnp.float32)
    with pytest.raises(ValueError, match="freqs"):
        L.spectrum_loss(x, np.zeros((0, 2), np.int32))
    with pytest.raises(ValueError, match="method"):
        L.spectrum_loss(x, [[1, 0]], method="fft")
    with pytest.raises(ValueError, match="c must"):
        L.combined_loss(x, [[1, 0]], [0.0], c=-1.0)
    with pytest.raises(ValueError, match="directions_deg"):
        L.sliced_wasserstein_loss(x, [0.0, 180.0])
    with pytest.raises(ValueError, match="directions_deg"):
        L.sliced_wasserstein_loss(x, [30.0, 30.0])
    with pytest.raises(ValueError, match="points"):
        L.sliced_wasserstein_loss(x + 1.0, [0.0])
    with pytest.raises(ValueError, match="weights"):
        L.linear_spectrum_loss(x, [[1, 0], [0, 1]], weights=[1.0])

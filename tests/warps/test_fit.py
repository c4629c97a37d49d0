"""Fitting (H Eq. 9 and the optimistix least-squares fit), the tabulated reference, MIS."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import anisosample.warps as W

VERTS = np.array([[-0.4, 0.2, 1.0], [0.9, -0.3, 1.3], [0.2, 0.8, 0.6]])
P = np.array([0.3, -0.5, 0.0])
N = np.array([0.0, 0.0, 1.0])


def _cos(w):
    return jnp.maximum(jnp.dot(w, jnp.asarray(N, jnp.float32)), 0.0)


def _moments(warp, n=2**16):
    """Mean and variance of cos / pdf over n uniform samples (float32, two-pass)."""
    u = jax.random.uniform(jax.random.key(5), (n, 2))
    x, pdf = jax.vmap(warp.sample_and_pdf)(u)
    e = jax.vmap(_cos)(x) / pdf
    m = jnp.mean(e)
    return m, jnp.mean((e - m) ** 2)


def _variance(warp, n=2**16):
    m, v = jax.jit(_moments, static_argnums=1)(warp, n)
    return float(m), float(v)


def test_pointwise_bilinear_is_cosine_at_the_corner_images():
    """H Sec. 3.3: PSS corners map to the vertices (two of them to B)."""
    tri = W.SphericalTriangle(VERTS, P)
    b = W.fit_pointwise(W.Bilinear, _cos, [tri])
    d = VERTS - P
    cos = d[:, 2] / np.linalg.norm(d, axis=1)  # A, B, C
    expected = np.array([[cos[1], cos[0]], [cos[1], cos[2]]])  # [i, j] at u = (i, j)
    np.testing.assert_allclose(np.asarray(b.values), expected, rtol=1e-5)


@jax.jit
def _all_fits():
    """Every technique's (mean, variance), in one compiled program."""
    tri = W.SphericalTriangle(jnp.asarray(VERTS, jnp.float32), jnp.asarray(P, jnp.float32))
    out = {"uniform": _moments(tri)}
    for kind in (W.Bilinear, W.Biquadratic):
        pw = W.fit_pointwise(kind, _cos, [tri])
        ls = W.fit_least_squares(kind, _cos, [tri], init=pw)
        out[kind.__name__] = (_moments(W.compose(pw, tri)), _moments(W.compose(ls, tri)))
    out["arvo"] = _moments(W.CosineSphericalTriangle(tri.vertices, tri.origin, jnp.asarray(N)))
    out["exact"] = W.projected_solid_angle(tri.a, tri.b, tri.c, jnp.asarray(N, jnp.float32))
    return out


def test_fits_reduce_variance_and_least_squares_is_at_least_as_good():
    r = jax.tree.map(float, _all_fits())
    exact = r["exact"]
    m0, v0 = r["uniform"]
    for kind in ("Bilinear", "Biquadratic"):
        (m_pw, v_pw), (m_ls, v_ls) = r[kind]
        for m in (m0, m_pw, m_ls):  # all unbiased
            assert abs(m - exact) < 4 * np.sqrt(v0 / 2**16)
        assert v_pw < v0 / 5
        assert v_ls <= v_pw * 1.05
    # The exact technique has (numerically) zero variance.
    m_a, v_a = r["arvo"]
    assert v_a < 1e-10 and abs(m_a - exact) < 1e-5


def test_fits_jit_and_vmap_over_shading_points():
    points = jnp.asarray([[0.0, 0.0, 0.0], [0.3, -0.5, 0.0], [-0.6, 0.4, 0.0]], jnp.float32)

    @jax.jit
    def fit_all(ps):
        def one(p):
            tri = W.SphericalTriangle(jnp.asarray(VERTS, jnp.float32), p)
            pw = W.fit_pointwise(W.Biquadratic, _cos, [tri])
            return pw.values, W.fit_least_squares(W.Biquadratic, _cos, [tri], init=pw).values

        return jax.vmap(one)(ps)

    pw, ls = fit_all(points)
    assert pw.shape == (3, 3, 3) and ls.shape == (3, 3, 3)
    assert np.all(np.isfinite(np.asarray(ls))) and np.all(np.asarray(ls) > 0)
    single = W.fit_pointwise(W.Biquadratic, _cos, [W.SphericalTriangle(VERTS, points[1])])
    np.testing.assert_allclose(np.asarray(pw[1]), np.asarray(single.values), rtol=1e-5)


def test_pointwise_all_zero_factor_gives_uniform():
    b = W.fit_pointwise(W.Bilinear, lambda x: jnp.zeros(()), [W.SphericalTriangle(VERTS, P)])
    np.testing.assert_allclose(np.asarray(b.values), 1.0)


def test_fit_bad_kind():
    with pytest.raises(ValueError, match="family must be"):
        W.fit_pointwise(W.Tabulated, _cos)


@pytest.mark.slow
def test_tabulated_reference_nearly_zero_variance():
    tri = W.SphericalTriangle(VERTS, P)
    _, v0 = _variance(tri)
    _, v_tab = _variance(W.compose(W.fit_tabulated(_cos, [tri]), tri))
    assert v_tab < v0 / 100


def test_arvo2001_check_values():
    w = W.CosineSphericalTriangle(np.eye(3), np.zeros(3), [0.0, 0.0, 1.0])
    np.testing.assert_allclose(float(w.phi_total), np.pi / 4, rtol=1e-6)
    sample, pdf = jax.jit(lambda v: w.sample(v)), jax.jit(lambda v: w.pdf(v))
    for u, x, p in [
        ((0.5, 0.5), (0.45738551, 0.40397275, 0.79221494), 1.0086793894),
        ((0.25, 0.75), (0.73520541, 0.19764395, 0.64839022), 0.8255560707),
    ]:
        got = sample(jnp.asarray(u, jnp.float32))
        np.testing.assert_allclose(np.asarray(got), x, atol=3e-7)
        np.testing.assert_allclose(float(pdf(got)), p, rtol=2e-6)


def test_arvo2001_below_horizon_raises():
    with pytest.raises(ValueError, match="above the horizon"):
        W.CosineSphericalTriangle(np.eye(3), np.zeros(3), [0.0, 0.0, -1.0])


def test_tabulated_bad_values():
    with pytest.raises(ValueError, match=">= 0"):
        W.Tabulated(-np.ones((4, 4)))
    with pytest.raises(ValueError, match="positive sum"):
        W.Tabulated(np.zeros((4, 4)))
    with pytest.raises(ValueError, match="shape"):
        W.Tabulated(np.ones(4))


@pytest.mark.parametrize(
    "fn,args,expected",
    [
        (W.power_heuristic, (1, 0.5, 1, 1.5), 0.1),
        (W.balance_heuristic, (1, 0.5, 1, 1.5), 0.25),
        (W.power_heuristic, (1, 2.0, 4, 1.0), 0.2),
        (W.power_heuristic, (1, 0.0, 1, 0.0), 0.0),
        (W.balance_heuristic, (1, 0.0, 1, 0.0), 0.0),
        (W.power_heuristic, (1, np.inf, 1, 1.0), 1.0),
    ],
)
def test_mis_values(fn, args, expected):
    np.testing.assert_allclose(float(fn(*args)), expected, rtol=1e-6)


def test_mis_weights_sum_to_one_with_composed_pdfs():
    """Both techniques' weights at the same points, pdfs by H Alg. 2, sum to 1."""
    tri = W.SphericalTriangle(VERTS, P)
    warped = W.compose(W.fit_pointwise(W.Bilinear, _cos, [tri]), tri)
    u = jax.random.uniform(jax.random.key(9), (1000, 2))
    x, _ = W.sample_batch(tri, u)
    p1, p2 = W.pdf_batch(tri, x), W.pdf_batch(warped, x)
    for h in (W.balance_heuristic, W.power_heuristic):
        np.testing.assert_allclose(np.asarray(h(1, p1, 1, p2) + h(1, p2, 1, p1)), 1.0, rtol=1e-5)


def test_least_squares_details_keep_the_solver_status():
    """``details=True``: the same warp bit for bit, with optimistix's RESULTS (the fits run with
    throw=False so that they vmap) and the step count. The default 32 steps do not reach
    rtol = 1e-4 here (the status says so; the warp is still the better iterate), 400 do."""
    tri = W.SphericalTriangle(VERTS, P)
    # jitted (as the module docstring advises): op by op, these fits compiled ~160 small programs
    fit_least_squares = eqx.filter_jit(W.fit_least_squares)
    plain = fit_least_squares(W.Biquadratic, _cos, [tri])
    fit = fit_least_squares(W.Biquadratic, _cos, [tri], details=True)
    assert isinstance(fit, W.WarpFit)
    np.testing.assert_array_equal(np.asarray(fit.warp.values), np.asarray(plain.values))
    assert not bool(fit.successful) and int(fit.steps) == 32
    assert not bool(fit.kept_start)
    done = fit_least_squares(W.Biquadratic, _cos, [tri], max_steps=400, details=True)
    assert bool(done.successful) and 32 < int(done.steps) < 400

    points = jnp.asarray([P, P + 0.1])
    many = jax.jit(jax.vmap(lambda p: W.fit_least_squares(
        W.Bilinear, _cos, [W.SphericalTriangle(VERTS, p)], max_steps=200, details=True)))(points)
    assert many.steps.shape == (2,) and bool(jnp.all(many.successful))


def test_the_old_kind_keyword_is_refused_naming_family():
    tri = W.SphericalTriangle(VERTS, P)
    for fit in (W.fit_pointwise, W.fit_least_squares):
        with pytest.raises(TypeError, match=r"takes family= where it took kind="):
            fit(kind=W.Bilinear, **{"factor" if fit is W.fit_pointwise else "f": _cos},
                later=[tri])
    fit = W.fit_pointwise(family=W.Bilinear, factor=_cos, later=[tri])
    assert isinstance(fit, W.Bilinear)

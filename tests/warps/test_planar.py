"""Planar warps against the fact sheet's float64 values (references/warps.md Secs. 1-4)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import anisosample.warps as W

BIL = [[1.0, 3.0], [2.0, 4.0]]  # w00=1, w10=2, w01=3, w11=4 (values[i, j] at u = (i, j))
V3 = np.array([[1, 2, 0.5], [3, 1, 2], [0.2, 4, 1]])


@pytest.mark.parametrize(
    "u,a,b,expected",
    [
        (0.5, 1.0, 3.0, 0.6180339887),
        (0.3, 2.0, 2.0, 0.3),
        (0.25, 0.0, 1.0, 0.5),
        (0.3, 1.0, 1.0 + 1e-6, 0.3000000105 * 0 + 0.3 + 0.3 * 0.7 * 1e-6 / 2),
        (0.7, 0.0, 0.0, 0.7),
    ],
)
def test_sample_linear_values(u, a, b, expected):
    x = W.sample_linear(jnp.float32(u), jnp.float32(a), jnp.float32(b))
    assert np.isfinite(float(x))
    np.testing.assert_allclose(float(x), expected, atol=2e-7)
    # The CDF undoes it; the pdf is the CDF's derivative.
    np.testing.assert_allclose(float(W.invert_linear_sample(x, a, b)), u, atol=2e-7)
    d = jax.grad(lambda t: W.invert_linear_sample(t, a, b))(jnp.float32(0.4))
    np.testing.assert_allclose(float(d), float(W.linear_pdf(jnp.float32(0.4), a, b)), rtol=1e-5)


def test_linear_pdf_off_support_and_degenerate():
    assert float(W.linear_pdf(jnp.float32(1.5), 1.0, 2.0)) == 0.0
    assert float(W.linear_pdf(jnp.float32(0.3), 0.0, 0.0)) == 1.0
    assert float(W.sample_linear(jnp.float32(0.0), 0.0, 1.0)) == 0.0


@pytest.mark.parametrize(
    "u,x,pdf",
    [
        ((0.5, 0.5), (0.54603038, 0.59629120), 1.095445115),
        ((0.25, 0.75), (0.28245375, 0.81124950), 1.161981101),
        ((0.0, 0.0), (0.0, 0.0), 0.4),
        ((1.0, 1.0), (1.0, 1.0), 1.6),
    ],
)
def test_bilinear_values(u, x, pdf):
    w = W.Bilinear(BIL)
    got = w.sample(jnp.asarray(u, jnp.float32))
    np.testing.assert_allclose(np.asarray(got), x, atol=2e-7)
    np.testing.assert_allclose(float(w.pdf(jnp.asarray(x, jnp.float32))), pdf, rtol=1e-6)


def test_bilinear_equal_values_is_identity():
    w = W.Bilinear(np.full((2, 2), 3.0))
    u = jax.random.uniform(jax.random.key(3), (1000, 2))
    x, pdf = W.sample_batch(w, u)
    np.testing.assert_allclose(np.asarray(x), np.asarray(u), atol=1e-7)
    np.testing.assert_allclose(np.asarray(pdf), 1.0, atol=1e-6)


@pytest.mark.parametrize(
    "u,x,pdf",
    [
        ((0.5, 0.5), (0.56172911, 0.48388610), 1.136713506),
        ((0.1, 0.9), (0.14703598, 0.87455256), 0.6704760736),
    ],
)
def test_biquadratic_values(u, x, pdf):
    w = W.Biquadratic(V3)
    got = w.sample(jnp.asarray(u, jnp.float32))
    np.testing.assert_allclose(np.asarray(got), x, atol=5e-7)
    np.testing.assert_allclose(float(w.pdf(jnp.asarray(x, jnp.float32))), pdf, rtol=2e-6)


def test_biquadratic_pdf_integrates_to_one_and_matches_closed_form_density():
    # Gauss-Legendre quadrature of the pdf (a degree-(2,2) polynomial: exact with 3 nodes).
    t, wts = np.polynomial.legendre.leggauss(4)
    t, wts = (t + 1) / 2, wts / 2
    X, Y = np.meshgrid(t, t, indexing="ij")
    pts = jnp.asarray(np.stack([X, Y], -1).reshape(-1, 2), jnp.float32)
    p = np.asarray(W.pdf_batch(W.Biquadratic(V3), pts)).reshape(4, 4)
    np.testing.assert_allclose(np.einsum("i,j,ij->", wts, wts, p), 1.0, rtol=1e-6)
    # Second way: the Bernstein sum written out in float64.
    b = lambda s: np.array([(1 - s) ** 2, 2 * s * (1 - s), s**2])  # noqa: E731
    direct = [9 * b(x) @ V3 @ b(y) / V3.sum() for x, y in np.asarray(pts, np.float64)]
    np.testing.assert_allclose(p.reshape(-1), direct, rtol=2e-6)


def test_composite_check_value():
    c = W.compose(W.Bilinear(BIL), W.Biquadratic(V3))
    x, pdf = c.sample_and_pdf(jnp.asarray([0.3, 0.6], jnp.float32))
    np.testing.assert_allclose(np.asarray(x), [0.41020778, 0.65498899], atol=5e-7)
    np.testing.assert_allclose(float(pdf), 1.0740083334, rtol=2e-6)
    np.testing.assert_allclose(float(c.pdf(x)), 1.0740083334, rtol=2e-6)
    # The product along the chain, computed by hand.
    x1 = W.Bilinear(BIL).sample(jnp.asarray([0.3, 0.6]))
    by_hand = W.Bilinear(BIL).pdf(x1) * W.Biquadratic(V3).pdf(x)
    np.testing.assert_allclose(float(pdf), float(by_hand), rtol=1e-6)


@pytest.mark.parametrize("cls,shape", [(W.Bilinear, (2, 2)), (W.Biquadratic, (3, 3))])
def test_bad_control_values(cls, shape):
    with pytest.raises(ValueError, match="values must be >= 0"):
        cls(-np.ones(shape))
    with pytest.raises(ValueError, match="positive sum"):
        cls(np.zeros(shape))
    with pytest.raises(ValueError, match="finite"):
        cls(np.full(shape, np.nan))
    with pytest.raises(ValueError, match=r"values must have shape"):
        cls(np.ones((4, 4)))


@pytest.mark.parametrize("cls,shape", [(W.Bilinear, (2, 2)), (W.Biquadratic, (3, 3))])
def test_traced_degenerate_values_are_uniform_not_nan(cls, shape):
    """Inside jit, all-zero (or negative) values give the uniform warp: documented, no NaN."""

    @jax.jit
    def run(v, u):
        w = cls(v)
        x = w.sample(u)
        return x, w.pdf(x), w.inverse(x)

    u = jnp.asarray([0.3, 0.8], jnp.float32)
    for v in (jnp.zeros(shape), -jnp.ones(shape)):
        x, p, back = run(v, u)
        np.testing.assert_allclose(np.asarray(x), np.asarray(u), atol=1e-7)
        assert float(p) == 1.0
        np.testing.assert_allclose(np.asarray(back), np.asarray(u), atol=1e-7)

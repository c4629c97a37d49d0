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


# --- robustness of the linear 1D triplet (issue 24 item 2; Peters 2021 Sec. 3.6) -------------


def _linear_cdf64(x, a, b):
    return x * (a * (2.0 - x) + b * x) / (a + b)


def _linear_root64(u, a, b):
    """float64 bisection of the CDF (H Table 3's ``l``, stable in every regime): an independent
    truth for ``sample_linear``, not a formula for its root."""
    lo, hi = np.zeros_like(u), np.ones_like(u)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        below = _linear_cdf64(mid, a, b) < u
        lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
    return 0.5 * (lo + hi)


_U_LIN = np.concatenate([np.linspace(0.0, 1.0 - 2.0**-24, 257), [2.0**-24, 1e-6, 0.999]]).astype(
    np.float32)


@pytest.mark.parametrize("a", [0.3, 1.0, 7.0])
def test_linear_triplet_is_exact_and_continuous_as_b_approaches_a(a):
    """b = a (1 + delta), delta from 1e-1 down to 0 (and below): sample, inverse and pdf stay
    within float32 rounding of float64 truth (a bisection of the CDF), and the sample moves
    continuously, ``|x(b) - x(a)| <= |b - a| / a`` (the slope of the root in b is below 1/a).
    H Table 3's textbook root ``(a - sqrt(lerp(u, a^2, b^2))) / (a - b)`` in float32 is NaN at
    b = a and off by far more than rounding near it: the check can fail."""
    u = jnp.asarray(_U_LIN)
    a32 = np.float32(a)
    x_at_a = np.asarray(W.sample_linear(u, a32, a32), np.float64)
    np.testing.assert_allclose(x_at_a, np.minimum(_U_LIN, 1 - 2.0**-24), atol=1.2e-7)
    for delta in [1e-1, 1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, -1e-7, -1e-4, -1e-1, 0.0]:
        b32 = np.float32(a * (1 + delta))
        a64, b64 = float(a32), float(b32)
        x = np.asarray(W.sample_linear(u, a32, b32), np.float64)
        truth = _linear_root64(_U_LIN.astype(np.float64), a64, b64)
        assert np.all(np.isfinite(x))
        np.testing.assert_allclose(x, truth, atol=2.4e-7, err_msg=f"delta={delta}")
        assert np.all(np.abs(x - x_at_a) <= abs(b64 - a64) / a64 + 2.4e-7), delta
        back = np.asarray(W.invert_linear_sample(jnp.asarray(truth, jnp.float32), a32, b32))
        np.testing.assert_allclose(back, _U_LIN, atol=2.4e-7, err_msg=f"delta={delta}")
        pdf = np.asarray(W.linear_pdf(jnp.asarray(truth, jnp.float32), a32, b32))
        pdf64 = 2 * ((1 - truth) * a64 + truth * b64) / (a64 + b64)
        np.testing.assert_allclose(pdf, pdf64, rtol=1e-6, err_msg=f"delta={delta}")
        # The sample's slope is 1/pdf (jacfwd through the branch-free root).
        slope = jax.vmap(jax.grad(lambda t, b32=b32: W.sample_linear(t, a32, b32)))(u[1:-4])
        np.testing.assert_allclose(np.asarray(slope) * pdf[1:-4], 1.0, rtol=2e-5)
    # The textbook form fails exactly where the rationalised one does not.
    b32 = np.float32(a * (1 + 1e-6))
    lerp = (1 - u) * a32 * a32 + u * b32 * b32
    textbook = np.asarray((a32 - jnp.sqrt(lerp)) / (a32 - b32), np.float64)
    truth = _linear_root64(_U_LIN.astype(np.float64), float(a32), float(b32))
    assert np.nanmax(np.abs(textbook - truth)) > 1e-3
    with np.errstate(invalid="ignore"):
        assert np.isnan(np.asarray((a32 - jnp.sqrt(u * 0 + a32 * a32)) / (a32 - a32))).all()


@pytest.mark.parametrize("scale", [1e-30, 1e-25, 1e-19, 1e19, 1e25, 1e30])
def test_linear_triplet_is_scale_invariant(scale):
    """The density ``lerp(x, a, b)`` does not change when ``(a, b)`` are scaled, nor may the
    triplet: the same samples, inverses and pdfs from ``1e-30`` to ``1e30`` times the values
    (beyond, products of a value and a float32 ``x`` leave the normal range). (Unscaled,
    ``a^2`` flushes to 0 below ~1e-19 -- a GGX tail in a product fit -- and overflows above
    ~1e19: samples off by up to 0.5, or NaN, with the pdf still right.)
    """
    u = jnp.asarray(_U_LIN)
    for a, b in [(0.3, 0.7), (1.0, 1.0), (0.0, 1.0), (2.0, 0.0), (1.0, 1.0 + 1e-6)]:
        ref = np.asarray(W.sample_linear(u, np.float32(a), np.float32(b)))
        sa, sb = np.float32(a * scale), np.float32(b * scale)
        x = np.asarray(W.sample_linear(u, sa, sb))
        np.testing.assert_allclose(x, ref, atol=2.4e-7, err_msg=f"{(a, b)} x {scale}")
        np.testing.assert_allclose(np.asarray(W.invert_linear_sample(jnp.asarray(x), sa, sb)),
                                   np.asarray(W.invert_linear_sample(jnp.asarray(ref), a, b)),
                                   atol=5e-7)
        np.testing.assert_allclose(np.asarray(W.linear_pdf(jnp.asarray(x), sa, sb)),
                                   np.asarray(W.linear_pdf(jnp.asarray(ref), a, b)), rtol=1e-6)
    bil = W.Bilinear(np.asarray(BIL) * scale)
    uu = jax.random.uniform(jax.random.key(5), (512, 2), jnp.float32)
    x, p = W.sample_batch(bil, uu)
    x1, p1 = W.sample_batch(W.Bilinear(BIL), uu)
    np.testing.assert_allclose(np.asarray(x), np.asarray(x1), atol=5e-7)
    np.testing.assert_allclose(np.asarray(p), np.asarray(p1), rtol=2e-6)


def test_linear_triplet_with_a_zero_end_is_the_closed_form():
    """Some-zero weights: density 2x (a = 0) is sampled by sqrt(u), density 2(1 - x) (b = 0) by
    1 - sqrt(1 - u), both ends included, no NaN; the bilinear warp with a single non-zero
    corner is the product of two such square roots (pdf 4 x y)."""
    u = _U_LIN.astype(np.float64)
    x = np.asarray(W.sample_linear(jnp.asarray(_U_LIN), 0.0, 2.5), np.float64)
    np.testing.assert_allclose(x, np.sqrt(u), atol=2.4e-7)
    x = np.asarray(W.sample_linear(jnp.asarray(_U_LIN), 0.4, 0.0), np.float64)
    np.testing.assert_allclose(x, 1 - np.sqrt(1 - u), atol=2.4e-7)
    w = W.Bilinear([[0.0, 0.0], [0.0, 3.0]])  # values[1, 1] at u = (1, 1): density 4 x y
    g = _U_LIN[1::8]  # u > 0: on the line y = 0 the density is 0 and any conditional will do
    uu = np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2)
    got, p = W.sample_batch(w, jnp.asarray(uu))
    got = np.asarray(got, np.float64)
    np.testing.assert_allclose(got, np.sqrt(uu.astype(np.float64)), atol=3e-7)
    np.testing.assert_allclose(np.asarray(p), 4 * got[:, 0] * got[:, 1], atol=2e-6)
    np.testing.assert_allclose(np.asarray(W.inverse_batch(w, jnp.asarray(got, jnp.float32))),
                               uu, atol=5e-7)
    assert np.all(np.isfinite(np.asarray(W.pdf_batch(w, jnp.asarray(got, jnp.float32)))))


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
    """Inside jit, all-zero values give the uniform warp (the fits' fallback): documented, no
    NaN. Negative values are refused there as eagerly (they were clamped to 0 before)."""

    @jax.jit
    def run(v, u):
        w = cls(v)
        x = w.sample(u)
        return x, w.pdf(x), w.inverse(x)

    u = jnp.asarray([0.3, 0.8], jnp.float32)
    x, p, back = run(jnp.zeros(shape), u)
    np.testing.assert_allclose(np.asarray(x), np.asarray(u), atol=1e-7)
    assert float(p) == 1.0
    np.testing.assert_allclose(np.asarray(back), np.asarray(u), atol=1e-7)
    with pytest.raises((ValueError, RuntimeError), match=r"values must be >= 0 \(a density\)"):
        jax.block_until_ready(run(-jnp.ones(shape), u))

"""Differentiable tuning of PSS warps: chain_variance and fit_min_variance (warps/tuning.py).

Independent truths: a float64 NumPy evaluation of the same quadrature with central differences
(the gradient); the identity base with a bilinear / biquadratic target (zero variance at the
optimum, values proportional to the target's); the triangle light's variance by brute force
through sampling (H Algorithm 1 on a fine midpoint grid of PSS inputs, Newton solves included)
against Lambert's closed form (``projected_solid_angle``).
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import anisosample.warps as W
from anisosample.metrics import midpoint_grid
from anisosample.warps import tuning

VERTS = np.array([[-0.4, 0.2, 1.0], [0.9, -0.3, 1.3], [0.2, 0.8, 0.6]])
P = np.array([0.3, -0.5, 0.0])
N = np.array([0.0, 0.0, 1.0])


def _cos(w):
    return jnp.maximum(jnp.dot(w, jnp.asarray(N, jnp.float32)), 0.0)


def _triangle(p=P):
    return W.SphericalTriangle(jnp.asarray(VERTS, jnp.float32), jnp.asarray(p, jnp.float32))


def _bernstein(t):
    return np.stack([(1 - t) ** 2, 2 * t * (1 - t), t**2])


def _np_pdf(values, y):
    """H Table 3's J for Bilinear / Biquadratic in float64, written from the table."""
    v = np.asarray(values, np.float64)
    if v.shape == (2, 2):
        bx = np.stack([1 - y[:, 0], y[:, 0]])
        by = np.stack([1 - y[:, 1], y[:, 1]])
        return 4 * np.einsum("in,ij,jn->n", bx, v, by) / v.sum()
    return 9 * np.einsum("in,ij,jn->n", _bernstein(y[:, 0]), v, _bernstein(y[:, 1])) / v.sum()


@pytest.mark.parametrize("kind", [W.Bilinear, W.Biquadratic])
def test_gradient_equals_finite_differences(kind):
    """jax.grad of the library's variance vs central differences of a float64 NumPy evaluation
    of ``int g^2 / J - I^2`` on the same rule (h = 1e-5: truncation ~1e-10, round-off ~1e-11)."""
    tri = _triangle()
    side = 2 if kind is W.Bilinear else 3
    values = np.random.default_rng(1).uniform(0.5, 2.0, (side, side))
    grad = jax.jit(jax.grad(lambda v: tuning.chain_variance(kind(v), _cos, [tri], grid=16)))(
        jnp.asarray(values, jnp.float32)
    )
    y, w = (np.asarray(a, np.float64) for a in tuning.quadrature(16))
    g = np.asarray(tuning.pss_target(_cos, [tri], jnp.asarray(y, jnp.float32)), np.float64)

    def var(v):
        return np.sum(w * g**2 / _np_pdf(v, y)) - np.sum(w * g) ** 2

    h = 1e-5
    fd = np.zeros_like(values)
    for idx in np.ndindex(values.shape):
        e = np.zeros_like(values)
        e[idx] = h
        fd[idx] = (var(values + e) - var(values - e)) / (2 * h)
    # float32 grad: relative error ~ a few ulps times the terms' spread.
    np.testing.assert_allclose(np.asarray(grad), fd, atol=2e-4 * np.abs(fd).max())
    # The variance is invariant under scaling the values: grad . values = 0 (Euler).
    assert abs(np.sum(fd * values)) < 1e-6 * np.abs(fd).max()


@functools.partial(jax.jit, static_argnums=(1, 2))
def _estimates(warp, f, res):
    u = midpoint_grid(res, indexing="ij", xp=jnp).reshape(-1, 2)
    x, pdf = jax.vmap(warp.sample_and_pdf)(u)
    return jax.vmap(f)(x) / pdf


def _brute_variance(warp, f, exact, res=256):
    """Var of f/p over u on a res x res midpoint grid of the composed warp's input, by sampling
    (float64 moments about the exact mean)."""
    e = np.asarray(_estimates(warp, f, res), np.float64)
    return float(np.mean((e - exact) ** 2)), float(np.mean(e))


@pytest.mark.parametrize(
    "kind,solver", [(W.Bilinear, "lm"), (W.Biquadratic, "lm"), (W.Bilinear, "bfgs")]
)
def test_identity_base_recovers_a_polynomial_target_with_zero_variance(kind, solver):
    """Through the identity base, f = a(y) of a ``kind`` warp: J_opt = f / I, variance 0."""
    side = 2 if kind is W.Bilinear else 3
    values = np.random.default_rng(2).uniform(0.2, 3.0, (side, side))
    target = kind(values)
    total = np.sum(values)

    def f(y):  # a(y) = J * sum / (4 or 9); integral sum / (4 or 9)
        return target.pdf(y)

    fit = jax.jit(lambda: tuning.fit_min_variance(kind, f, solver=solver, max_steps=128))()
    got = np.asarray(fit.values, np.float64)
    np.testing.assert_allclose(got / got.sum(), values / total, rtol=2e-3)
    assert float(tuning.chain_variance(fit, f)) < 1e-9
    var, mean = _brute_variance(fit, f, 1.0)
    assert abs(mean - 1.0) < 1e-5 and var < 1e-9
    # The uniform warp's variance of the same target is far from 0.
    assert float(tuning.chain_variance(kind(np.ones((side, side))), f)) > 1e-2


@functools.cache
def _triangle_fits():
    @jax.jit
    def fits():
        tri = _triangle()
        out = {}
        for kind in (W.Bilinear, W.Biquadratic):
            pw = W.fit_pointwise(kind, _cos, [tri])
            ls = W.fit_least_squares(kind, _cos, [tri], init=pw)
            mv = tuning.fit_min_variance(kind, _cos, [tri], init=pw)
            out[kind.__name__] = (pw, ls, mv)
        return out

    return fits()


@pytest.mark.parametrize("kind", ["Bilinear", "Biquadratic"])
def test_min_variance_beats_pointwise_and_least_squares(kind):
    """Brute-force variance through sampling (512^2 PSS inputs), exact mean from Lambert."""
    tri = _triangle()
    exact = float(W.projected_solid_angle(tri.a, tri.b, tri.c, jnp.asarray(N, jnp.float32)))
    pw, ls, mv = _triangle_fits()[kind]
    brute = {}
    for name, warp in (("pw", pw), ("ls", ls), ("mv", mv)):
        brute[name], mean = _brute_variance(W.compose(warp, tri), _cos, exact)
        assert abs(mean - exact) < 1e-4 * exact  # the grid mean is the integral
    # The quadrature objective (Gauss 32^2) agrees with the brute force, whose midpoint-rule error
    # at 256^2 is below 1% (it moves by 0.1% / 0.5% from 256^2 to 512^2 here).
    quad = float(jax.jit(lambda w: tuning.chain_variance(w, _cos, [tri]))(mv))
    np.testing.assert_allclose(quad, brute["mv"], rtol=2e-2)
    assert brute["mv"] <= brute["pw"]
    # Bilinear: the two optima differ by ~0.2%; the midpoint-rule error is common to both
    # (same base warp, same grid), so the order holds with a margin of 1e-4.
    assert brute["mv"] <= brute["ls"] * (1 + 1e-4)


def test_jit_and_vmap_over_shading_points():
    """vmap over three shading points; the middle one equals the single fit of _triangle_fits."""
    points = jnp.asarray([[0.0, 0.0, 0.0], [0.3, -0.5, 0.0], [-0.6, 0.4, 0.0]], jnp.float32)

    @jax.jit
    def fit_all(ps):
        def one(p):
            tri = _triangle(p)
            pw = W.fit_pointwise(W.Bilinear, _cos, [tri])
            return tuning.fit_min_variance(W.Bilinear, _cos, [tri], init=pw).values

        return jax.vmap(one)(ps)

    batch = np.asarray(fit_all(points))
    assert batch.shape == (3, 2, 2) and np.all(np.isfinite(batch)) and np.all(batch > 0)
    one = np.asarray(_triangle_fits()["Bilinear"][2].values)
    np.testing.assert_allclose(batch[1], one, rtol=1e-4)


def test_zero_integrand_gives_uniform():
    def zero(x):
        return jnp.zeros(())

    fit = jax.jit(lambda: tuning.fit_min_variance(W.Bilinear, zero, [_triangle()], grid=4))()
    np.testing.assert_allclose(np.asarray(fit.values), 1.0)
    assert float(tuning.chain_variance(fit, zero, [_triangle()], grid=4)) == 0.0


@pytest.mark.library_errors
@pytest.mark.parametrize(
    "kwargs,exc,match",
    [
        (dict(family=W.Tabulated), ValueError, "family must be"),
        (dict(grid=1), ValueError, "grid must be >= 2"),
        (dict(grid=8.0), TypeError, "grid must be an integer"),
        (dict(rule="simpson"), ValueError, "rule must be one of"),
        (dict(max_steps=0), ValueError, "max_steps must be >= 1"),
        (dict(solver="adam"), ValueError, "solver must be one of"),
        (dict(rtol=-1.0), ValueError, "rtol must be finite and > 0"),
        (dict(init=W.Biquadratic(np.ones((3, 3)))), TypeError, "init must be a Bilinear"),
        (dict(later=[np.eye(3)]), TypeError, r"later\[0\] must be a Warp"),
        (dict(later=3), TypeError, "later must be a Warp"),
    ],
)
def test_bad_parameters(kwargs, exc, match):
    args = dict(family=W.Bilinear, f=_cos, later=[_triangle()])
    args.update(kwargs)
    with pytest.raises(exc, match=match):
        tuning.fit_min_variance(args.pop("family"), args.pop("f"), args.pop("later"), **args)


def test_chain_variance_needs_a_pss_warp():
    with pytest.raises(TypeError, match="warp must be a Warp from"):
        tuning.chain_variance(_triangle(), _cos)


def test_min_variance_details_keep_the_solver_status():
    plain = tuning.fit_min_variance(W.Bilinear, _cos, [_triangle()], grid=8)
    for solver in ("lm", "bfgs"):
        fit = tuning.fit_min_variance(W.Bilinear, _cos, [_triangle()], grid=8, solver=solver,
                                      details=True)
        assert isinstance(fit, W.WarpFit) and int(fit.steps) >= 1
        assert bool(fit.successful) or int(fit.steps) == 64
    fit = tuning.fit_min_variance(W.Bilinear, _cos, [_triangle()], grid=8, details=True)
    np.testing.assert_array_equal(np.asarray(fit.warp.values), np.asarray(plain.values))
    with pytest.raises(TypeError, match="takes family= where it took kind="):
        tuning.fit_min_variance(kind=W.Bilinear, f=_cos, later=[_triangle()])

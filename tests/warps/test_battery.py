"""One battery for every warp in the catalogue: round trip, Jacobian = 1/pdf, extremes.

The chi-square goodness-of-fit part of the battery lives in test_chi2.py (it needs 10^6 samples).
"""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import anisosample.warps as W
from anisosample.metrics import midpoint_grid

from .helpers import ALL, ROUND_TRIP_TOL

IDS = [c[0] for c in ALL]
EPS = 2.0**-24


def _grid(n):
    return jnp.asarray(midpoint_grid(n, indexing="ij").reshape(-1, 2))


def _jac_measure(fn, u):
    jac = jax.jacfwd(fn)(u)
    if jac.shape[0] == 2:
        return jnp.abs(jnp.linalg.det(jac))
    return jnp.linalg.norm(jnp.cross(jac[:, 0], jac[:, 1]))


_EXTREMES = [0.0, EPS, 0.5, 1.0 - EPS, 1.0]
_U_EXT = np.asarray([[a, b] for a in _EXTREMES for b in _EXTREMES], np.float32)
_U_GRID = np.asarray(_grid(64))
_U_RAND = np.asarray(jax.random.uniform(jax.random.key(1), (100_000, 2), dtype=jnp.float32))
_U_JAC = np.clip(
    np.concatenate([np.asarray(_grid(12)), _U_RAND[:300]]), 0.01, 0.99
)  # the Jacobian of sqrt-like corners is infinite at the border
_OFF = {
    "planar": np.asarray([[-0.1, 0.5], [0.5, 1.2], [2.0, -3.0], [1.5, 1.5]], np.float32),
    "disk": np.asarray([[1.2, 0.0], [0.9, 0.9], [-2.0, 0.1], [0.0, -1.01]], np.float32),
    "spherical": np.asarray([[0.0, 0.0, -1.0], [0.3, -0.2, -0.9], [-0.5, 0.0, -0.8]], np.float32),
    "surface": np.asarray([[5.0, 5.0, 5.0], [-3.0, 0.0, 1.0], [0.5, 0.5, 3.0]], np.float32),
}
_FULL_SPHERE = {"octahedral"}


@eqx.filter_jit
def _evaluate(warp, u, u_jac, x_off):
    """Everything the battery looks at, in one compiled call per warp type."""
    x, pdf_alg1 = jax.vmap(warp.sample_and_pdf)(u)
    pdf_alg2 = jax.vmap(warp.pdf)(x)
    back = jax.vmap(warp.inverse)(x)
    det = jax.vmap(lambda v: _jac_measure(warp.sample, v))(u_jac)
    xj = jax.vmap(warp.sample)(u_jac)
    pdf_j = jax.vmap(warp.pdf)(xj)
    return dict(
        x=x,
        pdf_alg1=pdf_alg1,
        pdf=pdf_alg2,
        back=back,
        jac_prod=pdf_j * det,
        pdf_off=jax.vmap(warp.pdf)(x_off),
        back_off=jax.vmap(warp.inverse)(x_off),
    )


@functools.cache
def _results(name):
    factory = {c[0]: c[1] for c in ALL}[name]
    warp = factory()
    u = np.concatenate([_U_GRID, _U_RAND, _U_EXT])
    kind = {c[0]: c[2] for c in ALL}[name]
    out = _evaluate(warp, jnp.asarray(u), jnp.asarray(_U_JAC), jnp.asarray(_OFF[kind]))
    return u, {k: np.asarray(v) for k, v in out.items()}


@pytest.mark.parametrize("name,factory,kind", ALL, ids=IDS)
def test_round_trip(name, factory, kind):
    """inverse(sample(u)) == u on a 64x64 grid and 10^5 random points (float32)."""
    u, r = _results(name)
    n = len(_U_GRID) + len(_U_RAND)
    err = np.max(np.abs(r["back"][:n] - u[:n]), axis=1)
    worst = int(np.argmax(err))
    assert err[worst] <= ROUND_TRIP_TOL[kind], (
        f"{name}: inverse(sample(u)) off by {err[worst]:.3g} at u={u[worst]}"
        f" -> x={r['x'][worst]} -> {r['back'][worst]}"
    )
    assert np.all(r["pdf"][:n] > 0)


@pytest.mark.parametrize("name,factory,kind", ALL, ids=IDS)
def test_pdf_times_jacobian_is_one(name, factory, kind):
    """pdf(sample(u)) * |det d sample / du| = 1 (JAX adds this check to pbrt's battery)."""
    _, r = _results(name)
    prod = r["jac_prod"]
    worst = int(np.argmax(np.abs(prod - 1)))
    assert np.allclose(prod, 1.0, rtol=0, atol=2e-3), (
        f"{name}: pdf * |det J| = {prod[worst]} at u = {_U_JAC[worst]}"
    )


@pytest.mark.parametrize("name,factory,kind", ALL, ids=IDS)
def test_algorithm1_pdf_equals_algorithm2_pdf(name, factory, kind):
    """H Alg. 1 (product along the chain while sampling) == H Alg. 2 (inverting)."""
    _, r = _results(name)
    n = len(_U_GRID) + len(_U_RAND)
    np.testing.assert_allclose(r["pdf_alg1"][:n], r["pdf"][:n], rtol=1e-4)


@pytest.mark.parametrize("name,factory,kind", ALL, ids=IDS)
def test_extremes_finite(name, factory, kind):
    """No NaN or Inf at u in {0, eps, 1 - eps, 1}."""
    _, r = _results(name)
    m = len(_U_EXT)
    for what in ("x", "pdf", "back", "pdf_alg1"):
        assert np.all(np.isfinite(r[what][-m:])), f"{name}: {what} not finite at the extremes"
    assert np.all(r["pdf"][-m:] >= 0)
    x = r["x"][-m:]
    if kind == "planar":
        assert np.all((x >= 0) & (x < 1))
    elif kind == "disk":
        assert np.all(np.sum(x * x, axis=1) <= 1 + 1e-6)
    elif kind == "spherical":
        np.testing.assert_allclose(np.linalg.norm(x, axis=1), 1.0, atol=1e-5)


@pytest.mark.parametrize("name,factory,kind", ALL, ids=IDS)
def test_off_support_pdf_zero_and_inverse_clamped(name, factory, kind):
    if name in _FULL_SPHERE:
        pytest.skip("the support is the whole sphere")
    _, r = _results(name)
    assert np.all(np.isfinite(r["pdf_off"])) and np.all(np.isfinite(r["back_off"]))
    assert np.all(r["pdf_off"] == 0), f"{name}: pdf off the support = {r['pdf_off']}"
    assert np.all((r["back_off"] >= 0) & (r["back_off"] <= 1))


@pytest.mark.parametrize("name,factory,kind", ALL[:1] + ALL[-1:], ids=[IDS[0], IDS[-1]])
def test_jit_over_the_warp_itself(name, factory, kind):
    """Warps are pytrees: jit a function of the warp itself (as fits over shading points do)."""
    warp = factory()
    u = jnp.asarray([0.3, 0.6], jnp.float32)
    x1 = warp.sample(u)
    x2 = jax.jit(lambda w, v: w.sample(v))(warp, u)
    np.testing.assert_allclose(np.asarray(x1), np.asarray(x2), atol=1e-6)


def test_single_point_contract():
    warp = W.Bilinear([[1.0, 2.0], [3.0, 4.0]])
    with pytest.raises(ValueError, match="single point of shape"):
        warp.sample(jnp.zeros((5, 2)))
    with pytest.raises(ValueError, match="single point"):
        warp.pdf(jnp.zeros(3))


@eqx.filter_jit
def _chunked(warp, u, x):
    """Sampling and pdf of ``u``, and the inverse of ``x``, in chunks of 64 rows."""
    xs, ps = jax.lax.map(jax.vmap(warp.sample_and_pdf), u.reshape(-1, 64, 2))
    back = jax.lax.map(jax.vmap(warp.inverse), x.reshape(-1, 64, x.shape[-1]))
    return xs.reshape(x.shape), ps.reshape(-1), back.reshape(-1, 2)


@pytest.mark.parametrize("name,factory,kind", [c for c in ALL if c[2] != "planar"],
                         ids=[c[0] for c in ALL if c[2] != "planar"])
def test_large_batches_match_small_ones(name, factory, kind):
    """XLA's CPU backend (jaxlib 0.10.2) miscompiled fused 3-vector reductions past a few thousand
    vmapped rows in the renderer (see ``anisosample/render/_vec.py``): the battery's batch of
    about 10^5 rows (:func:`_results`) must give what chunks of 64 give, for sampling, pdf and
    inverse of every 3D warp, on its first 2^13 random rows. The two programs vectorize (and
    contract multiply-adds) differently, so they agree to float32 rounding (measured <= 6e-6
    absolute, on 0.03% of the entries at most); the miscompile gave O(1) errors."""
    u, r = _results(name)
    rows = slice(len(_U_GRID), len(_U_GRID) + 2**13)
    xs, ps, bs = _chunked(factory(), jnp.asarray(u[rows]), jnp.asarray(r["x"][rows]))
    np.testing.assert_allclose(r["x"][rows], np.asarray(xs), rtol=0, atol=1e-4)
    np.testing.assert_allclose(r["pdf_alg1"][rows], np.asarray(ps), rtol=1e-3)
    np.testing.assert_allclose(r["back"][rows], np.asarray(bs), rtol=0, atol=1e-4)

"""Bad input under the caller's ``jax.jit`` and ``jax.vmap`` (issue 26 item 5).

What the public API refuses eagerly it refuses traced too, with a message naming the parameter:
shape, dtype and static checks run while tracing (the same ``ValueError``/``TypeError``); value
checks (NaN, range, sign) run inside the program (``_validate.refuse_traced``:
``equinox.error_if``), which raises an ``EquinoxRuntimeError`` under ``jax.vmap`` and a
``JaxRuntimeError`` whose text holds the same message under plain ``jax.jit``.

Mechanisms tried for the traced half: ``jax.experimental.checkify`` (every plain ``jax.jit`` of
a checked function fails to trace unless the caller wraps it in ``checkify.checkify``: refused),
``jax.debug.callback`` raising ``ValueError`` (the message survives, but the callback runs on the
host at every call, good input or not, and prints its traceback), and ``equinox.error_if``
(kept: the callback runs only when the check fails, the checked array flows through it so XLA
keeps it, and it works under ``vmap`` and ``grad``).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from anisosample import directions, samplers, spectrum, vmf
from anisosample import warps as W

# The library's own errors under tracing, without jaxtyping's run-time checks (on for the rest
# of the suite), which would refuse a traced ``n: int`` or a wrongly typed argument first.
pytestmark = pytest.mark.library_errors

NAN = float("nan")
KEY = jax.random.key(0)
ERRORS = (ValueError, TypeError, RuntimeError)  # JaxRuntimeError and EquinoxRuntimeError too


def _points(n=64):
    return samplers.get("sobol-owen")(KEY, n)


def _hist():
    return jnp.asarray(vmf.bin_masses(1.0, 20.0, 90))


def _grid():
    return jnp.asarray(np.random.default_rng(0).uniform(size=(32, 32)), jnp.float32)


FREQS = jnp.asarray([[1, 0], [0, 1], [2, 3]], jnp.int32)
U = jnp.array([0.5, 0.5])

# (id, function of one argument, a bad argument, what the message must say). Each runs under
# jax.jit, and under jax.vmap over a batch of two (a good argument and the bad one) where
# the argument is an array.
CASES = [
    ("Bilinear values shape", lambda v: W.Bilinear(v).pdf(U), jnp.ones((3, 3)),
     r"values must have shape \(2, 2\)"),
    ("Bilinear values NaN", lambda v: W.Bilinear(v).pdf(U), jnp.ones((2, 2)).at[0, 0].set(NAN),
     "values must be finite"),
    ("Biquadratic values negative", lambda v: W.Biquadratic(v).pdf(U),
     jnp.ones((3, 3)).at[1, 1].set(-1.0), r"values must be >= 0"),
    ("sample_batch u NaN", lambda u: W.sample_batch(W.Bilinear(jnp.ones((2, 2))), u),
     jnp.full((4, 2), 0.5).at[0, 0].set(NAN), "u contains NaN"),
    ("sample_batch u range", lambda u: W.sample_batch(W.Bilinear(jnp.ones((2, 2))), u),
     jnp.full((4, 2), 1.5), r"u must lie in \[0, 1\]\^2"),
    ("warp sample u shape", lambda u: W.Bilinear(jnp.ones((2, 2))).sample(u), jnp.full(3, 0.5),
     r"u must be a single point of shape \(2,\)"),
    ("toroidal_shift points NaN", lambda p: samplers.toroidal_shift(KEY, p),
     _points().at[3, 1].set(NAN), "points contains NaN"),
    ("toroidal_shift points range", lambda p: samplers.toroidal_shift(KEY, p), _points() + 1.0,
     r"points must lie in \[0, 1\)\^2"),
    ("shear points shape", lambda p: samplers.shear(p, 30.0), jnp.zeros((8, 3)),
     r"points must have shape \(n, 2\)"),
    ("sampler key", lambda k: samplers.get("random")(k, 16), jnp.zeros(3, jnp.uint32),
     "key must be a single JAX PRNG key"),
    ("orientation_histogram values NaN", directions.orientation_histogram,
     _grid().at[5, 5].set(NAN), "values contains NaN"),
    ("orientation_histogram values shape", directions.orientation_histogram, _grid()[0],
     r"values must be a 2D \(h, w\) grid"),
    ("estimate values traced", directions.estimate, _grid(), "values is traced"),
    ("estimate_from_histogram hist NaN", directions.estimate_from_histogram,
     jnp.ones(180).at[7].set(NAN), "hist must hold finite, non-negative"),
    ("fit_reverse_kl hist NaN", lambda h: vmf.fit_reverse_kl(h, 0.9, 10.0).mu,
     _hist().at[3].set(NAN), "hist must hold finite, non-negative"),
    ("fit_reverse_kl hist zero", lambda h: vmf.fit_reverse_kl(h, 0.9, 10.0).mu,
     jnp.zeros(90), "hist must have positive total weight"),
    ("fit_reverse_kl hist shape", lambda h: vmf.fit_reverse_kl(h, 0.9, 10.0).mu, _hist()[None],
     r"hist must have shape \(K,\) for one fit"),
    ("fit_mle hist negative", lambda h: vmf.fit_mle(h).mu, _hist().at[0].set(-1.0),
     "hist must hold finite, non-negative"),
    ("power_spectrum points NaN", lambda p: spectrum.power_spectrum(p, FREQS),
     _points().at[0, 0].set(NAN), "points contain"),
    ("power_spectrum points shape", lambda p: spectrum.power_spectrum(p, FREQS),
     _points()[:, :1], r"points must have shape \(n, 2\)"),
]


@pytest.mark.parametrize("fn, bad, match", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_bad_input_is_refused_under_jit_naming_the_parameter(fn, bad, match):
    with pytest.raises(ERRORS, match=match):
        jax.block_until_ready(jax.jit(fn)(bad))


VMAP_CASES = [c for c in CASES if "shape" not in c[0] and c[0] != "sampler key"]


@pytest.mark.parametrize("fn, bad, match", [c[1:] for c in VMAP_CASES],
                         ids=[c[0] for c in VMAP_CASES])
def test_bad_input_is_refused_under_vmap_naming_the_parameter(fn, bad, match):
    good = jnp.where(jnp.isfinite(bad), bad, 0.25)
    if match.startswith("values must be >= 0") or "non-negative" in match:
        good = jnp.abs(good)
    if "positive total" in match:
        good = _hist()
    with pytest.raises(ERRORS, match=match):
        jax.block_until_ready(jax.vmap(fn)(jnp.stack([good, bad])))


def test_a_numpy_construction_refuses_a_traced_key():
    with pytest.raises(TypeError, match="key is traced"):
        jax.vmap(lambda k: samplers.get("pmj02bn")(k, 16))(jax.random.split(KEY, 2))
    # a traced n is refused as n, before any construction runs
    with pytest.raises(TypeError, match="n must be an integer"):
        jax.jit(lambda n: samplers.get("random")(KEY, n))(16)


def test_the_traced_checks_leave_good_input_bit_for_bit():
    pts = _points()
    np.testing.assert_array_equal(
        np.asarray(jax.jit(lambda p: samplers.toroidal_shift(KEY, p))(pts)),
        np.asarray(samplers.toroidal_shift(KEY, pts)))
    v = jnp.asarray([[1.0, 2.0], [3.0, 4.0]])
    u = jnp.full((5, 2), 0.3)
    got = jax.jit(lambda v, u: W.sample_batch(W.Bilinear(v), u))(v, u)
    want = W.sample_batch(W.Bilinear(v), u)
    for a, b in zip(got, want, strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    h = _hist()
    assert float(jax.jit(lambda h: vmf.fit_mle(h).kappa)(h)) == float(vmf.fit_mle(h).kappa)


def test_the_per_point_warp_methods_pass_nan_through_as_documented():
    """``sample``/``pdf``/``inverse`` are the inner loop (one point, vmapped by the caller): they
    check shapes only (warps' module docstring); :func:`warps.sample_batch` checks values."""
    assert "NaN" in W.__doc__
    out = W.Bilinear(jnp.ones((2, 2))).sample(jnp.array([NAN, 0.5]))
    assert np.isnan(np.asarray(out)[0])
    with pytest.raises(ValueError, match="u contains NaN"):
        W.sample_batch(W.Bilinear(jnp.ones((2, 2))), jnp.array([[NAN, 0.5]]))

"""The synthesis loop as an optimizer (issue 22 item 3): the objective is W Eqs. 10-15 as the
losses compute them, the lax.scan runtime takes the production loop's steps, and a gradient
through it agrees with finite differences."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import anisosample as asp
from anisosample import frequencies, losses
from anisosample import optimizer as O
from anisosample.synthesis import make_recipe

DIRS = (0.0, 90.0, 30.0)


def _x0(n, seed=1):
    return np.asarray(asp.samplers.get("jittered")(jax.random.key(seed), n), np.float64)


def test_objective_is_the_recipes_loss():
    n = 64
    with jax.enable_x64(True):
        x = jnp.asarray(_x0(n))
        # each side jitted: op by op they compiled ~100 small programs
        rate = eqx.filter_jit(lambda f, y: f(y))(O.objective(n, DIRS, make_recipe()), x)
        fset = frequencies.design(n, DIRS, "rate")
        want = jax.jit(lambda y: losses.linear_spectrum_loss(y, fset, method="direct"))(x)
        np.testing.assert_allclose(float(rate), float(want), rtol=1e-12)
        paper = eqx.filter_jit(lambda f, y: f(y))(O.objective(n, DIRS, make_recipe("paper")), x)
        fset = frequencies.design(n, DIRS, "paper")
        want = jax.jit(lambda y: losses.combined_loss(y, fset, DIRS, c=100.0, method="direct"))(x)
        np.testing.assert_allclose(float(paper), float(want), rtol=1e-12)


def test_autodiff_spectrum_matches_the_engine():
    v = np.array([[1, 0], [3, -2], [7, 5], [0, 11]])
    with jax.enable_x64(True):
        x = jnp.asarray(_x0(50))
        np.testing.assert_allclose(np.asarray(asp.spectrum.power_spectrum_autodiff(x, v)),
                                   np.asarray(asp.spectrum.power_spectrum(x, v,
                                                                          method="direct")),
                                   rtol=1e-12, atol=1e-15)


def test_scan_takes_the_production_loops_steps():
    """minimize() and synthesize() run the same step (optimizer.adam_step) on the same loss:
    with direct sums, the same points."""
    n = 64
    r = asp.synthesize(jax.random.key(1), n, DIRS, steps=10, method="direct",
                       show_progress=False)
    x = O.minimize(O.objective(n, DIRS, make_recipe()),
                   O.Adam.from_recipe(make_recipe(steps=10), n), _x0(n))
    np.testing.assert_allclose(np.asarray(x, np.float32), np.asarray(r.points), atol=1e-6)
    # a prefix is held still by both
    opt = O.Adam.from_recipe(make_recipe(steps=5, prefix="dihedral-8"), n)
    x0 = asp.prefix.place_prefix(_x0(n), asp.prefix.dihedral_points(8))
    x = O.minimize(O.objective(n, DIRS, make_recipe()), opt, x0)
    np.testing.assert_array_equal(np.asarray(x)[:8], x0[:8])


def test_gradient_through_the_scan_agrees_with_finite_differences():
    """d loss(final points) / d(learning rate) and / d(a weight tilt), reverse mode through
    eight unrolled steps, against central differences. Adam's epsilon is 0.05 here: with the
    recipe's 1e-30 the first step is lr * sign(gradient), whose derivative is zero almost
    everywhere and whose finite differences jump wherever a component changes sign."""
    n, h = 32, 1e-5
    obj = O.objective(n, DIRS, make_recipe())
    x0 = _x0(n)
    with jax.enable_x64(True):
        def of_lr(lr):
            return obj(O.minimize(obj, O.Adam(lr, 0.01, n, 8, eps=0.05), x0))

        def of_tilt(s):
            tilted = O.SynthesisObjective(
                obj.freqs, obj.weights * jnp.exp(s * obj.freqs[:, 0] / 10), obj.spectrum_weight,
                obj.c, obj.sw_directions, obj.sw_targets, n)
            return obj(O.minimize(tilted, O.Adam(0.5, 0.01, n, 8, eps=0.05), x0))

        for f, at in ((of_lr, 0.5), (of_tilt, 0.0)):
            g = float(jax.grad(f)(at))
            fd = float((f(at + h) - f(at - h)) / (2 * h))
            assert g == pytest.approx(fd, rel=1e-4), (f.__name__, g, fd)


def test_scan_vmaps_over_initial_sets():
    n = 32
    obj, opt = O.objective(n, DIRS, make_recipe()), O.Adam.from_recipe(make_recipe(steps=4), n)
    x0 = np.stack([_x0(n, 1), _x0(n, 2)])
    xs = jax.vmap(lambda x: O.minimize(obj, opt, x))(jnp.asarray(x0))
    for i in range(2):
        np.testing.assert_allclose(np.asarray(xs[i]), np.asarray(O.minimize(obj, opt, x0[i])),
                                   atol=1e-12)


def test_bad_input():
    with pytest.raises(ValueError, match="boundary"):
        O.Adam(0.5, 0.01, 64, 10, boundary="reflect")
    with pytest.raises(ValueError, match="steps"):
        O.Adam(0.5, 0.01, 64, 0)
    with pytest.raises(ValueError, match="x0"):
        O.minimize(O.objective(16, DIRS, make_recipe()), O.Adam(0.5, 0.01, 16, 2),
                   np.full((16, 2), 1.5))
    with pytest.raises(ValueError, match="weights"):
        O.objective(16, DIRS, make_recipe(), weights=np.ones(3))
    with pytest.raises(TypeError, match="recipe"):
        O.objective(16, DIRS, "rate")

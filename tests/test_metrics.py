"""anisosample.metrics against closed forms and brute force."""

import itertools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from anisosample import directions, metrics


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

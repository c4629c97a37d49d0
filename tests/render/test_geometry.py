"""Parallelogram primitives (rectangles, cube faces) against the same surfaces as triangle pairs."""

import itertools

import jax
import jax.numpy as jnp
import numpy as np

import anisosample.render as R
from anisosample.render.geometry import intersect, occluded


def _affine(rng):
    m = np.eye(4)
    m[:3, :3] = rng.normal(size=(3, 3)) * 0.4 + np.eye(3) * 0.6  # sheared, rotated, scaled
    m[:3, 3] = rng.normal(size=3) * 0.2
    return m


def _scenes():
    """The same rectangle and cube as parallelograms (SceneBuilder) and as explicit triangles."""
    rng = np.random.default_rng(3)
    rect, cube = _affine(rng), _affine(rng)
    cube[:3, 3] += (0.0, 0.0, -2.0)
    light = np.diag([0.3, 0.3, -1.0, 1.0])
    light[2, 3] = 3.0

    def build(as_triangles):
        b = R.SceneBuilder()
        m_rect, m_cube = b.diffuse(0.5), b.diffuse(0.25)
        if as_triangles:
            h = lambda m, p: (m @ np.append(p, 1.0))[:3]  # noqa: E731
            quad = [h(rect, (x, y, 0.0)) for x, y in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
            b.triangles(np.array(quad), np.array([(0, 1, 2), (0, 2, 3)]), m_rect)
            corners = np.array([h(cube, c) for c in itertools.product((-1, 1), repeat=3)])
            faces = []  # every face as two triangles; orientation does not matter to the test
            for axis in range(3):
                for side in (-1, 1):
                    idx = [i for i, c in enumerate(itertools.product((-1, 1), repeat=3))
                           if c[axis] == side]
                    a, b_, c, d = idx  # (s, t) = (-1,-1), (-1,1), (1,-1), (1,1)
                    faces += [(a, b_, d), (a, d, c)]
            b.triangles(corners, np.array(faces), m_cube)
        else:
            b.rectangle(rect, m_rect)
            b.cube(cube, m_cube)
        b.rectangle(light, b.diffuse(0.0), radiance=5.0)
        b.camera(np.eye(4), width=4, height=4, fov=40)
        return b.build()

    return build(False), build(True)


def test_parallelograms_hit_what_their_two_triangles_hit():
    para, tris = _scenes()
    assert para.tri_soa.shape[1] == 1 + 6 + 1 and tris.tri_soa.shape[1] == 2 + 12 + 1
    key = jax.random.key(0)
    k1, k2 = jax.random.split(key)
    o = jax.random.normal(k1, (4096, 3)) * 0.3 + jnp.array([[0.0, 0.0, 2.5]])
    target = jax.random.normal(k2, (4096, 3)) * 0.8 + jnp.array([[0.0, 0.0, -1.0]])
    d = target - o
    d = d / jnp.linalg.norm(d, axis=-1, keepdims=True)
    # jitted: op by op, each vmap compiled dozens of small programs
    ha = jax.jit(jax.vmap(lambda o, d: intersect(para, o, d)))(o, d)
    hb = jax.jit(jax.vmap(lambda o, d: intersect(tris, o, d)))(o, d)
    valid = np.asarray(ha.valid)
    # Rays through the shared diagonal or an edge may go either way: compare the rest.
    same = valid == np.asarray(hb.valid)
    assert same.mean() > 0.999 and 0.2 < valid.mean() < 0.95
    both = valid & np.asarray(hb.valid)
    np.testing.assert_allclose(np.asarray(ha.t)[both], np.asarray(hb.t)[both], rtol=1e-5)
    np.testing.assert_array_equal(np.asarray(ha.material)[both], np.asarray(hb.material)[both])
    cos_a = np.abs(np.sum(np.asarray(ha.n) * np.asarray(d), -1))[both]
    cos_b = np.abs(np.sum(np.asarray(hb.n) * np.asarray(d), -1))[both]
    np.testing.assert_allclose(cos_a, cos_b, atol=1e-5)
    block_a = jax.jit(jax.vmap(lambda o, p: occluded(para, o, p)))(o, target)
    block_b = jax.jit(jax.vmap(lambda o, p: occluded(tris, o, p)))(o, target)
    assert np.mean(np.asarray(block_a) == np.asarray(block_b)) > 0.999

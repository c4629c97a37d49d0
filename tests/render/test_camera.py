"""anisosample.render.camera.primary_hits against the geometry of a floor seen from above: every
hit lies on the floor (or on an occluder placed between), along the pixel's own ray, with the
normal facing the camera; pixels that see an emitter are not valid."""

import jax.numpy as jnp
import numpy as np

import anisosample.render as R
from anisosample.render.camera import generate_ray, primary_hits
from anisosample.render.xml import look_at

DOWN = look_at(np.array([0, 0, 1.0]), np.zeros(3), np.array([0, 1.0, 0]))  # from z = 1, down


def test_primary_hits_of_a_floor_seen_from_above():
    b = R.SceneBuilder()
    b.rectangle(np.diag([4.0, 4.0, 1.0, 1.0]), b.diffuse(0.5))  # the floor z = 0, normal +z
    occluder = np.diag([0.01, 0.01, 1.0, 1.0])
    occluder[2, 3] = 0.4  # a small square at z = 0.4 under the camera's central pixel
    b.rectangle(occluder, b.diffuse(0.2), flip_normals=True)
    light = np.diag([0.1, 0.1, -1.0, 1.0])
    light[:3, 3] = (0.0, 0.0, 2.0)  # behind the camera: never seen
    b.rectangle(light, b.diffuse(0.0), radiance=1.0)
    b.camera(DOWN, width=9, height=9, fov=10)
    scene = b.build()
    hits = primary_hits(scene)
    w, h = scene.width, scene.height
    assert hits.p.shape == (w * h, 3) and hits.material.shape == (w * h,)
    p, n, wi = (np.asarray(a, np.float64) for a in (hits.p, hits.n, hits.wi))
    cam = np.array([0.0, 0.0, 1.0])
    centre = (h // 2) * w + w // 2
    on_occluder = np.abs(p[:, 2] - 0.4) < 1e-5
    assert on_occluder[centre] and on_occluder.sum() < w * h
    np.testing.assert_allclose(p[~on_occluder, 2], 0.0, atol=1e-6)
    np.testing.assert_allclose(n, np.tile([0.0, 0.0, 1.0], (w * h, 1)), atol=1e-6)
    np.testing.assert_allclose(wi, (cam - p) / np.linalg.norm(cam - p, axis=1, keepdims=True),
                               atol=1e-5)
    assert np.all(np.asarray(hits.valid))
    mats = np.asarray(hits.material)
    assert len(set(mats[on_occluder])) == 1 and len(set(mats[~on_occluder])) == 1
    assert mats[centre] != mats[0]
    # row-major, row 0 at the top: pixel (col, row) is the ray through film ((col+.5)/w, ...)
    for q in (0, 7, 40, w * h - 1):
        film = jnp.asarray([(q % w + 0.5) / w, (q // w + 0.5) / h], jnp.float32)
        _, d = generate_ray(scene.camera, film, jnp.full(2, 0.5, jnp.float32))
        np.testing.assert_allclose(-wi[q], np.asarray(d), atol=1e-6)
    # point symmetry of the view straight down: pixel q and its mirror hit mirrored points
    mirror = w * h - 1 - np.arange(w * h)
    np.testing.assert_allclose(p[:, :2], -p[mirror, :2], atol=1e-6)


def test_pixels_that_see_an_emitter_are_not_valid():
    b = R.SceneBuilder()
    b.rectangle(np.diag([4.0, 4.0, 1.0, 1.0]), b.diffuse(0.5), radiance=1.0)  # an emitting floor
    b.camera(DOWN, width=4, height=4, fov=10)
    assert not np.any(np.asarray(primary_hits(b.build()).valid))

"""Textured emitters: :func:`anisosample.render.lights.texture_lookup` against a NumPy bilinear
lookup with wrap-around (Mitsuba's ``bitmap`` defaults), for two textures of different sizes
stacked into one padded array."""

import jax
import jax.numpy as jnp
import numpy as np

import anisosample.render as R
from anisosample.render.lights import texture_lookup


def _bilinear_wrap(img, u, v):
    """Mitsuba's bilinear ``bitmap`` lookup, texel centres at half-integers, wrapping."""
    h, w, _ = img.shape
    x = (u - np.floor(u)) * w - 0.5
    y = (v - np.floor(v)) * h - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    x0, y0 = x0.astype(int) % w, y0.astype(int) % h
    x1, y1 = (x0 + 1) % w, (y0 + 1) % h
    return ((1 - fx) * (1 - fy) * img[y0, x0] + fx * (1 - fy) * img[y0, x1]
            + (1 - fx) * fy * img[y1, x0] + fx * fy * img[y1, x1])


def test_lookup_matches_bilinear_wrap_on_two_padded_textures():
    rng = np.random.default_rng(0)
    imgs = [rng.random((5, 7, 3)).astype(np.float32), rng.random((3, 11, 3)).astype(np.float32)]
    b = R.SceneBuilder()
    m = b.diffuse(0.5)
    tex = [b.texture(i) for i in imgs]
    b.rectangle(np.eye(4), m)
    b.point_light((0, 0, 3), 1.0)
    b.camera(np.eye(4), width=4, height=4)
    scene = b.build(bvh=False)
    # uv across several periods, on texel centres, on edges, and at 0 and 1
    uv = np.concatenate([rng.uniform(-2.5, 3.5, (4000, 2)),
                         [[0, 0], [1, 1], [0.999999, 0.5], [-1e-7, 0.3]]]).astype(np.float32)
    for k, img in zip(tex, imgs, strict=True):
        got = jax.vmap(lambda p, k=k: texture_lookup(scene.textures, jnp.int32(k), p))(uv)
        want = _bilinear_wrap(img.astype(np.float64), uv[:, 0].astype(np.float64),
                              uv[:, 1].astype(np.float64))
        np.testing.assert_allclose(np.asarray(got), want, rtol=0, atol=2e-5)

"""Cameras: Mitsuba 3's ``perspective`` and ``thinlens`` sensors.

Film position ``(s, t)`` in ``[0, 1]^2`` (``s`` right, ``t`` down). In camera space (+z
forward, +y up, +x left, Mitsuba's ``lookat``) the point on the plane ``z = 1`` is
``((1 - 2s) tan(fov_x / 2), (1 - 2t) tan(fov_x / 2) / aspect, 1)``. The thin lens samples its
aperture with the concentric disk map (Shirley & Chiu 1997), as Mitsuba does, or a square
aperture (W Sec. 6.2, depth-of-field scene) and focuses at ``z = focus_distance``.

:func:`primary_hits`: what the rays through all pixel centres (lens centre) hit first, for work
that shades every pixel's primary hit outside the renderer (fitting warps per pixel, H Sec. 4).
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from ..warps import ConcentricDisk
from ._vec import matvec, norm
from .geometry import intersect
from .scene import THINLENS, Camera, Scene

__all__ = ["PrimaryHit", "crop", "generate_ray", "primary_hits"]


def generate_ray(
    camera: Camera,
    film: Float[Array, "2"],
    lens: Float[Array, "2"],
    *,
    square_aperture: bool = False,
):
    """World-space ray ``(origin, unit direction)`` through film point ``film`` and lens ``lens``.

    ``lens`` is ignored by the pinhole camera; for the thin lens it is the 2D aperture sample.
    ``film`` is a position on the image, which is the camera's ``window`` of the whole film
    (:func:`crop`).
    """
    tan = camera.tan_half_fov_x
    win = camera.window  # the image's position on the whole film (the full film: exact)
    film = win[:2] + film * win[2:]
    near = jnp.stack(
        [(1 - 2 * film[0]) * tan, (1 - 2 * film[1]) * tan / camera.aspect, jnp.float32(1.0)]
    )
    if camera.projection == THINLENS:
        if square_aperture:
            ax, ay = 2 * lens[0] - 1, 2 * lens[1] - 1
        else:
            ax, ay = ConcentricDisk().sample(lens)  # Shirley & Chiu 1997
        ap = jnp.stack([ax, ay, jnp.float32(0.0)]) * camera.aperture_radius
        d_local = near * camera.focus_distance - ap
    else:
        ap = jnp.zeros(3, jnp.float32)
        d_local = near
    m = camera.to_world
    o = matvec(m, ap) + m[:3, 3]
    d = matvec(m, d_local)
    return o, d / norm(d)


def crop(scene: Scene, offset, size) -> Scene:
    """``scene`` rendering only the ``size = (width, height)`` pixels from pixel ``offset = (x,
    y)`` of its image (Mitsuba's ``crop_offset_x/y``, ``crop_width/height``): the same rays as
    those pixels of the whole image, so a small window of a large image is rendered at the
    large image's pixel scale (W renders 1280^2: ``crop(load_xml(p, width=1280, height=1280),
    (x, y), (128, 128))``). A crop of a crop is a window of the same film. The crop's pixels,
    keys and blocks count from its own corner. The film's filter keeps its stddev in pixels."""
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be an anisosample.render.Scene, got {type(scene).__name__}")
    pairs = [_integer_pair(offset), _integer_pair(size)]
    if None in pairs:
        raise TypeError(f"offset and size must be pairs of integers, got {offset!r} and "
                        f"{size!r}")
    (x, y), (w, h) = pairs
    cam = scene.camera
    if x < 0 or y < 0 or w < 1 or h < 1 or x + w > cam.width or y + h > cam.height:
        raise ValueError(f"the crop (offset {x}, {y}, size {w} x {h}) must lie inside the "
                         f"{cam.width} x {cam.height} image and hold at least one pixel")
    s0, t0, ds, dt = np.asarray(cam.window, np.float64)
    window = jnp.asarray([s0 + ds * x / cam.width, t0 + dt * y / cam.height, ds * w / cam.width,
                          dt * h / cam.height], jnp.float32)
    camera = dataclasses.replace(cam, width=w, height=h, window=window)
    return dataclasses.replace(scene, camera=camera, culling=None)


def _integer_pair(v) -> tuple[int, int] | None:
    """``v`` as two Python ints (integral numbers), or None if it is not such a pair."""
    if isinstance(v, str) or not isinstance(v, (tuple, list, np.ndarray)) or len(v) != 2:
        return None
    try:
        return tuple(int(a) for a in v) if all(float(a) == int(a) for a in v) else None
    except (TypeError, ValueError):
        return None


class PrimaryHit(eqx.Module):
    """The first hits of the rays through pixel centres (:func:`primary_hits`), one row per
    pixel: position ``p``, geometric normal ``n`` flipped to the side of ``wi`` (the unit
    direction back to the camera), ``material`` index, and ``valid``: a surface that emits no
    light was hit (the rest hold whatever :func:`~anisosample.render.geometry.intersect`
    returns for a miss or an emitter)."""

    p: Float[Array, "*m 3"]  # made per pixel (vmap), returned for all m pixels
    n: Float[Array, "*m 3"]
    wi: Float[Array, "*m 3"]
    material: Int[Array, " *m"]
    valid: Bool[Array, " *m"]


def primary_hits(scene: Scene) -> PrimaryHit:
    """The primary hits of all ``scene.height * scene.width`` pixel centres, row-major (row 0 at
    the image top), through the lens centre (film ``((col + .5) / w, (row + .5) / h)``, lens
    ``(0.5, 0.5)``)."""
    w, h = scene.width, scene.height
    cols, rows = np.meshgrid(np.arange(w), np.arange(h), indexing="xy")
    films = jnp.asarray(
        np.stack([(cols.ravel() + 0.5) / w, (rows.ravel() + 0.5) / h], -1), jnp.float32
    )
    half = jnp.full(2, 0.5, jnp.float32)

    def one(film):
        o, d = generate_ray(scene.camera, film, half)
        hit = intersect(scene, o, d)
        wi = -d
        n = jnp.where(jnp.dot(hit.n, wi) > 0, hit.n, -hit.n)
        return PrimaryHit(p=hit.p, n=n, wi=wi, material=hit.material,
                          valid=hit.valid & (hit.light < 0))

    return jax.jit(jax.vmap(one))(films)

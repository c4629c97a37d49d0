"""Cameras: Mitsuba 3's ``perspective`` and ``thinlens`` sensors.

Film position ``(s, t)`` in ``[0, 1]^2`` (``s`` right, ``t`` down). In camera space (+z
forward, +y up, +x left, Mitsuba's ``lookat``) the point on the plane ``z = 1`` is
``((1 - 2s) tan(fov_x / 2), (1 - 2t) tan(fov_x / 2) / aspect, 1)``. The thin lens samples its
aperture with the concentric disk map (Shirley & Chiu 1997), as Mitsuba does, or a square
aperture (W Sec. 6.2, depth-of-field scene) and focuses at ``z = focus_distance``.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float

from ._vec import matvec, norm
from .scene import THINLENS, Camera


def _concentric_disk(u):
    # Shirley & Chiu 1997 (used here only for the lens; the warps package owns the general maps).
    a, b = 2 * u[0] - 1, 2 * u[1] - 1
    use_a = jnp.abs(a) > jnp.abs(b)
    r = jnp.where(use_a, a, b)
    safe_a = jnp.where(a == 0, 1.0, a)
    safe_b = jnp.where(b == 0, 1.0, b)
    phi = jnp.where(use_a, (jnp.pi / 4) * (b / safe_a), jnp.pi / 2 - (jnp.pi / 4) * (a / safe_b))
    phi = jnp.where((a == 0) & (b == 0), 0.0, phi)
    return r * jnp.cos(phi), r * jnp.sin(phi)


def generate_ray(
    camera: Camera,
    film: Float[Array, "2"],
    lens: Float[Array, "2"],
    *,
    square_aperture: bool = False,
):
    """World-space ray ``(origin, unit direction)`` through film point ``film`` and lens ``lens``.

    ``lens`` is ignored by the pinhole camera; for the thin lens it is the 2D aperture sample.
    """
    tan = camera.tan_half_fov_x
    near = jnp.stack(
        [(1 - 2 * film[0]) * tan, (1 - 2 * film[1]) * tan / camera.aspect, jnp.float32(1.0)]
    )
    if camera.kind == THINLENS:
        if square_aperture:
            ax, ay = 2 * lens[0] - 1, 2 * lens[1] - 1
        else:
            ax, ay = _concentric_disk(lens)
        ap = jnp.stack([ax, ay, jnp.float32(0.0)]) * camera.aperture_radius
        d_local = near * camera.focus_distance - ap
    else:
        ap = jnp.zeros(3, jnp.float32)
        d_local = near
    m = camera.to_world
    o = matvec(m, ap) + m[:3, 3]
    d = matvec(m, d_local)
    return o, d / norm(d)

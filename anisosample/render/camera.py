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

from ..warps import ConcentricDisk
from ._vec import matvec, norm
from .scene import THINLENS, Camera


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

"""Small float32-careful vector helpers shared by the spherical and surface warps."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np


def norm(v):
    return jnp.sqrt(jnp.sum(v * v, axis=-1))


def safe_normalize(v):
    """``v / |v|``, and the zero vector for ``v = 0`` (no NaN)."""
    n = norm(v)
    return v / jnp.where(n > 0, n, 1.0)[..., None]


def angle_between(a, b):
    """Angle between unit vectors without ``acos`` (accurate near 0 and pi; pbrt-v4 style)."""
    d = jnp.sum(a * b, axis=-1)
    small = 2.0 * jnp.arcsin(jnp.clip(norm(b - a) / 2.0, 0.0, 1.0))
    large = jnp.pi - 2.0 * jnp.arcsin(jnp.clip(norm(a + b) / 2.0, 0.0, 1.0))
    return jnp.where(d < 0, large, small)


def solid_angle_triangle(a, b, c):
    """Solid angle of the spherical triangle of unit vectors (Van Oosterom & Strackee 1983)."""
    num = jnp.abs(jnp.dot(a, jnp.cross(b, c)))
    den = 1.0 + jnp.dot(a, b) + jnp.dot(b, c) + jnp.dot(c, a)
    om = 2.0 * jnp.arctan2(num, den)
    return jnp.where(om < 0, om + 2.0 * jnp.pi, om)


def check_vectors(name: str, value, shape: tuple[int, ...]) -> jax.Array:
    """Shape (and, for concrete arrays, finiteness) check of geometry parameters."""
    arr_shape = getattr(value, "shape", None)
    if arr_shape is None:
        value = np.asarray(value, dtype=np.float32)
        arr_shape = value.shape
    if tuple(arr_shape) != shape:
        raise ValueError(f"{name} must have shape {shape}, got shape {tuple(arr_shape)}")
    if not isinstance(value, jax.core.Tracer):
        v = np.asarray(value, dtype=np.float64)
        if not np.all(np.isfinite(v)):
            raise ValueError(f"{name} must be finite, got {v.tolist()}")
    return jnp.asarray(value, dtype=jnp.float32)


def is_concrete(*arrays) -> bool:
    """True when no argument is being traced (pass derived values too: inside ``jit`` values
    computed from constants are tracers, and value checks must then be skipped)."""
    return not any(isinstance(a, jax.core.Tracer) for a in arrays)


def orthonormal_frame(n):
    """Rows ``(s, t, n)`` of a right-handed orthonormal basis around unit ``n`` (Duff et al.
    2017, *Building an Orthonormal Basis, Revisited*): ``frame @ w`` is ``w`` in the frame."""
    sign = jnp.where(n[2] >= 0, 1.0, -1.0)
    a = -1.0 / (sign + n[2])
    b = n[0] * n[1] * a
    s = jnp.stack([1.0 + sign * n[0] * n[0] * a, sign * b, -sign * n[0]])
    t = jnp.stack([b, sign + n[1] * n[1] * a, -n[1]])
    return jnp.stack([s, t, n])

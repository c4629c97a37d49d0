"""Parameterless maps of the square onto the disk, hemisphere and sphere (W Fig. 12; H Sec. 3).

All are Warps with no fields. pdfs are per unit disk area (``ConcentricDisk``) or per steradian;
``references/warps.md`` Sec. 7 has the formulas and check values.

* ``ConcentricDisk``: Shirley & Chiu 1997, equal-area, low distortion.
* ``UniformHemisphere``: equal-area via the concentric disk (Clarberg-style lift
  ``(x, y) sqrt(2 - r^2), 1 - r^2``), pdf ``1/(2 pi)``.
* ``AngularHemisphere``: the cylindrical ("angular") map ``z = u0, phi = 2 pi u1``, pdf
  ``1/(2 pi)``; curves great circles, unlike the octahedral maps.
* ``CosineHemisphere``: Malley's method on the concentric disk, pdf ``cos(theta)/pi``.
* ``HemiOctahedral`` / ``Octahedral``: Engelhardt & Dachsbacher 2008 / Cigolle et al. 2014,
  pdf ``|p|^3 / 2`` and ``|p|^3 / 4`` (``p`` the L1-normalised point); great circles map to
  straight segments within each octant face (W Sec. 6.3).
"""

from __future__ import annotations

import jax.numpy as jnp

from ._base import AbstractWarp, check_point
from ._geometry import norm, safe_normalize

_PI = jnp.pi
_EPS1 = 1.0 - 2.0**-24


def concentric_disk_map(u0, u1, xp=jnp):
    """Shirley & Chiu 1997's concentric square-to-disk map, ``(u0, u1)`` in ``[0, 1]^2`` to
    ``(x, y)`` in the unit disk (Mitsuba 3 ``square_to_uniform_disk_concentric``), elementwise.

    The one implementation: :class:`ConcentricDisk` and the hemisphere maps use it with
    ``xp = jax.numpy``; render/plastic.py's float64 table quadrature with ``xp = numpy``.
    """
    a, b = 2.0 * u0 - 1.0, 2.0 * u1 - 1.0
    use_a = xp.abs(a) > xp.abs(b)
    r = xp.where(use_a, a, b)
    safe_a = xp.where(a == 0, 1.0, a)
    safe_b = xp.where(b == 0, 1.0, b)
    phi = xp.where(use_a, (_PI / 4) * (b / safe_a), _PI / 2 - (_PI / 4) * (a / safe_b))
    origin = (a == 0) & (b == 0)
    return xp.where(origin, 0.0, r * xp.cos(phi)), xp.where(origin, 0.0, r * xp.sin(phi))


def _concentric(u):
    return jnp.stack(concentric_disk_map(u[0], u[1]))


def _concentric_inverse(p):
    r = norm(p)
    phi = jnp.arctan2(p[1], p[0])
    phi = jnp.where(phi < -_PI / 4, phi + 2 * _PI, phi)  # [-pi/4, 7pi/4)
    k = 4.0 / _PI
    a = jnp.select(
        [phi < _PI / 4, phi < 3 * _PI / 4, phi < 5 * _PI / 4],
        [r, -k * (phi - _PI / 2) * r, -r],
        k * (phi - 3 * _PI / 2) * r,
    )
    b = jnp.select(
        [phi < _PI / 4, phi < 3 * _PI / 4, phi < 5 * _PI / 4],
        [k * phi * r, r, -k * (phi - _PI) * r],
        -r,
    )
    return jnp.clip(jnp.stack([(a + 1) / 2, (b + 1) / 2]), 0.0, 1.0)


class ConcentricDisk(AbstractWarp):
    """Square to unit disk (Shirley & Chiu 1997); pdf ``1/pi`` per unit disk area."""

    measure = "area disk"

    def sample(self, u):
        return _concentric(check_point("u", u, 2))

    def pdf(self, x):
        x = check_point("x", x, 2)
        return jnp.where(jnp.sum(x * x) <= 1.0 + 1e-6, 1.0 / _PI, 0.0)

    def inverse(self, x):
        return _concentric_inverse(check_point("x", x, 2))


class UniformHemisphere(AbstractWarp):
    """Equal-area square to hemisphere ``z >= 0`` through the concentric disk; pdf ``1/(2pi)``."""

    out_dim = 3
    measure = "solid angle"

    def sample(self, u):
        d = _concentric(check_point("u", u, 2))
        r2 = jnp.sum(d * d)
        s = jnp.sqrt(jnp.maximum(2.0 - r2, 0.0))
        return jnp.stack([d[0] * s, d[1] * s, 1.0 - r2])

    def pdf(self, w):
        w = safe_normalize(check_point("w", w, 3))
        return jnp.where(w[2] >= -1e-6, 1.0 / (2 * _PI), 0.0)

    def inverse(self, w):
        w = safe_normalize(check_point("w", w, 3))
        z = jnp.clip(w[2], 0.0, 1.0)
        d = w[:2] / jnp.sqrt(1.0 + z)  # r^2 = 1 - z, |(x, y)| = r sqrt(2 - r^2)
        return _concentric_inverse(d)


class AngularHemisphere(AbstractWarp):
    """Cylindrical ("angular") map: ``z = u0``, ``phi = 2 pi u1``; pdf ``1/(2 pi)``."""

    out_dim = 3
    measure = "solid angle"

    def sample(self, u):
        u = check_point("u", u, 2)
        z = u[0]
        r = jnp.sqrt(jnp.maximum(1.0 - z * z, 0.0))
        phi = 2 * _PI * u[1]
        return jnp.stack([r * jnp.cos(phi), r * jnp.sin(phi), z])

    def pdf(self, w):
        w = safe_normalize(check_point("w", w, 3))
        return jnp.where(w[2] >= -1e-6, 1.0 / (2 * _PI), 0.0)

    def inverse(self, w):
        w = safe_normalize(check_point("w", w, 3))
        phi = jnp.arctan2(w[1], w[0])
        phi = jnp.where(phi < 0, phi + 2 * _PI, phi)
        return jnp.clip(jnp.stack([w[2], phi / (2 * _PI)]), 0.0, _EPS1)


class CosineHemisphere(AbstractWarp):
    """Malley's method on the concentric disk; pdf ``cos(theta) / pi`` per steradian."""

    out_dim = 3
    measure = "solid angle"

    def sample(self, u):
        d = _concentric(check_point("u", u, 2))
        z = jnp.sqrt(jnp.maximum(1.0 - jnp.sum(d * d), 0.0))
        return jnp.stack([d[0], d[1], z])

    def pdf(self, w):
        w = safe_normalize(check_point("w", w, 3))
        return jnp.where(w[2] >= 0, w[2] / _PI, 0.0)

    def inverse(self, w):
        w = safe_normalize(check_point("w", w, 3))
        return _concentric_inverse(w[:2])


def _sgn(x):
    return jnp.where(x < 0, -1.0, 1.0)


class HemiOctahedral(AbstractWarp):
    """Hemi-octahedral map (Cigolle et al. 2014): square -> diamond -> ``z >= 0``.

    pdf ``|p|^3 / 2`` with ``p = (x, y, 1 - |x| - |y|)`` (central projection of the octahedron
    face, ``references/warps.md`` Sec. 7).
    """

    out_dim = 3
    measure = "solid angle"

    def sample(self, u):
        u = check_point("u", u, 2)
        a, b = 2.0 * u[0] - 1.0, 2.0 * u[1] - 1.0
        x, y = (a + b) / 2, (a - b) / 2
        return safe_normalize(jnp.stack([x, y, 1.0 - jnp.abs(x) - jnp.abs(y)]))

    def pdf(self, w):
        w = safe_normalize(check_point("w", w, 3))
        p = w / jnp.sum(jnp.abs(w))
        return jnp.where(w[2] >= -1e-6, norm(p) ** 3 / 2.0, 0.0)

    def inverse(self, w):
        w = safe_normalize(check_point("w", w, 3))
        p = w / jnp.sum(jnp.abs(w))
        a, b = p[0] + p[1], p[0] - p[1]
        return jnp.clip(jnp.stack([(a + 1) / 2, (b + 1) / 2]), 0.0, 1.0)


class Octahedral(AbstractWarp):
    """Octahedral map of the whole sphere (Engelhardt & Dachsbacher 2008); pdf ``|p|^3 / 4``."""

    out_dim = 3
    measure = "solid angle"

    def sample(self, u):
        u = check_point("u", u, 2)
        a, b = 2.0 * u[0] - 1.0, 2.0 * u[1] - 1.0
        z = 1.0 - jnp.abs(a) - jnp.abs(b)
        fa = jnp.where(z < 0, (1.0 - jnp.abs(b)) * _sgn(a), a)
        fb = jnp.where(z < 0, (1.0 - jnp.abs(a)) * _sgn(b), b)
        return safe_normalize(jnp.stack([fa, fb, z]))

    def pdf(self, w):
        w = safe_normalize(check_point("w", w, 3))
        p = w / jnp.sum(jnp.abs(w))
        return norm(p) ** 3 / 4.0

    def inverse(self, w):
        w = safe_normalize(check_point("w", w, 3))
        p = w / jnp.sum(jnp.abs(w))
        a = jnp.where(p[2] < 0, (1.0 - jnp.abs(p[1])) * _sgn(p[0]), p[0])
        b = jnp.where(p[2] < 0, (1.0 - jnp.abs(p[0])) * _sgn(p[1]), p[1])
        return jnp.clip(jnp.stack([(a + 1) / 2, (b + 1) / 2]), 0.0, 1.0)

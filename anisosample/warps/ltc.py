"""A linearly transformed cosine (Heitz et al. 2016) restricted to a convex polygon.

E. Heitz, J. Dupuy, S. Hill, D. Neubelt, *Real-Time Polygonal-Light Shading with Linearly
Transformed Cosines* (SIGGRAPH 2016): a distribution ``D`` on the sphere is the clamped cosine
``D_o(w_o) = max(0, w_o.z) / pi`` pushed through ``w = M w_o / |M w_o|``; its density is
``D(w) = D_o(w_o) |det M^-1| / |M^-1 w|^3`` with ``w_o = M^-1 w / |M^-1 w|`` (their Eq. 1-2).
Restricted to a polygon ``P`` it is the clamped cosine restricted to the polygon ``M^-1 P``
(a linear map keeps a planar convex polygon planar and convex), which
:class:`~anisosample.warps.ProjectedSphericalPolygon` samples exactly (Peters 2021 pairs the two
this way, Sec. 5): sample ``w_o`` there, map it by ``M``. The density per steradian is
``(w_o.z / Phi_o) |det M^-1| / |M^-1 w|^3``, ``Phi_o`` the projected solid angle of ``M^-1 P``
clipped to ``w_o.z >= 0``; the inverse is the polygon warp's inverse of ``w_o``.

``frame`` (rows ``s, t, n``) takes world directions into the LTC's local frame, where ``M`` is
given; an invalid polygon warp (nothing of ``M^-1 P`` above its horizon) leaves this warp
invalid too (``pdf`` 0, the renderer falls back to area sampling).
"""

from __future__ import annotations

import jax.numpy as jnp

from .._types import Array, Float
from ._base import AbstractWarp, check_point
from ._geometry import check_vectors
from .polygon import ProjectedSphericalPolygon


def _norm3(v):
    return jnp.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])


class LTCPolygon(AbstractWarp):
    """Sample ``D`` (the LTC of ``m_inv``'s inverse in ``frame``) restricted to a polygon.

    ``vertices`` (k, 3) of a convex planar polygon, ``origin`` (3,), ``frame`` (3, 3) rows of an
    orthonormal basis (world -> local), ``m_inv`` (3, 3) the inverse LTC matrix (local).
    Outputs are unit world directions from ``origin``, pdfs per steradian.
    """

    out_dim = 3
    measure = "solid angle"

    frame: Float[Array, "3 3"]
    m_inv: Float[Array, "3 3"]
    m: Float[Array, "3 3"]
    det_inv: Float[Array, ""]
    polygon: ProjectedSphericalPolygon
    valid: Array

    def __init__(self, vertices, origin, frame, m_inv):
        origin = check_vectors("origin", origin, (3,))
        frame = check_vectors("frame", frame, (3, 3))
        m_inv = check_vectors("m_inv", m_inv, (3, 3))
        verts = jnp.asarray(vertices, jnp.float32)
        local = (verts - origin[None, :]) @ frame.T @ m_inv.T  # M^-1 frame (v - origin)
        self.frame, self.m_inv = frame, m_inv
        self.m = jnp.linalg.inv(m_inv)
        self.det_inv = jnp.abs(jnp.linalg.det(m_inv))
        self.polygon = ProjectedSphericalPolygon(local, jnp.zeros(3, jnp.float32),
                                                 jnp.asarray([0.0, 0.0, 1.0], jnp.float32))
        self.valid = self.polygon.valid

    def _to_world(self, wo):
        w = self.m @ wo
        return (w / jnp.maximum(_norm3(w), 1e-30)) @ self.frame

    def _local(self, w):
        q = self.m_inv @ (self.frame @ w)
        n = jnp.maximum(_norm3(q), 1e-30)
        return q / n, n

    def sample(self, u):
        u = check_point("u", u, 2)
        return self._to_world(self.polygon.sample(u))

    def sample_and_pdf(self, u):
        u = check_point("u", u, 2)
        wo, p = self.polygon.sample_and_pdf(u)
        w = self._to_world(wo)
        _, n = self._local(w)
        return w, jnp.where(self.valid, p * self.det_inv / (n * n * n), 0.0)

    def pdf(self, w):
        w = check_point("w", w, 3)
        wo, n = self._local(w / jnp.maximum(_norm3(w), 1e-30))
        return self.polygon.pdf(wo) * self.det_inv / (n * n * n)

    def inverse(self, w):
        w = check_point("w", w, 3)
        wo, _ = self._local(w / jnp.maximum(_norm3(w), 1e-30))
        return self.polygon.inverse(wo)

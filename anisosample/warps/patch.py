"""Area sampling of planar shapes and bilinear patches (H Sec. 4.2); pdfs per unit area.

* ``TriangleArea``: uniform area sampling of a triangle by ``b0 = 1 - sqrt(u0)``,
  ``(b1, b2) = sqrt(u0) (1 - u1, u1)`` (Shirley's square-to-triangle map); inverse from the
  barycentrics.
* ``Parallelogram``: ``corner + u0 edge_u + u1 edge_v``.
* ``BilinearPatch``: uniform *parametric* sampling of ``p(u, v)``; area pdf
  ``1 / |dp/du x dp/dv|`` (H Eq. 11). Inverse by Gauss-Newton on ``p(u, v) = x`` (a fixed number
  of steps from the patch centre; exact for planar patches in a few steps).
* :func:`patch_area_warp`: H Sec. 4.2's approximate equal-area sampling: a ``Bilinear`` PSS warp
  whose corner values are the area elements at the patch corners, composed with
  ``BilinearPatch``. Exact for planar convex quads (Arvo & Novins 2007).

Points off the surface (farther than ``1e-4`` of the shape's size from it) have pdf 0.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .._types import Array, Float
from ._base import AbstractWarp, Compose, check_point
from ._geometry import check_vectors, is_concrete, norm
from .planar import Bilinear

_ON_SURFACE_TOL = 1e-4
_INSIDE_TOL = 1e-5


def _solve2(e1, e2, d):
    """Least-squares coefficients ``(s, t)`` of ``d ~ s e1 + t e2`` (normal equations)."""
    a11, a12, a22 = jnp.dot(e1, e1), jnp.dot(e1, e2), jnp.dot(e2, e2)
    r1, r2 = jnp.dot(e1, d), jnp.dot(e2, d)
    det = a11 * a22 - a12 * a12
    det = jnp.where(det != 0, det, 1.0)
    return (a22 * r1 - a12 * r2) / det, (a11 * r2 - a12 * r1) / det


class TriangleArea(AbstractWarp):
    """Uniform area sampling of the triangle ``vertices`` (3, 3); pdf ``1/area``."""

    out_dim = 3
    measure = "area"

    vertices: Float[Array, "3 3"]
    area: Float[Array, ""]

    def __init__(self, vertices):
        v = check_vectors("vertices", vertices, (3, 3))
        area = 0.5 * norm(jnp.cross(v[1] - v[0], v[2] - v[0]))
        if is_concrete(v, area) and not float(area) > 0:
            raise ValueError("vertices must form a triangle of positive area")
        self.vertices = v
        self.area = jnp.where(area > 0, area, 1.0)

    def sample(self, u):
        u = check_point("u", u, 2)
        s = jnp.sqrt(u[0])
        v = self.vertices
        return (1 - s) * v[0] + s * (1 - u[1]) * v[1] + s * u[1] * v[2]

    def _bary(self, x):
        v = self.vertices
        b1, b2 = _solve2(v[1] - v[0], v[2] - v[0], x - v[0])
        resid = norm(x - (v[0] + b1 * (v[1] - v[0]) + b2 * (v[2] - v[0])))
        return b1, b2, resid

    def pdf(self, x):
        x = check_point("x", x, 3)
        b1, b2, resid = self._bary(x)
        size = jnp.sqrt(self.area)
        inside = (b1 >= -_INSIDE_TOL) & (b2 >= -_INSIDE_TOL) & (b1 + b2 <= 1 + _INSIDE_TOL)
        return jnp.where(inside & (resid <= _ON_SURFACE_TOL * size), 1.0 / self.area, 0.0)

    def inverse(self, x):
        x = check_point("x", x, 3)
        b1, b2, _ = self._bary(x)
        s = jnp.clip(b1 + b2, 0.0, 1.0)
        u1 = jnp.where(s > 0, b2 / jnp.where(s > 0, s, 1.0), 0.5)
        return jnp.clip(jnp.stack([s * s, u1]), 0.0, 1.0)


class Parallelogram(AbstractWarp):
    """Uniform area sampling of ``corner + s edge_u + t edge_v``; pdf ``1/|edge_u x edge_v|``."""

    out_dim = 3
    measure = "area"

    corner: Float[Array, "3"]
    edge_u: Float[Array, "3"]
    edge_v: Float[Array, "3"]
    area: Float[Array, ""]

    def __init__(self, corner, edge_u, edge_v):
        self.corner = check_vectors("corner", corner, (3,))
        self.edge_u = check_vectors("edge_u", edge_u, (3,))
        self.edge_v = check_vectors("edge_v", edge_v, (3,))
        area = norm(jnp.cross(self.edge_u, self.edge_v))
        if is_concrete(self.edge_u, self.edge_v, area) and not float(area) > 0:
            raise ValueError("edge_u and edge_v must span a parallelogram of positive area")
        self.area = jnp.where(area > 0, area, 1.0)

    def sample(self, u):
        u = check_point("u", u, 2)
        return self.corner + u[0] * self.edge_u + u[1] * self.edge_v

    def pdf(self, x):
        x = check_point("x", x, 3)
        s, t = _solve2(self.edge_u, self.edge_v, x - self.corner)
        resid = norm(x - self.sample(jnp.stack([s, t])))
        inside = (s >= -_INSIDE_TOL) & (s <= 1 + _INSIDE_TOL) & (t >= -_INSIDE_TOL)
        inside = inside & (t <= 1 + _INSIDE_TOL)
        ok = inside & (resid <= _ON_SURFACE_TOL * jnp.sqrt(self.area))
        return jnp.where(ok, 1.0 / self.area, 0.0)

    def inverse(self, x):
        x = check_point("x", x, 3)
        s, t = _solve2(self.edge_u, self.edge_v, x - self.corner)
        return jnp.clip(jnp.stack([s, t]), 0.0, 1.0)


class BilinearPatch(AbstractWarp):
    """Uniform parametric sampling of a bilinear patch; area pdf ``1/|p_u x p_v|`` (H Eq. 11).

    ``corners`` of shape ``(2, 2, 3)``: ``corners[i, j] = p_ij`` at ``(u, v) = (i, j)``.
    """

    out_dim = 3
    measure = "area"

    corners: Float[Array, "2 2 3"]
    newton_steps: int = 8

    def __init__(self, corners, *, newton_steps: int = 8):
        c = check_vectors("corners", corners, (2, 2, 3))
        e = jnp.stack(
            [
                norm(c[1, 0] - c[0, 0]),
                norm(c[0, 1] - c[0, 0]),
                norm(c[1, 1] - c[0, 1]),
                norm(c[1, 1] - c[1, 0]),
            ]
        )
        if is_concrete(c, e):
            if float(jnp.min(e)) <= 0:
                raise ValueError("corners must be four distinct points (no zero-length edge)")
        self.corners = c
        self.newton_steps = int(newton_steps)

    def point(self, uv):
        c = self.corners
        u, v = uv[0], uv[1]
        return (1 - u) * ((1 - v) * c[0, 0] + v * c[0, 1]) + u * ((1 - v) * c[1, 0] + v * c[1, 1])

    def partials(self, uv):
        """``(dp/du, dp/dv)`` at parameters ``uv``."""
        c = self.corners
        u, v = uv[0], uv[1]
        du = (1 - v) * (c[1, 0] - c[0, 0]) + v * (c[1, 1] - c[0, 1])
        dv = (1 - u) * (c[0, 1] - c[0, 0]) + u * (c[1, 1] - c[1, 0])
        return du, dv

    def area_element(self, uv):
        """``|dp/du x dp/dv|`` at parameters ``uv``."""
        du, dv = self.partials(uv)
        return norm(jnp.cross(du, dv))

    def corner_area_elements(self):
        """``(2, 2)`` area elements at the corners, ``[i, j]`` at ``(u, v) = (i, j)``."""
        c = self.corners
        e00 = norm(jnp.cross(c[1, 0] - c[0, 0], c[0, 1] - c[0, 0]))
        e10 = norm(jnp.cross(c[1, 0] - c[0, 0], c[1, 1] - c[1, 0]))
        e01 = norm(jnp.cross(c[1, 1] - c[0, 1], c[0, 1] - c[0, 0]))
        e11 = norm(jnp.cross(c[1, 1] - c[0, 1], c[1, 1] - c[1, 0]))
        return jnp.stack([jnp.stack([e00, e01]), jnp.stack([e10, e11])])

    def sample(self, u):
        return self.point(check_point("u", u, 2))

    def sample_and_pdf(self, u):
        """H Alg. 1 step: ``p(u)`` and ``1 / |p_u x p_v|`` at ``u`` itself (no inversion)."""
        u = check_point("u", u, 2)
        ae = self.area_element(u)
        return self.point(u), jnp.where(ae > 0, 1.0 / jnp.where(ae > 0, ae, 1.0), 0.0)

    def normal(self, uv):
        """Unit normal ``p_u x p_v / |p_u x p_v|`` at parameters ``uv`` (the front side)."""
        du, dv = self.partials(uv)
        n = jnp.cross(du, dv)
        return n / jnp.maximum(norm(n), 1e-30)

    def _invert(self, x):
        def step(_, uv):
            du, dv = self.partials(uv)
            r = x - self.point(uv)
            a, b = _solve2(du, dv, r)
            return jnp.clip(uv + jnp.stack([a, b]), -0.5, 1.5)

        return jax.lax.fori_loop(0, self.newton_steps, step, jnp.full((2,), 0.5, x.dtype))

    def pdf(self, x):
        x = check_point("x", x, 3)
        uv = self._invert(x)
        scale = jnp.max(norm(self.corners.reshape(4, 3) - self.corners[0, 0][None, :]))
        resid = norm(x - self.point(uv))
        inside = jnp.all((uv >= -_INSIDE_TOL) & (uv <= 1 + _INSIDE_TOL))
        ae = self.area_element(jnp.clip(uv, 0.0, 1.0))
        ok = inside & (resid <= _ON_SURFACE_TOL * scale) & (ae > 0)
        return jnp.where(ok, 1.0 / jnp.where(ae > 0, ae, 1.0), 0.0)

    def inverse(self, x):
        return jnp.clip(self._invert(check_point("x", x, 3)), 0.0, 1.0)


def patch_area_warp(corners) -> Compose:
    """H Sec. 4.2: ``compose(Bilinear(corner area elements), BilinearPatch(corners))``."""
    patch = BilinearPatch(corners)
    return Compose(Bilinear(patch.corner_area_elements()), patch)


def patch_three_warp(patch: BilinearPatch, origin, normal) -> Compose:
    """H Sec. 4.2's approximate cosine chain for a bilinear-patch light seen from ``origin``.

    ``compose(w_cos, w_geom, w_area, patch)``: ``w_area`` the bilinear approximate equal-area
    warp (corner area elements), ``w_geom`` a biquadratic fitted (H Eq. 9) to the geometric
    factor ``|cos_l| / r^2`` behind it, ``w_cos`` a biquadratic fitted to the receiver cosine
    ``max(n . w, 0)`` about ``normal`` behind both (the list after H Eq. 11). ``patch`` is the
    surface warp (a :class:`BilinearPatch`, or a subclass with its own inversion).
    """
    from .fit import fit_pointwise
    from .planar import Biquadratic

    origin = jnp.asarray(origin, jnp.float32)
    normal = jnp.asarray(normal, jnp.float32)

    def geometry(x):  # |cos_l| / r^2 = |d . n_l| / r^3
        d = x - origin
        r2 = jnp.dot(d, d)
        return jnp.abs(jnp.dot(d, patch.normal(patch.inverse(x)))) / (r2 * jnp.sqrt(r2))

    def cos_r(x):
        d = x - origin
        return jnp.maximum(jnp.dot(d, normal), 0.0) / norm(d)

    w_area = Bilinear(patch.corner_area_elements())
    w_geom = fit_pointwise(Biquadratic, geometry, [w_area, patch])
    w_cos = fit_pointwise(Biquadratic, cos_r, [w_geom, w_area, patch])
    return Compose(w_cos, w_geom, w_area, patch)

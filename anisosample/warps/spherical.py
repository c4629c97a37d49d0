"""Light-sampling warps ``[0, 1]^2 -> S^2`` with inverses: spherical triangles and rectangles.

Outputs are unit directions from ``origin``; pdfs are per steradian (``measure = "solid angle"``).
H Sec. 3.1 notes that composing PSS warps needs invertible base warps; the inverses here are the
CDFs of the construction, evaluated in closed form (``references/warps.md`` Secs. 5-6).

Degenerate geometry (a triangle or rectangle of zero solid angle seen from ``origin``, or an
``origin`` in the light's plane) raises ``ValueError`` when the parameters are concrete; when
they are traced (``vmap`` over shading points) the warp is marked invalid instead: ``pdf`` is 0
everywhere and ``sample`` returns a finite direction (documented; never NaN). Accuracy: all
arithmetic is float32; round trips stay within ~1e-4 in ``u`` for lights subtending more than
~1e-3 sr and degrade (like pbrt-v4's) for tiny solid angles.
"""

from __future__ import annotations

import jax.numpy as jnp

from .._types import Array, Float
from ._base import AbstractWarp, check_point
from ._geometry import (
    angle_between,
    check_vectors,
    is_concrete,
    norm,
    safe_normalize,
    solid_angle_triangle,
)

_INSIDE_TOL = 1e-5  # tolerance of the support tests (float32 samples on an edge stay inside)
_MIN_SOLID_ANGLE = 1e-7


class SphericalTriangle(AbstractWarp):
    """Uniform solid-angle sampling of a triangle (Arvo 1995), its inverse and pdf ``1/Omega``.

    ``vertices`` of shape ``(3, 3)`` (rows A, B, C), ``origin`` of shape ``(3,)``. PSS corners:
    ``u1 = 0 -> B``; ``(0, 1) -> A``; ``(1, 1) -> C``. Arvo 1995 Sec. 2: ``u0`` picks the
    sub-triangle ``A B C'`` of area ``u0 Omega`` (``C'`` on arc AC), ``u1`` the point on arc
    ``B C'`` by ``1 - cos``. Inverse: ``C'`` is where the great circle through B and the point
    meets arc AC.
    """

    out_dim = 3
    measure = "solid angle"

    vertices: Float[Array, "3 3"]
    origin: Float[Array, "3"]
    a: Float[Array, "3"]
    b: Float[Array, "3"]
    c: Float[Array, "3"]
    normals: Float[Array, "3 3"]
    alpha: Float[Array, ""]
    solid_angle: Float[Array, ""]
    valid: Array

    def __init__(self, vertices, origin):
        vertices = check_vectors("vertices", vertices, (3, 3))
        origin = check_vectors("origin", origin, (3,))
        self.vertices, self.origin = vertices, origin
        d = vertices - origin[None, :]
        a, b, c = safe_normalize(d[0]), safe_normalize(d[1]), safe_normalize(d[2])
        n_ab = jnp.cross(a, b)
        n_bc = jnp.cross(b, c)
        n_ca = jnp.cross(c, a)
        lens = jnp.stack([norm(n_ab), norm(n_bc), norm(n_ca)])
        n_ab, n_bc, n_ca = safe_normalize(n_ab), safe_normalize(n_bc), safe_normalize(n_ca)
        omega = solid_angle_triangle(a, b, c)
        triple = jnp.abs(jnp.dot(a, jnp.cross(b, c)))  # 0: origin in the triangle's plane
        valid = jnp.all(lens > 0) & jnp.all(norm(d) > 0) & (omega > _MIN_SOLID_ANGLE)
        valid = valid & (triple > 1e-8) & (omega < 2.0 * jnp.pi - 1e-3)
        if is_concrete(vertices, origin, valid) and not bool(valid):
            raise ValueError(
                "vertices must form a triangle of positive solid angle seen from origin"
                f" (got solid angle {float(omega):.3g} sr; collinear vertices, a vertex at the"
                " origin, or the origin in the triangle's plane)"
            )
        orient = jnp.sign(jnp.dot(a, jnp.cross(b, c)))
        orient = jnp.where(orient == 0, 1.0, orient)
        self.a, self.b, self.c = a, b, c
        self.normals = jnp.stack([n_ab, n_bc, n_ca]) * orient
        self.alpha = angle_between(n_ab, -n_ca)
        self.solid_angle = jnp.where(valid, omega, 1.0)
        self.valid = valid

    def corner_images(self):
        """``sample`` at the PSS corners (``[i, j]`` at ``u = (i, j)``) without sampling."""
        b = self.b
        return jnp.stack([jnp.stack([b, self.a]), jnp.stack([b, self.c])])

    def _c_prime(self, u0):
        # Arvo 1995's cos(b') = ((q t - p s) cos(alpha) - q) / ((q s + p t) sin(alpha)) loses
        # sqrt(eps) in b' near u0 = 0. Rewritten (our algebra, checked against the original):
        #   sin^2(b'/2) = (1 + cos c) sin^2(A'/2)
        #                 / (2 sin^2(A'/2) - sin(alpha) sin(A' - alpha) (1 - cos c)),
        # with A' = u0 Omega, cos c = A.B, 1 +- cos c from |A -+ B|^2 / 2: no cancellation.
        a, b, c, alpha = self.a, self.b, self.c, self.alpha
        area = u0 * self.solid_angle
        sh2 = jnp.sin(0.5 * area) ** 2
        one_plus_cc = 0.5 * jnp.sum((a + b) ** 2)
        one_minus_cc = 0.5 * jnp.sum((a - b) ** 2)
        den = 2.0 * sh2 - jnp.sin(alpha) * jnp.sin(area - alpha) * one_minus_cc
        half = one_plus_cc * sh2 / jnp.where(den > 0, den, 1.0)
        half = jnp.clip(jnp.where(den > 0, half, 0.0), 0.0, 1.0)
        cos_bp = 1.0 - 2.0 * half
        sin_bp = 2.0 * jnp.sqrt(half * (1.0 - half))
        return cos_bp * a + sin_bp * safe_normalize(c - jnp.dot(c, a) * a)

    def _on_arc(self, cp, u1):
        # 1 - cos(theta) = u1 (1 - C'.B) with 1 - C'.B = |C' - B|^2 / 2, free of cancellation.
        b = self.b
        one_minus_z = u1 * 0.5 * jnp.sum((cp - b) ** 2)
        z = 1.0 - one_minus_z
        sin_t = jnp.sqrt(jnp.maximum(one_minus_z * (2.0 - one_minus_z), 0.0))
        w = z * b + sin_t * safe_normalize(cp - jnp.dot(cp, b) * b)
        return jnp.where(self.valid, safe_normalize(w), self.a)

    def sample(self, u):
        u = check_point("u", u, 2)
        return self._on_arc(self._c_prime(u[0]), u[1])

    def grid_images(self, g):
        """``sample`` on the product grid ``g x g`` (``[i, j]`` at ``u = (g_i, g_j)``) with one
        ``C'`` per ``g_i`` instead of one per point: what a point-wise fit (H Eq. 9) of a
        biquadratic evaluates its factor at, for a third of the cost of nine samples."""
        g = [float(x) for x in g]  # concrete: u0 = 0 / 1 give C' = A / C, u1 = 0 / 1 B / C'
        ends = {0.0: self.a, 1.0: self.c}
        cps = [ends[gi] if gi in ends else self._c_prime(jnp.float32(gi)) for gi in g]

        def arc(cp, gj):
            if gj in (0.0, 1.0):
                return jnp.where(self.valid, self.b if gj == 0.0 else cp, self.a)
            return self._on_arc(cp, jnp.float32(gj))

        return jnp.stack([jnp.stack([arc(cp, gj) for gj in g]) for cp in cps])

    def sample_and_pdf(self, u):
        """H Alg. 1 step: the sample is on the triangle by construction, its pdf is ``1/Omega``."""
        return self.sample(u), jnp.where(self.valid, 1.0 / self.solid_angle, 0.0)

    def contains(self, w):
        """Whether the unit direction ``w`` lies in the spherical triangle (with tolerance)."""
        return jnp.all(self.normals @ w >= -_INSIDE_TOL)

    def pdf(self, w):
        w = safe_normalize(check_point("w", w, 3))
        ok = self.valid & self.contains(w)
        return jnp.where(ok, 1.0 / self.solid_angle, 0.0)

    def inverse(self, w):
        w = safe_normalize(check_point("w", w, 3))
        a, b, c = self.a, self.b, self.c
        cp = safe_normalize(jnp.cross(jnp.cross(b, w), jnp.cross(c, a)))
        cp = jnp.where(jnp.dot(cp, a + c) < 0, -cp, cp)
        u0 = solid_angle_triangle(a, b, cp) / self.solid_angle
        d_cp = jnp.sum((cp - b) ** 2)
        u1 = jnp.sum((w - b) ** 2) / jnp.where(d_cp > 0, d_cp, 1.0)
        u = jnp.clip(jnp.stack([u0, u1]), 0.0, 1.0)
        return jnp.where(self.valid, u, 0.0)


class SphericalRectangle(AbstractWarp):
    """Uniform solid-angle sampling of a rectangle (Urena, Fajardo & King 2013), pdf ``1/S``.

    The rectangle is ``corner + s edge_u + t edge_v`` (``s, t`` in ``[0, 1]``, edges
    perpendicular); ``sample(u) -> `` unit direction from ``origin``; :meth:`sample_point` gives the
    point on the rectangle. Inverse (``references/warps.md`` Sec. 6): ``u0`` is the solid angle of
    the sub-rectangle ``[x0, x_u] x [y0, y1]`` over ``S`` (closed form), ``u1`` the linear
    parameter of ``h = y / sqrt(x_u^2 + y^2 + z0^2)``.
    """

    out_dim = 3
    measure = "solid angle"

    corner: Float[Array, "3"]
    edge_u: Float[Array, "3"]
    edge_v: Float[Array, "3"]
    origin: Float[Array, "3"]
    frame: Float[Array, "3 3"]
    bounds: Float[Array, "5"]  # x0, x1, y0, y1, z0 (z0 <= 0)
    consts: Float[Array, "3"]  # b0, b1, k
    solid_angle: Float[Array, ""]
    valid: Array

    def __init__(self, corner, edge_u, edge_v, origin):
        corner = check_vectors("corner", corner, (3,))
        edge_u = check_vectors("edge_u", edge_u, (3,))
        edge_v = check_vectors("edge_v", edge_v, (3,))
        origin = check_vectors("origin", origin, (3,))
        self.corner, self.edge_u, self.edge_v, self.origin = corner, edge_u, edge_v, origin
        lx, ly = norm(edge_u), norm(edge_v)
        ex, ey = safe_normalize(edge_u), safe_normalize(edge_v)
        if is_concrete(edge_u, edge_v, lx, ly, ex, ey):
            if float(lx) <= 0 or float(ly) <= 0:
                raise ValueError("edge_u and edge_v must be non-zero vectors")
            if abs(float(jnp.dot(ex, ey))) > 1e-4:
                raise ValueError(
                    "edge_u and edge_v must be perpendicular (a rectangle), got a cosine of"
                    f" {float(jnp.dot(ex, ey)):.3g} between them"
                )
        ez = jnp.cross(ex, ey)
        d = corner - origin
        x0, y0, z0 = jnp.dot(d, ex), jnp.dot(d, ey), jnp.dot(d, ez)
        ez = jnp.where(z0 > 0, -ez, ez)
        z0 = -jnp.abs(z0)
        x1, y1 = x0 + lx, y0 + ly
        v00 = jnp.stack([x0, y0, z0])
        v10 = jnp.stack([x1, y0, z0])
        v11 = jnp.stack([x1, y1, z0])
        v01 = jnp.stack([x0, y1, z0])
        n0 = safe_normalize(jnp.cross(v00, v10))
        n1 = safe_normalize(jnp.cross(v10, v11))
        n2 = safe_normalize(jnp.cross(v11, v01))
        n3 = safe_normalize(jnp.cross(v01, v00))
        g0 = angle_between(-n0, n1)
        g1 = angle_between(-n1, n2)
        g2 = angle_between(-n2, n3)
        g3 = angle_between(-n3, n0)
        # The solid angle from the closed form (more accurate than g0+g1+g2+g3-2pi in float32).
        s_closed = _rect_solid_angle(x0, x1, y0, y1, z0)
        valid = (z0 < 0) & (s_closed > _MIN_SOLID_ANGLE) & (lx > 0) & (ly > 0)
        if is_concrete(corner, edge_u, edge_v, origin, valid) and not bool(valid):
            raise ValueError(
                "the rectangle must subtend a positive solid angle from origin (origin in the"
                f" rectangle's plane?), got {float(s_closed):.3g} sr"
            )
        self.frame = jnp.stack([ex, ey, ez])
        self.bounds = jnp.stack([x0, x1, y0, y1, z0])
        self.consts = jnp.stack([n0[2], n2[2], 2.0 * jnp.pi - g2 - g3])
        self.solid_angle = jnp.where(valid, g0 + g1 + g2 + g3 - 2.0 * jnp.pi, 1.0)
        self.valid = valid

    def _sample_local(self, u):
        x0, x1, y0, y1, z0 = self.bounds
        b0, b1, k = self.consts
        au = u[0] * self.solid_angle + k
        sin_au = jnp.sin(au)
        fu = (jnp.cos(au) * b0 - b1) / jnp.where(sin_au != 0, sin_au, 1e-30)
        cu = jnp.sign(fu) / jnp.sqrt(fu * fu + b0 * b0)
        cu = jnp.where(fu == 0, 0.0, cu)
        cu = jnp.clip(cu, -(1.0 - 2.0**-24), 1.0 - 2.0**-24)
        xu = jnp.clip(-(cu * z0) / jnp.sqrt(jnp.maximum(1.0 - cu * cu, 1e-30)), x0, x1)
        dd2 = xu * xu + z0 * z0
        h0 = y0 / jnp.sqrt(dd2 + y0 * y0)
        h1 = y1 / jnp.sqrt(dd2 + y1 * y1)
        hv = h0 + u[1] * (h1 - h0)
        hv2 = hv * hv
        yv = jnp.where(
            hv2 < 1 - 1e-6, hv * jnp.sqrt(dd2) / jnp.sqrt(jnp.maximum(1 - hv2, 1e-12)), y1
        )
        return jnp.stack([xu, jnp.clip(yv, y0, y1), z0])

    def corner_images(self):
        """``sample`` at the PSS corners, ``[i, j]`` at ``u = (i, j)``: the corner directions,
        ``corner + i edge_u + j edge_v`` seen from ``origin`` (world space, no frame rotation:
        this is what a per-shading-point fit (H Eq. 9) evaluates its factor at)."""
        d = self.corner - self.origin
        c = jnp.stack([jnp.stack([d, d + self.edge_v]),
                       jnp.stack([d + self.edge_u, d + self.edge_u + self.edge_v])])
        return safe_normalize(c)

    def sample_point(self, u):
        """The point on the rectangle (world space) that ``sample(u)`` points at."""
        u = check_point("u", u, 2)
        return self.origin + self._sample_local(u) @ self.frame

    def sample(self, u):
        u = check_point("u", u, 2)
        w = safe_normalize(self._sample_local(u)) @ self.frame
        return jnp.where(self.valid, w, self.frame[2])

    def sample_and_pdf(self, u):
        """H Alg. 1 step: the sample is on the rectangle by construction, its pdf is ``1/S``."""
        return self.sample(u), jnp.where(self.valid, 1.0 / self.solid_angle, 0.0)

    def _local_hit(self, w):
        wl = self.frame @ w
        z0 = self.bounds[4]
        hit = wl[2] < 0
        t = z0 / jnp.where(hit, wl[2], -1.0)
        return t * wl[0], t * wl[1], hit

    def pdf(self, w):
        w = safe_normalize(check_point("w", w, 3))
        x0, x1, y0, y1, _ = self.bounds
        xu, yv, hit = self._local_hit(w)
        tol = _INSIDE_TOL * jnp.maximum(x1 - x0, y1 - y0)
        inside = hit & (xu >= x0 - tol) & (xu <= x1 + tol) & (yv >= y0 - tol) & (yv <= y1 + tol)
        return jnp.where(self.valid & inside, 1.0 / self.solid_angle, 0.0)

    def inverse(self, w):
        w = safe_normalize(check_point("w", w, 3))
        x0, x1, y0, y1, z0 = self.bounds
        xu, yv, _ = self._local_hit(w)
        xu, yv = jnp.clip(xu, x0, x1), jnp.clip(yv, y0, y1)
        u0 = _rect_solid_angle(x0, xu, y0, y1, z0) / self.solid_angle
        dd2 = xu * xu + z0 * z0
        h0 = y0 / jnp.sqrt(dd2 + y0 * y0)
        h1 = y1 / jnp.sqrt(dd2 + y1 * y1)
        hv = yv / jnp.sqrt(dd2 + yv * yv)
        dh = h1 - h0
        u1 = (hv - h0) / jnp.where(dh > 0, dh, 1.0)
        return jnp.where(self.valid, jnp.clip(jnp.stack([u0, u1]), 0.0, 1.0), 0.0)


def _rect_solid_angle(x0, x1, y0, y1, z0):
    """Solid angle of ``[x0, x1] x [y0, y1]`` in the plane at distance ``|z0|`` (closed form)."""
    dist = jnp.abs(z0)

    def f(x, y):
        return jnp.arctan2(x * y, dist * jnp.sqrt(x * x + y * y + dist * dist))

    return f(x1, y1) - f(x0, y1) - f(x1, y0) + f(x0, y0)

"""Exact projected-solid-angle (cosine-weighted) sampling of convex polygons (Peters 2021).

C. Peters, *BRDF Importance Sampling for Polygonal Lights* (ACM TOG 40(4), 2021); the facts
used here are collected in ``references/projected_solid_angle.md`` (Secs. 1-3). Seen from the
shading point, the density ``max(0, n . w) / Phi`` per steradian over the light's spherical
polygon is the uniform density over the polygon's *orthographic shadow* on the unit disk
(``w -> (w_x, w_y)`` in the shading frame maps ``cos(theta) dw`` to area), so the sampler draws
a uniform point of that planar region and lifts it to the hemisphere:

1. **Horizon clipping** (Sec. 2): the polygon is clipped to ``z >= 0`` in the shading frame
   (Sutherland-Hodgman, inclusive, a vertex on the horizon is kept once).
2. **Edges become ellipse arcs** (Sec. 3.1): edge ``v_i -> v_i+1`` lies on the great circle of
   normal ``m = v_i x v_i+1``, whose shadow is the origin-centred ellipse ``p^T A p = 1``,
   ``A = I + e e^T``, ``e = m_xy / m_z``. With the unit normal we store ``B = m_z^2 A =
   m_z^2 I + m_xy m_xy^T`` (finite also for ``m_z = 0``, a radial edge of zero area).
3. **Sectors fanned from the disk centre** (Sec. 3.3): the rays through the clipped vertices
   cut the shadow into sectors in each of which one *outer* arc (traversed counter-clockwise)
   and at most one *inner* arc (clockwise; none when the zenith lies in the polygon, Peters'
   central case) bound it. The area between two rays ``a, b`` under one ellipse is
   ``S(a, b) = |m_z|/2 atan2(|m_z| (a x b), a^T B b)``; a sector has ``S_out - S_in``.
4. ``u0`` picks the sector by area and the target area ``t`` inside it; the **angular step**
   solves ``S_out(d0, d) - S_in(d0, d) = t`` for the ray ``d`` (Sec. 3.5): start at the exact
   solution for the quad of chords through the four boundary points on the sector's rays, then
   :data:`ANGULAR_ITERATIONS` steps of Peters' refinement, which replaces both ellipses by their
   tangent lines at the current ray (a Newton step with a rational model: value and slope of
   the true CDF match) and solves the resulting homogeneous quadratic in closed form.
5. The **radial step** is exact: ``r^2`` uniform between ``r_in^2`` and ``r_out^2`` (Sec. 3.6);
   ``w = (p, sqrt(1 - |p|^2))`` in the shading frame.

The inverse is closed form (Sec. 3.8): the sector by polar angle, ``u0`` the area before the
point's ray over ``Phi``, ``u1 = (r^2 - r_in^2) / (r_out^2 - r_in^2)``.

**Tolerance of the iteration.** With the chord start and three refinement steps the residual
of the angular CDF, ``|F(d) - t|`` relative to the sector's area, was at most 2.2e-12 in a
float64 prototype on the fact sheet's polygons and two grazing quads (start 0.13, then 3.3e-3,
6.2e-6, 2.2e-12 after 1, 2, 3 steps on the worst, the tilted parallelogram): below float32
rounding, which is what remains here (all arithmetic is float32);
``tests/warps/test_polygon.py`` checks ``<= 2e-5`` of the sector area on 10^5 samples per
polygon, grazing and horizon-crossing ones included. For small lights float32 rounding of a thin
sector's ``S_out - S_in`` dominates instead, about ``1.7e-7 / sqrt(Phi)`` (2.8e-5 at
``Phi = 3.6e-5`` sr), an error of the sample's position that no iteration count removes. The
count is fixed (no tolerance test, branch-free under ``vmap``, as in Peters' shader).

Degenerate input (fewer than three vertices left above the horizon, a projected solid angle
below :data:`MIN_PROJECTED_SOLID_ANGLE`, the origin in the polygon's plane) leaves the warp
*invalid*: ``pdf`` is 0 everywhere and ``sample`` returns the normal (finite, never NaN); the
renderer then falls back to area sampling, as pbrt-v4 does for spherical sampling.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .._types import Array, Float
from ._base import AbstractWarp, check_point
from ._geometry import check_vectors, is_concrete, orthonormal_frame

ANGULAR_ITERATIONS = 3
"""Refinement steps of the angular step (Peters' tangent-line Newton step), fixed."""
MIN_PROJECTED_SOLID_ANGLE = 1e-9
"""Below this projected solid angle (sr) the warp is invalid (float32 sectors lose meaning)."""
MAX_VERTICES = 8
_INSIDE_TOL = 2e-6  # |m . w| of float32 samples on an edge stay below it; a band this wide
# adds perimeter x 2e-6 sr, 0.03% of a 3e-4 sr light (1e-5, as for the triangles, made 0.2%)


def _cross2(a, b):
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _dot2(a, b):
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]


# 3-vector algebra spelled out per component: no small matmuls (a vmapped batch of 3x3 dots is
# slow on XLA's CPU backend) and no length-3 reductions (see render/_vec.py for the miscompile).
def _dot3(a, b):
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def _cross3(a, b):
    return jnp.stack(
        [
            a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
            a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
            a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0],
        ],
        axis=-1,
    )


def _normalize3(v):
    n = jnp.sqrt(_dot3(v, v))
    return v / jnp.where(n > 0, n, 1.0)[..., None]


def _to_frame(frame, v):
    """``frame @ v`` per component (``v`` of shape ``(..., 3)``)."""
    return jnp.stack([_dot3(v, frame[0]), _dot3(v, frame[1]), _dot3(v, frame[2])], axis=-1)


def _from_frame(frame, v):
    """``v @ frame`` per component: a shading-frame vector back to world space."""
    return v[..., 0:1] * frame[0] + v[..., 1:2] * frame[1] + v[..., 2:3] * frame[2]


def atan2(y, x):
    """``atan2(y, x)`` in float32 from Cephes' ``atanf`` polynomial (S. Moshier): ``|y/x|`` or
    its inverse reduced to ``[0, 1]``, then to ``|t| <= tan(pi/8)`` by ``(a - 1)/(a + 1)``.
    Max error 2.8e-7 absolute against float64 (``jnp.arctan2``: 2.5e-7), written with
    elementwise operations that XLA vectorises: about 20x faster than ``jnp.arctan2`` on the CPU
    backend, which evaluates it per element. (``atan2(0, 0) = 0``.)"""
    ax, ay = jnp.abs(x), jnp.abs(y)
    hi, lo = jnp.maximum(ax, ay), jnp.minimum(ax, ay)
    a = lo / jnp.where(hi > 0, hi, 1.0)
    big = a > 0.41421356237  # tan(pi/8)
    t = jnp.where(big, (a - 1.0) / (a + 1.0), a)
    z = t * t
    poly = ((8.05374449538e-2 * z - 1.38776856032e-1) * z + 1.99777106478e-1) * z
    r = (poly - 3.33329491539e-1) * z * t + t
    r = jnp.where(big, r + 0.25 * jnp.pi, r)
    r = jnp.where(ay > ax, 0.5 * jnp.pi - r, r)
    r = jnp.where(x < 0, jnp.pi - r, r)
    return jnp.where(y < 0, -r, r)


def _pseudo_angle(x, y):
    """A monotone stand-in for ``atan2(y, x)`` in ``(-2, 2]`` (the "diamond angle"): enough to
    sort rays by polar angle without trigonometry."""
    r = jnp.abs(x) + jnp.abs(y)
    a = 1.0 - x / jnp.where(r > 0, r, 1.0)
    return jnp.where(y >= 0, a, -a)


def clip_to_horizon(v: Float[Array, "k 3"]) -> tuple[Float[Array, "k1 3"], Array]:
    """Sutherland-Hodgman clip of a convex polygon (shading frame, ``z`` up) to ``z >= 0``.

    Returns ``k + 1`` vertex slots and the count of real ones; unused slots repeat the last
    vertex (zero-length edges, zero area). Inclusive: a vertex with ``z = 0`` is kept, and an
    edge is cut only where its end heights have strictly opposite signs, so a vertex on the
    horizon is never emitted twice (``references/projected_solid_angle.md`` Sec. 2). Cut points
    get ``z = 0`` exactly.
    """
    k = v.shape[0]
    z = v[:, 2]
    vn = jnp.roll(v, -1, axis=0)
    zn = vn[:, 2]
    inside = z >= 0
    crosses = ((z > 0) & (zn < 0)) | ((z < 0) & (zn > 0))
    s = z / jnp.where(crosses, z - zn, 1.0)
    cut = v[:, :2] + s[:, None] * (vn[:, :2] - v[:, :2])
    cut = jnp.concatenate([cut, jnp.zeros_like(z)[:, None]], axis=1)
    cand = jnp.stack([v, cut], axis=1).reshape(2 * k, 3)
    keep = jnp.stack([inside, crosses], axis=1).reshape(2 * k)
    # Compaction by gathering: slot r takes the candidate after the r-th kept one's
    # predecessors, i.e. the number of candidates with inclusive keep-count <= r; slots past
    # the count repeat the last kept candidate.
    lower = jnp.arange(2 * k)[None, :] <= jnp.arange(2 * k)[:, None]
    kept = jnp.sum(lower & keep[None, :], axis=1)  # inclusive running count
    count = kept[-1]
    slots = jnp.minimum(jnp.arange(k + 1), jnp.maximum(count - 1, 0))
    pick = jnp.sum(kept[None, :] <= slots[:, None], axis=1)
    return cand[jnp.clip(pick, 0, 2 * k - 1)], count


def _ellipse_q(m):
    """``m_z^2`` of a unit edge normal (0 for a missing ellipse, ``m = 0``)."""
    return m[..., 2] * m[..., 2]


def _quad_form(m, a, b):
    """``a^T B b`` with ``B = m_z^2 I + m_xy m_xy^T``."""
    mxy = m[..., :2]
    return _ellipse_q(m) * _dot2(a, b) + _dot2(mxy, a) * _dot2(mxy, b)


def ellipse_sector(m, a, b):
    """Area of the ellipse of unit edge normal ``m`` between the rays ``a -> b`` (CCW, < pi):
    ``S = |m_z|/2 atan2(|m_z| (a x b), a^T B b)`` (Sec. 3.3; 0 for ``m = 0``)."""
    mz = jnp.abs(m[..., 2])
    return 0.5 * mz * atan2(mz * _cross2(a, b), _quad_form(m, a, b))


def _radius2(m, d):
    """Squared radius of the ellipse of ``m`` along ``d``: ``m_z^2 |d|^2 / d^T B d`` (0 for
    ``m = 0``)."""
    q = _ellipse_q(m)
    den = _quad_form(m, d, d)
    return jnp.where(den > 0, q * _dot2(d, d) / jnp.where(den > 0, den, 1.0), 0.0)


def _root_in_unit(a, b, c):
    """The root of ``a x^2 + b x + c`` in ``[0, 1]`` (cancellation-free pair of roots)."""
    disc = jnp.sqrt(jnp.maximum(b * b - 4.0 * a * c, 0.0))
    q = -0.5 * (b + jnp.where(b >= 0, disc, -disc))
    r1 = c / jnp.where(q != 0, q, 1.0)
    r2 = q / jnp.where(a != 0, a, 1.0)
    r1 = jnp.where(q != 0, r1, jnp.inf)
    r2 = jnp.where(a != 0, r2, jnp.inf)
    ok1 = (r1 >= 0) & (r1 <= 1)
    return jnp.clip(jnp.where(ok1, r1, r2), 0.0, 1.0)


def _small_root(a, b, c):
    """The root of ``a x^2 + b x + c`` nearest 0 (``-2c / (b + sign(b) sqrt(disc))``)."""
    disc = jnp.sqrt(jnp.maximum(b * b - 4.0 * a * c, 0.0))
    den = b + jnp.where(b >= 0, disc, -disc)
    return jnp.where(den != 0, -2.0 * c / jnp.where(den != 0, den, 1.0), 0.0)


def _chord_start(d0, d1, mo, mi, frac):
    """``lambda`` in ``[0, 1]`` (ray ``(1 - lambda) d0 + lambda d1``) that cuts off the fraction
    ``frac`` of the quad of chords through the boundary points on the rays ``d0``, ``d1``.

    A chord through ``r0 d0`` and ``r1 d1`` cuts the wedge up to ``x(lambda)`` in a triangle of
    area ``K/2 r0^2 r1 lambda / (lambda r0 + (1 - lambda) r1)``, ``K = d0 x d1``; the quad's
    area is the outer triangle's minus the inner one's, and equating it to ``frac`` of its
    value at ``lambda = 1`` is a quadratic in ``lambda`` (linear without an inner arc).
    """
    k = _cross2(d0, d1)
    ro0, ro1 = jnp.sqrt(_radius2(mo, d0)), jnp.sqrt(_radius2(mo, d1))
    ri0, ri1 = jnp.sqrt(_radius2(mi, d0)), jnp.sqrt(_radius2(mi, d1))
    tgt = frac * 0.5 * k * (ro0 * ro1 - ri0 * ri1)
    a = 0.5 * k * (ro0**2 * ro1 * (ri0 - ri1) - ri0**2 * ri1 * (ro0 - ro1)) - tgt * (
        ro0 - ro1
    ) * (ri0 - ri1)
    b = 0.5 * k * ro1 * ri1 * (ro0**2 - ri0**2) - tgt * (ro1 * (ri0 - ri1) + ri1 * (ro0 - ro1))
    c = -tgt * ro1 * ri1
    lam_quad = _root_in_unit(a, b, c)
    den = 0.5 * k * ro0**2 * ro1 - tgt * (ro0 - ro1)
    lam_lin = jnp.clip(tgt * ro1 / jnp.where(den > 0, den, 1.0), 0.0, 1.0)
    return jnp.where(_ellipse_q(mi) > 0, lam_quad, lam_lin)


def _sector_cdf(d0, d1, mo, mi, lam):
    """``S_out(d0, x) - S_in(d0, x)`` at ``x = (1 - lambda) d0 + lambda d1``, with
    ``d0 x x = lambda (d0 x d1)`` and ``d0^T B x`` linear in ``lambda`` (no cancellation in the
    cross product of nearly parallel rays of a small light)."""
    k = lam * _cross2(d0, d1)

    def s(m):
        mz = jnp.abs(m[..., 2])
        g = (1.0 - lam) * _quad_form(m, d0, d0) + lam * _quad_form(m, d0, d1)
        return 0.5 * mz * atan2(mz * k, g)

    return s(mo) - s(mi)


def _tangent_step(d0, d1, mo, mi, lam, target):
    """Peters' refinement (Sec. 3.5 b): replace each ellipse by its tangent line at its boundary
    point on ``d = x(lambda)``; the area from ``d`` to ``x(lambda + delta)`` between them is
    ``K delta / 2 [q_o / (g_o + h_o delta) - q_i / (g_i + h_i delta)]`` (``q = m_z^2``,
    ``g = d^T B d``, ``h = d^T B (d1 - d0)``); setting it to the residual ``E`` gives a quadratic
    in ``delta`` whose root nearest 0 is the step (linear without an inner arc)."""
    k = _cross2(d0, d1)
    d = (1.0 - lam) * d0 + lam * d1
    e = target - _sector_cdf(d0, d1, mo, mi, lam)
    dd = d1 - d0
    qo, qi = _ellipse_q(mo), _ellipse_q(mi)
    go, gi = _quad_form(mo, d, d), _quad_form(mi, d, d)
    ho, hi = _quad_form(mo, d, dd), _quad_form(mi, d, dd)
    a = 0.5 * k * (qo * hi - qi * ho) - e * ho * hi
    b = 0.5 * k * (qo * gi - qi * go) - e * (go * hi + gi * ho)
    c = -e * go * gi
    step_quad = _small_root(a, b, c)
    den = 0.5 * k * qo - e * ho
    step_lin = e * go / jnp.where(den != 0, den, 1.0)
    step = jnp.where(qi > 0, step_quad, step_lin)
    return jnp.clip(lam + step, 0.0, 1.0)


def _sector_of_ray(d, rays, next_rays, areas):
    """Index of the sector (of positive area, hence narrower than pi) whose wedge holds ``d``."""
    inside = (_cross2(rays, d) >= 0) & (_cross2(d, next_rays) >= 0) & (areas > 0)
    return jnp.argmax(inside)


@jax.jit
def _sectors(vertices, origin, n):
    """:class:`ProjectedSphericalPolygon`'s fields for a checked polygon and unit normal ``n``:
    the shading frame, the edge normals and the sectors of Peters' sweep with their areas."""
    frame = orthonormal_frame(n)
    rel = vertices - origin[None, :]
    # Winding as seen from the origin: the sign of (polygon normal) . (v0 - origin).
    side = _dot3(_cross3(rel[1] - rel[0], rel[2] - rel[0]), rel[0])
    sigma = jnp.where(side > 0, 1.0, -1.0)
    edge_normals = _normalize3(_cross3(rel, jnp.roll(rel, -1, axis=0)) * sigma)

    clipped, count = clip_to_horizon(_to_frame(frame, rel))
    vh = _normalize3(clipped)
    vn = jnp.roll(vh, -1, axis=0)
    m = _normalize3(_cross3(vh, vn))
    p = vh[:, :2]
    pr = jnp.sqrt(_dot2(p, p))
    at_zenith = pr <= 1e-7
    unit = jnp.asarray([1.0, 0.0], p.dtype)
    ph = jnp.where(at_zenith[:, None], unit, p / jnp.where(at_zenith, 1.0, pr)[:, None])
    # Sort the rays by polar angle measured from the mean vertex direction: a decentral
    # polygon (less than pi of polar angle) then lies away from the branch cut, and its
    # sectors follow Peters' sweep from the most clockwise vertex.
    mean = jnp.sum(ph, axis=0)
    mn = jnp.sqrt(_dot2(mean, mean))
    centre = jnp.where(mn > 1e-6, mean / jnp.where(mn > 1e-6, mn, 1.0), unit)
    key = _pseudo_angle(_dot2(ph, centre), _cross2(centre, ph))
    kk = key.shape[0]
    idx = jnp.arange(kk)
    earlier = (key[None, :] < key[:, None]) | (
        (key[None, :] == key[:, None]) & (idx[None, :] < idx[:, None])
    )
    rank = jnp.sum(earlier, axis=1)
    order = jnp.argmax(rank[None, :] == idx[:, None], axis=1)  # the vertex of rank r
    rays = ph[order]
    next_rays = jnp.roll(rays, -1, axis=0)
    # A sector is non-empty only if narrower than pi (the wide gap of a decentral polygon
    # is empty); edge i bounds sector j if the sector's middle ray lies strictly inside the
    # edge's polar wedge: outer (+1) if the edge runs counter-clockwise once the polygon is
    # oriented by sigma, inner (-1) if clockwise. Edges from a vertex at the zenith are
    # radial (no polar extent).
    narrow = _cross2(rays, next_rays) > 0
    mid = rays + next_rays
    a, b = ph[:, None, :], jnp.roll(ph, -1, axis=0)[:, None, :]
    turn = jnp.sign(_cross2(ph, jnp.roll(ph, -1, axis=0)))[:, None]
    spans = (turn * _cross2(a, mid[None]) > 0) & (turn * _cross2(mid[None], b) > 0)
    spans = spans & ~(at_zenith | jnp.roll(at_zenith, -1))[:, None] & narrow[None, :]
    sign = jnp.where(spans, turn * sigma, 0.0)  # (edge, sector)
    o = jnp.argmax(sign, axis=0)
    i = jnp.argmin(sign, axis=0)
    has_out = jnp.max(sign, axis=0) > 0
    has_in = jnp.min(sign, axis=0) < 0
    outer = jnp.where(has_out[:, None], m[o], 0.0)
    inner = jnp.where(has_in[:, None], m[i], 0.0)
    areas = ellipse_sector(outer, rays, next_rays) - ellipse_sector(inner, rays, next_rays)
    areas = jnp.where(has_out & jnp.isfinite(areas), jnp.maximum(areas, 0.0), 0.0)
    total = jnp.sum(areas)
    valid = (count >= 3) & (side != 0) & (total > MIN_PROJECTED_SOLID_ANGLE)
    return (frame, edge_normals, rays, next_rays, outer, inner, areas, jnp.cumsum(areas) - areas,
            jnp.where(valid, total, 1.0), valid)


class ProjectedSphericalPolygon(AbstractWarp):
    """Cosine-weighted sampling of a convex polygon seen from ``origin`` (Peters 2021).

    ``vertices`` of shape ``(k, 3)``, ``3 <= k <= 8``, a planar convex polygon in either winding
    (triangles and parallelograms in the renderer); ``origin`` the shading point, ``normal`` its
    normal (need not be unit). ``pdf(w) = max(0, n . w) / Phi`` per steradian on the part of the
    polygon above the horizon of ``normal``, ``Phi`` its projected solid angle
    (:attr:`projected_solid_angle`, Lambert's formula as a sum of sector areas). See the module
    docstring for the method, the inverse and the iteration's tolerance.
    """

    out_dim = 3
    measure = "solid angle"

    vertices: Float[Array, "k 3"]
    origin: Float[Array, "3"]
    normal: Float[Array, "3"]
    frame: Float[Array, "3 3"]  # rows s, t, n: world -> shading frame
    edge_normals: Float[Array, "k 3"]  # unit, pointing into the polygon's cone
    rays: Float[Array, "k1 2"]  # first ray of each sector (unit, sorted by polar angle)
    next_rays: Float[Array, "k1 2"]
    outer: Float[Array, "k1 3"]  # unit edge normal of each sector's outer / inner arc (0: none)
    inner: Float[Array, "k1 3"]
    areas: Float[Array, " k1"]
    before: Float[Array, " k1"]  # area of the sectors before each
    projected_solid_angle: Float[Array, ""]
    valid: Array

    def __init__(self, vertices, origin, normal):
        vertices = _check_polygon(vertices)
        origin = check_vectors("origin", origin, (3,))
        normal = check_vectors("normal", normal, (3,))
        n = _normalize3(normal)
        if is_concrete(n) and float(_dot3(n, n)) == 0:
            raise ValueError("normal must be a non-zero vector")
        self.vertices, self.origin, self.normal = vertices, origin, n
        # One compiled program for the sectors (called outside jit, op by op, they compiled
        # ~100 small programs on first use); inside a jit or vmap it is inlined.
        sectors = _sectors(vertices, origin, n)
        (self.frame, self.edge_normals, self.rays, self.next_rays, self.outer, self.inner,
         self.areas, self.before, self.projected_solid_angle, self.valid) = sectors

    # --- sampling ------------------------------------------------------------------------------

    def _sector(self, u0):
        """The sector holding the area ``u0 Phi`` and the target area inside it."""
        t = u0 * self.projected_solid_angle
        ends = self.before + self.areas
        last = jnp.max(jnp.where(self.areas > 0, jnp.arange(self.areas.shape[0]), 0))
        j = jnp.minimum(jnp.sum(ends <= t), last)
        return j, jnp.clip(t - self.before[j], 0.0, self.areas[j])

    def _angular(self, u0):
        """The ray (unit, shading frame) and the arcs of the sector for the area ``u0 Phi``,
        and the ray's parameter ``lambda`` between the sector's rays."""
        j, target = self._sector(u0)
        area = self.areas[j]
        d0, d1 = self.rays[j], self.next_rays[j]
        mo, mi = self.outer[j], self.inner[j]
        sg = jax.lax.stop_gradient
        frac = sg(target / jnp.where(area > 0, area, 1.0))
        lam = _chord_start(sg(d0), sg(d1), sg(mo), sg(mi), frac)
        for _ in range(ANGULAR_ITERATIONS - 1):
            lam = _tangent_step(sg(d0), sg(d1), sg(mo), sg(mi), lam, sg(target))
        # The last step with live inputs: its derivative is the implicit one, d lambda / d t =
        # 1 / F'(lambda), so jacfwd through sample gives the true Jacobian.
        lam = _tangent_step(d0, d1, mo, mi, sg(lam), target)
        x = (1.0 - lam) * d0 + lam * d1
        return x / jnp.maximum(jnp.sqrt(_dot2(x, x)), 1e-30), mo, mi, lam

    def sample(self, u):
        u = check_point("u", u, 2)
        d, mo, mi, _ = self._angular(u[0])
        r2_in, r2_out = _radius2(mi, d), _radius2(mo, d)
        r2 = jnp.clip(r2_in + u[1] * (r2_out - r2_in), 0.0, 1.0)
        p = jnp.sqrt(r2) * d
        z = jnp.sqrt(jnp.maximum(1.0 - r2, 0.0))
        w = _from_frame(self.frame, jnp.concatenate([p, z[None]]))
        return jnp.where(self.valid, _normalize3(w), self.normal)

    def sample_and_pdf(self, u):
        """H Alg. 1 step: the sample and ``max(n . w, 0) / Phi`` (on the polygon by
        construction, so no support test)."""
        w = self.sample(u)
        pdf = jnp.maximum(_dot3(self.normal, w), 0.0) / self.projected_solid_angle
        return w, jnp.where(self.valid, pdf, 0.0)

    def contains(self, w):
        """Whether the unit direction ``w`` lies in the polygon's cone (with tolerance)."""
        return jnp.all(_dot3(self.edge_normals, w[None, :]) >= -_INSIDE_TOL)

    def pdf(self, w):
        w = _normalize3(check_point("w", w, 3))
        cos = _dot3(self.normal, w)
        ok = self.valid & self.contains(w) & (cos > 0)
        return jnp.where(ok, cos / self.projected_solid_angle, 0.0)

    def inverse(self, w):
        w = _normalize3(check_point("w", w, 3))
        p = _to_frame(self.frame, w)[:2]
        pr = jnp.sqrt(_dot2(p, p))
        unit = jnp.asarray([1.0, 0.0], p.dtype)
        d = jnp.where(pr > 0, p / jnp.where(pr > 0, pr, 1.0), unit)
        j = _sector_of_ray(d, self.rays, self.next_rays, self.areas)
        d0, mo, mi = self.rays[j], self.outer[j], self.inner[j]
        f = ellipse_sector(mo, d0, d) - ellipse_sector(mi, d0, d)
        u0 = (self.before[j] + jnp.clip(f, 0.0, self.areas[j])) / self.projected_solid_angle
        r2_in, r2_out = _radius2(mi, d), _radius2(mo, d)
        dr = r2_out - r2_in
        u1 = (pr * pr - r2_in) / jnp.where(dr > 0, dr, 1.0)
        u = jnp.clip(jnp.stack([u0, u1]), 0.0, 1.0)
        return jnp.where(self.valid, u, 0.0)

    def angular_residual(self, u0):
        """``|F(lambda) - t| / A_j`` of the angular step at ``u0`` (the iteration's error, for
        tests and diagnostics): the sector's CDF at the returned ray against its target."""
        j, target = self._sector(u0)
        _, mo, mi, lam = self._angular(u0)
        area = self.areas[j]
        f = _sector_cdf(self.rays[j], self.next_rays[j], mo, mi, lam)
        return jnp.abs(f - target) / jnp.where(area > 0, area, 1.0)


def _check_polygon(vertices) -> jax.Array:
    shape = getattr(vertices, "shape", None)
    if shape is None:
        vertices = np.asarray(vertices, dtype=np.float32)
        shape = vertices.shape
    if len(shape) != 2 or shape[1] != 3 or not 3 <= shape[0] <= MAX_VERTICES:
        raise ValueError(
            f"vertices must have shape (k, 3) with 3 <= k <= {MAX_VERTICES} (a convex polygon),"
            f" got shape {tuple(shape)}"
        )
    if not isinstance(vertices, jax.core.Tracer):
        v = np.asarray(vertices, dtype=np.float64)
        if not np.all(np.isfinite(v)):
            raise ValueError(f"vertices must be finite, got {v.tolist()}")
        _check_convex_planar(v)
    return jnp.asarray(vertices, dtype=jnp.float32)


def _check_convex_planar(v: np.ndarray) -> None:
    """ValueError unless ``v`` is a planar, convex polygon with non-zero area (float64)."""
    k = len(v)
    edges = np.roll(v, -1, axis=0) - v
    turns = np.cross(edges, np.roll(edges, -1, axis=0))  # at vertex i+1
    normal = np.sum(np.cross(v, np.roll(v, -1, axis=0)), axis=0)  # Newell's normal
    size = max(float(np.max(np.linalg.norm(edges, axis=1))), 1e-300)
    spread = np.max(np.linalg.norm(np.cross(v[1:] - v[0], v[2:, None] - v[0]), axis=-1))
    if spread <= 1e-12 * size * size:
        raise ValueError("vertices must span a polygon of non-zero area, got collinear points")
    if np.linalg.norm(normal) <= 1e-9 * size * size:
        raise ValueError("vertices must form a convex polygon listed in order, got a"
                         " self-intersecting one")
    unit = normal / np.linalg.norm(normal)
    height = (v - v[0]) @ unit
    if np.max(np.abs(height)) > 1e-5 * size:
        raise ValueError(
            f"vertices must be coplanar, got heights {np.round(height, 6).tolist()} off the"
            " plane of the polygon"
        )
    along = turns @ unit
    if np.any(along < -1e-9 * size * size) and k > 3:
        raise ValueError(
            "vertices must form a convex polygon listed in order (no reflex or crossing"
            f" corners), got turn directions {np.sign(along).astype(int).tolist()}"
        )

"""Bilinear patches in the ray caster: intersection, normals, area, and light sampling.

A patch has four corners ``corners[i, j] = p_ij`` (shape ``(2, 2, 3)``, the indexing of
:class:`anisosample.warps.BilinearPatch`) and the surface (H Sec. 4.2)

    p(u, v) = (1 - u)(1 - v) p00 + u (1 - v) p10 + (1 - u) v p01 + u v p11,   (u, v) in [0, 1]^2,

in general not planar. Its front side is the side of ``p_u x p_v`` (a patch with the corners of
Mitsuba's ``rectangle`` faces +z, like the rectangle).

**Intersection** (Reshetov 2019, "Cool Patches", Ray Tracing Gems ch. 8; pbrt-v4
``IntersectBilinearPatch``). For fixed ``u`` the patch is the segment ``a(u) + v (b(u) - a(u))``
with ``a(u) = lerp(u, p00, p10)``, ``b(u) = lerp(u, p01, p11)``. The ray ``o + t d`` meets that
line iff the two are coplanar, ``((a(u) - o) x d) . (b(u) - a(u)) = 0``: a quadratic in ``u``
(both factors are linear in ``u``) with ``f(0) = ((p00 - o) x d) . (p01 - p00)``,
``f(1) = ((p10 - o) x d) . (p11 - p10)`` and leading coefficient
``((p10 - p00) x (p01 - p11)) . d``. For each root in ``[0, 1]`` the closest points of ray and
line give ``t`` and ``v`` by Cramer's rule with ``perp = d x (b - a)``:
``t = det(a - o, b - a, perp) / |perp|^2``, ``v = det(a - o, d, perp) / |perp|^2``. The roots
use the cancellation-free form ``q = -(B + sign(B) sqrt(B^2 - 4AC)) / 2``, ``u = q / A, C / q``
(a planar parallelogram has ``A = 0`` and keeps the finite root). One Newton step on
``o + t d = p(u, v)`` then polishes ``(t, u, v)`` in float32 (skipped at grazing incidence).
A ray can meet a non-planar patch twice; both hits are returned.

**Light sampling** (H Sec. 4.2) is a chain of :mod:`anisosample.warps` ending in
:func:`SeenPatch` (:mod:`~anisosample.render.light_warps`): ``"parametric"`` is uniform in
``(u, v)`` with area pdf ``1 / |p_u x p_v|`` (H Eq. 11); ``"area"`` first warps ``x`` by the
bilinear PSS warp whose corner values are the area elements at the corners
(:func:`anisosample.warps.patch_area_warp`), area pdf ``bilinear_pdf(u, v) / |p_u x p_v|``:
approximately uniform by area, exactly for planar convex quads (Arvo & Novins 2007).
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from ..warps import BilinearPatch
from ._vec import cross, dot, norm

_INF = np.float32(np.inf)  # numpy: importing must not start the XLA backend (jax.distributed)


class Patches(eqx.Module):
    """The scene's bilinear patches (structure of arrays; one far-away placeholder if none)."""

    corners: Float[Array, "b 2 2 3"]  # corners[k, i, j] = p_ij of patch k, world space
    material: Int[Array, " b"]
    light: Int[Array, " b"]  # index into the light primitives, -1 if not emissive


# --- geometry ----------------------------------------------------------------------------------


def _lerp(t, a, b):
    return a + t * (b - a)


def patch_point(c: Float[Array, "2 2 3"], uv: Float[Array, "2"]) -> Float[Array, "3"]:
    """``p(u, v)`` of one patch."""
    u, v = uv[0], uv[1]
    return _lerp(u, _lerp(v, c[0, 0], c[0, 1]), _lerp(v, c[1, 0], c[1, 1]))


def patch_partials(c, uv):
    """``(p_u, p_v)`` at ``uv``."""
    u, v = uv[0], uv[1]
    pu = _lerp(v, c[1, 0] - c[0, 0], c[1, 1] - c[0, 1])
    pv = _lerp(u, c[0, 1] - c[0, 0], c[1, 1] - c[1, 0])
    return pu, pv


def patch_frame(c, uv):
    """Unit normal ``p_u x p_v / |p_u x p_v|`` and area element ``|p_u x p_v|`` at ``uv``
    (normal ``0`` where the area element vanishes)."""
    pu, pv = patch_partials(c, uv)
    nn = cross(pu, pv)
    ae = norm(nn)
    return nn / jnp.where(ae > 0, ae, 1.0), ae


def intersect_patches(
    corners: Float[Array, "b 2 2 3"], o: Float[Array, "3"], d: Float[Array, "3"]
) -> tuple[Float[Array, "b 2"], Float[Array, "b 2"], Float[Array, "b 2"]]:
    """Both ray/patch hits of every patch: ``(t, u, v)`` of shape ``(b, 2)``, ``t = inf`` where a
    root misses (see the module docstring). ``d`` need not be unit; ``t`` is in units of ``d``.
    """
    o1, d1 = o[None, :], d[None, :]
    p00, p10 = corners[:, 0, 0], corners[:, 1, 0]
    p01, p11 = corners[:, 0, 1], corners[:, 1, 1]
    qa = dot(cross(p10 - p00, p01 - p11), d1)
    qc = dot(cross(p00 - o1, d1), p01 - p00)
    qb = dot(cross(p10 - o1, d1), p11 - p10) - qa - qc
    disc = qb * qb - 4.0 * qa * qc
    real = disc >= 0
    q = -0.5 * (qb + jnp.where(qb >= 0, 1.0, -1.0) * jnp.sqrt(jnp.maximum(disc, 0.0)))
    r1 = jnp.where(qa != 0, q / jnp.where(qa != 0, qa, 1.0), -1.0)
    r2 = jnp.where(q != 0, qc / jnp.where(q != 0, q, 1.0), -1.0)
    u = jnp.stack([r1, r2], axis=-1)  # (b, 2)
    ok = real[:, None] & (u >= 0) & (u <= 1)
    u = jnp.clip(u, 0.0, 1.0)

    def per_root(c, u):  # one patch, one root
        a = _lerp(u, c[0, 0], c[1, 0])
        e = _lerp(u, c[0, 1], c[1, 1]) - a
        delta = a - o
        perp = cross(d, e)
        p2 = dot(perp, perp)
        s = jnp.where(p2 > 0, 1.0 / jnp.where(p2 > 0, p2, 1.0), 0.0)
        v = dot(cross(delta, d), perp) * s
        t = dot(cross(delta, e), perp) * s
        good = (p2 > 0) & (v >= 0) & (v <= 1)
        # One Newton step on F(t, u, v) = o + t d - p(u, v) (Jacobian [d, -p_u, -p_v]).
        uv = jnp.stack([u, jnp.clip(v, 0.0, 1.0)])
        pu, pv = patch_partials(c, uv)
        nn = cross(pu, pv)
        dn = dot(d, nn)
        well = jnp.abs(dn) > 1e-2 * norm(nn) * norm(d)
        inv = jnp.where(well, 1.0 / jnp.where(well, dn, 1.0), 0.0)
        f = o + t * d - patch_point(c, uv)
        t = t - dot(f, nn) * inv
        u2 = jnp.clip(uv[0] + dot(d, cross(f, pv)) * inv, 0.0, 1.0)
        v2 = jnp.clip(uv[1] + dot(d, cross(pu, f)) * inv, 0.0, 1.0)
        return jnp.where(good, t, _INF), u2, v2

    t, uu, vv = jax.vmap(jax.vmap(per_root, in_axes=(None, 0)))(corners, u)
    return jnp.where(ok, t, _INF), uu, vv


def closest_patch_hit(patches: Patches, o, d, tmin, tmax):
    """``(t, uv, k)``: the nearest hit with ``tmin < t < tmax`` over all patches (``t = inf``
    if none) and the index of its patch."""
    t, u, v = intersect_patches(patches.corners, o, d)
    t = jnp.where((t > tmin) & (t < tmax), t, _INF).reshape(-1)
    i = jnp.argmin(t)
    return t[i], jnp.stack([u.reshape(-1)[i], v.reshape(-1)[i]]), i // 2


def uv_towards(c: Float[Array, "2 2 3"], ref: Float[Array, "3"], p: Float[Array, "3"]):
    """``(uv, found)`` of the point ``p`` of patch ``c`` seen from ``ref``: the ray from ``ref``
    through ``p`` is intersected with the patch and the hit nearest ``p`` taken (exact, unlike
    Gauss-Newton inversion of ``p(u, v) = p``, which can fail on strongly twisted patches)."""
    w = p - ref
    dist = norm(w)
    t, u, v = intersect_patches(c[None], ref, w / jnp.maximum(dist, 1e-30))
    err = jnp.abs(t[0] - dist)
    i = jnp.argmin(err)
    found = err[i] <= 1e-3 * jnp.maximum(dist, 1e-30)
    return jnp.stack([u[0, i], v[0, i]]), found


# --- light sampling (H Sec. 4.2) --------------------------------------------------------------


class SeenPatch(BilinearPatch):
    """``warps.BilinearPatch`` seen from ``origin``: its inverse (hence its pdf and every
    chain's H Algorithm 2) finds ``(u, v)`` of a point by tracing the ray from ``origin``
    through it (:func:`uv_towards`, exact) instead of Gauss-Newton from the patch centre
    (which stays the fallback where the ray test finds no hit, e.g. at the boundary).
    The renderer's light chains end in it (:mod:`~anisosample.render.light_warps`)."""

    origin: Float[Array, "3"]

    def __init__(self, corners, origin):
        self.corners = jnp.asarray(corners, jnp.float32)
        self.newton_steps = 8
        self.origin = jnp.asarray(origin, jnp.float32)

    def _invert(self, x):
        uv, found = uv_towards(self.corners, self.origin, x)
        # Not found (a point on the patch's boundary, where the ray test's rounding can reject
        # the hit, or off the patch): Gauss-Newton, whose residual test then decides the pdf.
        return jnp.where(found, uv, super()._invert(x))


# --- building (numpy, float64) ----------------------------------------------------------------

_GL_X, _GL_W = np.polynomial.legendre.leggauss(24)


def patch_area(c) -> float:
    """Surface area ``int |p_u x p_v| du dv`` by 24x24-point Gauss-Legendre (float64)."""
    c = np.asarray(c, np.float64)
    g = 0.5 * (_GL_X + 1.0)
    u, v = np.meshgrid(g, g, indexing="ij")
    u, v = u[..., None], v[..., None]
    pu = (1 - v) * (c[1, 0] - c[0, 0]) + v * (c[1, 1] - c[0, 1])
    pv = (1 - u) * (c[0, 1] - c[0, 0]) + u * (c[1, 1] - c[1, 0])
    ae = np.linalg.norm(np.cross(pu, pv), axis=-1)
    return float(0.25 * np.einsum("i,j,ij->", _GL_W, _GL_W, ae))


def check_corners(corners) -> tuple[np.ndarray, float]:
    """Validate patch corners ``(2, 2, 3)`` (``[i, j] = p_ij``); returns them (float64) and
    the patch's area. Raises ``ValueError`` for a wrong shape, non-finite values, two coincident
    corners along an edge, or zero area."""
    c = np.asarray(corners, np.float64)
    if c.shape != (2, 2, 3):
        raise ValueError(f"bilinear patch corners must have shape (2, 2, 3), got {c.shape}")
    if not np.all(np.isfinite(c)):
        raise ValueError(f"bilinear patch corners must be finite, got {c.tolist()}")
    edges = [c[1, 0] - c[0, 0], c[0, 1] - c[0, 0], c[1, 1] - c[0, 1], c[1, 1] - c[1, 0]]
    scale = max(float(np.max(np.abs(c))), 1e-300)
    if min(np.linalg.norm(e) for e in edges) <= 1e-12 * scale:
        raise ValueError(
            "degenerate bilinear patch: two corners along an edge coincide (p00-p10, p00-p01,"
            f" p01-p11, p10-p11 must have non-zero length), got corners {c.tolist()}"
        )
    area = patch_area(c)
    diag = max(np.linalg.norm(c[1, 1] - c[0, 0]), np.linalg.norm(c[1, 0] - c[0, 1]))
    if not area > 1e-12 * diag * diag:
        raise ValueError(f"degenerate bilinear patch: zero area (corners {c.tolist()})")
    return c, area


class PatchRecord(NamedTuple):
    """A bilinear patch of the builder (``corners[i, j] = p_ij``)."""

    corners: np.ndarray  # (2, 2, 3)
    material: int
    light: int


def build_patches(entries: list) -> Patches:
    """:class:`Patches` from the builder's records (:class:`PatchRecord`)."""
    if not entries:
        corners = np.full((1, 2, 2, 3), 1e30)
        corners[0, 1, :, 0] += 1e29  # a far-away placeholder that no ray reaches
        corners[0, :, 1, 1] += 1e29
        entries = [PatchRecord(corners[0], 0, -1)]
    return Patches(
        corners=jnp.asarray(np.array([e.corners for e in entries]), jnp.float32),
        material=jnp.asarray(np.array([e.material for e in entries], np.int64), jnp.int32),
        light=jnp.asarray(np.array([e.light for e in entries], np.int64), jnp.int32),
    )

"""Ray intersection in JAX: brute force over all primitives, vmapped over rays by the callers.

Triangles use Moeller & Trumbore (1997); spheres the numerically careful quadratic of
pbrt-v4 / Ray Tracing Gems ch. 7 (the closest root from ``b' = d . (o - c)`` with the
discriminant written as ``r^2 - |(o - c) - b' d|^2``); bilinear patches Reshetov (2019) as in
:mod:`anisosample.render.patch`. The scenes this package ships hold tens of
primitives, for which testing every primitive is faster under XLA than walking a hierarchy;
a scene with many planar primitives (meshes) carries a BVH (:mod:`anisosample.render.bvh`,
``Scene.bvh``), which :func:`intersect` and :func:`occluded` then walk instead. Without one,
a render tests only the candidates of each pixel's tile (``subset=``,
:mod:`anisosample.render.culling`), and the tiles whose rays meet no sphere or patch render
with ``has_spheres`` / ``has_patches`` off (:func:`~anisosample.render.culling.tile_classes`).

Where dof's time went (2026-12-07, 128^2 x 64 spp, pmj02bn, one device, best of 7, load 1.5-2,
ad-hoc scripts; before the tiles without the sphere dropped its tests): 63.9 ms; without its one
sphere (then not culled: every primary and shadow ray tested it) 42.5 ms; with a pinhole instead
of the thin lens 58.7 ms (39.2 without the sphere); cornell 35.3 ms. Tried and not kept: the
hit's single-row gathers (a vmapped ``rows[k]``) written as chains of selects over the rows,
which :mod:`.bvh`'s traversal gained from. For the sphere's centre, material and light dof went
59.9 -> 80.7 ms; for the planar rows as well (attributes, ids, barycentrics, candidate index)
cornell went 30 -> 169-181 ms, dof 60 -> 152-157 ms, attic 66 -> 168-173 ms (the same images but
for float32 rounding on patch_light).

The shadow test's fusion (the reduction over a tile's candidates) takes the shadow ray's whole
computation with it, which XLA could evaluate once per candidate. Forcing the segment into
memory first did not pay (2026-12-07, ad-hoc script, 128^2 x 64 spp, best of 7, load 0.7-0.8,
the same image bits): ``lax.optimization_barrier`` on ``(o, d, lo, hi)`` is dropped before
fusion (the optimized module is unchanged), and a one-trip ``lax.while_loop`` around it gave
dof 69.3 -> 69.8 ms, blinds 56.5 -> 57.6, cornell 48.8 -> 47.5 (noise).
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from ._vec import dot, norm
from .bvh import any_hit, closest_hit, plane_test
from .patch import closest_patch_hit, intersect_patches, patch_frame
from .scene import Scene

_ARGMIN_MAX = 32  # _first_min: argmin up to this many planar primitives
_INF = np.float32(np.inf)  # numpy: importing must not start the XLA backend (jax.distributed)


class Hit(eqx.Module):
    """Closest hit along a ray (``valid`` false: the ray escaped)."""

    valid: Bool[Array, ""]
    t: Float[Array, ""]
    p: Float[Array, "3"]
    n: Float[Array, "3"]  # unit geometric normal of the front side
    uv: Float[Array, "2"]
    material: Int[Array, ""]
    light: Int[Array, ""]  # light primitive index, -1 if the surface does not emit


def _planar_rows(scene: Scene, subset):
    """The rows brute force tests: ``subset``'s candidates, or every planar primitive
    (structure of arrays: every line of plane_test is a vectorised op over them)."""
    return scene.tri_soa if subset is None else subset.soa


def closest_planar(scene: Scene, o, d, tmin, tmax, subset=None):
    """``(t, index, b1, b2)`` of the nearest planar primitive (``t = inf``, index 0: none).

    ``subset``: a :class:`~anisosample.render.culling.Subset` of candidates holding every
    primitive the ray can meet (:func:`~anisosample.render.culling.pixel_view`), tested
    instead of the BVH or of every primitive; None: those."""
    if subset is None and scene.bvh is not None:
        return closest_hit(scene.bvh, o, d, tmin, tmax)
    tt, b1, b2 = plane_test(_planar_rows(scene, subset), o, d)
    tt = jnp.where((tt > tmin) & (tt < tmax), tt, _INF)
    t, k = _first_min(tt)
    it = k if subset is None else jnp.where(jnp.isfinite(t), subset.index[k], 0)
    return t, it, b1[k], b2[k]


def _first_min(tt):
    """``(min(tt), argmin(tt))`` for distances without NaN (misses are ``inf``; index 0 when
    every entry is): ``argmin``'s variadic reduce over at most :data:`_ARGMIN_MAX` primitives,
    above that two plain reductions. Same bits either way. One-device render at 128^2 x 64
    spp, best of 3 (load 1.0-1.2), two reductions / argmin, since the render kernels compile
    without YNNPACK: cornell (18 planar primitives) 82-84 / 75 ms, attic (18) 121 / 115, dof
    (14) 107 / 103, blinds (44) 140 / 167. (Compiled with YNNPACK, f6a79a5 measured blinds with
    argmin 0.226-0.233 s, with two reductions 0.198-0.206 s, and cornell equal.)"""
    if tt.shape[0] <= _ARGMIN_MAX:
        it = jnp.argmin(tt).astype(jnp.int32)
        return tt[it], it
    t = jnp.min(tt)
    return t, jnp.min(jnp.where(tt == t, jnp.arange(tt.shape[0], dtype=jnp.int32),
                                tt.shape[0] - 1))


def _sphere_t(scene: Scene, o, d):
    """Both roots per sphere (inf where missed); ``d`` is a unit vector."""
    oc = o[None, :] - scene.sph_center
    b = dot(oc, d[None, :])
    perp = oc - b[:, None] * d[None, :]
    disc = scene.sph_radius**2 - dot(perp, perp)
    ok = (disc >= 0) & (scene.sph_radius > 0)
    s = jnp.sqrt(jnp.where(ok, disc, 0.0))
    c = dot(oc, oc) - scene.sph_radius**2
    q = -b - jnp.where(b >= 0, s, -s)
    t0 = jnp.where(q != 0, c / jnp.where(q != 0, q, 1.0), 0.0)
    t1 = q
    lo, hi = jnp.minimum(t0, t1), jnp.maximum(t0, t1)
    return jnp.where(ok, lo, _INF), jnp.where(ok, hi, _INF)


def intersect(
    scene: Scene,
    o: Float[Array, "3"],
    d: Float[Array, "3"],
    tmin: float | Array = 0.0,
    tmax: float | Array = jnp.inf,
    subset=None,
) -> Hit:
    """Closest hit with ``tmin < t < tmax``; ``d`` must be a unit vector. ``subset``: the
    planar primitives to test (:func:`closest_planar`; None: all)."""
    t_tri, it, w1, w2 = closest_planar(scene, o, d, tmin, tmax, subset)
    attr = scene.tri_attr[it]  # n, uv0, uv1, uv2: one gather
    ids = scene.tri_ids[it]  # material, light
    uv_tri = (1 - w1 - w2) * attr[3:5] + w1 * attr[5:7] + w2 * attr[7:9]
    if not scene.has_spheres:
        t, n, uv, material, light = t_tri, attr[0:3], uv_tri, ids[0], ids[1]
        valid = jnp.isfinite(t)
        p = o + jnp.where(valid, t, 0.0) * d
    else:
        s0, s1 = _sphere_t(scene, o, d)
        s0 = jnp.where((s0 > tmin) & (s0 < tmax), s0, _INF)
        s1 = jnp.where((s1 > tmin) & (s1 < tmax), s1, _INF)
        ts = jnp.minimum(s0, s1)
        is_ = jnp.argmin(ts)
        t_sph = ts[is_]
        use_sph = t_sph < t_tri
        t = jnp.minimum(t_tri, t_sph)
        valid = jnp.isfinite(t)
        p = o + jnp.where(valid, t, 0.0) * d
        ns = p - scene.sph_center[is_]
        ns = ns / jnp.maximum(norm(ns), 1e-30)
        n = jnp.where(use_sph, ns, attr[0:3])
        uv = jnp.where(use_sph, jnp.zeros(2, jnp.float32), uv_tri)
        material = jnp.where(use_sph, scene.sph_material[is_], ids[0])
        light = jnp.where(use_sph, scene.sph_light[is_], ids[1])
    if scene.has_patches:  # bilinear patches (render/patch.py)
        t_bp, uv_bp, k = closest_patch_hit(scene.patches, o, d, tmin, tmax)
        use_bp = t_bp < t
        t = jnp.minimum(t, t_bp)
        valid = jnp.isfinite(t)
        p = o + jnp.where(valid, t, 0.0) * d
        n = jnp.where(use_bp, patch_frame(scene.patches.corners[k], uv_bp)[0], n)
        uv = jnp.where(use_bp, uv_bp, uv)
        material = jnp.where(use_bp, scene.patches.material[k], material)
        light = jnp.where(use_bp, scene.patches.light[k], light)
    light = jnp.where(valid, light, -1)
    return Hit(valid=valid, t=t, p=p, n=n, uv=uv, material=material, light=light)


def occluded(
    scene: Scene, o: Float[Array, "3"], target: Float[Array, "3"], eps: float = 1e-4,
    subset=None,
) -> Bool[Array, ""]:
    """Whether anything blocks the open segment from ``o`` to ``target``.

    ``eps`` trims both ends of the segment (relative to its length) against self-hits.
    ``subset``: the planar primitives that can block it (:func:`closest_planar`; None: all).
    """
    v = target - o
    dist = norm(v)
    d = v / jnp.maximum(dist, 1e-30)
    lo, hi = dist * eps, dist * (1 - eps)
    inside = lambda t: (t > lo) & (t < hi)
    if subset is None and scene.bvh is not None:  # any hit, stopping at the first (bvh.py)
        blocked = any_hit(scene.bvh, o, d, lo, hi)
    else:
        blocked = jnp.any(inside(plane_test(_planar_rows(scene, subset), o, d)[0]))
    if scene.has_patches:
        blocked = blocked | jnp.any(inside(intersect_patches(scene.patches.corners, o, d)[0]))
    if not scene.has_spheres:
        return blocked
    s0, s1 = _sphere_t(scene, o, d)
    return blocked | jnp.any(inside(s0)) | jnp.any(inside(s1))


def offset_origin(scene: Scene, p, n, towards) -> Float[Array, "3"]:
    """Move a surface point off its surface, to the side of ``towards`` (against self-hits)."""
    side = jnp.where(dot(n, towards) >= 0, 1.0, -1.0)
    return p + (side * 1e-4 * scene.scale) * n

"""Light sampling: uniform emitter selection, then a 2D sample on the chosen emitter.

The 2D sample ``x`` in ``[0, 1)^2`` is the light sample of the per-pixel integrand (W Eq. 8):
``x[0]`` first picks an emitter uniformly (Mitsuba 3's ``sample_emitter``) and, for a mesh
emitter, one of its triangles with probability proportional to area; the remainder of ``x[0]`` is
rescaled to ``[0, 1)`` (sample reuse, pbrt-v4 ``SampleDiscrete``). The point on the primitive is
then, by ``technique``:

* ``"area"``: uniform by area. A parallelogram (Mitsuba ``rectangle``) maps ``x`` affinely
  onto itself, so straight shadow edges on the light stay straight in ``[0, 1)^2``; a triangle
  uses the square-root map (Shirley & Chiu; pbrt-v3 ``UniformSampleTriangle``); a sphere the
  uniform sphere map.
* ``"solid_angle"``: uniform in the solid angle the primitive subtends from the shading point
  (Ureña et al. 2013 for parallelograms, Arvo 1995 for triangles) through
  :mod:`anisosample.warps`, with the area density converted back by ``cos / d^2``.
* ``"parametric"``: uniform in the primitive's own parameters; the same as ``"area"`` except on
  bilinear patches.

Bilinear patches (:mod:`anisosample.render.patch`, H Sec. 4.2) are sampled by their approximate
equal-area warp (``warps.patch_area_warp``'s bilinear warp of the corner area elements) under
``"area"`` and, as in pbrt-v4 for non-rectangular patches, also under ``"solid_angle"``; under
``"parametric"`` uniformly in ``(u, v)`` (area pdf ``1 / |p_u x p_v|``, H Eq. 11).

Densities returned are per unit *area* on the light (including the selection probabilities) so
that the integrator has one formula; point lights have ``delta = True`` and a density equal to
their selection probability.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from ._vec import dot
from .patch import patch_pdf, sample_patch, uv_towards
from .scene import (
    LIGHT_PARALLELOGRAM,
    LIGHT_PATCH,
    LIGHT_POINT,
    LIGHT_SPHERE,
    LIGHT_TRIANGLE,
    Scene,
    Textures,
)

TECHNIQUES = ("area", "solid_angle", "parametric")


class LightSample(eqx.Module):
    p: Float[Array, "3"]
    n: Float[Array, "3"]
    radiance: Float[Array, "3"]  # emitted radiance towards the front (intensity for points)
    pdf: Float[Array, ""]  # per unit area (with selection), or selection prob for points
    delta: Bool[Array, ""]
    prim: Int[Array, ""]


def texture_lookup(textures: Textures, tex, uv) -> Float[Array, "3"]:
    """Bilinear lookup with wrap-around (Mitsuba ``bitmap`` defaults), ``uv = (0, 0)`` at the
    first pixel of the first stored row."""
    w = textures.size[tex, 0]
    h = textures.size[tex, 1]
    u = uv[0] - jnp.floor(uv[0])
    v = uv[1] - jnp.floor(uv[1])
    x = u * w.astype(jnp.float32) - 0.5
    y = v * h.astype(jnp.float32) - 0.5
    x0f, y0f = jnp.floor(x), jnp.floor(y)
    fx, fy = x - x0f, y - y0f
    x0 = jnp.mod(x0f.astype(jnp.int32), w)
    y0 = jnp.mod(y0f.astype(jnp.int32), h)
    x1 = jnp.mod(x0 + 1, w)
    y1 = jnp.mod(y0 + 1, h)
    img = textures.data[tex]
    return (
        (1 - fx) * (1 - fy) * img[y0, x0]
        + fx * (1 - fy) * img[y0, x1]
        + (1 - fx) * fy * img[y1, x0]
        + fx * fy * img[y1, x1]
    )


def emitted(scene: Scene, prim, uv) -> Float[Array, "3"]:
    """Radiance of light primitive ``prim`` at surface coordinates ``uv`` (front side)."""
    lights = scene.lights
    if not scene.has_textures:
        return lights.radiance[prim]
    tex = lights.texture[prim]
    textured = texture_lookup(scene.textures, jnp.maximum(tex, 0), uv)
    return lights.radiance[prim] * jnp.where(tex >= 0, textured, 1.0)


def area_pdf(scene: Scene, prim) -> Float[Array, ""]:
    """Area density of ``technique="area"`` sampling at any point of light primitive ``prim``."""
    lights = scene.lights
    n_em = lights.start.shape[0]
    return lights.prim_prob[prim] / (n_em * jnp.maximum(lights.area[prim], 1e-30))


def select(scene: Scene, x0):
    """Pick an emitter and a primitive from ``x0``; returns ``(prim, remapped x0)``."""
    lights = scene.lights
    if lights.n_prims == 1:  # one emitter, one primitive: static index, no gathers
        return 0, x0
    n_em = lights.start.shape[0]
    xe = x0 * n_em
    e = jnp.clip(jnp.floor(xe).astype(jnp.int32), 0, n_em - 1)
    xr = jnp.clip(xe - e.astype(jnp.float32), 0.0, 1.0)
    mine = lights.emitter == e
    below = jnp.sum(mine & (lights.prim_cdf <= xr))
    prim = jnp.clip(lights.start[e] + below, lights.start[e], lights.start[e] + lights.count[e] - 1)
    lo = lights.prim_cdf[prim] - lights.prim_prob[prim]
    xr = jnp.clip((xr - lo) / jnp.maximum(lights.prim_prob[prim], 1e-30), 0.0, 1.0 - 2.0**-24)
    return prim, xr


def _uv_on(lights, prim, a, b):
    return (
        lights.uv0[prim]
        + a * (lights.uv1[prim] - lights.uv0[prim])
        + b * (lights.uv2[prim] - lights.uv0[prim])
    )


def sample_light(
    scene: Scene, x: Float[Array, "2"], ref: Float[Array, "3"], technique: str = "area"
) -> LightSample:
    """Sample a point on the lights for shading point ``ref`` from ``x`` (see module doc)."""
    lights = scene.lights
    prim, x0 = select(scene, x[0])
    x1 = x[1]
    kind = lights.kind[prim]
    p0, e1, e2 = lights.p0[prim], lights.e1[prim], lights.e2[prim]
    # parallelogram
    p_par = p0 + x0 * e1 + x1 * e2
    uv_par = _uv_on(lights, prim, x0, x1)
    # triangle: b1 = 1 - sqrt(x0) complement, uniform by area
    sq = jnp.sqrt(x0)
    ta, tb = sq * (1 - x1), sq * x1
    p_tri = p0 + ta * e1 + tb * e2
    uv_tri = _uv_on(lights, prim, ta, tb)
    # sphere
    z = 1 - 2 * x0
    r = jnp.sqrt(jnp.maximum(1 - z * z, 0.0))
    phi = 2 * jnp.pi * x1
    dirs = jnp.stack([r * jnp.cos(phi), r * jnp.sin(phi), z])
    p_sph = p0 + e1[0] * dirs
    p = jnp.select(
        [kind == LIGHT_PARALLELOGRAM, kind == LIGHT_TRIANGLE, kind == LIGHT_SPHERE],
        [p_par, p_tri, p_sph],
        p0,
    )
    n = jnp.where(kind == LIGHT_SPHERE, dirs, lights.normal[prim])
    uv = jnp.where(kind == LIGHT_PARALLELOGRAM, uv_par, uv_tri)
    pdf = area_pdf(scene, prim)
    if technique == "solid_angle":
        p, pdf = _solid_angle(scene, prim, x0, x1, ref, p, pdf)
        # uv of the new point on a parallelogram / triangle, by solving in the edge basis
        uv = _uv_of_point(lights, prim, p)
    if scene.has_patches:  # bilinear patch lights (render/patch.py)
        is_bp = kind == LIGHT_PATCH
        c = scene.patches.corners[jnp.maximum(lights.patch[prim], 0)]
        method = "parametric" if technique == "parametric" else "area"
        p_bp, n_bp, uv_bp, pdf_bp = sample_patch(c, jnp.stack([x0, x1]), method)
        p, n, uv = jnp.where(is_bp, p_bp, p), jnp.where(is_bp, n_bp, n), jnp.where(is_bp, uv_bp, uv)
        pdf = jnp.where(is_bp, lights.prim_prob[prim] / lights.start.shape[0] * pdf_bp, pdf)
    delta = kind == LIGHT_POINT
    n_em = lights.start.shape[0]
    pdf = jnp.where(delta, 1.0 / n_em, pdf)
    return LightSample(p=p, n=n, radiance=emitted(scene, prim, uv), pdf=pdf, delta=delta, prim=prim)


def _uv_of_point(lights, prim, p):
    e1, e2 = lights.e1[prim], lights.e2[prim]
    d = p - lights.p0[prim]
    g11, g12, g22 = dot(e1, e1), dot(e1, e2), dot(e2, e2)
    r1, r2 = dot(d, e1), dot(d, e2)
    det = g11 * g22 - g12 * g12
    det = jnp.where(det == 0, 1.0, det)
    a = (g22 * r1 - g12 * r2) / det
    b = (g11 * r2 - g12 * r1) / det
    return _uv_on(lights, prim, a, b)


def _solid_angle(scene, prim, x0, x1, ref, p_area, pdf_area):
    """Solid-angle sampling of parallelograms and triangles via :mod:`anisosample.warps`."""
    from .. import warps  # issue 6; imported lazily so the renderer works without it

    lights = scene.lights
    kind = lights.kind[prim]
    p0, e1, e2, nl = lights.p0[prim], lights.e1[prim], lights.e2[prim], lights.normal[prim]
    u = jnp.stack([x0, x1])
    rect = warps.SphericalRectangle(p0, e1, e2, ref)
    tri = warps.SphericalTriangle(jnp.stack([p0, p0 + e1, p0 + e2]), ref)
    w_r, w_t = rect.sample(u), tri.sample(u)
    w = jnp.where(kind == LIGHT_PARALLELOGRAM, w_r, w_t)
    pdf_sa = jnp.where(kind == LIGHT_PARALLELOGRAM, rect.pdf(w), tri.pdf(w))
    # Where the ray from ref along w meets the primitive's plane.
    denom = dot(w, nl)
    t = dot(p0 - ref, nl) / jnp.where(denom == 0, 1e-30, denom)
    p = ref + t * w
    cos_l = jnp.abs(denom)
    d2 = t * t
    pdf = lights.prim_prob[prim] / lights.start.shape[0] * pdf_sa * cos_l / jnp.maximum(d2, 1e-30)
    valid = jnp.where(kind == LIGHT_PARALLELOGRAM, rect.valid, tri.valid)
    use = ((kind == LIGHT_PARALLELOGRAM) | (kind == LIGHT_TRIANGLE)) & valid
    # Where the warp declines (tiny or degenerate solid angle) fall back to area sampling,
    # as pbrt-v4 does; light_pdf makes the same choice.
    ok = use & jnp.isfinite(pdf) & (pdf > 0) & (t > 0)
    return jnp.where(use, p, p_area), jnp.where(use, jnp.where(ok, pdf, 0.0), pdf_area)


def light_pdf(scene: Scene, prim, p, ref, technique: str = "area") -> Float[Array, ""]:
    """Area density with which :func:`sample_light` produces point ``p`` on ``prim`` (for MIS)."""
    pdf = area_pdf(scene, prim)
    if technique == "solid_angle":
        from .. import warps

        lights = scene.lights
        kind = lights.kind[prim]
        p0, e1, e2, nl = lights.p0[prim], lights.e1[prim], lights.e2[prim], lights.normal[prim]
        v = p - ref
        d2 = dot(v, v)
        w = v / jnp.sqrt(jnp.maximum(d2, 1e-30))
        rect = warps.SphericalRectangle(p0, e1, e2, ref)
        tri = warps.SphericalTriangle(jnp.stack([p0, p0 + e1, p0 + e2]), ref)
        pdf_sa = jnp.where(kind == LIGHT_PARALLELOGRAM, rect.pdf(w), tri.pdf(w))
        conv = pdf_sa * jnp.abs(dot(w, nl)) / jnp.maximum(d2, 1e-30)
        sa = lights.prim_prob[prim] / lights.start.shape[0] * conv
        valid = jnp.where(kind == LIGHT_PARALLELOGRAM, rect.valid, tri.valid)
        use = ((kind == LIGHT_PARALLELOGRAM) | (kind == LIGHT_TRIANGLE)) & valid
        pdf = jnp.where(use, sa, pdf)
    if scene.has_patches:  # bilinear patches: the (u, v) of p from the ray ref -> p
        lights = scene.lights
        c = scene.patches.corners[jnp.maximum(lights.patch[prim], 0)]
        uv, found = uv_towards(c, ref, p)
        method = "parametric" if technique == "parametric" else "area"
        pb = jnp.where(found, patch_pdf(c, uv, method), 0.0)
        sel = lights.prim_prob[prim] / lights.start.shape[0]
        pdf = jnp.where(lights.kind[prim] == LIGHT_PATCH, sel * pb, pdf)
    return pdf

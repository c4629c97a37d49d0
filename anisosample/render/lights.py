"""Light sampling: uniform emitter selection, then a 2D sample on the chosen emitter.

The 2D sample ``x`` in ``[0, 1)^2`` is the light sample of the per-pixel integrand (W Eq. 8):
``x[0]`` first picks an emitter uniformly (Mitsuba 3's ``sample_emitter``) and, for a mesh
emitter, one of its triangles with probability proportional to area; the remainder of ``x[0]`` is
rescaled to ``[0, 1)`` (sample reuse, pbrt-v4 ``SampleDiscrete``). The point on the primitive then
comes from the primitive's warp chain (:mod:`anisosample.render.light_warps`): the base
technique chosen by ``technique``, with the PSS warp of ``light_warp`` in front, all fitted at
the point the rays leave from.

* ``"area"``: uniform by area. A parallelogram (Mitsuba ``rectangle``) maps ``x`` affinely
  onto itself, so straight shadow edges on the light stay straight in ``[0, 1)^2``; a triangle
  uses the square-root map (Shirley & Chiu; pbrt-v3 ``UniformSampleTriangle``); a sphere the
  uniform sphere map.
* ``"solid_angle"``: uniform in the solid angle the primitive subtends from the origin
  (Ureña et al. 2013 for parallelograms, Arvo 1995 for triangles), with the density converted
  to area by ``cos / d^2``. Where the spherical warp declines (a degenerate solid angle, or one
  outside pbrt-v4's range: below 2e-4 sr or above 6.22 sr for triangles, below 1e-4 sr for
  rectangles, :func:`~anisosample.render.light_warps.solid_angle_valid`) both
  :func:`sample_light` and :func:`light_pdf` fall back to area sampling, as pbrt-v4 does.
* ``"parametric"``: uniform in the primitive's own parameters; the same as ``"area"`` except on
  bilinear patches.

Bilinear patches (:mod:`anisosample.render.patch`, H Sec. 4.2) are sampled by their approximate
equal-area warp under ``"area"`` and, as in pbrt-v4 for non-rectangular patches, also under
``"solid_angle"``; under ``"parametric"`` uniformly in ``(u, v)`` (area pdf
``1 / |p_u x p_v|``, H Eq. 11).

Densities returned are per unit *area* on the light (including the selection probabilities) so
that the integrator has one formula; point lights have ``delta = True`` and a density equal to
their selection probability.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.typing import ArrayLike
from jaxtyping import Array, Bool, Float, Int

from ..warps import Compose
from ._vec import dot
from .light_warps import Receiver, chain, solid_angle_valid
from .scene import (
    LIGHT_PARALLELOGRAM,
    LIGHT_PATCH,
    LIGHT_POINT,
    LIGHT_SPHERE,
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
    prim: Int[ArrayLike, ""]  # a static 0 where the scene has one emitting primitive


def texture_lookup(textures: Textures, tex, uv) -> Float[Array, "3"]:
    """Bilinear lookup with wrap-around (Mitsuba ``bitmap`` defaults), ``uv = (0, 0)`` at the
    first pixel of the first stored row: one gather of the texel's quad (:class:`~anisosample.
    render.scene.Textures`). Against four gathers of one texel each and the indices wrapped by
    integer ``mod``, attic at 128^2 x 64 spp took 80-82 ms, with one gather 73-76 ms, and with
    the one wrap left as a select 69 ms (a lookup returning a constant: 55-59 ms; one device,
    the smallest of 15 renders in each of two processes per variant, 2026-12-07)."""
    w = textures.size[tex, 0]
    h = textures.size[tex, 1]
    u = uv[0] - jnp.floor(uv[0])
    v = uv[1] - jnp.floor(uv[1])
    x = u * w.astype(jnp.float32) - 0.5
    y = v * h.astype(jnp.float32) - 0.5
    x0f, y0f = jnp.floor(x), jnp.floor(y)
    fx, fy = x - x0f, y - y0f
    # u, v in [0, 1]: x0 in [-1, w - 1], and only -1 wraps.
    x0 = x0f.astype(jnp.int32)
    y0 = y0f.astype(jnp.int32)
    x0 = jnp.where(x0 < 0, x0 + w, x0)
    y0 = jnp.where(y0 < 0, y0 + h, y0)
    q = textures.quad[tex, y0, x0]
    return ((1 - fx) * (1 - fy) * q[0:3] + fx * (1 - fy) * q[3:6]
            + (1 - fx) * fy * q[6:9] + fx * fy * q[9:12])


def emitted(scene: Scene, prim, uv) -> Float[Array, "3"]:
    """Radiance of light primitive ``prim`` at surface coordinates ``uv`` (front side)."""
    lights = scene.lights
    if not scene.has_textures:
        return lights.radiance[prim]
    tex = lights.texture[prim]
    textured = texture_lookup(scene.textures, jnp.maximum(tex, 0), uv)
    return lights.radiance[prim] * jnp.where(tex >= 0, textured, 1.0)


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


def _uv_of_point(lights, prim, p):
    """Texture coordinates of point ``p`` of a parallelogram or triangle (its edge basis)."""
    e1, e2 = lights.e1[prim], lights.e2[prim]
    d = p - lights.p0[prim]
    g11, g12, g22 = dot(e1, e1), dot(e1, e2), dot(e2, e2)
    r1, r2 = dot(d, e1), dot(d, e2)
    det = g11 * g22 - g12 * g12
    det = jnp.where(det == 0, 1.0, det)
    a = (g22 * r1 - g12 * r2) / det
    b = (g11 * r2 - g12 * r1) / det
    uv0 = lights.uv0[prim]
    return uv0 + a * (lights.uv1[prim] - uv0) + b * (lights.uv2[prim] - uv0)


def _area_point(shape: int, lights, prim, u):
    """Uniform-by-area point of a parallelogram or triangle (the solid-angle fallback)."""
    p0, e1, e2 = lights.p0[prim], lights.e1[prim], lights.e2[prim]
    if shape == LIGHT_PARALLELOGRAM:
        return p0 + u[0] * e1 + u[1] * e2
    s = jnp.sqrt(u[0])
    return p0 + s * (1 - u[1]) * e1 + s * u[1] * e2


def _sample_shape(scene: Scene, shape: int, prim, u, rec: Receiver, technique, light_warp):
    """``(p, n, uv, pdf)`` on primitive ``prim`` of static ``shape``; ``pdf`` per unit area on
    the primitive (without the selection probability)."""
    lights = scene.lights
    p0 = lights.p0[prim]
    if shape == LIGHT_POINT:
        return p0, lights.normal[prim], jnp.zeros(2, jnp.float32), jnp.ones((), jnp.float32)
    if shape == LIGHT_SPHERE:  # uniform by area
        z = 1 - 2 * u[0]
        r = jnp.sqrt(jnp.maximum(1 - z * z, 0.0))
        phi = 2 * jnp.pi * u[1]
        n = jnp.stack([r * jnp.cos(phi), r * jnp.sin(phi), z])
        return p0 + lights.e1[prim][0] * n, n, jnp.zeros(2, jnp.float32), _inv_area(lights, prim)
    warp = chain(scene, shape, prim, rec, technique, light_warp)
    steps = warp.warps if isinstance(warp, Compose) else (warp,)
    y, pdf = u, jnp.ones((), jnp.float32)
    for w in steps[:-1]:  # H Algorithm 1, keeping the last warp's input (a patch's (u, v))
        y, j = w.sample_and_pdf(y)
        pdf = pdf * j
    x, j = steps[-1].sample_and_pdf(y)
    pdf = pdf * j
    if shape == LIGHT_PATCH:
        return x, steps[-1].normal(y), y, pdf
    nl = lights.normal[prim]
    if warp.measure == "solid angle":  # where the ray origin + t x meets the light's plane
        denom = dot(x, nl)
        t = dot(p0 - rec.origin, nl) / jnp.where(denom == 0, 1e-30, denom)
        p = rec.origin + t * x
        pdf = _solid_angle_to_area(pdf, x, nl, t * t)
        pdf = jnp.where(jnp.isfinite(pdf) & (pdf > 0) & (t > 0), pdf, 0.0)
        p = jnp.where(solid_angle_valid(warp), p, _area_point(shape, lights, prim, u))
        pdf = _or_area_fallback(warp, pdf, lights, prim)
    else:
        p = x
    uv = _uv_of_point(lights, prim, p) if scene.has_textures else jnp.zeros(2, jnp.float32)
    return p, nl, uv, pdf


def _inv_area(lights, prim):
    return 1.0 / jnp.maximum(lights.area[prim], 1e-30)


def _solid_angle_to_area(pdf_sa, w, n_light, d2):
    """A density per steradian at unit direction ``w`` to one per unit area on the light's
    plane at squared distance ``d2``: ``pdf |cos theta_l| / d^2`` (pbrt-v4 ``PDF_Li``)."""
    return pdf_sa * jnp.abs(dot(w, n_light)) / jnp.maximum(d2, 1e-30)


def _or_area_fallback(warp, pdf, lights, prim):
    """Where the spherical warp declines (a tiny or degenerate solid angle) both
    :func:`sample_light` and :func:`light_pdf` use area sampling, density ``1 / A``."""
    return jnp.where(solid_angle_valid(warp), pdf, _inv_area(lights, prim))


def _by_shape(scene: Scene, prim, per_shape):
    """``per_shape(shape)`` for the shapes present in the scene, selected by ``prim``'s shape."""
    shapes = scene.lights.shapes
    outs = [per_shape(k) for k in shapes]
    if len(shapes) == 1:
        return outs[0]
    which = scene.lights.shape[prim]
    conds = [which == k for k in shapes]
    return jax.tree.map(lambda *xs: jnp.select(conds, list(xs), xs[-1]), *outs)


def _receiver(rec_or_origin) -> Receiver:
    if isinstance(rec_or_origin, Receiver):
        return rec_or_origin
    o = jnp.asarray(rec_or_origin, jnp.float32)  # an origin only: enough for light_warp="none"
    z = jnp.zeros(3, jnp.float32)
    return Receiver(origin=o, n=z, wi=z, material=jnp.zeros((), jnp.int32))


def sample_light(
    scene: Scene,
    x: Float[Array, "2"],
    rec: Receiver | Float[Array, "3"],
    technique: str = "area",
    light_warp: str = "none",
) -> LightSample:
    """Sample a point on the lights for receiver ``rec`` from ``x`` (see the module doc).

    ``rec``: the :class:`~anisosample.render.light_warps.Receiver` (or, for ``light_warp="none"``,
    just the origin of the rays).
    """
    rec = _receiver(rec)
    lights = scene.lights
    prim, x0 = select(scene, x[0])
    u = jnp.stack([x0, x[1]])
    p, n, uv, pdf = _by_shape(
        scene, prim, lambda k: _sample_shape(scene, k, prim, u, rec, technique, light_warp)
    )
    delta = lights.shape[prim] == LIGHT_POINT
    n_em = lights.start.shape[0]
    pdf = jnp.where(delta, 1.0 / n_em, pdf * lights.prim_prob[prim] / n_em)
    return LightSample(p=p, n=n, radiance=emitted(scene, prim, uv), pdf=pdf, delta=delta, prim=prim)


def _pdf_shape(scene: Scene, shape: int, prim, p, rec: Receiver, technique, light_warp):
    lights = scene.lights
    if shape == LIGHT_POINT:  # no ray hits a point light
        return jnp.zeros((), jnp.float32)
    if shape == LIGHT_SPHERE:
        return _inv_area(lights, prim)
    warp = chain(scene, shape, prim, rec, technique, light_warp)
    if warp.measure != "solid angle":
        return warp.pdf(p)  # H Algorithm 2
    v = p - rec.origin
    d2 = jnp.maximum(dot(v, v), 1e-30)
    w = v * jax.lax.rsqrt(d2)
    pdf = _solid_angle_to_area(warp.pdf(w), w, lights.normal[prim], d2)  # H Algorithm 2
    return _or_area_fallback(warp, pdf, lights, prim)


def light_pdf(
    scene: Scene,
    prim,
    p: Float[Array, "3"],
    rec: Receiver | Float[Array, "3"],
    technique: str = "area",
    light_warp: str = "none",
) -> Float[Array, ""]:
    """Area density with which :func:`sample_light` produces point ``p`` on ``prim`` for the
    same receiver (for MIS): H Algorithm 2 through the same chain from the same origin."""
    rec = _receiver(rec)
    lights = scene.lights
    pdf = _by_shape(scene, prim,
                    lambda k: _pdf_shape(scene, k, prim, p, rec, technique, light_warp))
    return pdf * lights.prim_prob[prim] / lights.start.shape[0]

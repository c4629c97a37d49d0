"""Light-sampling techniques as warp chains, fitted where the rays leave (H Secs. 3-4).

After :func:`anisosample.render.lights.select` has picked a light primitive, the remaining 2D
sample ``u`` goes through a chain of :mod:`anisosample.warps` (H Eqs. 2-6, Algorithm 1) that ends
in the primitive's *base technique* (``technique``):

* parallelogram: ``"area"`` / ``"parametric"`` uniform by area (``warps.Parallelogram``);
  ``"solid_angle"`` uniform in solid angle (Urena et al. 2013, ``warps.SphericalRectangle``);
* triangle: uniform by area (square-root map, ``warps.TriangleArea``); ``"solid_angle"``
  Arvo 1995 (``warps.SphericalTriangle``);
* bilinear patch: ``"area"`` (and, as in pbrt-v4, ``"solid_angle"``) the approximate equal-area
  warp of H Sec. 4.2 (a ``Bilinear`` of the corner area elements, then the patch);
  ``"parametric"`` uniform in ``(u, v)``;
* spheres and point lights have no chain (see :mod:`~anisosample.render.lights`).

``light_warp`` (:data:`LIGHT_WARPS`) chooses what comes in front of, or instead of, the base:

* ``"none"``: the base technique alone;
* ``"cosine-bilinear"``, ``"cosine-biquadratic"``: a PSS warp fitted point-wise (H Eq. 9) to the
  receiver cosine ``max(n . w, 0)``, ``w`` the direction from the origin to the base's output
  (H Sec. 4.1). Control points at or below the horizon are clamped to 0.01 of the largest value
  (``warps.fit_pointwise``'s ``floor``; pbrt-v4 takes ``max(0.01, |cos|)``, which gives a corner
  far below the horizon the weight of one above it), so the density stays positive wherever
  the cosine might not vanish inside the cell; a light wholly below the horizon gets the
  uniform warp (all values 0);
* ``"product-bilinear"``, ``"product-biquadratic"``, ``"product-tabulated"``: fitted to the BSDF
  times that cosine (luminance of ``bsdf.eval_bsdf``), H Sec. 4.3; ``tabulated`` is the 32x32
  reference (``warps.fit_tabulated``);
* ``"arvo2001"``: exact cosine-weighted spherical-triangle sampling (Arvo 2001,
  ``warps.CosineSphericalTriangle``) instead of the base, triangle lights only. Where a vertex
  lies below the receiver's horizon the cosine-weighted warp is not defined (clipping is not
  implemented); there the cosine is taken about the light plane's normal (every vertex is above
  that axis), which keeps the technique exact and unbiased but no longer cosine-proportional;
* ``"projected-solid-angle"``: exact cosine-weighted sampling of the light's polygon clipped to
  the receiver's horizon (Peters 2021, ``warps.ProjectedSphericalPolygon``) instead of the base,
  triangle and parallelogram lights; with light sampling alone an unoccluded diffuse receiver
  gets zero variance, also where the light dips below its horizon (``technique`` is ignored);
* ``"ltc"``: the GGX lobe's linearly transformed cosine (Heitz et al. 2016, fitted by
  :mod:`~anisosample.render.ltc`) restricted to the light's polygon, sampled exactly
  (``warps.LTCPolygon``, Peters 2021's pairing) instead of the base, triangle and parallelogram
  lights; conductors only, other materials get the clamped cosine (= ``"projected-solid-angle"``);
* ``"patch-three-warp"``: H Sec. 4.2's chain (``warps.patch_three_warp``) instead of the base,
  bilinear-patch lights only;
* a callable ``make(base, receiver) -> warp`` (your own chain): given the base warp of the
  primitive and the :class:`Receiver`, it returns the chain (ending in ``base``) to sample and
  evaluate, e.g. ``lambda base, rec: warps.compose(warps.fit_pointwise(...), base)``. It must
  be hashable (a function; it is a static argument of the jitted kernels).

One shading frame (:class:`Receiver`): the chain is fitted at the offset point every ray leaves
from, the light sample is drawn from there and the BSDF sample's light pdf is H Algorithm 2
through the same chain from the same point. (Fitting at the surface point while tracing from the
offset point loses the samples near the light's edges and gives BSDF samples that hit the light
a light pdf of 0.)
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from .. import warps as W
from .._validate import renamed_keywords
from ._vec import dot, norm
from .bsdf import eval_bsdf
from .patch import SeenPatch
from .scene import (
    LIGHT_PARALLELOGRAM,
    LIGHT_PATCH,
    LIGHT_POINT,
    LIGHT_SHAPE_NAMES,
    LIGHT_TRIANGLE,
    LUMINANCE,
    Scene,
)

LIGHT_WARPS = (
    "none",
    "cosine-bilinear",
    "cosine-biquadratic",
    "arvo2001",
    "product-bilinear",
    "product-biquadratic",
    "product-tabulated",
    "patch-three-warp",
    "projected-solid-angle",
    "ltc",
)
_FITTED = (LIGHT_PARALLELOGRAM, LIGHT_TRIANGLE, LIGHT_PATCH)
APPLIES_TO = {
    "arvo2001": (LIGHT_TRIANGLE,),
    "patch-three-warp": (LIGHT_PATCH,),
    "projected-solid-angle": (LIGHT_TRIANGLE, LIGHT_PARALLELOGRAM),
    "ltc": (LIGHT_TRIANGLE, LIGHT_PARALLELOGRAM),
    **{name: _FITTED for name in LIGHT_WARPS[1:]
       if name not in ("arvo2001", "patch-three-warp", "projected-solid-angle", "ltc")},
}


class Receiver(eqx.Module):
    """The shading frame of one light sample: where the rays leave and what they leave from.

    ``origin`` is the offset point (``geometry.offset_origin``) of every shadow and BSDF ray;
    ``n`` the geometric normal of the front side and ``wi`` the direction to the viewer, as
    ``bsdf.eval_bsdf`` takes them; ``material`` the surface's material.
    """

    origin: Float[Array, "3"]
    n: Float[Array, "3"]
    wi: Float[Array, "3"]
    material: Int[Array, ""]

    def facing_normal(self) -> Float[Array, "3"]:
        """The normal on the side of ``wi`` (the hemisphere the reflected light comes from)."""
        return jnp.where(dot(self.n, self.wi) < 0, -self.n, self.n)


def check_light_warp(scene: Scene, light_warp: str) -> str:
    """``light_warp`` if it is a name of :data:`LIGHT_WARPS` and applies to every area light of
    ``scene``; ``ValueError`` naming the light otherwise (before tracing)."""
    from .._validate import check_choice

    if callable(light_warp):
        allowed, label = _FITTED, "a callable light_warp"
    else:
        check_choice("light_warp", light_warp, LIGHT_WARPS)
        if light_warp == "none":
            return light_warp
        allowed, label = APPLIES_TO[light_warp], f"light_warp={light_warp!r}"
    shapes = np.asarray(scene.lights.shape)
    emitters = np.asarray(scene.lights.emitter)
    names = " and ".join(LIGHT_SHAPE_NAMES[k] for k in allowed)
    for i, k in enumerate(shapes):
        if int(k) != LIGHT_POINT and int(k) not in allowed:
            raise ValueError(
                f"{label} applies to {names} lights only; light primitive {i}"
                f" (emitter {int(emitters[i])}) is a {LIGHT_SHAPE_NAMES[int(k)]}"
            )
    if not np.any(np.isin(shapes, allowed)):
        raise ValueError(
            f"{label} applies to {names} lights; this scene has"
            " only point lights (nothing to warp)"
        )
    return light_warp


@renamed_keywords(kind="shape")
def base_warp(scene: Scene, shape: int, prim, origin, technique: str) -> W.AbstractWarp:
    """The base technique of light primitive ``prim`` of (static) ``shape`` seen from ``origin``."""
    lights = scene.lights
    p0, e1, e2 = lights.p0[prim], lights.e1[prim], lights.e2[prim]
    solid = technique == "solid_angle"
    if shape == LIGHT_PARALLELOGRAM:
        return W.SphericalRectangle(p0, e1, e2, origin) if solid else W.Parallelogram(p0, e1, e2)
    if shape == LIGHT_TRIANGLE:
        verts = jnp.stack([p0, p0 + e1, p0 + e2])
        return W.SphericalTriangle(verts, origin) if solid else W.TriangleArea(verts)
    if shape == LIGHT_PATCH:
        patch = _patch(scene, prim, origin)
        if technique == "parametric":
            return patch
        return W.Compose(W.Bilinear(patch.corner_area_elements()), patch)
    raise ValueError(f"no warp chain for light shape {LIGHT_SHAPE_NAMES.get(shape, shape)!r}")


def _polygon(scene: Scene, shape: int, prim) -> Array:
    """The vertices of a triangle (3) or parallelogram (4) light primitive, in order."""
    lights = scene.lights
    p0, e1, e2 = lights.p0[prim], lights.e1[prim], lights.e2[prim]
    if shape == LIGHT_PARALLELOGRAM:
        return jnp.stack([p0, p0 + e1, p0 + e1 + e2, p0 + e2])
    return jnp.stack([p0, p0 + e1, p0 + e2])


def _patch(scene, prim, origin) -> SeenPatch:
    return SeenPatch(scene.patches.corners[jnp.maximum(scene.lights.patch[prim], 0)], origin)


def _towards(warp, origin):
    """The direction from ``origin`` to an output ``x`` of ``warp`` (a direction already, or a
    point)."""
    if warp.measure == "solid angle":
        return lambda x: x

    def direction(x):
        v = x - origin
        return v / jnp.maximum(norm(v), 1e-30)

    return direction


def light_warp_name(light_warp) -> str:
    """The name a render records for ``light_warp`` (a callable's ``__name__``)."""
    return light_warp if isinstance(light_warp, str) else getattr(
        light_warp, "__name__", "custom")


@renamed_keywords(kind="shape")
def chain(
    scene: Scene, shape: int, prim, rec: Receiver, technique: str, light_warp
) -> W.AbstractWarp:
    """The warp chain of ``light_warp`` on primitive ``prim`` (static ``shape``) for ``rec``:
    maps ``u`` in ``[0, 1]^2`` to a direction (``measure == "solid angle"``) or a point on the
    light (``"area"``); its ``pdf`` is H Algorithm 2."""
    nf = rec.facing_normal()
    if light_warp == "arvo2001":
        lights = scene.lights
        p0, e1, e2 = lights.p0[prim], lights.e1[prim], lights.e2[prim]
        verts = jnp.stack([p0, p0 + e1, p0 + e2])
        d = verts - rec.origin[None, :]
        above = jnp.all(d @ nf > 1e-6 * jnp.sqrt(jnp.sum(d * d, axis=-1)))
        nl = lights.normal[prim]
        axis = jnp.where(dot(p0 - rec.origin, nl) >= 0, nl, -nl)  # towards the light's plane
        return W.CosineSphericalTriangle(verts, rec.origin, jnp.where(above, nf, axis))
    if light_warp == "projected-solid-angle":
        return W.ProjectedSphericalPolygon(_polygon(scene, shape, prim), rec.origin, nf)
    if light_warp == "ltc":
        from .ltc import frame as ltc_frame
        from .ltc import m_inv_for

        m_inv = m_inv_for(scene.materials, rec.material, nf, rec.wi)
        return W.LTCPolygon(_polygon(scene, shape, prim), rec.origin, ltc_frame(nf, rec.wi), m_inv)
    if light_warp == "patch-three-warp":
        return W.patch_three_warp(_patch(scene, prim, rec.origin), rec.origin, nf)
    base = base_warp(scene, shape, prim, rec.origin, technique)
    if callable(light_warp):
        return light_warp(base, rec)
    if light_warp == "none":
        return base
    later = list(base.warps) if isinstance(base, W.Compose) else [base]
    towards = _towards(base, rec.origin)
    if light_warp.startswith("cosine-"):

        def factor(x):
            return jnp.maximum(dot(nf, towards(x)), 0.0)
    else:
        mats, lum = scene.materials, jnp.asarray(LUMINANCE, jnp.float32)

        def factor(x):  # BSDF x cosine (eval_bsdf includes the cosine), luminance
            return dot(eval_bsdf(mats, rec.material, rec.n, rec.wi, towards(x)), lum)

    if light_warp == "product-tabulated":
        fitted = W.fit_tabulated(factor, later)
    else:
        kind_ = W.Bilinear if light_warp.endswith("-bilinear") else W.Biquadratic
        fitted = W.fit_pointwise(kind_, factor, later)
    return W.Compose(fitted, *later)


MIN_SPHERICAL_SAMPLE_AREA = {"triangle": 2e-4, "rectangle": 1e-4}
"""Below these solid angles (sr) a spherical triangle / rectangle is sampled by area instead
(pbrt-v4 ``Triangle::MinSphericalSampleArea``, ``BilinearPatch::MinSphericalSampleArea``): a
light that small contributes little, and float32 spherical sampling loses accuracy there (the
rectangle's solid angle from its corner angles is off by 1.5e-4 relative at 3e-4 sr and 1.4e-3
at 3.3e-5 sr; ``tests/render/test_light_robustness.py``)."""
MAX_SPHERICAL_SAMPLE_AREA = {"triangle": 6.22}
"""Above this solid angle (sr) a spherical triangle is sampled by area instead (pbrt-v4
``Triangle::MaxSphericalSampleArea``: near a hemisphere BSDF sampling is the better strategy
anyway, and the conversion to area density ``cos / d^2`` at grazing points has little
precision). pbrt-v4 has no upper limit for rectangles, nor do we."""


def solid_angle_valid(warp) -> Array | bool:
    """Whether a solid-angle chain is usable; the renderer falls back to area sampling (density
    ``1 / A``, the warps in front of the base dropped) where it is not, as pbrt-v4 does: the
    spherical base must subtend a positive solid angle from the origin (the warp's own
    ``valid``), and a spherical triangle (also the one Arvo 2001's warp is built on) or rectangle
    one inside ``[MIN_SPHERICAL_SAMPLE_AREA, MAX_SPHERICAL_SAMPLE_AREA]``. The projected-solid-
    angle warp has only its own ``valid`` (Peters' sectors stay float32-accurate down to
    ``warps.polygon.MIN_PROJECTED_SOLID_ANGLE``)."""
    last = warp.warps[-1] if isinstance(warp, W.Compose) else warp
    last = getattr(last, "triangle", last)  # CosineSphericalTriangle wraps a SphericalTriangle
    ok = getattr(last, "valid", True)
    if isinstance(last, W.SphericalTriangle):
        sa = last.solid_angle
        ok = ok & (sa >= MIN_SPHERICAL_SAMPLE_AREA["triangle"])
        ok = ok & (sa <= MAX_SPHERICAL_SAMPLE_AREA["triangle"])
    elif isinstance(last, W.SphericalRectangle):
        ok = ok & (last.solid_angle >= MIN_SPHERICAL_SAMPLE_AREA["rectangle"])
    return ok

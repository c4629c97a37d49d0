"""BSDFs: Lambertian ``diffuse``, GGX ``roughconductor`` and ``roughplastic`` (Mitsuba 3).

Each BSDF is a triplet (STYLE): ``eval`` (the BSDF times the cosine at ``wo``), ``pdf`` (per
steradian) and ``sample``. ``wi`` points towards the viewer, ``wo`` towards the light, both unit
vectors in world space; ``n`` is the surface's front normal. BSDFs are one-sided (zero unless
both directions lie on the front side) unless the material is two-sided, in which case the
normal is flipped to the side of ``wi``.

GGX (Trowbridge & Reitz 1975; Walter et al. 2007): ``D(m) = a^2 / (pi cos^4 (a^2 + tan^2)^2)``,
separable Smith ``G = G1(wi) G1(wo)``, ``G1(v) = 2 / (1 + sqrt(1 + a^2 tan^2 theta_v))``;
sampled with visible normals (Heitz 2018). Conductor Fresnel: the exact unpolarised formula for a
complex index ``eta + i k`` (as in pbrt-v3's ``FrConductor`` and Mitsuba's
``fresnel_conductor``). ``f = F D G / (4 cos_i cos_o)``. ``roughplastic`` (GGX or Beckmann,
with Mitsuba's rough-interface transmittance tables) lives in :mod:`.plastic`.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float

from . import plastic
from ._vec import cross, dot, norm
from .scene import CONDUCTOR, DIFFUSE, PLASTIC, Materials


def frame(n):
    """Orthonormal basis ``(s, t)`` around unit ``n`` (Duff et al. 2017)."""
    sign = jnp.where(n[2] >= 0, 1.0, -1.0)
    a = -1.0 / (sign + n[2])
    b = n[0] * n[1] * a
    s = jnp.stack([1 + sign * n[0] * n[0] * a, sign * b, -sign * n[0]])
    t = jnp.stack([b, sign + n[1] * n[1] * a, -n[1]])
    return s, t


def _to_local(v, s, t, n):
    return jnp.stack([dot(v, s), dot(v, t), dot(v, n)])


def ggx_d(m, alpha):
    """GGX normal distribution, per steradian of microfacet normal (``m`` local, unit)."""
    a2 = alpha * alpha
    c2 = m[2] * m[2]
    denom = c2 * (a2 - 1) + 1
    return jnp.where(m[2] > 0, a2 / (jnp.pi * denom * denom), 0.0)


def ggx_g1(v, m, alpha):
    c2 = jnp.maximum(v[2] * v[2], 1e-20)
    tan2 = jnp.maximum(1 - c2, 0.0) / c2
    g = 2.0 / (1 + jnp.sqrt(1 + alpha * alpha * tan2))
    return jnp.where(dot(v, m) * v[2] > 0, g, 0.0)


def fresnel_conductor(cos_i, eta, k):
    """Unpolarised Fresnel reflectance of a conductor with complex IOR ``eta + i k`` (RGB)."""
    c2 = cos_i * cos_i
    s2 = 1 - c2
    s4 = s2 * s2
    temp1 = eta * eta - k * k - s2
    a2pb2 = jnp.sqrt(jnp.maximum(temp1 * temp1 + 4 * k * k * eta * eta, 0.0))
    a = jnp.sqrt(jnp.maximum(0.5 * (a2pb2 + temp1), 0.0))
    term1 = a2pb2 + c2
    term2 = 2 * cos_i * a
    rs = (term1 - term2) / (term1 + term2)
    term3 = a2pb2 * c2 + s4
    term4 = term2 * s2
    rp = rs * (term3 - term4) / (term3 + term4)
    return 0.5 * (rs + rp)


def plastic_parameters(materials: Materials, mat) -> dict:
    """Material ``mat``'s roughplastic parameters as :mod:`anisosample.render.plastic`'s
    ``eval_plastic``, ``pdf_plastic`` and ``sample_plastic`` take them (a dict of arrays)."""
    return dict(
        alpha=materials.alpha[mat],
        eta=materials.eta[mat, 0],
        specular=materials.specular[mat],
        reflectance=materials.reflectance[mat],
        transmittance=materials.transmittance[mat],
        internal=materials.internal[mat],
        spec_weight=materials.spec_weight[mat],
        flags=materials.flags[mat],
        beckmann=materials.distribution[mat] == plastic.BECKMANN,
    )


def _local(materials: Materials, mat, n, wi, wo):
    two = materials.twosided[mat] > 0
    n = jnp.where(two & (dot(n, wi) < 0), -n, n)
    s, t = frame(n)
    return _to_local(wi, s, t, n), _to_local(wo, s, t, n), (s, t, n)


def eval_bsdf(materials: Materials, mat, n, wi, wo) -> Float[Array, "3"]:
    """BSDF value times ``cos(theta_o)`` (RGB)."""
    li, lo, _ = _local(materials, mat, n, wi, wo)
    ok = (li[2] > 0) & (lo[2] > 0)
    material = materials.material[mat]
    diffuse = materials.reflectance[mat] * (lo[2] / jnp.pi)
    if not materials.has_glossy:
        return jnp.where(ok, diffuse, 0.0)
    alpha = materials.alpha[mat]
    h = li + lo
    h = h / jnp.maximum(norm(h), 1e-30)
    d = ggx_d(h, alpha)
    g = ggx_g1(li, h, alpha) * ggx_g1(lo, h, alpha)
    f = fresnel_conductor(dot(li, h), materials.eta[mat], materials.k[mat])
    cond = materials.specular[mat] * f * (d * g / (4 * jnp.maximum(li[2], 1e-20)))
    val = jnp.where(material == DIFFUSE, diffuse, jnp.where(material == CONDUCTOR, cond, 0.0))
    if materials.has_plastic:
        val = jnp.where(material == PLASTIC,
                        plastic.eval_plastic(plastic_parameters(materials, mat), li, lo), val)
    return jnp.where(ok, val, 0.0)


def pdf_bsdf(materials: Materials, mat, n, wi, wo) -> Float[Array, ""]:
    """Solid-angle density of :func:`sample_bsdf` at ``wo``."""
    li, lo, _ = _local(materials, mat, n, wi, wo)
    ok = (li[2] > 0) & (lo[2] > 0)
    alpha = materials.alpha[mat]
    h = li + lo
    h = h / jnp.maximum(norm(h), 1e-30)
    # Visible-normal density D_wi(h) = G1(wi) max(0, wi.h) D(h) / cos_i, then / (4 wo.h).
    vis = (
        ggx_g1(li, h, alpha)
        * jnp.maximum(dot(li, h), 0.0)
        * ggx_d(h, alpha)
        / jnp.maximum(li[2], 1e-20)
    )
    cond = vis / (4 * jnp.maximum(dot(lo, h), 1e-20))
    p = jnp.where(materials.material[mat] == DIFFUSE, lo[2] / jnp.pi, cond)
    if materials.has_plastic:
        p = jnp.where(materials.material[mat] == PLASTIC,
                      plastic.pdf_plastic(plastic_parameters(materials, mat), li, lo), p)
    return jnp.where(ok, p, 0.0)


def _sample_ggx_vndf(wi, alpha, u):
    # Heitz 2018, "Sampling the GGX Distribution of Visible Normals".
    vh = jnp.stack([alpha * wi[0], alpha * wi[1], wi[2]])
    vh = vh / norm(vh)
    lensq = vh[0] ** 2 + vh[1] ** 2
    inv = jnp.where(lensq > 0, 1 / jnp.sqrt(jnp.where(lensq > 0, lensq, 1.0)), 0.0)
    t1v = jnp.where(
        lensq > 0,
        jnp.stack([-vh[1] * inv, vh[0] * inv, jnp.float32(0)]),
        jnp.array([1.0, 0.0, 0.0], jnp.float32),
    )
    t2v = cross(vh, t1v)
    r = jnp.sqrt(u[0])
    phi = 2 * jnp.pi * u[1]
    t1, t2 = r * jnp.cos(phi), r * jnp.sin(phi)
    s = 0.5 * (1 + vh[2])
    t2 = (1 - s) * jnp.sqrt(jnp.maximum(1 - t1 * t1, 0.0)) + s * t2
    nh = t1 * t1v + t2 * t2v + jnp.sqrt(jnp.maximum(1 - t1 * t1 - t2 * t2, 0.0)) * vh
    m = jnp.stack([alpha * nh[0], alpha * nh[1], jnp.maximum(nh[2], 0.0)])
    return m / jnp.maximum(norm(m), 1e-30)


def sample_ggx_vndf(wi, alpha, u):
    """A GGX visible normal for the local view ``wi`` (Heitz 2018), as :func:`sample_bsdf` draws
    it (the LTC fit, :mod:`.ltc`, probes the lobe with it)."""
    return _sample_ggx_vndf(wi, alpha, u)


def sample_bsdf(materials: Materials, mat, n, wi, u: Float[Array, "2"]):
    """Sample ``wo`` (world) for the BSDF at ``n`` seen from ``wi``: ``(wo, pdf)``.

    Diffuse: cosine-weighted hemisphere (Malley's method); conductor: GGX visible normals;
    plastic: the lobe mixture of :func:`.plastic.sample_plastic`.
    ``pdf`` is 0 where no valid direction came out.
    """
    two = materials.twosided[mat] > 0
    n = jnp.where(two & (dot(n, wi) < 0), -n, n)
    s, t = frame(n)
    li = _to_local(wi, s, t, n)
    # Malley: uniform disk point lifted to the hemisphere.
    r = jnp.sqrt(u[0])
    phi = 2 * jnp.pi * u[1]
    lo_d = jnp.stack([r * jnp.cos(phi), r * jnp.sin(phi), jnp.sqrt(jnp.maximum(1 - u[0], 0.0))])
    m = _sample_ggx_vndf(li, materials.alpha[mat], u)
    lo_c = 2 * dot(li, m) * m - li
    lo = jnp.where(materials.material[mat] == DIFFUSE, lo_d, lo_c)
    if materials.has_plastic:
        lo_p = plastic.sample_plastic(plastic_parameters(materials, mat), li, u, _sample_ggx_vndf)
        lo = jnp.where(materials.material[mat] == PLASTIC, lo_p, lo)
    wo = lo[0] * s + lo[1] * t + lo[2] * n
    p = pdf_bsdf(materials, mat, n, wi, wo)
    return wo, jnp.where(li[2] > 0, p, 0.0)

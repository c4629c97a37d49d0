"""Mitsuba 3's ``roughplastic``: a diffuse base under a rough dielectric coating.

The model (Mitsuba 3 ``roughplastic``, ``src/bsdfs/roughplastic.cpp``), with ``wi`` towards
the viewer, ``wo`` towards the light, both in the local frame of the front normal and above it,
``eta = int_ior / ext_ior`` and ``H`` the half vector:

``f cos_o = s F(wi.H, eta) D(H) G(wi, wo, H) / (4 cos_i)
          + rho / (1 - F_int) / (pi eta^2) cos_o T(cos_i) T(cos_o)``

* ``D``, ``G = G1(wi) G1(wo)``: GGX (Walter et al. 2007) or Beckmann with Mitsuba's rational
  fit of the Smith ``G1`` (Walter et al. 2007, Eq. 27), isotropic ``alpha``;
* ``F``: the unpolarised Fresnel reflectance of a dielectric (total internal reflection gives 1);
* ``T(mu)``: the external transmittance of the *rough* interface, the fraction of light from a
  direction with cosine ``mu`` that refracts into the coating and leaves the microsurface
  unshadowed, ``E[G1(w_t, m) (1 - F(wi.m, eta))]`` over visible normals ``m``; tabulated at
  ``mu_i = max(1e-6, i / 63)``, ``i = 0..63``, and linearly interpolated, as Mitsuba does;
* ``F_int = 2 mean_i(mu_i R(mu_i))`` with ``R(mu) = E[G1(w_r, m) F(wi.m, 1 / eta)]`` the
  rough interface's reflectance seen from inside (Mitsuba's ``m_internal_reflectance``); with
  ``nonlinear`` the denominator is ``1 - rho F_int`` instead (Mitsuba ``plastic``).

Both expectations are over the distribution of visible normals and are computed as Mitsuba 3
does (``eval_transmittance`` / ``eval_reflectance`` in ``mitsuba/render/microfacet.h``): a
tensor Gauss-Legendre rule (32 x 32 nodes for ``eta > 1``, 128 x 128 otherwise) on the unit
square, pushed through the visible-normal sampling routine (Heitz 2018 with a concentric disk
for GGX; Jakob 2014's numerically inverted routine for Beckmann). Re-derived here in float64.

Sampling (Mitsuba 3): the glossy lobe is picked with probability
``p = (1 - T(cos_i)) w / ((1 - T(cos_i)) w + T(cos_i) (1 - w))``, ``w = mean(s) / (mean(rho) +
mean(s))`` (the specular sampling weight), and then a visible normal (or, with
``sample_visible=false``, a normal from ``D(m) cos(m)``) is reflected; otherwise ``wo`` is
cosine-distributed. The pdf is the mixture ``p pdf_spec + (1 - p) cos_o / pi``. One uniform
number both picks the lobe and, rescaled, drives the chosen lobe.
"""

from __future__ import annotations

import functools

import jax.numpy as jnp
import numpy as np

from ..warps.hemisphere import concentric_disk_map

RES = 64  # table resolution (Mitsuba's MI_ROUGH_TRANSMITTANCE_RES)
GGX, BECKMANN = 0, 1
DISTRIBUTIONS = {"ggx": GGX, "beckmann": BECKMANN}
# Flags per material.
NONLINEAR, VISIBLE = 1, 2

# Named indices of refraction (Mitsuba 3 ``ior.h``, after the dielectric plugin's table).
IOR = {
    "vacuum": 1.0,
    "helium": 1.000036,
    "hydrogen": 1.000132,
    "air": 1.000277,
    "carbon dioxide": 1.00045,
    "water": 1.3330,
    "acetone": 1.36,
    "ethanol": 1.361,
    "carbon tetrachloride": 1.461,
    "glycerol": 1.4729,
    "benzene": 1.501,
    "silicone oil": 1.52045,
    "bromine": 1.661,
    "water ice": 1.31,
    "fused quartz": 1.458,
    "pyrex": 1.470,
    "acrylic glass": 1.49,
    "polypropylene": 1.49,
    "bk7": 1.5046,
    "sodium chloride": 1.544,
    "amber": 1.55,
    "pet": 1.5750,
    "diamond": 2.419,
}


def lookup_ior(name: str, value) -> float:
    """An index of refraction given as a number or one of Mitsuba's names (:data:`IOR`)."""
    if isinstance(value, str):
        try:
            return float(value)
        except ValueError:
            pass
        key = value.strip().lower()
        if key not in IOR:
            raise ValueError(f"{name} must be a number or one of {sorted(IOR)}, got {value!r}")
        return IOR[key]
    return float(value)


def make_params(
    *,
    alpha,
    int_ior,
    ext_ior,
    diffuse_reflectance,
    specular_reflectance,
    distribution: str,
    nonlinear: bool,
    sample_visible: bool,
) -> dict:
    """Validate a ``roughplastic`` and precompute its constants (float64, numpy).

    Returns ``eta``, ``transmittance`` (the ``RES`` table of ``T``), ``internal`` (``F_int``),
    ``spec_weight`` (``w``) and ``flags``. Raises ``ValueError`` naming the parameter.
    """
    alpha = float(alpha)
    if not (np.isfinite(alpha) and alpha > 0):
        raise ValueError(f"alpha must be a finite number > 0, got {alpha}")
    int_ior = lookup_ior("int_ior", int_ior)
    ext_ior = lookup_ior("ext_ior", ext_ior)
    for nm, v in (("int_ior", int_ior), ("ext_ior", ext_ior)):
        if not (np.isfinite(v) and v > 0):
            raise ValueError(f"{nm} must be a finite number > 0, got {v}")
    if int_ior == ext_ior:
        raise ValueError(f"int_ior and ext_ior must differ, both are {int_ior}")
    for nm, v in (
        ("diffuse_reflectance", diffuse_reflectance),
        ("specular_reflectance", specular_reflectance),
    ):
        v = np.asarray(v, np.float64)
        if v.shape != (3,) or not np.all((v >= 0) & (v <= 1)):
            raise ValueError(f"{nm} must be one or three numbers in [0, 1], got {v.tolist()}")
    if distribution not in DISTRIBUTIONS:
        raise ValueError(
            f"distribution must be one of {sorted(DISTRIBUTIONS)}, got {distribution!r}"
        )
    dist = DISTRIBUTIONS[distribution]
    alpha = max(alpha, 1e-4)  # Mitsuba clamps alpha to 1e-4
    eta = int_ior / ext_ior
    d_mean = float(np.mean(diffuse_reflectance))
    s_mean = float(np.mean(specular_reflectance))
    weight = s_mean / (d_mean + s_mean) if d_mean + s_mean > 0 else 0.5
    trans, internal = _tables(alpha, eta, dist)
    return dict(
        alpha=alpha,
        eta=eta,
        transmittance=trans,
        internal=internal,
        spec_weight=weight,
        flags=(NONLINEAR if nonlinear else 0) | (VISIBLE if sample_visible else 0),
        distribution=dist,
    )


# --- precomputation (numpy, float64) ------------------------------------------------------------


@functools.lru_cache(maxsize=64)
def _tables(alpha: float, eta: float, dist: int) -> tuple[tuple, float]:
    """``(T(mu_i), F_int)``: Mitsuba's ``m_external_transmittance``, ``m_internal_reflectance``."""
    mu = np.maximum(1e-6, np.linspace(0.0, 1.0, RES))
    trans = rough_transmittance(mu, alpha, eta, dist)
    internal = 2.0 * float(np.mean(rough_reflectance(mu, alpha, 1.0 / eta, dist) * mu))
    return tuple(trans.tolist()), internal


def _fresnel_np(cos_i, eta):
    """Unpolarised dielectric Fresnel reflectance and the signed refracted cosine (Mitsuba
    ``fresnel``): ``eta`` is the relative IOR of the side ``cos_i < 0`` points into."""
    outside = cos_i >= 0
    eta_it = np.where(outside, eta, 1 / eta)
    eta_ti = np.where(outside, 1 / eta, eta)
    ct2 = 1 - (1 - cos_i * cos_i) * eta_ti * eta_ti
    ci, ct = np.abs(cos_i), np.sqrt(np.maximum(ct2, 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        a_s = (ci - eta_it * ct) / (ci + eta_it * ct)
        a_p = (ct - eta_it * ci) / (ct + eta_it * ci)
    r = 0.5 * (a_s * a_s + a_p * a_p)
    r = np.where(ci == 0, 1.0, r)
    return r, np.where(outside, -ct, ct), eta_ti


def _smith_g1_np(v, m, alpha, dist):
    xy = alpha * alpha * (v[..., 0] ** 2 + v[..., 1] ** 2)
    with np.errstate(invalid="ignore", divide="ignore"):
        t2 = xy / (v[..., 2] ** 2)
        if dist == GGX:
            g = 2 / (1 + np.sqrt(1 + t2))
        else:
            a = 1 / np.sqrt(t2)
            fit = (3.535 * a + 2.181 * a * a) / (1 + 2.276 * a + 2.577 * a * a)
            g = np.where(a >= 1.6, 1.0, fit)
    g = np.where(xy == 0, 1.0, g)
    return np.where(np.sum(v * m, -1) * v[..., 2] <= 0, 0.0, g)


def _visible_slope_np(cos_i, u, dist):
    """Slopes of a visible normal of the ``alpha = 1`` distribution for an incident direction
    with cosine ``cos_i`` in the x-z plane (Heitz 2018 for GGX; Jakob 2014 for Beckmann)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        return _visible_slope_np_(cos_i, u, dist)


def _visible_slope_np_(cos_i, u, dist):
    if dist == GGX:
        px, py = concentric_disk_map(u[..., 0], u[..., 1], np)
        s = 0.5 * (1 + cos_i)
        py = (1 - s) * np.sqrt(np.maximum(1 - px * px, 0.0)) + s * py
        z = np.sqrt(np.maximum(1 - px * px - py * py, 0.0))
        sin_i = np.sqrt(np.maximum(1 - cos_i * cos_i, 0.0))
        nrm = 1 / (sin_i * py + cos_i * z)
        return (cos_i * py - sin_i * z) * nrm, px * nrm
    from scipy.special import erf, erfinv

    tan_i = np.sqrt(np.maximum(1 - cos_i * cos_i, 0.0)) / cos_i
    cot_i = 1 / tan_i
    maxval = erf(cot_i)
    u = np.clip(u, 1e-6, 1 - 1e-6)
    ux, uy = u[..., 0], u[..., 1]
    x = maxval - (maxval + 1) * erf(np.sqrt(-np.log(ux)))
    ux = ux * (1 + maxval + tan_i * np.exp(-cot_i * cot_i) / np.sqrt(np.pi))
    for _ in range(3):
        slope = erfinv(x)
        value = 1 + x + tan_i * np.exp(-slope * slope) / np.sqrt(np.pi) - ux
        x = x - value / (1 - slope * tan_i)
    return erfinv(x), erfinv(2 * uy - 1)


def _quadrature(mu, alpha, dist, res):
    """Visible normals ``m`` (k, q, 3) at the Gauss-Legendre nodes for ``wi`` (k, 3) in the
    x-z plane with cosines ``mu``, and the node weights (q,) summing to 1."""
    nodes, weights = np.polynomial.legendre.leggauss(res)
    nx, ny = np.meshgrid(nodes, nodes)
    wx, wy = np.meshgrid(weights, weights)
    u = np.stack([nx.ravel(), ny.ravel()], -1) * 0.5 + 0.5
    w = (wx * wy).ravel() * 0.25
    wi = np.stack([np.sqrt(1 - mu * mu), np.zeros_like(mu), mu], -1)
    # Stretch wi; it stays in the x-z plane (azimuth 0), so no rotation is needed.
    ws = wi * np.array([alpha, alpha, 1.0])
    ws = ws / np.linalg.norm(ws, axis=-1, keepdims=True)
    sx, sy = np.broadcast_arrays(*_visible_slope_np(ws[:, 2:3], u[None], dist))
    m = np.stack([-sx * alpha, -sy * alpha, np.ones_like(sx)], -1)
    m = m / np.linalg.norm(m, axis=-1, keepdims=True)
    return wi[:, None, :], m, w


def rough_reflectance(mu, alpha, eta, dist=GGX):
    """``E[G1(w_r, m) F(wi.m, eta)]`` over visible normals, per cosine in ``mu`` (Mitsuba
    ``eval_reflectance``)."""
    wi, m, w = _quadrature(np.asarray(mu, np.float64), alpha, dist, 32 if eta > 1 else 128)
    c = np.sum(wi * m, -1)
    f, _, _ = _fresnel_np(c, eta)
    wr = 2 * c[..., None] * m - wi
    val = _smith_g1_np(wr, m, alpha, dist) * f
    val = np.where((wr[..., 2] <= 0) | (wi[..., 2] <= 0), 0.0, val)
    return val @ w


def rough_transmittance(mu, alpha, eta, dist=GGX):
    """``E[G1(w_t, m) (1 - F(wi.m, eta))]`` over visible normals, per cosine in ``mu`` (Mitsuba
    ``eval_transmittance``)."""
    wi, m, w = _quadrature(np.asarray(mu, np.float64), alpha, dist, 32 if eta > 1 else 128)
    c = np.sum(wi * m, -1)
    f, ct, eta_ti = _fresnel_np(c, eta)
    wt = m * (c * eta_ti + ct)[..., None] - wi * eta_ti[..., None]
    val = _smith_g1_np(wt, m, alpha, dist) * (1 - f)
    val = np.where(wt[..., 2] * wi[..., 2] >= 0, 0.0, val)
    return val @ w


# --- evaluation (JAX, one direction pair per call) ----------------------------------------------


def fresnel_dielectric(cos_i, eta):
    """Unpolarised Fresnel reflectance for ``cos_i >= 0`` into relative IOR ``eta`` (1 beyond
    the critical angle)."""
    ct2 = 1 - (1 - cos_i * cos_i) / (eta * eta)
    ct = jnp.sqrt(jnp.maximum(ct2, 0.0))
    den_s = cos_i + eta * ct
    den_p = ct + eta * cos_i
    a_s = (cos_i - eta * ct) / jnp.where(den_s > 0, den_s, 1.0)
    a_p = (ct - eta * cos_i) / jnp.where(den_p > 0, den_p, 1.0)
    r = 0.5 * (a_s * a_s + a_p * a_p)
    return jnp.where(cos_i > 0, r, 1.0)


def microfacet_d(m, alpha, beckmann):
    """GGX or Beckmann normal distribution per steradian of ``m`` (local, unit)."""
    a2 = alpha * alpha
    c2 = m[2] * m[2]
    ggx = a2 / (jnp.pi * jnp.square(c2 * (a2 - 1) + 1))
    c2s = jnp.maximum(c2, 1e-30)
    bk = jnp.exp(-(1 - c2) / (c2s * a2)) / (jnp.pi * a2 * c2s * c2s)
    d = jnp.where(beckmann, bk, ggx)
    return jnp.where(d * m[2] > 1e-20, d, 0.0)


def smith_g1(v, m, alpha, beckmann):
    """Smith masking ``G1`` (GGX exact; Beckmann by Mitsuba's rational approximation)."""
    c2 = jnp.maximum(v[2] * v[2], 1e-30)
    xy = alpha * alpha * (v[0] * v[0] + v[1] * v[1])
    t2 = xy / c2
    ggx = 2.0 / (1 + jnp.sqrt(1 + t2))
    a = 1 / jnp.sqrt(jnp.maximum(t2, 1e-30))
    bk = jnp.where(a >= 1.6, 1.0, (3.535 * a + 2.181 * a * a) / (1 + 2.276 * a + 2.577 * a * a))
    g = jnp.where(xy > 0, jnp.where(beckmann, bk, ggx), 1.0)
    ok = (v[0] * m[0] + v[1] * m[1] + v[2] * m[2]) * v[2] > 0
    return jnp.where(ok, g, 0.0)


def table_lookup(table, cos):
    """Mitsuba's ``lerp_gather``: linear interpolation of the ``RES`` table at ``cos``."""
    x = jnp.clip(cos, 0.0, 1.0) * (RES - 1)
    i = jnp.minimum(jnp.floor(x).astype(jnp.int32), RES - 2)
    t = x - i.astype(x.dtype)
    return (1 - t) * table[i] + t * table[i + 1]


def _spec_prob(m, cos_i):
    t_i = table_lookup(m["transmittance"], cos_i)
    w = m["spec_weight"]
    ps = (1 - t_i) * w
    pd = t_i * (1 - w)
    tot = ps + pd
    return jnp.where(tot > 0, ps / jnp.where(tot > 0, tot, 1.0), 0.5), t_i


def eval_plastic(m: dict, li, lo):
    """BSDF times ``cos_o`` (RGB) for local ``li``, ``lo`` (callers zero it below the surface).

    ``m``: this material's row (``alpha``, ``eta``, ``specular``, ``reflectance``,
    ``transmittance``, ``internal``, ``flags``, ``beckmann``).
    """
    alpha, eta, beck = m["alpha"], m["eta"], m["beckmann"]
    cos_i = jnp.maximum(li[2], 1e-20)
    cos_o = lo[2]
    h = li + lo
    h = h / jnp.maximum(jnp.sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2]), 1e-30)
    d = microfacet_d(h, alpha, beck)
    g = smith_g1(li, h, alpha, beck) * smith_g1(lo, h, alpha, beck)
    f = fresnel_dielectric(li[0] * h[0] + li[1] * h[1] + li[2] * h[2], eta)
    spec = m["specular"] * (f * d * g / (4 * cos_i))
    t_i = table_lookup(m["transmittance"], li[2])
    t_o = table_lookup(m["transmittance"], lo[2])
    rho = m["reflectance"]
    nonlinear = (m["flags"] & NONLINEAR) > 0
    denom = 1 - jnp.where(nonlinear, rho * m["internal"], m["internal"])
    diff = rho / denom * (cos_o * t_i * t_o / (jnp.pi * eta * eta))
    return spec + diff


def pdf_plastic(m: dict, li, lo):
    """Solid-angle density of :func:`sample_plastic` (the lobe mixture)."""
    alpha, beck = m["alpha"], m["beckmann"]
    cos_i = jnp.maximum(li[2], 1e-20)
    p_spec, _ = _spec_prob(m, li[2])
    h = li + lo
    h = h / jnp.maximum(jnp.sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2]), 1e-30)
    d = microfacet_d(h, alpha, beck)
    visible = (m["flags"] & VISIBLE) > 0
    o_h = lo[0] * h[0] + lo[1] * h[1] + lo[2] * h[2]
    p_vis = d * smith_g1(li, h, alpha, beck) / (4 * cos_i)
    p_nor = d * h[2] / (4 * jnp.maximum(o_h, 1e-20))
    p = p_spec * jnp.where(visible, p_vis, p_nor) + (1 - p_spec) * lo[2] / jnp.pi
    return p


def _sample_normal(li, alpha, beck, u):
    """A normal from ``D(m) cos(m)`` (``sample_visible=false``; Walter et al. 2007 Eqs. 28, 35)."""
    a2 = alpha * alpha
    u0 = jnp.minimum(u[0], 1 - 1e-7)
    tan2 = jnp.where(beck, -a2 * jnp.log1p(-u0), a2 * u0 / (1 - u0))
    cos_t = 1 / jnp.sqrt(1 + tan2)
    sin_t = jnp.sqrt(jnp.maximum(1 - cos_t * cos_t, 0.0))
    phi = 2 * jnp.pi * u[1]
    return jnp.stack([sin_t * jnp.cos(phi), sin_t * jnp.sin(phi), cos_t])


def _beckmann_visible(li, alpha, u):
    """Beckmann visible normal (Heitz & d'Eon 2014; Jakob 2014's numerical inversion)."""
    from jax.scipy.special import erf, erfinv

    vs = jnp.stack([alpha * li[0], alpha * li[1], li[2]])
    vs = vs / jnp.sqrt(vs[0] * vs[0] + vs[1] * vs[1] + vs[2] * vs[2])
    s2 = vs[0] * vs[0] + vs[1] * vs[1]
    inv = jnp.where(s2 > 1e-12, 1 / jnp.sqrt(jnp.where(s2 > 1e-12, s2, 1.0)), 0.0)
    cos_phi = jnp.where(s2 > 1e-12, jnp.clip(vs[0] * inv, -1.0, 1.0), 1.0)
    sin_phi = jnp.where(s2 > 1e-12, jnp.clip(vs[1] * inv, -1.0, 1.0), 0.0)
    cos_i = jnp.maximum(vs[2], 1e-6)
    tan_i = jnp.sqrt(jnp.maximum(1 - cos_i * cos_i, 0.0)) / cos_i
    cot_i = 1 / jnp.maximum(tan_i, 1e-12)
    maxval = erf(cot_i)
    uu = jnp.clip(u, 1e-6, 1 - 1e-6)
    x = maxval - (maxval + 1) * erf(jnp.sqrt(-jnp.log(uu[0])))
    ux = uu[0] * (1 + maxval + tan_i * jnp.exp(-cot_i * cot_i) / jnp.sqrt(jnp.pi))
    for _ in range(3):
        slope = erfinv(x)
        value = 1 + x + tan_i * jnp.exp(-slope * slope) / jnp.sqrt(jnp.pi) - ux
        x = x - value / (1 - slope * tan_i)
    # float32 Newton steps can land a hair outside (-1, 1): keep erfinv finite.
    sx = erfinv(jnp.clip(x, -1 + 1e-7, 1 - 1e-7))
    sy = erfinv(jnp.clip(2 * uu[1] - 1, -1 + 1e-7, 1 - 1e-7))
    tx = (cos_phi * sx - sin_phi * sy) * alpha
    ty = (sin_phi * sx + cos_phi * sy) * alpha
    mm = jnp.stack([-tx, -ty, jnp.ones_like(tx)])
    return mm / jnp.sqrt(mm[0] * mm[0] + mm[1] * mm[1] + mm[2] * mm[2])


def sample_plastic(m: dict, li, u, ggx_visible):
    """A local direction ``lo`` from the lobe mixture of :func:`pdf_plastic`.

    ``ggx_visible(li, alpha, u)`` is the GGX visible-normal sampler shared with the conductor.
    """
    alpha, beck = m["alpha"], m["beckmann"]
    p_spec, _ = _spec_prob(m, li[2])
    spec = u[0] < p_spec
    u0 = jnp.where(
        spec,
        u[0] / jnp.where(p_spec > 0, p_spec, 1.0),
        (u[0] - p_spec) / jnp.where(p_spec < 1, 1 - p_spec, 1.0),
    )
    uu = jnp.stack([jnp.clip(u0, 0.0, 1 - 1e-7), u[1]])
    visible = (m["flags"] & VISIBLE) > 0
    h_vis = jnp.where(beck, _beckmann_visible(li, alpha, uu), ggx_visible(li, alpha, uu))
    h = jnp.where(visible, h_vis, _sample_normal(li, alpha, beck, uu))
    lo_s = 2 * (li[0] * h[0] + li[1] * h[1] + li[2] * h[2]) * h - li
    r = jnp.sqrt(uu[0])
    phi = 2 * jnp.pi * uu[1]
    lo_d = jnp.stack([r * jnp.cos(phi), r * jnp.sin(phi), jnp.sqrt(jnp.maximum(1 - uu[0], 0.0))])
    return jnp.where(spec, lo_s, lo_d)

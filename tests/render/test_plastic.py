"""``roughplastic`` (render/plastic.py) against independent truths.

* Mitsuba 3's own plugin (``mi.load_dict``, scalar_rgb): BSDF value and pdf at random direction
  pairs for GGX and Beckmann, visible and plain normal sampling, ``nonlinear``, named IORs;
* the smooth limit (``alpha = 0.01``): the specular lobe's albedo is the textbook Fresnel
  reflectance, the diffuse lobe's albedo is ``rho (1 - F(cos_i))`` times the Stokes ratio
  ``(1 - Fdr_ext) / (eta^2 (1 - F_int))`` (both hemispherical Fresnel integrals by our own
  Gauss-Legendre quadrature of the textbook formula), and Mitsuba's internal reflectance is its
  64-point mean of the textbook ``F(mu) mu``;
* a white furnace (``rho = 1``): the albedo never exceeds 1;
* the pdf: a quadrature of it over the hemisphere plus the fraction of samples that leave it
  is 1, and a chi-square test of the sampled directions against it;
* bad parameters: errors naming the file, line and parameter.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

import anisosample.render as R
from anisosample.render import bsdf as B
from anisosample.render.plastic import pdf_plastic

ETA = 1.49 / 1.000277  # Mitsuba's defaults: polypropylene in air
N = jnp.array([0.0, 0.0, 1.0], jnp.float32)


def _materials(**kw):
    b = R.SceneBuilder()
    b.roughplastic(**kw)
    b.camera(np.eye(4), width=1, height=1)
    b.point_light((0, 0, 1), (1, 1, 1))
    return b.build().materials


_eval = jax.jit(jax.vmap(lambda m, wi, wo: B.eval_bsdf(m, 0, N, wi, wo), in_axes=(None, 0, 0)))
_pdf = jax.jit(jax.vmap(lambda m, wi, wo: B.pdf_bsdf(m, 0, N, wi, wo), in_axes=(None, 0, 0)))
_pdf_lobe = jax.jit(jax.vmap(pdf_plastic, in_axes=(None, None, 0)))  # local frame, no hemisphere
_sample = jax.jit(jax.vmap(lambda m, wi, u: B.sample_bsdf(m, 0, N, wi, u), in_axes=(None, None, 0)))


def _f32(a):
    return jnp.asarray(np.asarray(a, np.float64), jnp.float32)


def _fresnel(c, eta):
    """Textbook unpolarised Fresnel reflectance (float64; 1 under total internal reflection)."""
    s2 = 1 - c * c
    ct = np.sqrt(np.maximum(1 - s2 / eta**2, 0.0))
    rs = (c - eta * ct) / (c + eta * ct)
    rp = (eta * c - ct) / (eta * c + ct)
    return 0.5 * (rs**2 + rp**2)


def _wi(cos_i):
    return np.array([np.sqrt(1 - cos_i**2), 0.0, cos_i])


def _hemisphere_integral(fn, m, cos_i, n=192):
    """Integral over the upper hemisphere of ``fn(m, wi, wo)`` (Gauss-Legendre in cos theta,
    midpoints in phi), per channel."""
    x, w = np.polynomial.legendre.leggauss(n)
    mu, wmu = (x + 1) / 2, w / 2
    phi = (np.arange(2 * n) + 0.5) / (2 * n) * 2 * np.pi
    M, P = np.meshgrid(mu, phi, indexing="ij")
    s = np.sqrt(1 - M**2)
    wo = np.stack([s * np.cos(P), s * np.sin(P), M], -1).reshape(-1, 3)
    wt = (wmu[:, None] * np.full(2 * n, np.pi / n)[None]).reshape(-1)
    wi = np.broadcast_to(_wi(cos_i), wo.shape)
    f = np.asarray(fn(m, _f32(wi), _f32(wo)), np.float64).reshape(len(wo), -1)
    return wt @ f


def _specular_albedo(m, cos_i, alpha, n=192):
    """Albedo of a narrow lobe, integrated over half vectors ``h`` with ``tan theta_h =
    alpha tan psi`` (Gauss-Legendre in psi) and ``d wo = 4 (wi.h) d h``."""
    x, w = np.polynomial.legendre.leggauss(n)
    psi, wpsi = (x + 1) * np.pi / 4, w * np.pi / 4
    th = np.arctan(alpha * np.tan(psi))
    dth = alpha / np.cos(psi) ** 2 / (1 + (alpha * np.tan(psi)) ** 2)
    phi = (np.arange(2 * n) + 0.5) / (2 * n) * 2 * np.pi
    T, P = np.meshgrid(th, phi, indexing="ij")
    wt = ((wpsi * dth * np.sin(th))[:, None] * np.full(2 * n, np.pi / n)[None]).reshape(-1)
    h = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1).reshape(-1, 3)
    wi = _wi(cos_i)
    c = h @ wi
    wo = 2 * c[:, None] * h - wi
    f = np.asarray(_eval(m, _f32(np.broadcast_to(wi, wo.shape)), _f32(wo)), np.float64)
    return (wt * 4 * np.maximum(c, 0.0)) @ f


# --- against Mitsuba 3's plugin -----------------------------------------------------------------

CONFIGS = [
    dict(distribution="ggx", alpha=0.2),
    dict(distribution="ggx", alpha=0.05, sample_visible=False, int_ior=1.6),
    dict(distribution="ggx", alpha=0.5, nonlinear=True, specular_reflectance=(0.9, 0.7, 0.5)),
    dict(distribution="beckmann", alpha=0.3, int_ior="bk7", ext_ior="water"),
    dict(distribution="beckmann", alpha=0.1, sample_visible=False, nonlinear=True),
]


@pytest.mark.parametrize("cfg", CONFIGS, ids=lambda c: "-".join(f"{v}" for v in c.values()))
def test_eval_and_pdf_match_mitsuba(cfg):
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    rho = (0.8, 0.3, 0.1)
    d = {"type": "roughplastic", "diffuse_reflectance": {"type": "rgb", "value": list(rho)}}
    for k, v in cfg.items():
        d[k] = {"type": "rgb", "value": list(v)} if isinstance(v, tuple) else v
    plugin = mi.load_dict(d)
    m = _materials(diffuse_reflectance=rho, **cfg)
    rng = np.random.default_rng(7)
    # Random pairs, plus pairs near the mirror direction (inside the glossy lobe).
    v = rng.normal(size=(2, 96, 3))
    v[..., 2] = np.abs(v[..., 2])
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    wi, wo = v[0], v[1]
    mirror = wi[:32] * np.array([-1, -1, 1]) + 0.1 * rng.normal(size=(32, 3))
    mirror[:, 2] = np.abs(mirror[:, 2])
    wo[:32] = mirror / np.linalg.norm(mirror, axis=-1, keepdims=True)
    ctx = mi.BSDFContext()
    ref_f, ref_p = [], []
    for a, b in zip(wi, wo, strict=True):
        si = mi.SurfaceInteraction3f()
        si.wi = mi.Vector3f(*a)
        si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
        ref_f.append(np.array(plugin.eval(ctx, si, mi.Vector3f(*b))))
        ref_p.append(float(plugin.pdf(ctx, si, mi.Vector3f(*b))))
    ref_f, ref_p = np.array(ref_f), np.array(ref_p)
    ours_f = np.asarray(_eval(m, _f32(wi), _f32(wo)))
    ours_p = np.asarray(_pdf(m, _f32(wi), _f32(wo)))
    # float32 on both sides: agreement to a few ulps of the largest terms.
    np.testing.assert_allclose(ours_f, ref_f, rtol=2e-4, atol=1e-6)
    np.testing.assert_allclose(ours_p, ref_p, rtol=2e-4, atol=1e-6)


# --- smooth limit and energy --------------------------------------------------------------------


@pytest.mark.parametrize("distribution", ["ggx", "beckmann"])
def test_smooth_limit_specular_albedo_is_fresnel(distribution):
    alpha = 0.01
    m = _materials(alpha=alpha, distribution=distribution, diffuse_reflectance=0.0)
    for cos_i in (0.2, 0.5, 1.0):
        albedo = _specular_albedo(m, cos_i, alpha)
        # Masking costs O(alpha tan theta_i)^2 at grazing incidence; float32 sums ~1e-4.
        tol = 0.02 if cos_i < 0.3 else 0.005
        np.testing.assert_allclose(albedo, _fresnel(cos_i, ETA), rtol=tol)


def _fdr(eta, n=512):
    """Hemispherical Fresnel reflectance ``2 int_0^1 F(mu) mu d mu`` (textbook F)."""
    x, w = np.polynomial.legendre.leggauss(n)
    mu = (x + 1) / 2
    return float(np.sum(w * _fresnel(mu, eta) * mu))


def test_smooth_limit_internal_reflectance_and_diffuse_albedo():
    alpha, rho = 0.01, 0.5
    m = _materials(alpha=alpha, distribution="ggx", diffuse_reflectance=rho,
                   specular_reflectance=0.0)
    f_int = float(m.internal[0])
    # Mitsuba's F_int is 2 mean(R(mu_i) mu_i) over mu_i = max(1e-6, i / 63); in the smooth
    # limit R is the textbook F seen from inside (1 beyond the critical angle); roughness
    # alpha blurs that step over O(alpha) in mu: a few 1e-3.
    mu = np.maximum(1e-6, np.linspace(0, 1, 64))
    np.testing.assert_allclose(f_int, 2 * np.mean(_fresnel(mu, 1 / ETA) * mu), rtol=5e-3)
    # (which is about 1.5% below the integral 2 int F mu d mu: Mitsuba's rule, kept.)
    assert abs(f_int / _fdr(1 / ETA) - 1) < 0.03
    # Stokes: eta^2 (1 - Fdr_int) = 1 - Fdr_ext for the exact integrals.
    np.testing.assert_allclose(ETA**2 * (1 - _fdr(1 / ETA)), 1 - _fdr(ETA), rtol=1e-3)
    stokes = (1 - _fdr(ETA)) / (ETA**2 * (1 - f_int))
    for cos_i in (0.2, 0.5, 0.9, 1.0):
        albedo = _hemisphere_integral(_eval, m, cos_i)
        expect = rho * (1 - _fresnel(cos_i, ETA)) * stokes
        np.testing.assert_allclose(albedo, expect, rtol=5e-3)


@pytest.mark.parametrize("distribution", ["ggx", "beckmann"])
def test_white_furnace_never_creates_energy(distribution):
    for alpha in (0.01, 0.2, 0.8):
        ms = _materials(alpha=alpha, distribution=distribution, diffuse_reflectance=0.0)
        md = _materials(alpha=alpha, distribution=distribution, diffuse_reflectance=1.0,
                        specular_reflectance=0.0, nonlinear=True)
        for cos_i in (0.1, 0.5, 1.0):
            total = (_specular_albedo(ms, cos_i, alpha, n=128)
                     + _hemisphere_integral(_eval, md, cos_i, n=128))
            assert np.all(total <= 1.0 + 1e-3), (alpha, cos_i, total)
            if alpha == 0.01 and cos_i >= 0.5:
                # Smooth limit: F + (1 - F) * (Stokes ratio with Mitsuba's F_int) ~ 0.98.
                assert np.all(total > 0.97), (alpha, cos_i, total)


# --- sampling -----------------------------------------------------------------------------------


@pytest.mark.parametrize("distribution", ["ggx", "beckmann"])
@pytest.mark.parametrize("visible", [True, False])
def test_glossy_pdf_integrates_to_one(distribution, visible):
    """With no diffuse part the lobe is sampled alone; its pdf, extended below the horizon
    (where sample_bsdf's reflections go to waste), integrates to 1 over all reflections:
    ``int D(h) G1(wi, h) (wi.h)^+ dh = cos_i`` (visible normals, Heitz 2014; Beckmann's G1 is
    Mitsuba's rational fit, < 0.35% off), or, sampling ``D(h) cos h`` (whose normals facing
    away from ``wi`` are wasted), the textbook ``int_{wi.h > 0} D(h) cos h dh``. Quadrature
    over half vectors, leaving out the sliver ``wi.h < 1e-3`` where float32 cannot resolve
    ``1 / (wo.h)``."""
    from anisosample.render.bsdf import plastic_parameters

    n = 192
    for alpha in (0.05, 0.3, 0.8):
        m = plastic_parameters(_materials(alpha=alpha, distribution=distribution,
                                    diffuse_reflectance=0.0, sample_visible=visible), 0)
        x, w = np.polynomial.legendre.leggauss(n)
        psi, wpsi = (x + 1) * np.pi / 4, w * np.pi / 4
        th = np.arctan(alpha * np.tan(psi))
        dth = alpha / np.cos(psi) ** 2 / (1 + (alpha * np.tan(psi)) ** 2)
        phi = (np.arange(2 * n) + 0.5) / (2 * n) * 2 * np.pi
        T, P = np.meshgrid(th, phi, indexing="ij")
        wt = ((wpsi * dth * np.sin(th))[:, None] * np.full(2 * n, np.pi / n)[None]).reshape(-1)
        h = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1)
        h = h.reshape(-1, 3)
        for cos_i in (0.3, 0.9):
            wi = _wi(cos_i)
            c = h @ wi
            wo = 2 * c[:, None] * h - wi
            p = _pdf_lobe(m, _f32(wi), _f32(wo))
            keep = c > 1e-3
            total = float((wt * 4 * c * keep) @ np.asarray(p, np.float64))
            expect = 1.0
            if not visible:
                t2 = np.tan(T.reshape(-1)) ** 2
                d = (np.exp(-t2 / alpha**2) / (np.pi * alpha**2 * h[:, 2] ** 4)
                     if distribution == "beckmann"
                     else alpha**2 / (np.pi * h[:, 2] ** 4 * (alpha**2 + t2) ** 2))
                expect = float((wt * keep) @ (d * h[:, 2]))
            tol = 5e-3 if distribution == "beckmann" and visible else 2e-3
            assert abs(total - expect) < tol, (alpha, cos_i, total, expect)

SAMPLING = [
    dict(distribution="ggx", alpha=0.3),
    dict(distribution="ggx", alpha=0.15, sample_visible=False),
    dict(distribution="beckmann", alpha=0.3),
    dict(distribution="beckmann", alpha=0.15, sample_visible=False),
]


@pytest.mark.parametrize("cfg", SAMPLING, ids=lambda c: "-".join(f"{v}" for v in c.values()))
def test_sampling_matches_pdf(cfg):
    """Pearson chi-square of sampled directions (equal-area cells in (cos theta, phi)) against
    the pdf integrated over each cell, plus one cell for samples that leave the hemisphere,
    whose expected mass is 1 minus the pdf's integral over the hemisphere."""
    m = _materials(diffuse_reflectance=(0.3, 0.3, 0.3), **cfg)
    n, res_z, res_phi, sub = 200_000, 24, 48, 6
    for k, cos_i in enumerate((0.35, 0.8)):
        wi = _wi(cos_i)
        u = jax.random.uniform(jax.random.key(11 + k), (n, 2), jnp.float32)
        wo, p = _sample(m, _f32(wi), u)
        wo, p = np.asarray(wo, np.float64), np.asarray(p)
        ok = (wo[:, 2] > 0) & (p > 0)
        z = wo[ok, 2]
        ph = np.mod(np.arctan2(wo[ok, 1], wo[ok, 0]), 2 * np.pi)
        obs, _, _ = np.histogram2d(z, ph, bins=[res_z, res_phi], range=[[0, 1], [0, 2 * np.pi]])
        g = (np.arange(sub) + 0.5) / sub
        zz = (np.arange(res_z)[:, None] + g[None]).reshape(-1) / res_z
        pp = (np.arange(res_phi)[:, None] + g[None]).reshape(-1) / res_phi * 2 * np.pi
        Z, P = np.meshgrid(zz, pp, indexing="ij")
        s = np.sqrt(1 - Z**2)
        dirs = np.stack([s * np.cos(P), s * np.sin(P), Z], -1).reshape(-1, 3)
        dens = np.asarray(_pdf(m, _f32(np.broadcast_to(wi, dirs.shape)), _f32(dirs)), np.float64)
        cell = dens.reshape(res_z, sub, res_phi, sub).mean(axis=(1, 3)) * (2 * np.pi / (
            res_z * res_phi))
        exp = cell.reshape(-1) * n
        lost_exp = n - exp.sum()
        o = np.append(obs.reshape(-1), n - ok.sum())
        e = np.append(exp, lost_exp)
        assert lost_exp > -1e-3 * n, lost_exp  # the pdf's hemisphere integral is <= 1
        small = e < 5
        o = np.append(o[~small], o[small].sum())
        e = np.append(e[~small], max(e[small].sum(), 1e-9))
        stat = float(np.sum((o - e) ** 2 / e))
        pval = float(stats.chi2.sf(stat, len(o) - 1))
        assert pval > 1e-3, (cfg, cos_i, stat, len(o), pval)


# --- errors -------------------------------------------------------------------------------------

SCENE = """<scene version="3.0.0">
  <integrator type="direct"/>
  <sensor type="perspective">
    <float name="fov" value="40"/>
    <film type="hdrfilm"><integer name="width" value="4"/><integer name="height" value="4"/>
      <rfilter type="box"/></film>
  </sensor>
  <shape type="rectangle"><transform name="to_world"><translate z="-2"/></transform>
    <emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>
  <shape type="cube">
    <bsdf type="roughplastic">
      <string name="distribution" value="ggx"/>
      {prop}
    </bsdf>
  </shape>
</scene>
"""


@pytest.mark.parametrize(
    "prop, match",
    [
        ('<float name="alpha" value="0"/>', "alpha must be a finite number > 0, got 0.0"),
        ('<float name="alpha" value="-0.1"/>', "alpha must be"),
        ('<float name="int_ior" value="-1.5"/>', "int_ior must be a finite number > 0"),
        ('<float name="ext_ior" value="0"/>', "ext_ior must be a finite number > 0"),
        ('<float name="int_ior" value="1.000277"/>', "int_ior and ext_ior must differ"),
        ('<string name="int_ior" value="unobtainium"/>', "int_ior must be a number or one of"),
        ('<rgb name="diffuse_reflectance" value="0.5, 1.2, 0.5"/>',
         r"diffuse_reflectance must be one or three numbers in \[0, 1\]"),
        ('<float name="specular_reflectance" value="-0.1"/>', "specular_reflectance must be"),
        ('<float name="alpha_u" value="0.1"/>', "unsupported property 'alpha_u'"),
        ('<rgb name="int_ior" value="1.5"/>', "must be a <float> or a <string>"),
    ],
)
def test_bad_parameters_name_file_line_and_parameter(tmp_path, prop, match):
    p = tmp_path / "s.xml"
    p.write_text(SCENE.format(prop=prop))
    with pytest.raises(R.SceneFormatError, match=r"s\.xml:1[0-9]: <(bsdf|float|string|rgb)"):
        R.load_xml(p)
    with pytest.raises(R.SceneFormatError, match=match):
        R.load_xml(p)


def test_bad_distribution_and_defaults(tmp_path):
    p = tmp_path / "s.xml"
    p.write_text(SCENE.format(prop="").replace('value="ggx"', 'value="phong"'))
    with pytest.raises(R.SceneFormatError, match="distribution must be one of"):
        R.load_xml(p)
    # No distribution: Mitsuba's default, beckmann; default IORs polypropylene / air.
    p.write_text(SCENE.format(prop="").replace('<string name="distribution" value="ggx"/>', ""))
    m = R.load_xml(p).materials
    assert int(m.distribution[-1]) == 1
    np.testing.assert_allclose(float(m.eta[-1, 0]), ETA, rtol=1e-6)
    with pytest.raises(ValueError, match="alpha must be"):
        R.SceneBuilder().roughplastic(alpha=float("nan"))

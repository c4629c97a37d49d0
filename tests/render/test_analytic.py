"""The renderer against closed forms, a second sampling technique and brute-force references."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import anisosample.render as R
import anisosample.render.integrator  # noqa: F401  (R.integrator.LUMINANCE)
from anisosample import samplers
from anisosample.metrics import midpoint_grid

from .helpers import SCENES, form_factor_parallel, plane_under_light


@pytest.mark.parametrize("technique", ["area", "solid_angle"])
def test_form_factor_of_a_square_light(technique):
    # Radiance leaving a Lambertian floor under a uniform square emitter is
    # albedo * L * F with F the point-to-rectangle form factor (4 quadrants of Howell C-11).
    h, half, L, rho = 1.98, 0.25, 10.0, 0.5
    scene = plane_under_light(h, half, L, rho)
    exact = rho * L * 4 * form_factor_parallel(h, half, half)
    f = R.pixel_integrand(scene, (4, 4), channel="r", technique=technique)
    # Smooth integrand: the midpoint rule on 256^2 cells errs by O(1/256^2).
    value = float(jnp.mean(f(jnp.asarray(midpoint_grid(256)))))
    assert value == pytest.approx(exact, rel=1e-3)


def test_off_centre_point_by_superposition():
    # A point not under the centre: the rectangle splits into four with corners above it.
    h, half, L, rho = 1.0, 0.5, 3.0, 0.8
    scene = plane_under_light(h, half, L, rho)
    film = (0.5 + 0.3 / (2 * np.tan(np.radians(5))), 0.5)  # hit x = -0.3 (camera +x is left)
    f = R.pixel_integrand(scene, (4, 4), channel="g", film=film)
    x = 0.3
    exact = rho * L * (2 * form_factor_parallel(h, half + x, half)
                       + 2 * form_factor_parallel(h, half - x, half))
    value = float(jnp.mean(f(jnp.asarray(midpoint_grid(256)))))
    assert value == pytest.approx(exact, rel=1e-3)


def test_two_techniques_agree_on_a_penumbra_pixel():
    scene = R.load_xml(SCENES / "cornell.xml", width=32, height=32)
    x = jnp.asarray(midpoint_grid(256))
    a = float(jnp.mean(R.pixel_integrand(scene, (12, 27))(x)))
    b = float(jnp.mean(R.pixel_integrand(scene, (12, 27), technique="solid_angle")(x)))
    assert a > 0
    assert b == pytest.approx(a, rel=5e-3)


def test_estimator_is_unbiased_for_every_sampler():
    # A pixel in the tall box's penumbra: the light-sample integrand has a shadow edge.
    scene = R.load_xml(SCENES / "cornell.xml", width=32, height=32)
    f = R.pixel_integrand(scene, (12, 27))
    ref = float(jnp.mean(f(jnp.asarray(midpoint_grid(512)))))
    grid = np.asarray(f(jnp.asarray(midpoint_grid(64))))
    assert 0 < (grid > 1e-6).mean() < 1, "the pixel must see part of the light"
    n, reps = 64, 96
    for name in samplers.names():
        try:
            sampler = samplers.get(name)
        except (TypeError, ValueError):  # samplers that need options (aligned tables)
            continue
        keys = jax.random.split(jax.random.key(7), reps)
        pts = []
        for k in keys:
            k1, k2 = jax.random.split(k)
            pts.append(samplers.toroidal_shift(k2, sampler(k1, n)))
        ests = np.asarray(jnp.mean(f(jnp.stack(pts)), axis=1), np.float64)
        se = ests.std(ddof=1) / np.sqrt(reps)
        # 4.5 standard errors; the reference's own quadrature error is far below that.
        assert abs(ests.mean() - ref) < 4.5 * se + 1e-4 * abs(ref), (name, ests.mean(), ref, se)


def test_render_is_deterministic_and_matches_the_integrand_mean():
    scene = R.load_xml(SCENES / "cornell.xml", width=8, height=8)
    a = R.render(scene, jax.random.key(3), spp=16, pixel_center=True, progress=False)
    b = R.render(scene, jax.random.key(3), spp=16, pixel_center=True, progress=False)
    np.testing.assert_array_equal(a.mean, b.mean)
    # Converged pixel-centre render == quadrature of the pixel integrand.
    c = R.render(scene, jax.random.key(4), spp=16, sampler="jittered", pixel_center=True,
                 realizations=64, progress=False)
    f = R.pixel_integrand(scene, (3, 6), channel="r")
    ref = float(jnp.mean(f(jnp.asarray(midpoint_grid(256)))))
    se = np.sqrt(c.variance[6, 3, 0] / 64)
    assert abs(c.mean[6, 3, 0] - ref) < 4.5 * se + 1e-5


def test_large_batches_match_small_ones():
    # Regression for the XLA CPU miscompile of fused 3-vector reductions at large vmap sizes
    # (rows past ~2/3 of a 4096 batch came out wrong): a jitted 4096-batch equals 256-batches.
    scene = R.load_xml(SCENES / "cornell.xml", width=16, height=16)
    f = R.pixel_integrand(scene, (8, 12))
    x = jax.random.uniform(jax.random.key(0), (4096, 2))
    big = np.asarray(f(x))  # one vmapped block of 4096 under jit
    small = np.concatenate([np.asarray(f(x[i:i + 256])) for i in range(0, 4096, 256)])
    np.testing.assert_allclose(big, small, rtol=1e-4, atol=1e-6)


def test_pixel_integrand_plugs_into_the_variance_engine():
    # The image estimator of a pixel is the variance engine's estimator: a fresh point set per
    # realization, toroidally shifted (W Sec. 5.4). Both ways of measuring agree.
    from anisosample import variance

    scene = R.load_xml(SCENES / "cornell.xml", width=32, height=32)
    f = R.pixel_integrand(scene, (9, 28))
    sampler = samplers.get("jittered")
    reps = 512
    engine = variance.estimate_variance(f, sampler, 64, jax.random.key(0), reps,
                                        randomization="fresh+shift")
    pts = []
    for k in jax.random.split(jax.random.key(1), reps):
        k1, k2 = jax.random.split(k)
        pts.append(samplers.toroidal_shift(k2, sampler(k1, 64)))
    ests = np.asarray(jnp.mean(f(jnp.stack(pts)), axis=1), np.float64)
    direct = ests.var(ddof=1)
    # Two independent estimates, each with a relative standard error of about 6-7% here.
    assert engine.variance == pytest.approx(direct, rel=0.3)
    assert engine.mean == pytest.approx(ests.mean(), rel=0.01)


def test_depth_of_field_lens_integrand_matches_the_render():
    scene = R.load_xml(SCENES / "dof.xml", width=16, height=16)
    f = R.pixel_integrand(scene, (12, 14))  # "auto": the lens sample (point light only)
    assert f.options.dimension == "lens"
    grid = np.asarray(f(jnp.asarray(midpoint_grid(128))))
    ref = float(grid.mean())
    res = R.render(scene, jax.random.key(2), spp=64, sampler="jittered", pixel_center=True,
                   realizations=32, progress=False)
    lum = np.tensordot(res.mean, np.asarray(R.integrator.LUMINANCE), axes=1)
    var = np.tensordot(res.variance, np.asarray(R.integrator.LUMINANCE) ** 2, axes=1)
    se = float(np.sqrt(var[14, 12] / 32))
    assert abs(lum[14, 12] - ref) < 4.5 * se + 2e-3 * ref


def test_mis_and_light_sampling_estimate_the_same_image():
    # Two estimators of one integral on glossy GGX surfaces (H Sec. 4.3): light sampling alone
    # and light + BSDF sampling with the power heuristic.
    scene = R.load_xml(SCENES / "glossy.xml", width=8, height=8)
    kw = dict(spp=128, realizations=16, pixel_center=True, progress=False)
    a = R.render(scene, jax.random.key(0), mis=False, **kw)
    b = R.render(scene, jax.random.key(1), mis=True, **kw)
    se = np.sqrt((a.variance + b.variance) / 16)
    z = (a.mean - b.mean) / np.maximum(se, 1e-6)
    assert np.mean(z**2) < 2.0, np.mean(z**2)  # ~1 for agreeing estimators (chi^2 / dof)
    assert np.max(np.abs(z)) < 5.5


def test_pss_warp_in_front_of_the_light_keeps_the_integral():
    # H Sec. 3.3 / 4.1: a bilinear PSS warp fitted to the integrand at the PSS corners (Eq. 9)
    # in front of uniform area sampling leaves the pixel value unchanged and, for the smooth
    # cosine/distance factors of an unoccluded pixel, lowers the variance.
    from anisosample import warps

    scene = R.load_xml(SCENES / "triangle_light.xml", width=16, height=16)
    plain = R.pixel_integrand(scene, (4, 13))
    corners = np.asarray(plain(jnp.array([[0.0, 0.0], [1 - 1e-6, 0.0], [0.0, 1 - 1e-6],
                                          [1 - 1e-6, 1 - 1e-6]])))
    assert np.all(corners > 0)
    warped = R.pixel_integrand(scene, (4, 13), warp=warps.Bilinear(corners.reshape(2, 2).T))
    x = jnp.asarray(midpoint_grid(128))
    a, b = np.asarray(plain(x)), np.asarray(warped(x))
    assert b.mean() == pytest.approx(a.mean(), rel=1e-3)
    assert b.std() < a.std()


def test_hashed_uniforms_are_uniform_and_independent():
    """The film/BSDF random numbers (lowbias32 of a counter): moments, a KS test per coordinate,
    no correlation between the coordinates or between two pixels' streams."""
    from scipy import stats

    from anisosample.render.integrator import hashed_uniforms

    n = 1 << 16
    a = np.asarray(hashed_uniforms(jax.random.key(1), n), np.float64)
    b = np.asarray(hashed_uniforms(jax.random.key(2), n), np.float64)
    assert a.shape == (n, 2) and a.min() >= 0 and a.max() < 1
    se = np.sqrt(1 / 12 / n)
    for u in (a[:, 0], a[:, 1], b[:, 0]):
        assert abs(u.mean() - 0.5) < 5 * se
        assert abs(u.var() - 1 / 12) < 5 * np.sqrt(1 / 180 / n)
        assert stats.kstest(u, "uniform").pvalue > 1e-4
    for x, y in ((a[:, 0], a[:, 1]), (a[:, 0], b[:, 0]), (a[:-1, 0], a[1:, 0])):
        assert abs(np.corrcoef(x, y)[0, 1]) < 5 / np.sqrt(n)
    # 2D uniformity: chi-square over a 16x16 grid.
    counts = np.histogram2d(a[:, 0], a[:, 1], bins=16, range=[[0, 1], [0, 1]])[0].ravel()
    assert stats.chisquare(counts).pvalue > 1e-4

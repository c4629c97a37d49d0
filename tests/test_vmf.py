"""von Mises-Fisher machinery (anisosample.vmf) against scipy, quadrature and closed forms."""

import logging
import math

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest
import scipy.integrate
import scipy.special
import scipy.stats
from helpers import assert_pytree_round_trips

from anisosample import vmf

KAPPAS = [0.5, 1.0, 2.0, 5.0, 10.0, 30.0, 50.0, 100.0, 1000.0]
# references/directions_vmf.md Sec. 3 (scipy, float64)
A_REF = [
    0.2424996126,
    0.4463899659,
    0.6977746580,
    0.8933831370,
    0.9485998260,
    0.9831895554,
    0.9899489674,
    0.9949873730,
    0.9994998749,
]
LOGI0_REF = [
    0.0615497192,
    0.2359143585,
    0.8239935415,
    3.3046817758,
    7.9429720831,
    27.3847014332,
    47.1275755019,
    96.7797326899,
    995.6273088899,
]
DA_REF = [
    0.4561947,
    0.3543460,
    0.1642232,
    2.318994e-2,
    5.298388e-3,
    5.653130e-4,
    2.020626e-4,
    5.025383e-5,
    5.002504e-7,
]


def test_bessel_ratios_match_reference_table():
    k = jnp.asarray(KAPPAS, jnp.float32)
    np.testing.assert_allclose(vmf.mean_resultant_length(k), A_REF, rtol=2e-6)
    np.testing.assert_allclose(vmf.log_i0(k), LOGI0_REF, rtol=2e-6, atol=1e-6)
    # float32 A' is the cancelling quantity: the stable branches keep it to 1e-3 relative
    np.testing.assert_allclose(vmf.mean_resultant_length_derivative(k), DA_REF, rtol=1e-3)


def test_bessel_ratios_match_scipy_float64():
    k = np.geomspace(1e-4, 2e3, 60)
    a = scipy.special.i1e(k) / scipy.special.i0e(k)
    da = 1.0 - a / k - a * a  # exact enough in float64 up to k ~ 1e3 only for moderate k
    with jax.enable_x64(True):
        kk = jnp.asarray(k)
        np.testing.assert_allclose(vmf.mean_resultant_length(kk), a, rtol=1e-12)
        got = np.asarray(vmf.mean_resultant_length_derivative(kk))
    mid = k < 25  # scipy's float64 formula is trustworthy there; beyond, compare with the table
    np.testing.assert_allclose(got[mid], da[mid], rtol=1e-8)
    assert got[0] == pytest.approx(0.5, abs=1e-8)


def test_pdf_is_finite_normalised_and_uniform_at_zero_kappa():
    x = jnp.linspace(0, 2 * math.pi, 1001, dtype=jnp.float32)
    for kappa in [0.0, 1e-3, 10.0, 700.0, 1e4]:
        q = vmf.pdf(x, 1.0, kappa)
        assert bool(jnp.all(jnp.isfinite(q))), kappa
    np.testing.assert_allclose(vmf.pdf(x, 2.0, 0.0), 1.0 / (2 * math.pi), rtol=1e-6)
    for kappa in [0.5, 10.0, 100.0, 900.0]:
        total = float(jnp.sum(vmf.bin_masses(0.3, kappa, 180)))
        assert total == pytest.approx(1.0, abs=1e-5), kappa


def test_pdf_matches_scipy_vonmises():
    x = np.linspace(-3, 3, 13)
    for kappa in [0.7, 10.0, 80.0]:
        ref = scipy.stats.vonmises.pdf(x, kappa, loc=0.4)
        with jax.enable_x64(True):
            got = vmf.pdf(jnp.asarray(x), 0.4, kappa)
        np.testing.assert_allclose(got, ref, rtol=1e-10)


@pytest.mark.parametrize(
    "rbar,kappa",
    [
        (0.10, 0.201008),
        (0.30, 0.629215),
        (0.50, 1.159320),
        (0.70, 2.013628),
        (0.85, 3.680408),
        (0.90, 5.304689),
        (0.95, 10.271689),
        (0.99, 50.253847),
    ],
)
def test_kappa_from_resultant_table(rbar, kappa):
    with jax.enable_x64(True):
        got = float(vmf.kappa_from_resultant(jnp.float64(rbar)))
    assert got == pytest.approx(kappa, abs=1e-6)  # the table has 6 decimals
    got32 = float(vmf.kappa_from_resultant(jnp.float32(rbar)))
    assert got32 == pytest.approx(kappa, rel=1e-3)


def test_kappa_from_resultant_edge_cases():
    assert float(vmf.kappa_from_resultant(0.0)) == 0.0
    k1 = float(vmf.kappa_from_resultant(1.0))
    assert np.isfinite(k1) and k1 > 1e3


def test_negentropy_is_numerical_integral_of_q_log_q():
    for kappa in [0.5, 5.0, 50.0, 500.0]:

        def integrand(x, kappa=kappa):
            logq = scipy.stats.vonmises.logpdf(x, kappa)
            return np.exp(logq) * logq

        ref, _ = scipy.integrate.quad(
            integrand, -math.pi, math.pi, points=[0.0], limit=200, epsabs=1e-13, epsrel=1e-12
        )
        with jax.enable_x64(True):
            got = float(vmf.negentropy(jnp.float64(kappa)))
        assert got == pytest.approx(ref, abs=1e-9), kappa


def _eq17_by_quadrature(hist, mu, kappa, floor):
    """W Eq. 17, int q log(q/p), by adaptive quadrature per bin (float64, scipy)."""
    nbins = len(hist)
    delta = 2 * math.pi / nbins
    p = hist / hist.sum()
    p = (p + floor) / (1 + nbins * floor)
    total = 0.0
    for i in range(nbins):
        a, b = (i - 0.5) * delta, (i + 0.5) * delta

        def f(x, i=i):
            logq = scipy.stats.vonmises.logpdf(x, kappa, loc=mu)
            return np.exp(logq) * (logq - np.log(p[i] / delta))

        total += scipy.integrate.quad(f, a, b, epsabs=1e-14, epsrel=1e-12)[0]
    return total


def _test_hist(nbins=90):
    rng = np.random.default_rng(5)
    x = 2 * math.pi * np.arange(nbins) / nbins
    h = np.exp(3 * np.cos(x - 1.0)) + 0.5 * np.exp(8 * np.cos(x - 4.0)) + rng.uniform(0, 0.3, nbins)
    h[10:14] = 0.0  # empty bins, as the zeroed 0/90 windows make them
    return h


@pytest.mark.parametrize("mu,kappa", [(1.2, 3.0), (4.1, 40.0), (0.2, 150.0)])
def test_reverse_kl_closed_form_equals_numerical_eq17(mu, kappa):
    hist = _test_hist()
    ref = _eq17_by_quadrature(hist, mu, kappa, floor=1e-4)
    with jax.enable_x64(True):
        got = float(
            vmf.reverse_kl(
                jnp.asarray(hist), jnp.float64(mu), jnp.float64(kappa), floor=1e-4, nodes=8
            )
        )
    assert got == pytest.approx(ref, abs=1e-6)
    got32 = float(vmf.reverse_kl(jnp.asarray(hist, jnp.float32), mu, kappa, floor=1e-4))
    assert got32 == pytest.approx(ref, abs=1e-4 * max(1.0, abs(ref)))


def test_reverse_kl_vanishes_for_a_piecewise_constant_p_matched_by_q():
    # q = uniform (kappa -> 0) against a uniform histogram: D = 0 exactly.
    with jax.enable_x64(True):
        d = float(vmf.reverse_kl(jnp.ones(36, jnp.float64), 0.3, 1e-9, floor=1e-12))
    assert abs(d) < 1e-12
    # and D >= 0 everywhere on a grid of parameters
    hist = jnp.asarray(_test_hist(), jnp.float32)
    for kappa in [0.1, 3.0, 30.0, 300.0]:
        vals = vmf.reverse_kl_all_mu(hist, jnp.float32(kappa))
        assert bool(jnp.all(vals > -1e-5)) and bool(jnp.all(jnp.isfinite(vals)))


def _closed_form_grads(hist, mu, kappa, floor, nodes):
    """dD/dmu, dD/dkappa of the bin-integrated objective in float64 numpy (fact sheet Sec. 4)."""
    nbins = len(hist)
    delta = 2 * math.pi / nbins
    p = hist / hist.sum()
    p = (p + floor) / (1 + nbins * floor)
    logp = np.log(p / delta)
    t, w = np.polynomial.legendre.leggauss(nodes)
    x = (np.arange(nbins) * delta)[:, None] + t[None, :] / 2 * delta
    q = np.exp(kappa * np.cos(x - mu)) / (2 * math.pi * scipy.special.i0(kappa))
    a = scipy.special.i1(kappa) / scipy.special.i0(kappa)
    da = 1 - a / kappa - a * a
    dq_dmu = delta * (q * kappa * np.sin(x - mu)) @ (w / 2)
    dq_dk = delta * (q * (np.cos(x - mu) - a)) @ (w / 2)
    return -np.sum(dq_dmu * logp), kappa * da - np.sum(dq_dk * logp)


# d/dmu, d/dkappa of the reverse KL, compiled once for every case below (op by op, each
# gradient ran ~90 small programs)
_KL_GRAD_4_NODES = jax.jit(jax.grad(lambda h, m, k: vmf.reverse_kl(h, m, k, floor=1e-4, nodes=4),
                                    argnums=(1, 2)))
_KL_GRAD = jax.jit(jax.grad(lambda h, m, k: vmf.reverse_kl(h, m, k, floor=1e-4), argnums=(1, 2)))


@pytest.mark.parametrize("mu,kappa", [(0.9, 2.0), (3.5, 12.0), (5.9, 60.0)])
def test_reverse_kl_autodiff_matches_closed_form_derivatives(mu, kappa):
    hist = _test_hist()
    g_mu, g_k = _closed_form_grads(hist, mu, kappa, 1e-4, 4)
    with jax.enable_x64(True):
        gm, gk = _KL_GRAD_4_NODES(jnp.asarray(hist), jnp.float64(mu), jnp.float64(kappa))
    assert float(gm) == pytest.approx(g_mu, rel=1e-8, abs=1e-10)
    assert float(gk) == pytest.approx(g_k, rel=1e-6, abs=1e-10)
    gm32, gk32 = _KL_GRAD(jnp.asarray(hist, jnp.float32), jnp.float32(mu), jnp.float32(kappa))
    assert float(gm32) == pytest.approx(g_mu, rel=1e-3, abs=1e-4)
    assert float(gk32) == pytest.approx(g_k, rel=1e-3, abs=1e-4)


def test_reverse_kl_all_mu_matches_pointwise():
    hist = jnp.asarray(_test_hist(), jnp.float32)
    allmu = vmf.reverse_kl_all_mu(hist, 25.0, floor=1e-4)
    x = vmf.bin_centers(hist.shape[0])
    pointwise = jax.vmap(lambda m: vmf.reverse_kl(hist, m, 25.0, floor=1e-4))(x)
    np.testing.assert_allclose(allmu, pointwise, rtol=1e-5, atol=1e-5)


def _fig4_hist(nbins=360):
    """W Fig. 4: 3/4 vMF(90 deg, 10) + 1/4 vMF(180 deg, 30), exact bin masses on [0, 2 pi)."""
    return 0.75 * vmf.bin_masses(math.pi / 2, 10.0, nbins) + 0.25 * vmf.bin_masses(
        math.pi, 30.0, nbins
    )


def test_fig4_reverse_kl_is_mode_seeking_and_mle_mode_averaging():
    hist = _fig4_hist()
    mle = vmf.fit_mle(hist)
    mle_deg = math.degrees(float(mle.mu))
    # starts at the two histogram maxima (90 and 180 deg), as in W Sec. 5.2
    starts = jnp.radians(jnp.asarray([90.0, 180.0]))
    fit = jax.vmap(lambda m: vmf.fit_reverse_kl(hist, m, 20.0))(starts)
    got = np.degrees(np.asarray(fit.mu))
    assert abs(got[0] - 90) <= 2 and abs(got[1] - 180) <= 2, got
    assert bool(jnp.all(fit.converged))
    # MLE lands between the modes, far from both (mode averaging): 109.06 deg (fact sheet)
    assert 95 < mle_deg < 170 and mle_deg == pytest.approx(109.06, abs=0.05)
    assert float(mle.rbar) == pytest.approx(0.7527, abs=1e-3)
    # fixed kappa = 50 on the integer-degree grid: local minima exactly at 90 and 180
    obj = np.asarray(vmf.reverse_kl_all_mu(hist, 50.0))
    assert int(np.argmin(obj)) == 90
    w = obj[170:191]
    assert 170 + int(np.argmin(w)) == 180


def test_fit_reverse_kl_single_mode_agrees_with_mle():
    hist = vmf.bin_masses(2.0, 15.0, 180)
    mle = vmf.fit_mle(hist)
    fit = vmf.fit_reverse_kl(hist, 1.7, 5.0)
    assert float(mle.mu) == pytest.approx(2.0, abs=1e-3)
    assert float(fit.mu) == pytest.approx(2.0, abs=5e-3)
    assert float(fit.kappa) == pytest.approx(15.0, rel=0.05)
    assert float(mle.kappa) == pytest.approx(15.0, rel=0.01)


def test_mask_treats_bins_as_unobserved():
    hist = jnp.asarray(_test_hist(), jnp.float32)
    full = vmf.reverse_kl_all_mu(hist, 20.0, mask=jnp.ones(90, bool))
    np.testing.assert_allclose(full, vmf.reverse_kl_all_mu(hist, 20.0), rtol=1e-6, atol=1e-6)
    mask = jnp.arange(90) % 7 != 0
    x = vmf.bin_centers(90)
    got = vmf.reverse_kl_all_mu(hist, 20.0, mask=mask)
    q = jax.vmap(lambda m: vmf.bin_masses(m, 20.0, 90))(x)  # (mu, bins)
    total = float(hist.sum())
    p = (hist / total + vmf.DEFAULT_FLOOR) / (1 + 90 * vmf.DEFAULT_FLOOR)
    logp = jnp.log(p / (2 * math.pi / 90))
    mf = mask.astype(jnp.float32)[None, :]
    ref = vmf.negentropy(20.0) - (q * mf * logp[None, :]).sum(1) / (q * mf).sum(1)
    np.testing.assert_allclose(got, ref, rtol=1e-5, atol=1e-5)


def test_fit_reverse_kl_is_jittable():
    hist = _fig4_hist()
    f = jax.jit(lambda h, m: vmf.fit_reverse_kl(h, m, 20.0).mu)
    assert abs(math.degrees(float(f(hist, jnp.float32(math.radians(95.0))))) - 90) < 2


def test_reverse_kl_fit_keeps_the_solver_status():
    """The fit keeps optimistix's RESULTS (throw=False), vmapped or not: converged from a start
    near the mode; max_steps=2 stops BFGS before it converges (nonlinear_max_steps_reached),
    and says so instead of raising."""
    hist = _fig4_hist()
    fit = vmf.fit_reverse_kl(hist, math.radians(95.0), 20.0)
    assert isinstance(fit.result, optx.RESULTS)
    assert fit.result == optx.RESULTS.successful and bool(fit.converged)
    short = vmf.fit_reverse_kl(hist, math.radians(95.0), 20.0, max_steps=2)
    assert short.result == optx.RESULTS.nonlinear_max_steps_reached
    assert not bool(short.converged)
    starts = jnp.radians(jnp.asarray([90.0, 180.0]))
    both = jax.vmap(lambda m: vmf.fit_reverse_kl(hist, m, 20.0, max_steps=2))(starts)
    assert both.converged.shape == (2,) and not bool(jnp.any(both.converged))


def test_fits_are_pytrees():
    hist = _fig4_hist()
    assert_pytree_round_trips(vmf.fit_mle(hist))
    assert_pytree_round_trips(vmf.fit_reverse_kl(hist, math.radians(95.0), 20.0))
    fit = jax.jit(lambda h: vmf.fit_reverse_kl(h, 1.6, 20.0))(hist)  # built under jit
    assert bool(fit.converged)


def test_bad_input_raises():
    with pytest.raises(ValueError, match="all-zero"):
        vmf.reverse_kl(jnp.zeros(36), 0.0, 1.0)
    with pytest.raises(ValueError, match="non-negative"):
        vmf.reverse_kl(jnp.asarray([1.0, jnp.nan, 2.0]), 0.0, 1.0)
    with pytest.raises(ValueError, match="K >= 2"):
        vmf.fit_mle(jnp.zeros((0,)))
    for kappa in [0.0, -1.0, float("nan")]:
        with pytest.raises(ValueError, match="kappa"):
            vmf.reverse_kl(jnp.ones(36), 0.0, kappa)
    with pytest.raises(ValueError, match="all-zero"):
        vmf.fit_mle(jnp.zeros(36))
    with pytest.raises(ValueError, match="kappa"):
        vmf.fit_reverse_kl(jnp.ones(36), 0.0, -2.0)


def test_mle_of_uniform_histogram_is_flagged():
    fit = vmf.fit_mle(jnp.ones(180))
    assert not bool(fit.defined) and float(fit.kappa) == pytest.approx(0.0, abs=1e-4)
    assert np.isfinite(float(fit.mu))


def test_fitted_mu_stays_below_two_pi_for_modes_at_zero():
    """A mode centred on bin 0 can be fitted at mu = -1e-7; float32 mod(-1e-7, 2 pi) is the float
    nearest 2 pi, outside the documented [0, 2 pi). Both fits must return a mu in [0, 2 pi) that
    is circularly ~0 (the histogram is symmetric about 0 up to 1e-6)."""
    two_pi = np.float32(2 * np.pi)
    h = np.zeros(180, np.float32)
    h[0], h[1], h[-1] = 1.0, 0.5, 0.5
    fit = vmf.fit_reverse_kl(h, -1e-7, 50.0)
    h2 = h.copy()
    h2[-1] += 1e-6
    mle = vmf.fit_mle(h2)
    for mu in (float(fit.mu), float(mle.mu)):
        assert 0.0 <= mu < two_pi
        assert min(mu, 2 * np.pi - mu) < 1e-4


def test_fit_and_objective_options_are_validated():
    h = jnp.ones(36)
    cases = [
        (lambda: vmf.fit_reverse_kl(h, 0.0, 1.0, rtol=0.0), "rtol must be finite and > 0"),
        (lambda: vmf.fit_reverse_kl(h, 0.0, 1.0, atol=-1.0), "atol must be finite and > 0"),
        (lambda: vmf.fit_reverse_kl(h, 0.0, 1.0, max_steps=0), "max_steps must be >= 1"),
        (lambda: vmf.fit_reverse_kl(h, float("nan"), 1.0), "mu0 must be finite"),
        (lambda: vmf.reverse_kl(h, float("inf"), 1.0), "mu must be finite"),
        (lambda: vmf.reverse_kl(h, 0.0, 1.0, mask=np.ones(35, bool)), r"mask must be .* \(36,\)"),
        (lambda: vmf.reverse_kl_all_mu(h, 1.0, mask=np.ones(36)), "mask must be a boolean"),
        (lambda: vmf.fit_reverse_kl(h, 0.0, 1.0, mask=np.zeros(36, bool)), "at least one bin"),
    ]
    for call, message in cases:
        with pytest.raises(ValueError, match=message):
            call()


class _LogRecords(logging.Handler):
    """The records logged under ``name`` while in the ``with`` block."""

    def __init__(self, name):
        super().__init__(logging.DEBUG)
        self.logger, self.records = logging.getLogger(name), []

    def emit(self, record):
        self.records.append(record)

    def __enter__(self):
        self.logger.addHandler(self)
        return self.records

    def __exit__(self, *exc):
        self.logger.removeHandler(self)


def test_fits_compile_once_per_shape_and_settings():
    """fit_reverse_kl re-traced optimistix's BFGS on every call (seconds each) and fit_mle ran
    op by op; both are jitted now: a second histogram of the same shape reuses the program."""
    h = np.asarray(vmf.bin_masses(1.0, 20.0, 90))
    vmf.fit_reverse_kl(h, 0.9, 10.0)
    vmf.fit_mle(h)
    with jax.log_compiles(), _LogRecords("jax") as records:
        a = vmf.fit_reverse_kl(h[::-1].copy(), 2.0, 5.0)
        vmf.fit_mle(h[::-1].copy())
    compiled = [r.getMessage() for r in records if r.getMessage().startswith("Compiling")]
    assert compiled == []
    assert float(a.kappa) == pytest.approx(20.0, rel=0.05)  # still the right fit


def test_kappa_from_resultant_refuses_nan_and_out_of_range():
    """NaN rbar gave a NaN kappa silently, 1.5 was clipped to 1 silently."""
    for bad in (float("nan"), 1.5, -0.2):
        with pytest.raises(ValueError, match="rbar must be finite and in"):
            vmf.kappa_from_resultant(bad)
    with pytest.raises(ValueError, match="kappa_max"):
        vmf.kappa_from_resultant(0.5, kappa_max=0.0)
    assert float(vmf.kappa_from_resultant(1.0 + 1e-8)) == pytest.approx(1e4, rel=1e-3)

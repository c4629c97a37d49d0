"""Von Mises-Fisher (circular von Mises) machinery for direction histograms (W Sec. 5.2).

Everything here lives on the circle ``x in [0, 2 pi)`` (radians), as in W Eq. 16.
:mod:`anisosample.directions` feeds it *doubled* axial angles (``x = 2 alpha`` for a direction
``alpha in [0, pi)``), so a ``kappa`` used there is the concentration of the doubled angle:
angular spread ``~ 1/sqrt(kappa)`` rad in ``x``, half that in ``alpha`` (kappa = 50 -> ~4 deg).

Histograms are arrays of ``K`` non-negative bin weights on ``[0, 2 pi)``; bin ``i`` is centred at
``x_i = 2 pi i / K`` and covers ``[x_i - Delta/2, x_i + Delta/2)``, ``Delta = 2 pi / K``. They are
read as the piecewise-constant density ``p(x) = p_i / Delta`` on bin ``i`` (``p_i`` the normalised
masses), which makes W Eq. 17 a well-defined integral.

Numerics (see ``references/directions_vmf.md`` Sec. 7):

* Bessel functions only through the exponentially scaled ``i0e``/``i1e``: the density is written
  ``exp(kappa (cos(x - mu) - 1)) / (2 pi i0e(kappa))``, so nothing overflows at any kappa.
* ``A'(kappa) = 1 - A/kappa - A^2`` cancels in float32 for large kappa; above ``kappa = 25`` the
  asymptotic series is used instead, and the small-kappa limit 1/2 below ``1e-3``.
* Empty histogram bins: ``log 0 = -inf`` would make the reverse KL infinite for every ``mu``.
  Every bin gets a fixed floor, ``p <- (p + floor) / (1 + K floor)`` (default ``floor = 1e-6``
  per bin), before the logarithm. The floor sets how strongly ``q`` is repelled from empty bins.
"""

from __future__ import annotations

import functools
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jax.scipy.special import i0e, i1e
from jaxtyping import Bool

from ._types import Array, Float
from ._validate import check_int, check_positive_float, refuse_traced

__all__ = [
    "log_i0",
    "mean_resultant_length",
    "mean_resultant_length_derivative",
    "kappa_from_resultant",
    "pdf",
    "log_pdf",
    "negentropy",
    "bin_centers",
    "bin_masses",
    "reverse_kl",
    "reverse_kl_all_mu",
    "fit_mle",
    "fit_reverse_kl",
    "MLEFit",
    "ReverseKLFit",
    "DEFAULT_FLOOR",
    "DEFAULT_NODES",
]

DEFAULT_FLOOR = 1e-6
"""Per-bin floor added to normalised histograms before ``log`` (see module docstring)."""

DEFAULT_NODES = 4
"""Gauss-Legendre nodes per bin for the bin integrals of ``q``."""

_TWO_PI = 2.0 * math.pi


def _wrap_2pi(x):
    """``x mod 2 pi`` in ``[0, 2 pi)``: ``mod`` of a tiny negative float32 rounds up to ``2 pi``
    itself (the float nearest 2 pi), which is the same angle as 0."""
    r = jnp.mod(x, _TWO_PI)
    return jnp.where(r >= jnp.asarray(_TWO_PI, r.dtype), jnp.zeros_like(r), r)


# --- Bessel ratios ------------------------------------------------------------------------------


def log_i0(kappa):
    """``log I_0(kappa)`` without overflow: ``log i0e(kappa) + kappa``."""
    kappa = jnp.asarray(kappa)
    return jnp.log(i0e(kappa)) + kappa


def mean_resultant_length(kappa):
    """``A(kappa) = I_1(kappa) / I_0(kappa) = E_q[cos(x - mu)]`` (monotone from 0 to 1)."""
    kappa = jnp.asarray(kappa)
    return i1e(kappa) / i0e(kappa)


def mean_resultant_length_derivative(kappa):
    """``A'(kappa) = 1 - A/kappa - A^2``, stable at both ends.

    Small kappa (< 1e-3): ``A/kappa -> 1/2 - kappa^2/16``. Large kappa (> 25): the asymptotic
    ``1/(2k^2) + 1/(4k^3) + 3/(8k^4) + 25/(32 k^5)``, which avoids float32 cancellation.
    """
    kappa = jnp.asarray(kappa)
    a = mean_resultant_length(kappa)
    small = kappa < 1e-3
    k_safe = jnp.where(small, 1.0, kappa)
    a_over_k = jnp.where(small, 0.5 - kappa * kappa / 16.0, a / k_safe)
    exact = 1.0 - a_over_k - a * a
    big = kappa > 25.0
    k_big = jnp.where(big, kappa, 25.0)
    inv = 1.0 / k_big
    asym = inv * inv * (0.5 + inv * (0.25 + inv * (0.375 + inv * 25.0 / 32.0)))
    return jnp.where(big, asym, exact)


def kappa_from_resultant(rbar, *, newton_steps: int = 6, kappa_max: float = 1e4):
    """Solve ``A(kappa) = rbar`` (the vMF maximum-likelihood kappa), ``rbar in [0, 1]``.

    Best & Fisher's piecewise approximation as the start, then Newton with the stable ``A'``.
    ``rbar = 0`` gives ``kappa = 0``; ``rbar -> 1`` is capped at ``kappa_max``. Concrete ``rbar``
    must be finite and within 1e-6 of ``[0, 1]`` (round-off beyond the ends is clipped).
    """
    newton_steps = check_int("newton_steps", newton_steps, minimum=0)
    kappa_max = check_positive_float("kappa_max", kappa_max)
    if not isinstance(rbar, jax.core.Tracer):
        rb = np.asarray(rbar, dtype=np.float64)
        if not np.all(np.isfinite(rb)) or np.any(rb < -1e-6) or np.any(rb > 1 + 1e-6):
            raise ValueError(
                f"rbar must be finite and in [0, 1], got {rb.reshape(-1)[:8].tolist()}"
            )
    r = jnp.clip(jnp.asarray(rbar), 0.0, 1.0)
    r_hi = jnp.minimum(r, 1.0 - 1e-7)
    k0 = jnp.where(
        r < 0.53,
        2.0 * r + r**3 + 5.0 * r**5 / 6.0,
        jnp.where(
            r < 0.85,
            -0.4 + 1.39 * r + 0.43 / (1.0 - r_hi),
            1.0 / jnp.maximum(r_hi**3 - 4.0 * r_hi**2 + 3.0 * r_hi, 1e-30),
        ),
    )
    k = jnp.clip(k0, 0.0, kappa_max)

    def newton(k, _):
        step = (mean_resultant_length(k) - r) / mean_resultant_length_derivative(k)
        return jnp.clip(k - step, 0.0, kappa_max), None

    k, _ = jax.lax.scan(newton, k, None, length=newton_steps)
    return jnp.where(r <= 0.0, 0.0, k)


# --- density ------------------------------------------------------------------------------------


def log_pdf(x, mu, kappa):
    """``log q(x | mu, kappa)`` of W Eq. 16 (radians; per unit angle on the circle).

    ``kappa >= 0``; concrete ``x``, ``mu`` must be finite and ``kappa`` finite and ``>= 0``
    (``ValueError`` otherwise; traced values are not checked).
    """
    _check_mu("x", x)
    _check_mu("mu", mu)
    _check_kappa(kappa, allow_zero=True)
    kappa = jnp.asarray(kappa)
    return kappa * (jnp.cos(x - mu) - 1.0) - jnp.log(_TWO_PI * i0e(kappa))


def pdf(x, mu, kappa):
    """W Eq. 16: ``q(x | mu, kappa) = exp(kappa cos(x - mu)) / (2 pi I_0(kappa))``.

    Evaluated as ``exp(kappa (cos(x - mu) - 1)) / (2 pi i0e(kappa))``: finite for every
    ``kappa >= 0`` (``kappa = 0`` is the uniform density ``1/(2 pi)``).
    """
    return jnp.exp(log_pdf(x, mu, kappa))  # log_pdf checks the arguments


@jax.custom_jvp
def negentropy(kappa):
    """``E_q[log q] = kappa A(kappa) - log(2 pi I_0(kappa))`` (first terms of W Eq. 18).

    Its derivative ``kappa A'(kappa)`` (because ``I_0' = I_1``) is supplied explicitly so that
    autodiff uses the stable ``A'``.
    """
    kappa = jnp.asarray(kappa)
    return kappa * (mean_resultant_length(kappa) - 1.0) - jnp.log(_TWO_PI * i0e(kappa))


@negentropy.defjvp
def _negentropy_jvp(primals, tangents):
    (kappa,), (dk,) = primals, tangents
    return negentropy(kappa), kappa * mean_resultant_length_derivative(kappa) * dk


# --- histograms -------------------------------------------------------------------------------


def bin_centers(nbins: int, dtype=jnp.float32):
    """Centres ``x_i = 2 pi i / K`` of ``K`` bins on ``[0, 2 pi)`` (bins centred on the grid)."""
    return jnp.arange(nbins, dtype=dtype) * (_TWO_PI / nbins)


def _gauss_legendre(nodes: int):
    t, w = np.polynomial.legendre.leggauss(nodes)
    return t / 2.0, w / 2.0  # nodes on [-1/2, 1/2], weights summing to 1


def bin_masses(mu, kappa, nbins: int, *, nodes: int = DEFAULT_NODES):
    """``Q_i = integral of q(. | mu, kappa) over bin i`` (Gauss-Legendre, ``nodes`` per bin).

    ``sum_i Q_i = 1`` up to the quadrature error (< 1e-5 for ``kappa`` up to ~1e3 with 180 bins
    and 4 nodes; raise ``nodes`` for narrower q).
    """
    nbins = check_int("nbins", nbins, minimum=1)
    nodes = check_int("nodes", nodes, minimum=1)
    _check_mu("mu", mu)
    _check_kappa(kappa, allow_zero=True)
    mu = jnp.asarray(mu)
    dtype = (
        jnp.result_type(mu, jnp.float32) if not jnp.issubdtype(mu.dtype, jnp.floating) else mu.dtype
    )
    t, w = _gauss_legendre(nodes)
    delta = _TWO_PI / nbins
    x = bin_centers(nbins, dtype)[:, None] + jnp.asarray(t, dtype)[None, :] * delta
    q = pdf(x, mu, jnp.asarray(kappa, dtype))
    return delta * (q @ jnp.asarray(w, dtype))


def _log_density(hist, floor):
    """``log(p_i / Delta)`` of the floored, normalised histogram (never -inf)."""
    hist = jnp.asarray(hist)
    nbins = hist.shape[-1]
    total = jnp.sum(hist, axis=-1, keepdims=True)
    p = hist / jnp.where(total > 0, total, 1.0)
    p = (p + floor) / (1.0 + nbins * floor)
    return jnp.log(p) - math.log(_TWO_PI / nbins)


def check_hist(hist):
    """``hist`` as a float array of shape ``(..., K)``, ``K >= 2``; concrete values must be
    finite, non-negative and of positive total (``ValueError`` otherwise; traced values are
    checked inside the program, :func:`anisosample._validate.refuse_traced`)."""
    hist = jnp.asarray(hist)
    if hist.ndim < 1 or hist.shape[-1] < 2:
        raise ValueError(f"hist must have shape (..., K) with K >= 2 bins, got {hist.shape}")
    if not jnp.issubdtype(hist.dtype, jnp.floating):
        hist = hist.astype(jnp.float32)
    if isinstance(hist, jax.core.Tracer):
        hist = refuse_traced(hist, ~jnp.all(jnp.isfinite(hist) & (hist >= 0)),
                             "hist must hold finite, non-negative bin weights")
        return refuse_traced(hist, jnp.any(jnp.sum(hist, axis=-1) <= 0),
                             "hist must have positive total weight; got an all-zero histogram")
    else:
        h = np.asarray(hist)
        if not np.all(np.isfinite(h)) or np.any(h < 0):
            raise ValueError("hist must hold finite, non-negative bin weights")
        if np.any(h.sum(axis=-1) <= 0):
            raise ValueError("hist must have positive total weight; got an all-zero histogram")
    return hist


def reverse_kl(
    hist, mu, kappa, *, floor: float = DEFAULT_FLOOR, nodes: int = DEFAULT_NODES, mask=None
):
    """Reverse KL ``D_KL(q(. | mu, kappa) || p)`` of W Eqs. 17-18 against a histogram ``p``.

    ``p`` is the piecewise-constant density of the normalised, floored histogram (module
    docstring), so ``E_q[log p] = sum_i Q_i log(p_i / Delta)`` with ``Q_i`` the bin integrals of
    ``q`` (:func:`bin_masses`), and ``E_q[log q]`` is the closed form :func:`negentropy`.
    The result is exactly W Eq. 17 for that ``p`` (up to quadrature error), hence >= 0 and zero
    only for ``q = p``. Differentiable in ``mu`` and ``kappa`` (``kappa > 0``).

    ``mask`` (optional boolean ``(K,)``): bins marked False are *unobserved* (e.g. the windows
    around 0 and 90 degrees that W Sec. 5.1 zeroes), not empty: the cross term becomes the
    average of ``log p`` over the observed bins under ``q``,
    ``sum_{i in mask} Q_i log(p_i/Delta) / sum_{i in mask} Q_i``, so ``q`` is not pushed away
    from the masked windows (their floor would otherwise bias directions near the axes).
    """
    hist = check_hist(hist)
    floor = check_positive_float("floor", floor)
    nodes = check_int("nodes", nodes, minimum=1)
    _check_kappa(kappa)
    _check_mu("mu", mu)
    mask = _check_mask(mask, hist.shape[-1])
    return _reverse_kl(hist, mu, kappa, floor, nodes, mask)


def _reverse_kl(hist, mu, kappa, floor, nodes, mask=None):
    logp = _log_density(hist, floor)
    q = bin_masses(mu, kappa, hist.shape[-1], nodes=nodes)
    if mask is None:
        return negentropy(kappa) - jnp.sum(q * logp, axis=-1)
    m = jnp.asarray(mask, q.dtype)
    cross = jnp.sum(q * m * logp, axis=-1) / jnp.maximum(jnp.sum(q * m, axis=-1), 1e-30)
    return negentropy(kappa) - cross


def _check_mask(mask, nbins: int):
    """``mask``: ``None`` or ``(K,)`` booleans with at least one observed (True) bin."""
    if mask is None or isinstance(mask, jax.core.Tracer):
        return mask
    m = np.asarray(mask)
    if m.shape != (nbins,) or m.dtype != np.bool_:
        raise ValueError(
            f"mask must be a boolean array of shape ({nbins},), got {m.dtype} {m.shape}"
        )
    if not m.any():
        raise ValueError("mask must mark at least one bin as observed (True)")
    return jnp.asarray(m)


def _check_mu(name: str, mu):
    if isinstance(mu, jax.core.Tracer):
        return
    m = np.asarray(mu)
    if not np.issubdtype(m.dtype, np.number) or np.iscomplexobj(m):
        raise TypeError(f"{name} must be real angles in radians, got dtype {m.dtype}")
    if not np.all(np.isfinite(m)):
        raise ValueError(f"{name} must be finite (radians), got {np.asarray(mu).tolist()}")


def _check_kappa(kappa, *, allow_zero: bool = False):
    if not isinstance(kappa, jax.core.Tracer):
        k = np.asarray(kappa)
        if not np.issubdtype(k.dtype, np.number) or np.iscomplexobj(k):
            raise TypeError(f"kappa must be a real number, got {k.dtype}")
        if not np.all(np.isfinite(k)) or np.any(k < 0) or (not allow_zero and np.any(k == 0)):
            bound = ">= 0" if allow_zero else "> 0"
            raise ValueError(f"kappa must be finite and {bound}, got {k.tolist()}")


def _circulant_kernel(nbins: int, kappa, nodes: int, dtype):
    """``C[m, i] = Q_i(mu = x_m)``: the bin masses of ``q`` centred on every bin centre."""
    q0 = bin_masses(jnp.zeros((), dtype), kappa, nbins, nodes=nodes)  # Q_d for mu = 0
    idx = (jnp.arange(nbins)[None, :] - jnp.arange(nbins)[:, None]) % nbins
    return q0[idx]


def reverse_kl_all_mu(
    hist, kappa, *, floor: float = DEFAULT_FLOOR, nodes: int = DEFAULT_NODES, mask=None
):
    """W Eq. 18 at fixed ``kappa`` for ``mu`` at every bin centre: shape ``(..., K)``.

    W Sec. 5.2's practical variant (fixed kappa, mu on the bin grid) as one circulant matrix
    product per histogram; entry ``m`` equals ``reverse_kl(hist, x_m, kappa, mask=mask)``.
    """
    hist = check_hist(hist)
    floor = check_positive_float("floor", floor)
    nodes = check_int("nodes", nodes, minimum=1)
    _check_kappa(kappa)
    mask = _check_mask(mask, hist.shape[-1])
    return _reverse_kl_all_mu(hist, kappa, floor, nodes, mask)


def _reverse_kl_all_mu(hist, kappa, floor, nodes, mask=None):
    logp = _log_density(hist, floor)
    c = _circulant_kernel(hist.shape[-1], kappa, nodes, logp.dtype)
    ne = negentropy(jnp.asarray(kappa, logp.dtype))
    if mask is None:
        return ne - logp @ c.T
    m = jnp.asarray(mask, logp.dtype)
    return ne - ((logp * m) @ c.T) / jnp.maximum(m @ c.T, 1e-30)


# --- fits ----------------------------------------------------------------------------------------


class MLEFit(eqx.Module):
    """A single-vMF maximum-likelihood fit: ``mu`` in ``[0, 2 pi)``, ``kappa``, ``rbar``.

    ``defined`` is False where the mean resultant length is 0 (uniform data: ``mu`` undefined,
    returned as 0). Closed form plus a fixed number of Newton steps: no solver, no status.
    """

    mu: Float[Array, "..."]
    kappa: Float[Array, "..."]
    rbar: Float[Array, "..."]
    defined: Array


def fit_mle(hist) -> MLEFit:
    """Maximum-likelihood single vMF for a weighted histogram (the mode-averaging baseline).

    Mean direction ``atan2(S, C)`` of the weighted bin centres, ``rbar = |(C, S)| / sum w``,
    ``kappa`` from ``A(kappa) = rbar`` (:func:`kappa_from_resultant`). W Sec. 5.2, "Maximum
    Likelihood Estimation"; Mardia & Jupp Sec. 5.3.
    """
    hist = check_hist(hist)
    return _fit_mle_jit(hist)


@jax.jit
def _fit_mle_jit(hist):
    return _fit_mle(hist)


def _fit_mle(hist):
    x = bin_centers(hist.shape[-1], hist.dtype)
    total = jnp.sum(hist, axis=-1)
    c = jnp.sum(hist * jnp.cos(x), axis=-1)
    s = jnp.sum(hist * jnp.sin(x), axis=-1)
    rbar = jnp.sqrt(c * c + s * s) / jnp.where(total > 0, total, 1.0)
    defined = rbar > 1e-6
    mu = jnp.where(defined, _wrap_2pi(jnp.arctan2(s, c)), 0.0)
    return MLEFit(mu, kappa_from_resultant(rbar), rbar, defined)


class ReverseKLFit(eqx.Module):
    """Result of :func:`fit_reverse_kl`: ``mu`` in ``[0, 2 pi)``, ``kappa``, objective value.

    ``result``: optimistix's ``RESULTS`` of the BFGS solve (``optimistix.RESULTS.successful``,
    ``max_steps_reached``, ...; the fit runs with ``throw=False`` so that it ``vmap``s, and
    keeps it here); ``converged`` is ``result == optimistix.RESULTS.successful``.
    """

    mu: Float[Array, "..."]
    kappa: Float[Array, "..."]
    value: Float[Array, "..."]
    result: optx.RESULTS

    @property
    def converged(self) -> Bool[Array, "..."]:
        """``result == optimistix.RESULTS.successful``."""
        return self.result == optx.RESULTS.successful


def fit_reverse_kl(
    hist,
    mu0,
    kappa0,
    *,
    floor: float = DEFAULT_FLOOR,
    nodes: int = DEFAULT_NODES,
    kappa_max: float = 1e3,
    kappa_min: float = 1e-3,
    mask=None,
    rtol: float = 1e-6,
    atol: float = 1e-6,
    max_steps: int = 100,
) -> ReverseKLFit:
    """Fit ``(mu, kappa)`` of one vMF minimising the reverse KL (W Eq. 18) from ``(mu0, kappa0)``.

    W Sec. 5.2 / Fig. 4c: the gradient fit, mode-seeking, converging to the local minimum near
    its start (start at histogram maxima). Optimistix BFGS over ``(mu, log kappa)`` (``log``
    keeps kappa > 0; ``kappa`` is clipped to ``[kappa_min, kappa_max]``, the upper bound keeping
    the bin quadrature exact).
    Pure and jit/vmap-able: batch over starts or histograms with ``jax.vmap``. ``mask``: as in
    :func:`reverse_kl`.
    """
    hist = check_hist(hist)
    if hist.ndim != 1:
        raise ValueError(f"hist must have shape (K,) for one fit (jax.vmap for batches), got "
                         f"shape {hist.shape}")
    floor = check_positive_float("floor", floor)
    nodes = check_int("nodes", nodes, minimum=1)
    kappa_max = check_positive_float("kappa_max", kappa_max)
    kappa_min = check_positive_float("kappa_min", kappa_min)
    if kappa_min >= kappa_max:
        raise ValueError(f"kappa_min must be < kappa_max, got {kappa_min} >= {kappa_max}")
    _check_kappa(kappa0)
    _check_mu("mu0", mu0)
    mask = _check_mask(mask, hist.shape[-1])
    rtol = check_positive_float("rtol", rtol)
    atol = check_positive_float("atol", atol)
    max_steps = check_int("max_steps", max_steps, minimum=1)
    return _fit_reverse_kl_jit(
        hist, mu0, kappa0, floor, nodes, kappa_max, rtol, atol, max_steps, mask, kappa_min
    )


@functools.partial(jax.jit, static_argnums=(3, 4, 5, 6, 7, 8, 10))
def _fit_reverse_kl_jit(
    hist, mu0, kappa0, floor, nodes, kappa_max, rtol, atol, max_steps, mask, kappa_min
):
    """:func:`_fit_reverse_kl` compiled once per histogram shape and settings (the public
    :func:`fit_reverse_kl` traced optimistix's BFGS anew on every call: seconds each)."""
    return _fit_reverse_kl(
        hist, mu0, kappa0, floor, nodes, kappa_max, rtol, atol, max_steps, mask, kappa_min
    )


def _fit_reverse_kl(
    hist, mu0, kappa0, floor, nodes, kappa_max, rtol, atol, max_steps, mask=None, kappa_min=1e-3
):
    dtype = hist.dtype
    lo, hi = math.log(kappa_min), math.log(kappa_max)

    def objective(y, _):
        kappa = jnp.exp(jnp.clip(y[1], lo, hi))
        return _reverse_kl(hist, y[0], kappa, floor, nodes, mask)

    y0 = jnp.stack([jnp.asarray(mu0, dtype), jnp.log(jnp.asarray(kappa0, dtype))])
    sol = optx.minimise(
        objective, optx.BFGS(rtol=rtol, atol=atol), y0, max_steps=max_steps, throw=False
    )
    mu = _wrap_2pi(sol.value[0])
    kappa = jnp.exp(jnp.clip(sol.value[1], lo, hi))
    value = objective(sol.value, None)
    value = eqx.error_if(value, ~jnp.isfinite(value), "reverse KL fit produced a non-finite value")
    return ReverseKLFit(mu, kappa, value, sol.result)

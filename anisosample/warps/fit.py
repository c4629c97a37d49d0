"""Fitting PSS warps to a factor of the integrand: point-wise (H Eq. 9) and least squares.

* :func:`fit_pointwise` (H Sec. 3.3, Eq. 9): each control value ``v`` of a ``Bilinear`` or
  ``Biquadratic`` warp is the factor evaluated at its PSS point pushed through all *later* warps,
  ``v <- f((w_m o ... o w_(i+1))(u_v))``. Control points: the corners for the bilinear warp, the
  3x3 grid ``{0, 1/2, 1}^2`` for the biquadratic (H leaves this choice open; a Bezier surface
  interpolates only its corners, so this is an approximation there).
* :func:`fit_least_squares` (beyond the paper): choose the control values that minimise the
  second moment -- hence the variance -- of the estimator ``f / p`` over a ``probes x probes``
  midpoint grid, with **optimistix**' Levenberg-Marquardt. With the fitted warp first in the
  chain and ``y`` the PSS point entering the later warps (pdf ``p_rest``),
  ``E[(f/p)^2] = int f(x(y))^2 / (J(y) p_rest(x(y))^2) dy``, so the residuals are
  ``r_k = f(x_k) / (p_rest(x_k) sqrt(K J_theta(y_k)))`` at fixed probes: only the fitted warp's
  closed-form pdf depends on the parameters ``theta = log(values)`` (no differentiation through
  sampling).
* :func:`fit_tabulated`: the 32x32 tabulated product reference of H Sec. 4.3.

All three are pure JAX functions of the later warps' parameters: ``jit`` them and ``vmap`` them
over shading points. Factors are callables on one output point ``x`` returning a scalar.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Bool, Int

from .._types import Array
from .._validate import renamed_keywords
from ..metrics import midpoint_grid
from ._base import AbstractWarp, Compose
from .planar import Bilinear, Biquadratic
from .tabulated import Tabulated

# the API; the checks below are shared with warps.tuning
__all__ = ["fit_pointwise", "fit_least_squares", "fit_tabulated", "WarpFit"]

_FAMILIES = (Bilinear, Biquadratic)


class WarpFit(eqx.Module):
    """A solver's warp fit with its status (``details=True`` of :func:`fit_least_squares` and
    :func:`~anisosample.warps.tuning.fit_min_variance`); ``vmap``ped fits hold one entry per fit.

    ``warp``: the fitted warp (what ``details=False`` returns). ``result``: optimistix's
    ``RESULTS`` of the solve (``optimistix.RESULTS.successful``, ``max_steps_reached``, ...; the
    fits run with ``throw=False`` so that they ``vmap``, and keep it here).
    ``steps``: the solver's steps. ``kept_start``: the solver's answer was not better than its
    start (or was not finite), so ``warp`` is the start.
    """

    warp: AbstractWarp
    result: optx.RESULTS
    steps: Int[Array, "..."]
    kept_start: Bool[Array, "..."]

    @property
    def successful(self) -> Bool[Array, "..."]:
        """``result == optimistix.RESULTS.successful``."""
        return self.result == optx.RESULTS.successful


def check_fit_family(family):
    """``family`` must be a fittable PSS warp class (:class:`Bilinear` or :class:`Biquadratic`)."""
    if family not in _FAMILIES:
        raise ValueError(f"family must be Bilinear or Biquadratic, got {family!r}")


def later_chain(later) -> AbstractWarp | None:
    """The warps after the fitted one as one warp (H Eq. 9's ``p_rest``), ``None`` if none."""
    if isinstance(later, AbstractWarp):
        return later
    later = tuple(later)
    if len(later) == 1:  # the warp itself, so that fit_pointwise sees its corner_images
        return later[0]
    return Compose(*later) if later else None


def _clean(v, floor):
    v = jnp.where(jnp.isfinite(v), v, 0.0)
    v = jnp.maximum(v, 0.0)
    vmax = jnp.max(v)
    v = jnp.maximum(v, floor * vmax)
    return jnp.where(vmax > 0, v, 1.0)


@renamed_keywords(kind="family")
def fit_pointwise(
    family,
    factor: Callable,
    later: Sequence[AbstractWarp] | AbstractWarp = (),
    *,
    floor: float = 0.01,
):
    """H Eq. 9: a ``family`` warp whose control values are ``factor`` at the later warps' images.

    Values are clamped below at ``floor`` times their maximum (pbrt-v4 clamps cosines at 0.01) so
    that the density stays positive wherever the factor might not vanish; a factor that is 0 at
    every control point gives the uniform warp. Called outside ``jit`` (concrete values), a
    factor that is NaN or infinite at a control point, or negative at every control point where
    it is not zero (no density to follow), is a ``ValueError``; inside ``jit`` such values are
    cleaned as above (the renderer's own factors are finite).
    """
    check_fit_family(family)
    if not callable(factor):
        raise TypeError(f"factor must be a callable f(x) -> scalar, got {type(factor).__name__}")
    floor = float(floor)
    if not 0.0 <= floor < 1.0:
        raise ValueError(f"floor must lie in [0, 1), got {floor}")
    pts = jnp.asarray(family.control_points())
    rest = later_chain(later)
    if family is Bilinear and hasattr(rest, "corner_images"):
        x = rest.corner_images()  # the base warp knows its corners' images: no sampling
    elif hasattr(rest, "grid_images"):  # the base warp maps the control grid in one go
        x = rest.grid_images(family.control_points()[:, 0, 0])
    else:
        x = pts if rest is None else jax.vmap(jax.vmap(rest.sample))(pts)
    v = jax.vmap(jax.vmap(factor))(x)
    if not isinstance(v, jax.core.Tracer):  # the Python boundary: say what is wrong
        vals = np.asarray(v, np.float64)
        if not np.all(np.isfinite(vals)):
            raise ValueError(f"factor must be finite at the {family.__name__} control points, got "
                             f"{vals.ravel().tolist()}")
        if vals.max() <= 0.0 and vals.min() < 0.0:
            raise ValueError(f"factor must be >= 0 (a density to follow) at some control point; "
                             f"it is negative at every one: {vals.ravel().tolist()}")
    return family(_clean(v.astype(jnp.float32), floor))


def _probes(probes: int):
    return jnp.asarray(midpoint_grid(probes, indexing="ij").reshape(-1, 2))


@renamed_keywords(kind="family")
def fit_least_squares(
    family,
    f: Callable,
    later: Sequence[AbstractWarp] | AbstractWarp,
    *,
    probes: int = 8,
    init: AbstractWarp | None = None,
    max_steps: int = 32,
    rtol: float = 1e-4,
    atol: float = 1e-6,
    details: bool = False,
):
    """Variance-minimising control values for a ``family`` warp placed before ``later``.

    ``f`` is the whole integrand (one output point -> scalar); ``init`` (e.g. the point-wise fit)
    is the starting point, else the uniform warp. Levenberg-Marquardt from optimistix on the
    residuals of the module docstring; ``throw=False`` so that it ``vmap``s over shading points
    (a run that hits ``max_steps`` returns its last iterate). ``details=True`` returns a
    :class:`WarpFit` (the warp with the solver's status) instead of the warp.
    """
    check_fit_family(family)
    rest = later_chain(later)
    if rest is None:
        raise ValueError("later must hold at least the base warp")
    y = _probes(int(probes))
    x, p_rest = jax.vmap(rest.sample_and_pdf)(y)
    fx = jax.vmap(f)(x)
    target = jnp.where(p_rest > 0, fx / jnp.where(p_rest > 0, p_rest, 1.0), 0.0)
    target = jnp.where(jnp.isfinite(target), jnp.abs(target), 0.0).astype(jnp.float32)
    scale = jnp.maximum(jnp.sqrt(jnp.mean(target**2)), 1e-30)
    target = target / scale  # residuals of order 1
    n_side = 2 if family is Bilinear else 3
    theta0 = (
        jnp.zeros((n_side, n_side), jnp.float32)
        if init is None
        else jnp.log(jnp.maximum(init.values / jnp.max(init.values), 1e-6))
    )

    theta, result, steps, kept = _least_squares_solve(family, target, y, theta0, int(max_steps),
                                                      float(rtol), float(atol))
    warp = family(jnp.exp(jnp.clip(theta - jnp.max(theta), -14.0, 0.0)))
    if details:
        return WarpFit(warp, result, steps, kept)
    return warp


def _pdf_residuals(family, target, y):
    """The residuals of the module docstring for control values ``exp(theta)``."""
    k = target.shape[0]

    def residuals(theta, _):
        warp = family(jnp.exp(jnp.clip(theta, -14.0, 14.0)))
        j = jax.vmap(warp.pdf)(y)
        return target / jnp.sqrt(k * jnp.maximum(j, 1e-12))

    return residuals


@eqx.filter_jit
def _least_squares_solve(family, target, y, theta0, max_steps, rtol, atol):
    """:func:`fit_least_squares`' Levenberg-Marquardt solve, compiled once per family, probe
    count and solver settings (the residuals are built from the arguments, so a second fit of
    the same shapes reuses the program): ``(theta, result, steps, kept_start)``."""
    residuals = _pdf_residuals(family, target, y)
    sol = optx.least_squares(residuals, optx.LevenbergMarquardt(rtol=rtol, atol=atol), theta0,
                             max_steps=max_steps, throw=False)
    # Keep the start if the solver did not improve the probe objective (e.g. hit max_steps early).
    better = jnp.sum(residuals(sol.value, None) ** 2) <= jnp.sum(residuals(theta0, None) ** 2)
    return jnp.where(better, sol.value, theta0), sol.result, sol.stats["num_steps"], ~better


def fit_tabulated(f: Callable, later: Sequence[AbstractWarp] | AbstractWarp, *, res: int = 32):
    """H Sec. 4.3's reference: a ``res x res`` table of ``f / p_rest`` at the PSS cell centres."""
    rest = later_chain(later)
    if rest is None:
        raise ValueError("later must hold at least the base warp")
    # DESIGN grid convention: values[i, j] at x = (j + .5)/res, y = (i + .5)/res.
    pts = jnp.asarray(midpoint_grid(res))
    x, p = jax.vmap(jax.vmap(rest.sample_and_pdf))(pts)
    fx = jax.vmap(jax.vmap(f))(x)
    v = jnp.where(p > 0, fx / jnp.where(p > 0, p, 1.0), 0.0)
    return Tabulated(_clean(v.astype(jnp.float32), 1e-3))

"""Differentiable tuning of a PSS warp: the estimator variance as a function of control values.

Beyond the paper (H Sec. 3.3 fits point-wise, Eq. 9). With a ``Bilinear`` or ``Biquadratic`` warp
``w_theta`` first in the chain ``compose(w_theta, *later)``, ``y = w_theta(u)`` the PSS point
entering the later warps (density ``J_theta(y)``, H Table 3) and ``p_rest`` the later warps' pdf
(H Algorithm 1), the one-sample estimator ``f / p`` has

    Var(theta) = int g(y)^2 / J_theta(y) dy - I^2 = int (g / J_theta - I)^2 J_theta dy,
    g(y) = f(x(y)) / p_rest(x(y)),  I = int g dy,

so only the fitted warp's closed-form density depends on ``theta``. :func:`chain_variance`
evaluates the right-hand form (no cancellation of ``M - I^2``) by a tensor-product quadrature in
``y``: the rule is fixed, so the gradient in ``theta`` is exact by autodiff -- no differentiation
through sampling, Newton solves or visibility. :func:`fit_min_variance` minimises it over
``theta = log(values)`` with optimistix (Levenberg-Marquardt on residuals whose sum of squares
is this variance, or BFGS on the scalar).

Compared with :func:`~anisosample.warps.fit_least_squares` (the second moment ``sum g^2 / J`` as
residuals on an 8x8 midpoint probe grid, Levenberg-Marquardt), this minimises the variance in the
right-hand form on a finer rule. The form matters more than the rule: the second moment is
``I^2 (1 + relative variance)`` and a good fit's relative variance is 1e-6..1e-4, so a rule that
integrates ``J_theta`` to ``1 + e`` (a coarse midpoint grid: ``e ~ 5e-4`` for a bulging
biquadratic) lets ``sum g^2 / J`` fall by ``~ e I^2`` -- more than the whole variance -- by
raising ``J`` at the probes; ``sum w (g / J - I)^2 J`` charges for that (it equals
``sum w g^2 / J - I^2 (2 - sum w J)``), its errors scale with the variance itself, and its
residuals vanish at a perfect fit, where Gauss-Newton converges fast. The default
Gauss-Legendre rule integrates ``J_theta`` (degree <= 2 per axis) exactly, so the discrete
variance is the exact variance up to the rule's error on ``g^2 / J``
(``experiments/beyond_differentiable_tuning.py`` measures both effects).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from .._validate import check_choice, check_int, check_positive_float, renamed_keywords
from ._base import AbstractWarp
from .fit import WarpFit, check_fit_family, later_chain
from .planar import Bilinear

RULES = ("gauss", "midpoint")
SOLVERS = ("lm", "bfgs")
_LOG_CLIP = 14.0  # values within e^{-28} of each other: J stays positive, never NaN


def _check_later(later) -> AbstractWarp | None:
    if isinstance(later, AbstractWarp):
        return later
    if not isinstance(later, Sequence):
        raise TypeError(f"later must be a Warp or a sequence of Warps, got {type(later).__name__}")
    for i, w in enumerate(later):
        if not isinstance(w, AbstractWarp):
            raise TypeError(f"later[{i}] must be a Warp, got {type(w).__name__}")
    return later_chain(later)


def quadrature(grid: int, rule: str = "gauss"):
    """Nodes ``(grid^2, 2)`` in ``[0, 1]^2`` and weights ``(grid^2,)`` summing to 1.

    ``rule="gauss"``: the tensor Gauss-Legendre rule (exact for degree ``2 grid - 1`` per axis);
    ``"midpoint"``: the ``grid x grid`` cell centres (robust for discontinuous ``g``).
    """
    grid = check_int("grid", grid, minimum=2, maximum=1024)
    rule = check_choice("rule", rule, RULES)
    if rule == "gauss":
        t, w = np.polynomial.legendre.leggauss(grid)
        t, w = (t + 1.0) / 2.0, w / 2.0
    else:
        t = (np.arange(grid) + 0.5) / grid
        w = np.full(grid, 1.0 / grid)
    nodes = np.stack(np.meshgrid(t, t, indexing="ij"), -1).reshape(-1, 2)
    weights = np.outer(w, w).reshape(-1)
    return jnp.asarray(nodes, jnp.float32), jnp.asarray(weights, jnp.float32)


def pss_target(f: Callable, later: Sequence[AbstractWarp] | AbstractWarp, y):
    """``g(y) = f(x(y)) / p_rest(x(y))`` at PSS points ``y`` of shape ``(m, 2)``: the integrand
    the first warp of ``compose(w_theta, *later)`` sees (module docstring), 0 where ``p_rest``
    is 0 or ``g`` is not finite. ``later`` empty is the identity base (``g = f``)."""
    return _target(f, _check_later(later), jnp.asarray(y))


def _target(f: Callable, rest: AbstractWarp | None, y):
    if rest is None:  # the identity base: x = y, p_rest = 1
        x, p = y, jnp.ones(y.shape[:1], y.dtype)
    else:
        x, p = jax.vmap(rest.sample_and_pdf)(y)
    fx = jax.vmap(f)(x).astype(jnp.float32)
    g = jnp.where(p > 0, fx / jnp.where(p > 0, p, 1.0), 0.0)
    return jnp.where(jnp.isfinite(g), g, 0.0)


def _variance(j, g, w):
    """``sum w (g / J - I)^2 J`` with ``I = sum w g`` (the stable form of the module docstring)."""
    i = jnp.sum(w * g)
    ok = j > 0
    jj = jnp.where(ok, j, 1.0)
    # A node where J = 0 but g != 0 would be an infinite variance; J > 0 on [0,1]^2 for our warps.
    return jnp.sum(jnp.where(ok, w * (g / jj - i) ** 2 * jj, 0.0))


def chain_variance(
    warp: AbstractWarp,
    f: Callable,
    later: Sequence[AbstractWarp] | AbstractWarp = (),
    *,
    grid: int = 32,
    rule: str = "gauss",
):
    """Variance of the one-sample estimator ``f / p`` through ``compose(warp, *later)``.

    ``warp`` maps ``[0, 1]^2`` to itself (its ``pdf`` is ``J`` per unit PSS area); ``later`` may be
    empty (the identity base: ``f`` is a function on ``[0, 1]^2``). By the ``grid x grid``
    quadrature of the module docstring; differentiable in ``warp``'s fields (e.g.
    ``jax.grad(lambda v: chain_variance(Bilinear(v), f, later))(values)``).
    """
    if not isinstance(warp, AbstractWarp) or warp.out_dim != 2 or warp.measure != "area [0,1]^2":
        raise TypeError(f"warp must be a Warp from [0,1]^2 to [0,1]^2, got {warp!r:.80}")
    rest = _check_later(later)
    y, w = quadrature(grid, rule)
    g = _target(f, rest, y)
    return _variance(jax.vmap(warp.pdf)(y), g, w)


@renamed_keywords(kind="family")
def fit_min_variance(
    family,
    f: Callable,
    later: Sequence[AbstractWarp] | AbstractWarp = (),
    *,
    grid: int = 32,
    rule: str = "gauss",
    solver: str = "lm",
    init: AbstractWarp | None = None,
    max_steps: int = 64,
    rtol: float = 1e-6,
    atol: float = 1e-8,
    details: bool = False,
):
    """The ``family`` warp before ``later`` whose control values minimise :func:`chain_variance`.

    ``family`` is ``Bilinear`` or ``Biquadratic``; ``f`` the whole integrand on one output point;
    ``later`` the warps after it (the base technique last; empty for the identity). The
    parameters are ``theta = log(values)`` (positive values, so ``J > 0``; ``theta`` and
    ``theta + c`` are the same warp), started at ``init``'s values (e.g. the point-wise fit, H
    Eq. 9) or the uniform warp. The objective is the relative variance ``Var / int g^2`` (order
    1, so ``rtol``/``atol`` mean the same at every shading point), minimised by

    * ``solver="lm"`` (default): optimistix' Levenberg-Marquardt on the residuals
      ``r_k = sqrt(w_k J_k) (g_k / J_k - I)``, whose sum of squares *is* the quadrature
      variance (so ``2 J_r^T r`` is its exact gradient) and which vanish at a perfect fit
      (Gauss-Newton converges fast there; ``fit_least_squares``' second-moment residuals do not
      vanish at its optimum);
    * ``solver="bfgs"``: ``optx.BFGS`` on the scalar variance and its autodiff gradient
      (slower on the ill-conditioned Bezier parameters: for a biquadratic target through the
      identity, 128 BFGS steps left a relative variance of 1.9e-6 where Levenberg-Marquardt
      reached 7e-15 in 27 steps).

    ``throw=False``, so it ``jit``s and ``vmap``s over shading points; a run that hits
    ``max_steps`` returns its last iterate, and the start is kept if it was better. An integrand
    that is 0 at every node gives the uniform warp. ``details=True`` returns a
    :class:`~anisosample.warps.WarpFit` (the warp with the solver's status) instead.
    """
    check_fit_family(family)
    rest = _check_later(later)
    y, w = quadrature(grid, rule)
    solver = check_choice("solver", solver, SOLVERS)
    max_steps = check_int("max_steps", max_steps, minimum=1)
    rtol = check_positive_float("rtol", rtol)
    atol = check_positive_float("atol", atol)
    n_side = 2 if family is Bilinear else 3
    if init is not None:
        if not isinstance(init, family):
            raise TypeError(f"init must be a {family.__name__} warp or None, got {init!r:.80}")
        v0 = init.values
        theta0 = jnp.log(jnp.maximum(v0 / jnp.max(v0), jnp.exp(-2 * _LOG_CLIP)))
    else:
        theta0 = jnp.zeros((n_side, n_side), jnp.float32)

    g = _target(f, rest, y)
    scale = jnp.sqrt(jnp.sum(w * g * g))
    ok = scale > 0
    g = jnp.where(ok, g / jnp.where(ok, scale, 1.0), 0.0)
    integral = jnp.sum(w * g)

    theta, result, steps, kept = _min_variance_solve(family, solver, y, w, g, integral, ok,
                                                     theta0, max_steps, rtol, atol)
    if details:
        return WarpFit(_warp_of(family, theta), result, steps, kept)
    return _warp_of(family, theta)


def _warp_of(family, theta):
    return family(jnp.exp(jnp.clip(theta - jnp.max(theta), -2 * _LOG_CLIP, 0.0)))


@eqx.filter_jit
def _min_variance_solve(family, solver, y, w, g, integral, ok, theta0, max_steps, rtol, atol):
    """:func:`fit_min_variance`'s solve, compiled once per family, solver, node count and
    settings (its objective is built from the arguments, so a second fit of the same shapes
    reuses the program): ``(theta, result, steps, kept_start)``."""

    def residuals(theta, _):
        j = jnp.maximum(jax.vmap(_warp_of(family, theta).pdf)(y), 1e-30)
        return jnp.sqrt(w * j) * (g / j - integral)

    def objective(theta, _):
        return _variance(jax.vmap(_warp_of(family, theta).pdf)(y), g, w)

    if solver == "lm":
        sol = optx.least_squares(residuals, optx.LevenbergMarquardt(rtol=rtol, atol=atol),
                                 theta0, max_steps=max_steps, throw=False)
    else:
        sol = optx.minimise(objective, optx.BFGS(rtol=rtol, atol=atol), theta0,
                            max_steps=max_steps, throw=False)
    theta = jnp.where(jnp.isfinite(sol.value), sol.value, theta0)
    better = objective(theta, None) <= objective(theta0, None)
    theta = jnp.where(better & ok, theta, jnp.where(ok, theta0, 0.0))
    return theta, sol.result, sol.stats["num_steps"], ~(better & ok)

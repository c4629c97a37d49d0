"""Safeguarded Newton-bisection for monotone 1D equations ``g(t) = target`` on ``[lo, hi]``.

Used to invert the cubic CDFs of the biquadratic warp (H Table 3) and the projected-solid-angle
CDFs of Arvo's 2001 cosine-weighted triangle. Why not the closed-form cubic root: it branches on
the discriminant and is ill-conditioned when the cubic coefficient ``c0 - 2 c1 + c2`` is near 0
(nearly linear densities, the common case), while Newton on a monotone, bracketed function with a
bisection fallback converges from any start, vectorises without branches and costs a fixed
number of iterations under ``jit`` (pbrt-v4's ``NewtonBisection`` is the same idea).

The returned root carries the implicit-function derivative ``dt = (d target - dg) / g'(t)``:
the loop runs on ``stop_gradient`` values and one final Newton step re-attaches the derivatives,
so ``jax.jacfwd`` through a warp gives the true Jacobian, not the derivative of the iteration.
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp


def newton_bisection(
    g: Callable[[jax.Array], jax.Array],
    target: jax.Array,
    lo: jax.Array,
    hi: jax.Array,
    t0: jax.Array,
    *,
    iterations: int | jax.Array,
) -> jax.Array:
    """Root of the non-decreasing ``g(t) - target`` on ``[lo, hi]`` (``g(lo) <= target <= g(hi)``).

    ``g`` may close over differentiable parameters; derivatives w.r.t. them and ``target`` flow
    through the final implicit step only. ``iterations`` is fixed (static), or a traced int
    where a caller traces the warp holding it (``Biquadratic.iterations`` is a pytree leaf:
    ``tuning.fit_min_variance`` traces it).
    """
    sg = jax.lax.stop_gradient
    tgt = sg(target)

    def value_and_slope(t):
        f, df = jax.jvp(g, (t,), (jnp.ones_like(t),))
        return sg(f), sg(df)

    def body(_, state):
        t, a, b = state
        f, df = value_and_slope(t)
        f = f - tgt
        a = jnp.where(f <= 0, t, a)
        b = jnp.where(f >= 0, t, b)
        step = f / jnp.where(df > 0, df, 1.0)
        t_newton = t - step
        ok = (df > 0) & (t_newton >= a) & (t_newton <= b)
        t = jnp.where(ok, t_newton, 0.5 * (a + b))
        t = jnp.where(f == 0, sg(state[0]), t)
        return t, a, b

    lo_, hi_ = sg(lo), sg(hi)
    t = jnp.clip(sg(t0), lo_, hi_)
    t, _, _ = jax.lax.fori_loop(0, iterations, body, (t, lo_, hi_))
    # Re-attach derivatives: one Newton step from the converged (constant) root.
    t = sg(t)
    f, df = jax.jvp(g, (t,), (jnp.ones_like(t),))
    safe = df > 0
    t_out = t - jnp.where(safe, (f - target) / jnp.where(safe, df, 1.0), 0.0)
    # The step is ~0 in value; keep the converged value exactly and only take its tangent.
    return t + (t_out - sg(t_out))

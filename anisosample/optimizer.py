"""The synthesis loop as an optimizer (W Sec. 4; issue 22 item 3), in the optimistix shape.

Three parts, each replaceable:

* the **objective** (:class:`SynthesisObjective`): W Eqs. 10-15 on a frequency design: the
  linear spectrum loss ``n sum_v w_v P_S(v) / sum_v w_v`` (the ``"rate"`` recipe) or W Eq. 11's
  squared loss ``n^2 sum_v w_v P_S(v)^2 / sum_v w_v`` (``"paper"``), plus ``c`` times the
  sliced-Wasserstein loss (W Eqs. 12-15). Its frequencies, weights and ``c`` are arrays: a
  caller may make them functions of continuous design parameters and differentiate through.
* the **optimizer** (:class:`Adam`, the default; Kingma & Ba 2015): ``init(x) -> state`` and
  ``step(x, grad, state) -> (x, state)``, the recipe's decaying learning rate in units of the
  point spacing, wrapping or clipping to the square, fixed prefix points (W Sec. 7) held still.
  The arithmetic of a step is :func:`adam_step`, the one the production loop runs.
* the **runtime**: :func:`minimize` is a pure ``lax.scan`` of ``steps`` steps, differentiable end
  to end with respect to the objective's arrays and the optimizer's learning rate (direct sums
  with plain autodiff, :func:`anisosample.spectrum.power_spectrum_autodiff`, so gradients of
  gradients exist); :func:`anisosample.synthesize` is the production runtime (type-1 NUFFT terms
  with closed-form adjoints on threads and devices, checkpoints, resume, progress, CPU affinity)
  around the same step.

Small ``n`` (hundreds of points) is the scan path's regime: a direct sum costs ``O(n m)`` per
step and reverse mode keeps every step's state.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from . import frequencies as _freq
from . import losses as _losses
from . import prefix as _prefix
from ._validate import check_choice, check_int, check_points

__all__ = ["SynthesisObjective", "objective", "AdamState", "Adam", "adam_update", "adam_step",
           "minimize"]


def adam_update(grad, state, step, *, lr, b1, b2, eps):
    """One Adam update (Kingma & Ba 2015, Alg. 1) of an array; ``state = (m, v)``, ``step >= 1``.
    Returns ``(dx, (m, v))``."""
    m, v = state
    m = b1 * m + (1 - b1) * grad
    v = b2 * v + (1 - b2) * grad * grad
    mhat = m / (1 - b1**step)
    vhat = v / (1 - b2**step)
    return -lr * mhat / (jnp.sqrt(vhat) + eps), (m, v)


def adam_step(x, g, m, v, t, *, lr0, decay, b1, b2, eps, wrap: bool, fixed: int = 0,
              sequence_from: int = 0):
    """One synthesis step: Adam at the learning rate ``lr0 decay^t`` (``t`` steps taken),
    then ``x mod 1`` (``wrap``) or a clip to ``[0, 1 - 2^-53]``. The first ``fixed`` points (a
    prefix) get no gradient and no step; in a sequence (``sequence_from > 0``) point ``i`` steps
    in units of the spacing of the first nested prefix holding it. Returns ``(x, m, v, t + 1)``.
    """
    if fixed:
        free = (jnp.arange(x.shape[0]) >= fixed)[:, None]
        g = jnp.where(free, g, 0.0)
    lr = lr0 * decay ** t.astype(jnp.float64)
    dx, (m, v) = adam_update(g, (m, v), (t + 1).astype(x.dtype), lr=lr, b1=b1, b2=b2, eps=eps)
    if sequence_from:
        n = x.shape[0]
        i = jnp.arange(1, n + 1, dtype=jnp.float64)
        entry = jnp.clip(2.0 ** jnp.ceil(jnp.log2(i)), sequence_from, n)
        dx = dx * jnp.sqrt(n / entry)[:, None]
    if fixed:
        dx = jnp.where(free, dx, 0.0)
    x = x + dx
    x = x - jnp.floor(x) if wrap else jnp.clip(x, 0.0, 1.0 - 2.0**-53)
    return x, m, v, t + 1


# --- the objective ----------------------------------------------------------------------------


class SynthesisObjective(eqx.Module):
    """W Eq. 10 as data: ``a L_spec(x) + c L_SW(x)`` for ``n`` points.

    ``L_spec`` is the linear loss ``n sum w P_S / sum w`` (``squared=False``, the rate recipe)
    or W Eq. 11's ``n^2 sum w P_S^2 / sum w`` (``squared=True``, the paper's), at ``freqs``
    ``(m, 2)`` (float, integer-valued, one of each ``+-v``) with ``weights`` ``(m,)``;
    ``L_SW`` the sliced-Wasserstein loss along ``sw_directions`` ``(k, 2)`` to the quantile
    targets ``sw_targets`` ``(k, n)`` (W Eqs. 12-15). Every array is differentiable."""

    freqs: jax.Array
    weights: jax.Array
    spectrum_weight: jax.Array
    c: jax.Array
    sw_directions: jax.Array
    sw_targets: jax.Array
    n: int = eqx.field(static=True)
    squared: bool = eqx.field(static=True, default=False)

    def __call__(self, x) -> jax.Array:
        from .spectrum import power_spectrum_autodiff

        x = jnp.asarray(x, self.freqs.dtype)
        p = power_spectrum_autodiff(x, self.freqs)
        scale = self.n * (self.n if self.squared else 1)
        spec = scale * jnp.sum(self.weights * (p * p if self.squared else p)) / jnp.sum(
            self.weights)
        out = self.spectrum_weight * spec
        if self.sw_targets.shape[0]:
            out = out + self.c * _losses.sliced_wasserstein_value(x, self.sw_directions,
                                                                  self.sw_targets)
        return out


def _check_recipe(recipe):
    if not all(hasattr(recipe, a) for a in ("design", "learning_rate", "spectrum_weight")):
        raise TypeError("recipe must be a synthesis Recipe (anisosample.synthesis.make_recipe("
                        f"'rate', ...)), got {type(recipe).__name__}")
    return recipe


def objective(n: int, directions_deg, recipe, *, freqs=None,
              weights=None) -> SynthesisObjective:
    """The :class:`SynthesisObjective` of a :class:`~anisosample.synthesis.Recipe` (make one
    with :func:`~anisosample.synthesis.make_recipe`) for ``n`` points and ``directions_deg``:
    the recipe's frequency design, weights, ``spectrum_weight`` and ``c``. ``freqs`` /
    ``weights`` replace the design's (``freqs`` as ``(m, 2)`` integers or a
    :class:`~anisosample.frequencies.FrequencySet`; ``weights`` may be a traced array)."""
    n = check_int("n", n, minimum=2)
    rec = _check_recipe(recipe)
    if freqs is None:
        fset = _freq.design(n, directions_deg, rec.design, **dict(rec.frequency_options))
    else:
        fset = _losses.as_frequency_set(freqs)
    with jax.enable_x64(True):
        v = jnp.asarray(np.asarray(fset.freqs, np.float64))
        w = jnp.asarray(fset.weights if weights is None else weights, jnp.float64)
        if w.shape != (v.shape[0],):
            raise ValueError(f"weights must have one entry per frequency ({v.shape[0]}), got "
                             f"shape {w.shape}")
        if rec.c > 0:
            d, tgt = _losses.sliced_wasserstein_targets(directions_deg, n)
        else:
            d, tgt = jnp.zeros((0, 2), jnp.float64), jnp.zeros((0, n), jnp.float64)
        return SynthesisObjective(v, w, jnp.float64(rec.spectrum_weight), jnp.float64(rec.c),
                                  d, tgt, n, squared=rec.name == "paper")


# --- the optimizer ----------------------------------------------------------------------------


class AdamState(eqx.Module):
    """Adam's moments ``m``, ``v`` (like the points) and the steps taken ``t``."""

    m: jax.Array
    v: jax.Array
    t: jax.Array


class Adam(eqx.Module):
    """Adam on point positions, the synthesis recipe's way (:func:`adam_step`).

    ``learning_rate`` is in units of the point spacing ``1 / sqrt(n)`` and decays exponentially
    to ``final_lr_fraction`` of itself over ``steps``; ``learning_rate`` and
    ``final_lr_fraction`` may be traced arrays (differentiate through :func:`minimize`).
    ``boundary``: ``"wrap"`` (torus) or ``"clip"``; ``fixed``: the number of leading points
    held still (a prefix, W Sec. 7); ``sequence_from``: per-point step scale of a sequence."""

    learning_rate: float | jax.Array
    final_lr_fraction: float | jax.Array
    n: int = eqx.field(static=True)
    steps: int = eqx.field(static=True)
    b1: float = eqx.field(static=True, default=0.9)
    b2: float = eqx.field(static=True, default=0.9)
    eps: float = eqx.field(static=True, default=1e-30)
    boundary: str = eqx.field(static=True, default="wrap")
    fixed: int = eqx.field(static=True, default=0)
    sequence_from: int = eqx.field(static=True, default=0)

    def __check_init__(self):
        check_int("n", self.n, minimum=2)
        check_int("steps", self.steps, minimum=1)
        check_choice("boundary", self.boundary, ("wrap", "clip"))
        check_int("fixed", self.fixed, minimum=0)

    @classmethod
    def from_recipe(cls, recipe, n: int) -> Adam:
        """The optimizer a :class:`~anisosample.synthesis.Recipe` runs for ``n`` points."""
        rec = _check_recipe(recipe)
        return cls(rec.learning_rate, rec.final_lr_fraction, n, rec.steps, rec.b1, rec.b2,
                   rec.adam_eps, rec.boundary, _prefix.prefix_size(rec.prefix),
                   rec.sequence_from)

    def schedule(self):
        """``(lr0, decay)``: the first step's learning rate and the per-step factor. Python
        floats when the fields are (the production loop bakes them in), else traced."""
        span = 1.0 / max(self.steps - 1, 1)
        if isinstance(self.learning_rate, int | float) and isinstance(
                self.final_lr_fraction, int | float):
            return self.learning_rate / math.sqrt(self.n), self.final_lr_fraction ** span
        return (jnp.asarray(self.learning_rate, jnp.float64) / math.sqrt(self.n),
                jnp.asarray(self.final_lr_fraction, jnp.float64) ** span)

    def init(self, x) -> AdamState:
        z = jnp.zeros_like(x)
        return AdamState(z, z, jnp.zeros((), jnp.int64))

    def step(self, x, grad, state: AdamState):
        """One step: ``(x, state)``."""
        lr0, decay = self.schedule()
        x, m, v, t = adam_step(x, grad, state.m, state.v, state.t, lr0=lr0, decay=decay,
                               b1=self.b1, b2=self.b2, eps=self.eps,
                               wrap=self.boundary == "wrap", fixed=self.fixed,
                               sequence_from=self.sequence_from)
        return x, AdamState(m, v, t)


# --- the scan runtime -------------------------------------------------------------------------


def minimize(objective, optimizer: Adam, x0, *, steps: int | None = None):
    """``steps`` (default ``optimizer.steps``) optimizer steps on ``objective`` from ``x0``
    ``(n, 2)`` as one pure ``lax.scan`` (float64): jit-able, vmap-able over initial sets and
    differentiable end to end in the objective's arrays and the optimizer's learning rate.
    Returns the final points (float64, in the square; not rounded to float32)."""
    if not isinstance(x0, jax.core.Tracer):
        check_points("x0", x0)
    steps = optimizer.steps if steps is None else check_int("steps", steps, minimum=1)
    with jax.enable_x64(True):
        x0 = jnp.asarray(x0, jnp.float64)
        grad = jax.grad(objective)

        def body(carry, _):
            x, state = carry
            return optimizer.step(x, grad(x), state), None

        (x, _), _ = jax.lax.scan(body, (x0, optimizer.init(x0)), None, length=steps)
        return x

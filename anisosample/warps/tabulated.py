"""Piecewise-constant PSS warp from a grid of values (the 32x32 product reference of H Sec. 4.3).

``Tabulated(values)`` with ``values`` of shape ``(h, w)`` in the DESIGN grid convention
(``values[i, j]`` is the cell ``x in [j/w, (j+1)/w)``, ``y in [i/h, (i+1)/h)``: rows are y).
Sampling inverts the marginal CDF of the rows, then the conditional CDF within the row; both are
piecewise linear, so the inverse and the pdf (``values[i, j] / mean(values)``) are exact.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .._types import Array, Float
from .._validate import ONE_MINUS_EPSILON
from ._base import AbstractWarp, check_point

_EPS1 = float(ONE_MINUS_EPSILON)


def _cdf(p):
    c = jnp.cumsum(p, axis=-1)
    total = c[..., -1:]
    c = c / jnp.where(total > 0, total, 1.0)
    zero = jnp.zeros(p.shape[:-1] + (1,), p.dtype)
    return jnp.concatenate([zero, c], axis=-1), total[..., 0]


def _sample_1d(u, cdf):
    n = cdf.shape[0] - 1
    k = jnp.clip(jnp.searchsorted(cdf, u, side="right") - 1, 0, n - 1)
    width = cdf[k + 1] - cdf[k]
    frac = jnp.where(width > 0, (u - cdf[k]) / jnp.where(width > 0, width, 1.0), 0.5)
    return k, jnp.clip((k.astype(jnp.float32) + jnp.clip(frac, 0.0, 1.0)) / n, 0.0, _EPS1)


def _invert_1d(x, cdf):
    n = cdf.shape[0] - 1
    k = jnp.clip(jnp.floor(x * n).astype(jnp.int32), 0, n - 1)
    return k, cdf[k] + (x * n - k.astype(jnp.float32)) * (cdf[k + 1] - cdf[k])


class Tabulated(AbstractWarp):
    """Piecewise-constant density on ``[0, 1]^2`` proportional to ``values`` (rows are y)."""

    values: Float[Array, "h w"]
    row_cdf: Float[Array, " h1"]
    col_cdf: Float[Array, "h w1"]
    mean: Float[Array, ""]

    def __init__(self, values):
        shape = getattr(values, "shape", None) or np.shape(values)
        if len(shape) != 2 or min(shape) < 1:
            raise ValueError(f"values must have shape (h, w), got shape {tuple(shape)}")
        if not isinstance(values, jax.core.Tracer):
            v = np.asarray(values, np.float64)
            if not np.all(np.isfinite(v)) or np.any(v < 0):
                raise ValueError("values must be finite and >= 0 (a density)")
            if not np.any(v > 0):
                raise ValueError("values must have a positive sum, got all zeros")
        v = jnp.maximum(jnp.asarray(values, jnp.float32), 0.0)
        v = jnp.where(jnp.sum(v) > 0, v, 1.0)  # traced all-zero values: uniform (documented)
        self.values = v
        self.col_cdf, row_sums = _cdf(v)
        self.row_cdf, _ = _cdf(row_sums)
        self.mean = jnp.mean(v)

    def sample(self, u):
        u = check_point("u", u, 2)
        i, y = _sample_1d(u[1], self.row_cdf)
        _, x = _sample_1d(u[0], self.col_cdf[i])
        return jnp.stack([x, y])

    def pdf(self, x):
        x = check_point("x", x, 2)
        h, w = self.values.shape
        i = jnp.clip(jnp.floor(x[1] * h).astype(jnp.int32), 0, h - 1)
        j = jnp.clip(jnp.floor(x[0] * w).astype(jnp.int32), 0, w - 1)
        inside = jnp.all((x >= 0) & (x <= 1))
        return jnp.where(inside, self.values[i, j] / self.mean, 0.0)

    def inverse(self, x):
        x = jnp.clip(check_point("x", x, 2), 0.0, 1.0)
        i, uy = _invert_1d(x[1], self.row_cdf)
        _, ux = _invert_1d(x[0], self.col_cdf[i])
        return jnp.clip(jnp.stack([ux, uy]), 0.0, 1.0)

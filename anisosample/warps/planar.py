"""Primary-sample-space warps ``[0, 1]^2 -> [0, 1]^2``: linear 1D triplet, Bilinear, Biquadratic.

H Tables 2-3 (with the index convention fixed as in ``references/warps.md`` Sec. 3: ``values[i, j]``
is the control value at ``u = (i, j)``, ``i`` along x and ``j`` along y, for both warps). Sampling
is marginal-then-conditional inversion: first ``y`` from the marginal, then ``x`` from the
conditional given ``y``. pdfs are per unit area of ``[0, 1]^2``.

Control values must be finite and ``>= 0`` with a positive sum. Concrete arrays are checked when
the warp is made (``ValueError``); traced values (a warp fitted inside ``jit``/``vmap``) are
checked inside the program with the same messages (``_validate.refuse_traced``). An all-zero
set of values gives the uniform warp (identity, pdf 1), as pbrt-v4 does, traced or not (the
fits' fallback where a factor vanishes).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .._types import Array, Float
from .._validate import ONE_MINUS_EPSILON, refuse_traced
from ._base import AbstractWarp, check_point
from ._solve import newton_bisection

_ONE_MINUS_EPS = float(ONE_MINUS_EPSILON)
_TINY = 1e-30  # a normal float32


def _lerp(t, a, b):
    return (1.0 - t) * a + t * b


# --- the linear 1D triplet (H Table 3's h and l; pbrt-v4 SampleLinear) -------------------------


def sample_linear(u, a, b):
    """Sample ``x`` in ``[0, 1)`` with density ``∝ (1 - x) a + x b`` (``a, b >= 0``, ``u >= 0``).

    Uses the rationalised root ``x = u (a + b) / (a + sqrt(lerp(u, a^2, b^2)))`` instead of H
    Table 3's ``h(u, a, b) = (a - sqrt(lerp(u, a^2, b^2))) / (a - b)``, which is 0/0 at ``a = b``
    and loses ``eps / |a - b|`` relative accuracy near it (the failure Peters 2021 reports for
    lights clipped at the horizon, where equal end values are common); the rationalised form is
    continuous through ``a = b`` (``x = u`` there) and exact to float32 rounding on both sides
    (``tests/warps/test_planar.py`` against a float64 bisection of the CDF).

    The root is homogeneous of degree 0 in ``(a, b)``, so ``a`` and ``b`` are first divided by
    ``max(a, b)``: the squares then neither flush to zero (values below ~1e-19, e.g. a GGX lobe's
    tail in a product fit) nor overflow (above ~1e19), both of which made the unscaled form
    return ``x`` far from its density (or NaN) while :func:`linear_pdf` stayed right; the triplet
    is now the same for any scale of ``(a, b)`` in ``[1e-30, 1e30]`` (beyond, products of a value
    and a float32 ``x`` in the pdf and CDF leave the normal range). After
    scaling ``a + b >= 1`` and the denominator vanishes only where ``x = u`` is the answer
    (``a = 0`` at ``u = 0``); adding ``_TINY`` (1e-30) to both ``a + b`` and the denominator
    gives that without a branch (elsewhere the denominator is ``>= sqrt(u)``, so the change is far
    below float32 rounding). ``a = b = 0`` gives ``x = u`` (the uniform density, as
    :func:`linear_pdf` says). Branch-free because it is the whole cost of the bilinear warp (H
    Sec. 4.1; ``experiments/bench_warps.py``).
    """
    s = jax.lax.stop_gradient(jnp.maximum(a, b))  # x(a / c, b / c) = x(a, b) for any c > 0:
    ok = s > 0  # a constant scale keeps derivatives exact and their s^2 out of float32's way
    s = jnp.where(ok, s, 1.0)
    a, b = a / s, b / s
    q = jnp.maximum(a * a + u * (b * b - a * a), 0.0)
    x = u * (a + b + _TINY) / (a + jnp.sqrt(q) + _TINY)
    return jnp.minimum(jnp.where(ok, x, u), _ONE_MINUS_EPS)


def linear_pdf(x, a, b):
    """Density ``2 lerp(x, a, b) / (a + b)`` on ``[0, 1]`` (1 if ``a = b = 0``), 0 outside."""
    s = a + b
    p = jnp.where(s > 0, 2.0 * _lerp(x, a, b) / jnp.where(s > 0, s, 1.0), 1.0)
    return jnp.where((x >= 0) & (x <= 1), p, 0.0)


def invert_linear_sample(x, a, b):
    """The CDF ``x (a (2 - x) + b x) / (a + b)`` (H Table 3's ``l``), ``x`` clamped to [0, 1]."""
    x = jnp.clip(x, 0.0, 1.0)
    s = a + b
    return jnp.where(s > 0, x * (a * (2.0 - x) + b * x) / jnp.where(s > 0, s, 1.0), x)


# --- helpers for control values ------------------------------------------------------------------


def _control_values(name: str, values, shape: tuple[int, int]) -> jax.Array:
    arr_shape = getattr(values, "shape", None)
    if arr_shape is None:
        values = np.asarray(values, dtype=np.float32)
        arr_shape = values.shape
    if tuple(arr_shape) != shape:
        raise ValueError(f"{name} must have shape {shape}, got shape {tuple(arr_shape)}")
    if isinstance(values, jax.core.Tracer):  # the same checks inside the program
        v = refuse_traced(jnp.asarray(values, jnp.float32), ~jnp.all(jnp.isfinite(values)),
                          f"{name} must be finite")
        v = refuse_traced(v, jnp.any(v < 0), f"{name} must be >= 0 (a density)")
        # all zeros stays the identity (pdf 1): the fits' uniform fallback
        return v
    v = np.asarray(values, dtype=np.float64)
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be finite, got {v.tolist()}")
    if np.any(v < 0):
        raise ValueError(f"{name} must be >= 0 (a density), got {v.tolist()}")
    if not np.any(v > 0):
        raise ValueError(f"{name} must have a positive sum, got all zeros")
    return jnp.asarray(v, dtype=jnp.float32)


class Bilinear(AbstractWarp):
    """Bilinear warp (H Tables 2-3): density ``J = 4 a(x) / sum(values)`` on ``[0, 1]^2``.

    ``values`` of shape ``(2, 2)``: corner ``(i, j)`` at ``u = (i, j)``, so
    ``a(x, y) = sum_ij values[i, j] (x if i else 1 - x) (y if j else 1 - y)``. Equal values give
    the identity with pdf 1. Exact for area sampling of planar quadrilaterals (Arvo & Novins 2007).
    """

    values: Float[Array, "2 2"]

    def __init__(self, values):
        self.values = _control_values("values", values, (2, 2))

    @staticmethod
    def control_points() -> np.ndarray:
        """PSS points of the control values, shape ``(2, 2, 2)``: ``[i, j] -> (i, j)`` (H Eq. 9)."""
        g = np.arange(2, dtype=np.float32)
        return np.stack(np.meshgrid(g, g, indexing="ij"), axis=-1)

    def _density(self, x, y):
        v = self.values
        return _lerp(x, _lerp(y, v[0, 0], v[0, 1]), _lerp(y, v[1, 0], v[1, 1]))

    def _sample(self, u):
        u = check_point("u", u, 2)
        v = self.values
        y = sample_linear(u[1], v[0, 0] + v[1, 0], v[0, 1] + v[1, 1])
        a0, a1 = _lerp(y, v[0, 0], v[0, 1]), _lerp(y, v[1, 0], v[1, 1])  # a(0, y), a(1, y)
        x = sample_linear(u[0], a0, a1)
        return x, y, a0, a1

    def sample(self, u):
        x, y, _, _ = self._sample(u)
        return jnp.stack([x, y])

    def sample_and_pdf(self, u):
        """``(x, pdf(x))`` in one pass: ``J = 4 a(x) / sum(values)`` from the conditional's end
        values ``a(0, y), a(1, y)`` that sampling computed anyway (no re-evaluation of ``a``, no
        domain test: ``x`` is inside by construction). This is the cost H Sec. 4.1 measures."""
        x, y, a0, a1 = self._sample(u)
        total = jnp.sum(self.values)
        ok = total > 0
        p = jnp.where(ok, _lerp(x, a0, a1) * (4.0 / jnp.where(ok, total, 1.0)), 1.0)
        return jnp.stack([x, y]), p

    def pdf(self, x):
        x = check_point("x", x, 2)
        total = jnp.sum(self.values)
        inside = jnp.all((x >= 0) & (x <= 1))
        p = jnp.where(
            total > 0, 4.0 * self._density(x[0], x[1]) / jnp.where(total > 0, total, 1), 1
        )
        return jnp.where(inside, p, 0.0)

    def inverse(self, x):
        x = jnp.clip(check_point("x", x, 2), 0.0, 1.0)
        v = self.values
        uy = invert_linear_sample(x[1], v[0, 0] + v[1, 0], v[0, 1] + v[1, 1])
        a0, a1 = _lerp(x[1], v[0, 0], v[0, 1]), _lerp(x[1], v[1, 0], v[1, 1])
        ux = invert_linear_sample(x[0], a0, a1)
        return jnp.stack([ux, uy])


# --- biquadratic Bezier ---------------------------------------------------------------------------


def _bernstein2(t):
    s = 1.0 - t
    return jnp.stack([s * s, 2.0 * s * t, t * t])


def _bezier_cdf(t, c):
    """Normalised CDF ``B(t; c0, c1, c2)`` of a quadratic Bezier density (H Table 3)."""
    c0, c1, c2 = c[0], c[1], c[2]
    s = c0 + c1 + c2
    cub = ((c0 - 2.0 * c1 + c2) * t + 3.0 * (c1 - c0)) * t * t + 3.0 * c0 * t
    return jnp.where(s > 0, cub / jnp.where(s > 0, s, 1.0), t)


def _sample_bezier(u, c, iterations):
    s = c[0] + c[1] + c[2]
    # Start from the linear-density root through the end control values (close for smooth c).
    t0 = sample_linear(u, c[0], c[2])
    t = newton_bisection(
        lambda t: _bezier_cdf(t, c),
        u,
        jnp.zeros_like(u),
        jnp.ones_like(u),
        t0,
        iterations=iterations,
    )
    return jnp.where(s > 0, jnp.clip(t, 0.0, _ONE_MINUS_EPS), u)


class Biquadratic(AbstractWarp):
    """Biquadratic Bezier warp (H Tables 2-3): ``J = 9 a(x) / sum(values)`` on ``[0, 1]^2``.

    ``values`` of shape ``(3, 3)`` are Bezier control values, ``values[i, j]`` at ``u = (i/2, j/2)``
    (``i`` along x): ``a(x, y) = sum_ij values[i, j] b_i(x) b_j(y)`` with the Bernstein basis
    ``b = ((1-t)^2, 2t(1-t), t^2)``. Sampling solves the two cubic CDF equations with safeguarded
    Newton-bisection (``iterations`` fixed steps, see ``_solve``); the inverse is closed form.
    """

    values: Float[Array, "3 3"]
    iterations: int = 8

    def __init__(self, values, *, iterations: int = 8):
        self.values = _control_values("values", values, (3, 3))
        self.iterations = int(iterations)

    @staticmethod
    def control_points() -> np.ndarray:
        """PSS points of the control values, ``(3, 3, 2)``: ``[i, j] -> (i/2, j/2)`` (H Eq. 9)."""
        g = np.linspace(0.0, 1.0, 3, dtype=np.float32)
        return np.stack(np.meshgrid(g, g, indexing="ij"), axis=-1)

    def sample(self, u):
        u = check_point("u", u, 2)
        v = self.values
        y = _sample_bezier(u[1], jnp.sum(v, axis=0), self.iterations)
        c = v @ _bernstein2(y)  # c_i = sum_j v_ij b_j(y)
        x = _sample_bezier(u[0], c, self.iterations)
        return jnp.stack([x, y])

    def pdf(self, x):
        x = check_point("x", x, 2)
        xc = jnp.clip(x, 0.0, 1.0)
        total = jnp.sum(self.values)
        a = _bernstein2(xc[0]) @ self.values @ _bernstein2(xc[1])
        p = jnp.where(total > 0, 9.0 * a / jnp.where(total > 0, total, 1.0), 1.0)
        return jnp.where(jnp.all((x >= 0) & (x <= 1)), p, 0.0)

    def inverse(self, x):
        x = jnp.clip(check_point("x", x, 2), 0.0, 1.0)
        v = self.values
        uy = _bezier_cdf(x[1], jnp.sum(v, axis=0))
        ux = _bezier_cdf(x[0], v @ _bernstein2(x[1]))
        return jnp.clip(jnp.stack([ux, uy]), 0.0, 1.0)

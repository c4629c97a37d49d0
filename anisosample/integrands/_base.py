"""The integrand base class and argument checks shared by the integrand modules."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np


def check_frequencies_any(v) -> np.ndarray:
    v = np.asarray(v)
    if v.ndim < 1 or v.shape[-1] != 2:
        raise ValueError(f"v must have shape (..., 2), got shape {v.shape}")
    if not np.issubdtype(v.dtype, np.integer):
        floating = np.issubdtype(v.dtype, np.floating)
        # inf == round(inf): without isfinite an infinite frequency gave NaN coefficients
        if not (floating and np.all(np.isfinite(v)) and np.all(v == np.round(v))):
            raise ValueError("v must hold integer frequency vectors")
    return v.astype(np.float64)

def check_point2(name: str, p) -> tuple[float, float]:
    p = np.asarray(p, dtype=np.float64)
    if p.shape != (2,) or not np.all(np.isfinite(p)):
        raise ValueError(f"{name} must be two finite numbers (x, y), got {p.tolist()}")
    return float(p[0]), float(p[1])

def check_real(name: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.number):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__} {value!r}")
    if not np.isfinite(float(value)):
        raise ValueError(f"{name} must be finite, got {value}")
    return float(value)

def as_float(x):
    x = jnp.asarray(x)
    if x.ndim < 1 or x.shape[-1] != 2:
        raise ValueError(f"x must have shape (..., 2), got shape {x.shape}")
    if not jnp.issubdtype(x.dtype, jnp.floating):
        raise TypeError(f"x must be a floating-point array, got dtype {x.dtype}")
    return x

# --- the integrand base ------------------------------------------------------------------------

class Integrand(eqx.Module):
    """Base of the analytic integrands: ``f(x)`` over ``(..., 2)``, ``integral``, directions."""

    def __call__(self, x):
        raise NotImplementedError

    @property
    def integral(self) -> float:
        raise NotImplementedError

    @property
    def directions_deg(self) -> tuple[float, ...]:
        """Spectral directions of the discontinuities, apart from the axes' 0 and 90 degrees."""
        return ()

    def fourier_coefficients(self, v) -> np.ndarray | np.complexfloating:
        """``F_f(v)`` for integer ``v`` of shape ``(..., 2)``, complex128 (W Eq. 3; a NumPy
        scalar for one ``v`` of shape ``(2,)``)."""
        raise NotImplementedError(f"{type(self).__name__} has no closed-form Fourier coefficients")

    def power_spectrum(self, v) -> np.ndarray | np.floating:
        """``P_f(v) = |F_f(v)|^2`` (W Eq. 4), float64."""
        return np.abs(self.fourier_coefficients(v)) ** 2

    def second_moment(self) -> float:
        """``int f^2`` where known in closed form (for ``Var f = int f^2 - I^2``)."""
        raise NotImplementedError(f"{type(self).__name__} has no closed-form second moment")

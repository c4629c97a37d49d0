"""Validation at the Python boundary, before tracing (the first tier of DESIGN's errors).

Every public function checks its arguments with these helpers so that messages read the same
everywhere: they name the parameter, what is allowed and what came.

Shapes, dtypes and static arguments are checked while tracing too, so those errors are the same
``ValueError``/``TypeError`` under ``jax.jit`` and ``jax.vmap``. Values are checked eagerly where
they are concrete; where they are traced (the caller's ``jit``, ``vmap``, ``grad``) the same
check runs inside the program through :func:`refuse_traced` (``equinox.error_if``), with the same
message: under ``jax.vmap`` or ``equinox.filter_jit`` an ``EquinoxRuntimeError`` carrying it,
under plain ``jax.jit`` a ``jax.errors.JaxRuntimeError`` (a ``RuntimeError``) whose text holds it.
"""

from __future__ import annotations

import functools
import numbers
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

ONE_MINUS_EPSILON = np.float32(1.0 - 2.0**-24)
"""Largest float32 below 1 (pbrt-v4's ``OneMinusEpsilon``): points are clamped to it."""


def check_int(name: str, value, *, minimum: int | None = None, maximum: int | None = None) -> int:
    """Return ``value`` as a Python int, or raise naming ``name`` and the allowed range."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral | np.integer):
        if isinstance(value, float | np.floating) and float(value).is_integer():
            raise TypeError(f"{name} must be an integer, got the float {value!r}")
        raise TypeError(f"{name} must be an integer, got {type(value).__name__} {value!r}")
    value = int(value)
    if minimum is not None and value < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {value}")
    if maximum is not None and value > maximum:
        raise ValueError(f"{name} must be <= {maximum}, got {value}")
    return value


def check_bool(name: str, value) -> bool:
    """``value`` if it is True or False (NumPy's too), else ``TypeError`` naming ``name``."""
    if not isinstance(value, bool | np.bool_):
        raise TypeError(f"{name} must be True or False, got {value!r}")
    return bool(value)


def check_positive_float(name: str, value, *, allow_zero: bool = False) -> float:
    """Return ``value`` as a finite float > 0 (or >= 0), or raise naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real | np.floating | np.integer):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__} {value!r}")
    value = float(value)
    if not np.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
        bound = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{name} must be finite and {bound}, got {value}")
    return value


def check_key(name: str, key) -> jax.Array:
    """A JAX PRNG key: a typed key (``jax.random.key``) or a raw uint32 ``(2,)`` key."""
    if isinstance(key, jax.Array):
        if jax.dtypes.issubdtype(key.dtype, jax.dtypes.prng_key) and key.shape == ():
            return key
        if key.dtype == np.uint32 and key.shape == (2,):
            return key
    raise TypeError(
        f"{name} must be a single JAX PRNG key (jax.random.key(seed) or jax.random.PRNGKey(seed)),"
        f" got {type(key).__name__}"
        + (f" of shape {key.shape} and dtype {key.dtype}" if hasattr(key, "shape") else "")
    )


def check_points(name: str, points, *, check_range: bool = True,
                 closed: bool = False) -> np.ndarray | jax.Array:
    """A point set of shape ``(n, 2)``, finite, in ``[0, 1)^2`` (``[0, 1]^2`` if ``closed``:
    primary samples entering a warp may touch 1).

    Concrete arrays are range-checked here; traced ones inside the program
    (:func:`refuse_traced`): use the returned array, or the traced check is dropped.
    """
    shape = getattr(points, "shape", None)
    if shape is None:
        points = np.asarray(points)
        shape = points.shape
    if len(shape) != 2 or shape[1] != 2 or shape[0] < 1:
        raise ValueError(f"{name} must have shape (n, 2) with n >= 1, got shape {tuple(shape)}")
    if not np.issubdtype(np.dtype(points.dtype), np.floating):
        raise TypeError(f"{name} must be a floating-point array, got dtype {points.dtype}")
    square = "[0, 1]^2" if closed else "[0, 1)^2"
    if check_range and isinstance(points, jax.core.Tracer):
        points = refuse_traced(points, ~jnp.all(jnp.isfinite(points)),
                               f"{name} contains NaN or Inf")
        outside = (points < 0) | ((points >= 1) if not closed else (points > 1))
        return refuse_traced(points, jnp.any(outside), f"{name} must lie in {square}")
    if check_range:
        p = np.asarray(points)
        if not np.all(np.isfinite(p)):
            raise ValueError(f"{name} contains NaN or Inf")
        if p.min() < 0.0 or p.max() > 1.0 or (p.max() == 1.0 and not closed):
            raise ValueError(f"{name} must lie in {square}, got values in [{p.min()}, {p.max()}]")
    return points


def renamed_keywords(**old_to_new: str):
    """Decorator: calling with an old keyword (``kind=``) raises ``TypeError`` naming the new one
    (``family=``) instead of Python's bare "unexpected keyword" (DESIGN's vocabulary)."""

    def decorate(fn):
        @functools.wraps(fn)
        def wrapper(*args, **kwargs):
            for old, new in old_to_new.items():
                if old in kwargs:
                    raise TypeError(f"{fn.__name__}() takes {new}= where it took {old}= "
                                    f"(docs/design.md, Vocabulary)")
            return fn(*args, **kwargs)

        return wrapper

    return decorate


def refuse_traced(x, bad, message: str):
    """``x`` unchanged, with the check ``bad`` (a traced boolean) attached: running the program
    with ``bad`` true raises ``message`` (``equinox.error_if``; module docstring). The traced
    half of a value check whose eager half raises ``ValueError(message)``; the message names the
    parameter as the eager one does. Use the returned ``x``: XLA drops a check nothing uses."""
    return eqx.error_if(x, bad, message)


def check_frequencies(name: str, freqs) -> np.ndarray | jax.Array:
    """Integer frequency vectors of shape ``(m, 2)``; float arrays must hold integers."""
    shape = getattr(freqs, "shape", None)
    if shape is None:
        freqs = np.asarray(freqs)
        shape = freqs.shape
    if len(shape) != 2 or shape[1] != 2:
        raise ValueError(f"{name} must have shape (m, 2), got shape {tuple(shape)}")
    if shape[0] == 0:
        raise ValueError(f"{name} must hold at least one frequency, got an empty array")
    dtype = np.dtype(freqs.dtype)
    if np.issubdtype(dtype, np.integer):
        return freqs
    if np.issubdtype(dtype, np.floating) and not isinstance(freqs, jax.core.Tracer):
        f = np.asarray(freqs)
        if np.all(np.isfinite(f)) and np.all(f == np.round(f)):
            if np.abs(f).max() >= 2**31:  # astype(int32) would wrap around silently
                raise ValueError(f"{name} must fit in int32, got values up to {np.abs(f).max()}")
            return f.astype(np.int32)
    raise ValueError(f"{name} must hold integer frequency vectors, got dtype {dtype}")


def check_directions_deg(
    name: str, directions_deg, *, integer: bool = False, allow_empty: bool = False
) -> tuple[float, ...]:
    """Spectral directions in degrees, each in ``[0, 180)``, no duplicates (axial data)."""
    if isinstance(directions_deg, numbers.Real):
        directions_deg = (directions_deg,)
    if not isinstance(directions_deg, Sequence | np.ndarray | jax.Array):
        raise TypeError(f"{name} must be a sequence of angles in degrees, got {directions_deg!r}")
    d = np.asarray(directions_deg, dtype=np.float64).reshape(-1)
    if d.size == 0 and not allow_empty:
        raise ValueError(f"{name} must hold at least one direction")
    if not np.all(np.isfinite(d)) or np.any(d < 0) or np.any(d >= 180):
        raise ValueError(f"{name} must lie in [0, 180) degrees, got {d.tolist()}")
    if integer and np.any(d != np.round(d)):
        raise ValueError(f"{name} must be integer degrees here, got {d.tolist()}")
    if len(np.unique(d)) != d.size:
        raise ValueError(f"{name} must not repeat a direction, got {d.tolist()}")
    return tuple(float(x) for x in d)


def check_choice(name: str, value, choices: Sequence[str]) -> str:
    if value not in choices:
        raise ValueError(f"{name} must be one of {sorted(choices)}, got {value!r}")
    return value


def check_devices(name: str, devices) -> list | None:
    """``None`` (the default device), or a non-empty sequence of distinct ``jax.Device`` s as a
    list (under ``jax.distributed`` they may be other processes' devices: ``jax.devices()``)."""
    if devices is None:
        return None
    if isinstance(devices, jax.Device):
        raise TypeError(f"{name} must be a sequence of jax.Device (e.g. jax.devices()), got one "
                        f"device {devices}: pass [{devices}]")
    try:
        devs = list(devices)
    except TypeError:
        raise TypeError(f"{name} must be None or a sequence of jax.Device, got "
                        f"{type(devices).__name__}") from None
    if not devs:
        raise ValueError(f"{name} must hold at least one device")
    for i, d in enumerate(devs):
        if not isinstance(d, jax.Device):
            raise TypeError(f"{name}[{i}] must be a jax.Device, got {type(d).__name__}")
    if len(set(devs)) != len(devs):
        raise ValueError(f"{name} must be distinct, got {devs}")
    return devs


def check_spectrum_grid(name: str, grid) -> np.ndarray:
    """A centred spectrum grid: a square ``(2r+1, 2r+1)`` array of finite values (the layout of
    ``spectrum.power_spectrum_grid``), as float64."""
    g = np.asarray(grid, dtype=np.float64)
    if g.ndim != 2 or g.shape[0] != g.shape[1] or g.shape[0] % 2 != 1:
        raise ValueError(f"{name} must be a square centred spectrum of odd side (2r+1, 2r+1), "
                         f"got shape {g.shape}")
    if not np.all(np.isfinite(g)):
        raise ValueError(f"{name} contains NaN or Inf")
    return g

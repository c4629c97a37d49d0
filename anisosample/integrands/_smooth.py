"""Curved and smooth integrands: disk, smoothed edge, Gaussian bump, textures."""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import scipy.integrate
import scipy.special

from .._validate import check_choice, check_positive_float, renamed_keywords
from ._base import Integrand, as_float, check_frequencies_any, check_point2, check_real


class Disk(Integrand):
    """``value * 1[|x - center| < radius]``, the disk inside the square: no principal direction.

    The control case of W Sec. 6: its spectrum is isotropic,
    ``F(v) = value * radius * J1(2 pi radius |v|) / |v| * exp(-2 pi i v . center)``.
    """

    center: tuple[float, float] = eqx.field(static=True)
    radius: float = eqx.field(static=True)
    value: float = eqx.field(static=True)

    def __init__(self, center=(0.5, 0.5), radius=0.3, value=1.0):
        self.center = check_point2("center", center)
        self.radius = check_positive_float("radius", radius)
        self.value = check_real("value", value)
        cx, cy = self.center
        if min(cx, cy, 1.0 - cx, 1.0 - cy) < self.radius:
            raise ValueError(
                "radius must keep the disk inside [0, 1]^2 (clipped disks are not supported): "
                f"got center {self.center} and radius {self.radius}"
            )

    def __call__(self, x):
        x = as_float(x)
        dx = x[..., 0] - jnp.asarray(self.center[0], x.dtype)
        dy = x[..., 1] - jnp.asarray(self.center[1], x.dtype)
        inside = dx * dx + dy * dy < jnp.asarray(self.radius**2, x.dtype)
        return jnp.where(inside, jnp.asarray(self.value, x.dtype), jnp.zeros((), x.dtype))

    @property
    def integral(self) -> float:
        return self.value * math.pi * self.radius**2

    def second_moment(self) -> float:
        return self.value * self.integral

    def fourier_coefficients(self, v) -> np.ndarray | np.complexfloating:
        v = check_frequencies_any(v)
        rho = np.hypot(v[..., 0], v[..., 1])
        safe = np.where(rho == 0, 1.0, rho)
        amp = np.where(rho == 0, math.pi * self.radius**2,
                       self.radius * scipy.special.j1(2 * math.pi * self.radius * safe) / safe)
        phase = np.exp(-2j * math.pi * (v[..., 0] * self.center[0] + v[..., 1] * self.center[1]))
        return self.value * amp * phase

def _lambda(z):
    """Second antiderivative of the normal CDF: ``Lambda'' = Phi``, ``Lambda(-inf) = 0``."""
    return 0.5 * ((z * z + 1.0) * scipy.special.ndtr(z) + z * np.exp(-0.5 * z * z)
                  / math.sqrt(2 * math.pi))

def _psi(z):
    """First antiderivative of the normal CDF: ``Psi(z) = z Phi(z) + phi(z)``."""
    return z * scipy.special.ndtr(z) + np.exp(-0.5 * z * z) / math.sqrt(2 * math.pi)

class SmoothedEdge(Integrand):
    """A :class:`HalfPlane` convolved with an isotropic Gaussian of std ``sigma`` (W Fig. 11).

    ``f(x) = value * Phi((offset - x . n) / sigma)``, ``n = (cos phi, sin phi)``: the plane's
    half-plane blurred, restricted to the square. W Fig. 11 blurs a 2048^2 grid with sigma = 2.83
    and 8.5 pixels, i.e. ``sigma = 2.83 / 2048`` and ``8.5 / 2048`` here.
    The integral is the closed form ``sigma^2/(n_x n_y) sum_corners +-Lambda(u)`` with
    ``Lambda'' = Phi``; near the axes (``|n_x n_y| < 1e-3``) it switches to adaptive quadrature
    of the exact inner integral. Both are accurate to better than 1e-10.
    The spectral direction is ``phi mod 180``, but the blur cuts that ray off at
    ``|v| ~ 1 / (2 pi sigma)`` (fourier_variance.md Sec. 4.3).
    """

    normal_deg: float = eqx.field(static=True)
    offset: float = eqx.field(static=True)
    sigma: float = eqx.field(static=True)
    value: float = eqx.field(static=True)

    def __init__(self, normal_deg, offset, sigma, value=1.0):
        self.normal_deg = check_real("normal_deg", normal_deg)
        self.offset = check_real("offset", offset)
        self.sigma = check_positive_float("sigma", sigma)
        self.value = check_real("value", value)

    @classmethod
    def through(cls, point, normal_deg, sigma, value=1.0) -> SmoothedEdge:
        px, py = check_point2("point", point)
        phi = math.radians(check_real("normal_deg", normal_deg))
        return cls(normal_deg, px * math.cos(phi) + py * math.sin(phi), sigma, value)

    def _n(self):
        phi = math.radians(self.normal_deg)
        return math.cos(phi), math.sin(phi)

    def __call__(self, x):
        x = as_float(x)
        nx, ny = self._n()
        t = x[..., 0] * jnp.asarray(nx, x.dtype) + x[..., 1] * jnp.asarray(ny, x.dtype)
        u = (jnp.asarray(self.offset, x.dtype) - t) / jnp.asarray(self.sigma, x.dtype)
        return jnp.asarray(self.value, x.dtype) * jax.scipy.special.ndtr(u)

    @property
    def integral(self) -> float:
        nx, ny = self._n()
        s, c = self.sigma, self.offset

        def u(x, y):
            return (c - nx * x - ny * y) / s

        if abs(nx * ny) >= 1e-3:
            total = _lambda(u(1, 1)) - _lambda(u(1, 0)) - _lambda(u(0, 1)) + _lambda(u(0, 0))
            return self.value * float(s * s / (nx * ny) * total)
        # Near an axis: integrate over the coordinate with the larger normal component exactly
        # (Psi) and over the other one by adaptive quadrature.
        if abs(nx) >= abs(ny):
            def inner(y):
                return -(s / nx) * (_psi(u(1, y)) - _psi(u(0, y)))
        else:
            def inner(xv):
                return -(s / ny) * (_psi(u(xv, 1)) - _psi(u(xv, 0)))
        val, _ = scipy.integrate.quad(inner, 0.0, 1.0, epsabs=1e-14, epsrel=1e-13, limit=200)
        return self.value * float(val)

    @property
    def directions_deg(self) -> tuple[float, ...]:
        theta = round(self.normal_deg % 180.0, 9) % 180.0
        return () if theta in (0.0, 90.0) else (theta,)

def _damped_erf(p: float, beta):
    """``exp(-beta^2) erf(p + i beta)`` for real ``p`` and real arrays ``beta``, stably:
    ``erfc(z) = exp(-z^2) w(i z)`` (Faddeeva ``w``), and ``erf`` odd with conjugate symmetry."""
    if p < 0:
        return -np.conj(_damped_erf(-p, beta))
    beta = np.asarray(beta, dtype=np.float64)
    return np.exp(-beta**2) - np.exp(-p * p) * np.exp(-2j * p * beta) * scipy.special.wofz(
        -beta + 1j * p)


class GaussianBump(Integrand):
    """``amplitude * exp(-|x - center|^2 / (2 sigma^2))``: a smooth integrand (no edges).

    Exact integral ``2 pi sigma^2 prod_d [Phi((1 - c_d)/sigma) - Phi(-c_d/sigma)]``. Keep the bump
    well inside the square (the defaults leave ``exp(-19.5)`` at the border) so that it is also
    smooth on the torus.
    """

    center: tuple[float, float] = eqx.field(static=True)
    sigma: float = eqx.field(static=True)
    amplitude: float = eqx.field(static=True)

    def __init__(self, center=(0.5, 0.5), sigma=0.08, amplitude=1.0):
        self.center = check_point2("center", center)
        self.sigma = check_positive_float("sigma", sigma)
        self.amplitude = check_real("amplitude", amplitude)

    def __call__(self, x):
        x = as_float(x)
        dx = x[..., 0] - jnp.asarray(self.center[0], x.dtype)
        dy = x[..., 1] - jnp.asarray(self.center[1], x.dtype)
        k = jnp.asarray(-0.5 / self.sigma**2, x.dtype)
        return jnp.asarray(self.amplitude, x.dtype) * jnp.exp(k * (dx * dx + dy * dy))

    def _mass(self, sigma) -> float:
        out = 2 * math.pi * sigma**2
        for c in self.center:
            out *= float(scipy.special.ndtr((1 - c) / sigma) - scipy.special.ndtr(-c / sigma))
        return out

    @property
    def integral(self) -> float:
        return self.amplitude * self._mass(self.sigma)

    def second_moment(self) -> float:
        # f^2 is a bump with sigma / sqrt(2)
        return self.amplitude**2 * self._mass(self.sigma / math.sqrt(2.0))

    def fourier_coefficients(self, v) -> np.ndarray | np.complexfloating:
        """Closed form, separable: per axis, with ``t = (x - c) / (sigma sqrt 2)`` and
        ``beta = pi k sigma sqrt 2``,
        ``int_0^1 exp(-(x-c)^2/(2 sigma^2) - 2 pi i k x) dx = sigma sqrt(pi/2) e^{-2 pi i k c}
        e^{-beta^2} [erf(b + i beta) - erf(a + i beta)]``, ``a, b`` the ends in ``t``; the product
        ``e^{-beta^2} erf(.)`` is evaluated through the Faddeeva function (no overflow)."""
        v = check_frequencies_any(v)
        out = np.full(v.shape[:-1], self.amplitude, dtype=np.complex128)
        s = self.sigma
        for d, c in enumerate(self.center):
            k = v[..., d]
            beta = math.pi * k * s * math.sqrt(2.0)
            a, b = -c / (s * math.sqrt(2.0)), (1.0 - c) / (s * math.sqrt(2.0))
            diff = _damped_erf(b, beta) - _damped_erf(a, beta)
            out = out * (s * math.sqrt(math.pi / 2.0) * np.exp(-2j * math.pi * k * c) * diff)
        return out

class Texture(Integrand):
    """A smooth periodic texture ``offset + sum_j a_j cos(2 pi k_j . x + phase_j)``.

    ``freqs``: ``(m, 2)`` nonzero integer frequencies ``k_j``; ``amplitudes``, ``phases``: ``(m,)``.
    A trigonometric polynomial: smooth on the torus, ``integral = offset``, and its spectrum is
    ``m`` pairs of deltas. Multiply a shape by it with :class:`Textured`.
    """

    freqs: tuple[tuple[int, int], ...] = eqx.field(static=True)
    amplitudes: tuple[float, ...] = eqx.field(static=True)
    phases: tuple[float, ...] = eqx.field(static=True)
    offset: float = eqx.field(static=True)

    def __init__(self, freqs, amplitudes, phases=None, offset=1.0):
        k = np.asarray(freqs)
        if k.ndim != 2 or k.shape[1] != 2 or k.shape[0] < 1:
            raise ValueError(f"freqs must have shape (m, 2) with m >= 1, got shape {k.shape}")
        if not np.all(k == np.round(k)):
            raise ValueError("freqs must hold integer frequency vectors")
        if np.any(np.all(k == 0, axis=1)):
            raise ValueError("freqs must not contain the zero frequency (use offset)")
        a = np.asarray(amplitudes, dtype=np.float64).reshape(-1)
        p = np.zeros_like(a) if phases is None else np.asarray(phases, np.float64).reshape(-1)
        if a.shape[0] != k.shape[0] or p.shape[0] != k.shape[0]:
            raise ValueError(
                f"amplitudes and phases must have {k.shape[0]} entries (one per frequency), "
                f"got {a.shape[0]} and {p.shape[0]}"
            )
        if not (np.all(np.isfinite(a)) and np.all(np.isfinite(p))):
            raise ValueError("amplitudes and phases must be finite")
        self.freqs = tuple((int(x), int(y)) for x, y in k)
        self.amplitudes = tuple(float(x) for x in a)
        self.phases = tuple(float(x) for x in p)
        self.offset = check_real("offset", offset)

    def __call__(self, x):
        x = as_float(x)
        out = jnp.full(x.shape[:-1], self.offset, dtype=x.dtype)
        for (kx, ky), a, p in zip(self.freqs, self.amplitudes, self.phases, strict=True):
            # reduce the phase modulo one turn before scaling by 2 pi (float32 accuracy)
            t = x[..., 0] * kx + x[..., 1] * ky
            t = t - jnp.floor(t)
            out = out + jnp.asarray(a, x.dtype) * jnp.cos(
                jnp.asarray(2 * math.pi, x.dtype) * t + jnp.asarray(p, x.dtype))
        return out

    @property
    def integral(self) -> float:
        return self.offset

    def second_moment(self) -> float:
        return self.offset**2 + 0.5 * sum(a * a for a in self.amplitudes)  # distinct +-k_j assumed

    def _terms(self):
        """``T(x) = sum_t c_t exp(2 pi i k_t . x)`` as (k_t, c_t) pairs, including the offset."""
        terms = [((0, 0), complex(self.offset))]
        for (kx, ky), a, p in zip(self.freqs, self.amplitudes, self.phases, strict=True):
            terms.append(((kx, ky), 0.5 * a * complex(math.cos(p), math.sin(p))))
            terms.append(((-kx, -ky), 0.5 * a * complex(math.cos(p), -math.sin(p))))
        return terms

    def fourier_coefficients(self, v) -> np.ndarray | np.complexfloating:
        v = check_frequencies_any(v)
        out = np.zeros(v.shape[:-1], dtype=np.complex128)
        for (kx, ky), c in self._terms():
            out = out + np.where((v[..., 0] == kx) & (v[..., 1] == ky), c, 0.0)
        return out

@renamed_keywords(kind="name")
def smooth_texture(name: str = "default") -> Texture:
    """The smooth texture of our W Fig. 6 "with texture" integrands: positive, low frequency.

    ``1 + 0.35 cos(2 pi (x + 2y) + 0.3) + 0.25 cos(2 pi (3x - y) + 1.1) + 0.15 cos(2 pi (2x + 3y))``
    (values in [0.25, 1.75]).
    """
    check_choice("name", name, ["default"])
    return Texture([(1, 2), (3, -1), (2, 3)], [0.35, 0.25, 0.15], [0.3, 1.1, 0.0], offset=1.0)

class Textured(Integrand):
    """``texture(x) * shape(x)``: a smooth texture on a discontinuous shape (W Fig. 6).

    Exact integral and Fourier coefficients from the shape's closed-form coefficients:
    ``F_{T s}(v) = sum_t c_t F_s(v - k_t)`` for ``T = sum_t c_t exp(2 pi i k_t . x)``.
    """

    texture: Texture
    shape: Integrand

    def __init__(self, texture: Texture, shape: Integrand):
        if not isinstance(texture, Texture):
            raise TypeError(f"texture must be a Texture, got {type(texture).__name__}")
        if not isinstance(shape, Integrand):
            raise TypeError(f"shape must be an Integrand, got {type(shape).__name__}")
        try:
            shape.fourier_coefficients(np.zeros((1, 2), dtype=np.int64))
        except NotImplementedError:
            raise ValueError(
                "shape must have closed-form Fourier coefficients (HalfPlane, Polygon, Disk, "
                f"GaussianBump), got {type(shape).__name__}"
            ) from None
        self.texture = texture
        self.shape = shape

    def __call__(self, x):
        return self.texture(x) * self.shape(x)

    @property
    def integral(self) -> float:
        return float(np.real(self.fourier_coefficients(np.zeros(2, dtype=np.int64))))

    @property
    def directions_deg(self) -> tuple[float, ...]:
        return self.shape.directions_deg

    def fourier_coefficients(self, v) -> np.ndarray | np.complexfloating:
        v = check_frequencies_any(v)
        out = np.zeros(v.shape[:-1], dtype=np.complex128)
        for k, c in self.texture._terms():
            out = out + c * self.shape.fourier_coefficients(v - np.asarray(k, dtype=np.float64))
        return out

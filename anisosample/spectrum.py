"""Power spectra of point sets (W Eq. 6), expected spectra, profiles and pictures.

``F_S(v) = (1/N) sum_j exp(-2 pi i v . x_j)`` and ``P_S(v) = |F_S(v)|^2`` for integer ``v``, so
``P_S(0) = 1`` and white noise has ``<P_S(v)> = 1/N``. Plots show ``N P_S`` (white noise -> 1).

Three evaluation paths, all differentiable with respect to the points:

* ``"direct"``: the sum itself, chunked over frequencies (the reference; the fast path on GPUs).
  In float32 the phase ``v . x`` is reduced modulo 1 from an exact high part and a small low part
  of ``x``, so it stays accurate for frequencies up to tens of thousands (``|v| < 2^24``).
* ``"nufft"``: a type-1 NUFFT (jax-finufft) onto the centred grid that bounds the frequencies,
  then a gather: cheap when the frequencies fill their bounding box.
* ``"nufft3"``: a type-3 NUFFT at exactly the requested frequencies, in coordinates rotated to the
  frequencies' principal axis, so that its cost follows a long thin strip's length, not its
  bounding box.

``method="auto"`` picks the direct sum for small problems and on accelerators, and otherwise the
NUFFT path whose cost is lower.
"""

from __future__ import annotations

import functools
import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from ._validate import (
    check_choice,
    check_frequencies,
    check_int,
    check_key,
    check_points,
    check_positive_float,
)

__all__ = [
    "power_spectrum",
    "power_spectrum_grid",
    "frequency_grid",
    "expected_power_spectrum",
    "expected_power_spectrum_grid",
    "radial_profile",
    "angular_profile",
    "save_spectrum_image",
    "white_noise_level",
]

METHODS = ("auto", "direct", "nufft", "nufft3")

_DIRECT_MAX_WORK = 1 << 22  # n * m below which the direct sum is cheapest on a CPU
_CHUNK = 256  # frequencies per chunk of the direct sum
_MAX_FREQ = 1 << 24  # float32 holds every integer frequency below this exactly


def white_noise_level(n: int) -> float:
    """``<P_S(v)>`` of ``n`` independent uniform points: ``1 / n``."""
    return 1.0 / check_int("n", n, minimum=1)


def frequency_grid(radius: int) -> np.ndarray:
    """All integer frequencies of the centred ``(2r+1)^2`` grid as ``(m, 2)`` int32, ``(v_x, v_y)``.

    Ordered so that ``.reshape(2r+1, 2r+1, 2)[i, j] == (j - r, i - r)``: rows are ``v_y``.
    """
    r = check_int("radius", radius, minimum=1)
    k = np.arange(-r, r + 1, dtype=np.int32)
    vx, vy = np.meshgrid(k, k, indexing="xy")
    return np.stack([vx.reshape(-1), vy.reshape(-1)], axis=-1)


# --- direct sum -----------------------------------------------------------------------------------


def _phase_fraction(points, v):
    """``v . x`` modulo 1 (up to an integer), accurate in float32 for large integer ``v``.

    ``x = x_hi + x_lo`` with ``x_hi = k / 1024`` (a truncation, ``k < 1024``) and
    ``0 <= x_lo < 2^-10``. Since ``1024 x_hi`` is an integer, ``v x_hi = (v mod 1024) x_hi`` modulo
    1, a product of two 10-bit numbers that float32 holds exactly, so its fraction is exact for
    every ``|v| < 2^24``; ``v x_lo`` (``|v x_lo| < |v| / 1024``) is rounded once and reduced
    modulo 1 too, so the phase error grows only like ``|v| 2^-34``. The gradient flows through
    ``x_lo`` (``x_hi`` is a truncation), which is exact: ``d(v . x)/dx = v``.
    """
    scale = jnp.asarray(1024.0, points.dtype)
    hi = jax.lax.stop_gradient(jnp.floor(points * scale) / scale)
    lo = points - hi
    v_mod = v - scale * jnp.floor(v / scale)  # in [0, 1024), exact
    prod_hi = v_mod[:, None, :] * hi[None, :, :]  # (c, n, 2), exact
    prod_lo = v[:, None, :] * lo[None, :, :]
    frac = (prod_hi - jnp.floor(prod_hi)) + (prod_lo - jax.lax.stop_gradient(jnp.floor(prod_lo)))
    return jnp.sum(frac, axis=-1)


def _direct_chunk(points, v):
    if points.dtype == jnp.float64:
        phase = v @ points.T
    else:
        phase = _phase_fraction(points, v)
    angle = (2.0 * math.pi) * phase
    re = jnp.sum(jnp.cos(angle), axis=-1)
    im = jnp.sum(jnp.sin(angle), axis=-1)
    n = points.shape[0]
    return (re * re + im * im) / (float(n) * float(n))


@jax.jit
def _power_spectrum_direct(points, freqs):
    m = freqs.shape[0]
    pad = (-m) % _CHUNK
    v = jnp.concatenate([freqs, jnp.zeros((pad, 2), freqs.dtype)]).astype(points.dtype)
    chunk = jax.checkpoint(functools.partial(_direct_chunk, points))
    out = jax.lax.map(chunk, v.reshape(-1, min(_CHUNK, v.shape[0]), 2))
    return out.reshape(-1)[:m]


# --- NUFFT paths ----------------------------------------------------------------------------------

NUFFT_THREADS = 1
"""OpenMP threads of every CPU FINUFFT call. FINUFFT's multithreaded spreader (types 1 and 3)
adds the threads' subgrids into the fine grid in whatever order they finish, so with more than
one thread the same call gives different bits from run to run (n = 1024, 300 synthesis steps:
coordinates differ by 3e-5). One thread makes every transform a fixed sequence of operations:
same key, same bits across runs, thread counts and resumes (DESIGN). Interpolation (type 2) is
order-independent but its FFT's plan depends on the thread count, so it runs on one thread too.
On a GPU, cuFINUFFT's options apply (its atomics make it nondeterministic there)."""


def finufft_opts(eps, *, upsampfac=None):
    """The FINUFFT options of every call: :data:`NUFFT_THREADS` threads on the CPU and, for
    type 1/2 grids, ``upsampfac`` where the CPU library supports it (``eps >= 1e-9``)."""
    from jax_finufft.options import Opts

    if jax.default_backend() != "cpu":
        return None
    up = upsampfac if upsampfac is not None and eps >= 1e-9 else 0.0
    return Opts(nthreads=NUFFT_THREADS, upsampfac=up)



def _nufft_eps(dtype) -> float:
    return 1e-11 if dtype == jnp.float64 else 1e-6


@functools.partial(jax.jit, static_argnames=("rx", "ry"))
def _fourier_grid_nufft1(points, rx, ry):
    """``F_S`` on the grid ``|v_x| <= rx, |v_y| <= ry``, indexed ``[v_x + rx, v_y + ry]``."""
    import jax_finufft

    cdtype = jnp.complex128 if points.dtype == jnp.float64 else jnp.complex64
    n = points.shape[0]
    c = jnp.full((n,), 1.0 / n, dtype=cdtype)
    x = (2.0 * math.pi) * points[:, 0]
    y = (2.0 * math.pi) * points[:, 1]
    eps = _nufft_eps(points.dtype)
    return jax_finufft.nufft1((2 * rx + 1, 2 * ry + 1), c, x, y, eps=eps, iflag=-1,
                              opts=finufft_opts(eps))


@functools.partial(jax.jit, static_argnames=("rx", "ry"))
def _power_spectrum_nufft1(points, freqs, rx, ry):
    F = _fourier_grid_nufft1(points, rx, ry)
    f = F[freqs[:, 0] + rx, freqs[:, 1] + ry]
    return jnp.real(f) ** 2 + jnp.imag(f) ** 2


@jax.jit
def _power_spectrum_nufft3(points, freqs, rotation):
    """Type-3 NUFFT at the given frequencies, in coordinates rotated by ``rotation`` (2x2).

    ``v . x = (R v) . (R x)`` for a rotation R; centring the points only changes the phase.
    """
    import jax_finufft

    cdtype = jnp.complex128 if points.dtype == jnp.float64 else jnp.complex64
    n = points.shape[0]
    R = rotation.astype(points.dtype)
    xr = (points - 0.5) @ R.T
    s = (2.0 * math.pi) * (freqs.astype(points.dtype) @ R.T)
    c = jnp.full((n,), 1.0 / n, dtype=cdtype)
    eps = _nufft_eps(points.dtype)
    f = jax_finufft.nufft3(c, xr[:, 0], xr[:, 1], s[:, 0], s[:, 1], eps=eps, iflag=-1,
                           opts=finufft_opts(eps))
    return jnp.real(f) ** 2 + jnp.imag(f) ** 2


def _principal_rotation(freqs: np.ndarray) -> np.ndarray:
    """Rotation taking the frequencies' principal axis (axial, through 0) to the x axis."""
    f = freqs.astype(np.float64)
    _, vecs = np.linalg.eigh(f.T @ f)
    a = vecs[:, -1]
    ang = math.atan2(a[1], a[0])
    c, s = math.cos(ang), math.sin(ang)
    return np.array([[c, s], [-s, c]])


def _choose_method(n: int, freqs: np.ndarray) -> str:
    m = freqs.shape[0]
    if jax.default_backend() != "cpu" or n * m <= _DIRECT_MAX_WORK:
        return "direct"
    rx, ry = np.abs(freqs).max(axis=0)
    box = (2 * int(rx) + 1) * (2 * int(ry) + 1)
    # type 1 costs ~ the box plus n; type 3 ~ the rotated extent of the set plus n and m.
    rot = _principal_rotation(freqs) @ freqs.T.astype(np.float64)
    ext = np.ptp(rot, axis=1) + 1.0
    return "nufft" if box <= 4 * max(m, float(ext[0] * ext[1])) else "nufft3"


def power_spectrum(points, freqs, *, method: str = "auto"):
    """``P_S(v)`` of a point set at integer frequencies (W Eq. 6): ``(m,)`` values.

    Args:
        points: ``(n, 2)`` in ``[0, 1)^2`` (float32, or float64 under ``jax.enable_x64``).
        freqs: ``(m, 2)`` integer frequency vectors ``(v_x, v_y)`` with ``|v_x|, |v_y| < 2^24``.
        method: ``"auto"``, ``"direct"``, ``"nufft"`` (type 1 on the bounding grid) or
            ``"nufft3"`` (type 3 in rotated coordinates). All agree to ~1e-6 (float32) or
            ~1e-10 (float64) relative to ``P_S(0) = 1``, and all are differentiable in ``points``.
    """
    check_choice("method", method, METHODS)
    points = check_points("points", points)
    freqs = check_frequencies("freqs", freqs)
    if (
        not isinstance(freqs, jax.core.Tracer)
        and np.abs(np.asarray(freqs, np.int64)).max() >= _MAX_FREQ
    ):
        raise ValueError(f"freqs must satisfy |v_x|, |v_y| < 2^24, got up to {np.abs(freqs).max()}")
    pts = jnp.asarray(points)
    if pts.dtype not in (jnp.float32, jnp.float64):
        pts = pts.astype(jnp.float32)
    if method == "auto":
        method = _choose_method(pts.shape[0], np.asarray(freqs))
    if method == "direct":
        return _power_spectrum_direct(pts, jnp.asarray(freqs, jnp.int32))
    if method == "nufft":
        f = np.asarray(freqs)
        rx, ry = (int(r) for r in np.abs(f).max(axis=0))
        return _power_spectrum_nufft1(pts, jnp.asarray(f, jnp.int32), max(rx, 1), max(ry, 1))
    rot = _principal_rotation(np.asarray(freqs))
    return _power_spectrum_nufft3(pts, jnp.asarray(freqs, jnp.int32), jnp.asarray(rot))


def power_spectrum_grid(points, radius: int, *, method: str = "auto"):
    """``P_S`` on the centred grid of half-width ``radius``: ``grid[i, j] = P_S(j - r, i - r)``.

    Rows are ``v_y`` and columns ``v_x``, as in DESIGN's grids (``imshow(origin="lower")``).
    """
    r = check_int("radius", radius, minimum=1)
    check_choice("method", method, METHODS)
    points = check_points("points", points)
    pts = jnp.asarray(points)
    if method in ("auto", "nufft") and (
        method == "nufft" or pts.shape[0] * (2 * r + 1) ** 2 > _DIRECT_MAX_WORK
    ):
        F = _fourier_grid_nufft1(
            pts.astype(pts.dtype if pts.dtype == jnp.float64 else jnp.float32), r, r
        )
        return (jnp.real(F) ** 2 + jnp.imag(F) ** 2).T
    vals = power_spectrum(pts, frequency_grid(r), method="direct" if method == "auto" else method)
    return vals.reshape(2 * r + 1, 2 * r + 1)


# --- expected spectra over realizations -----------------------------------------------------------


def _average_over_realizations(sampler, n, key, realizations, shift, progress, spectrum_of):
    """``mean_r spectrum_of(S_r)`` over independent (optionally shifted) sets ``S_r``.

    The one loop behind :func:`expected_power_spectrum` and :func:`expected_power_spectrum_grid`;
    the arguments are already validated (the sampler may be a name).
    """
    from . import samplers as _samplers
    from .progress import progress as _progress

    if isinstance(sampler, str):
        sampler = _samplers.get(sampler)
    acc = None
    for k in _progress(
        jax.random.split(key, realizations), desc="expected spectrum", disable=not progress
    ):
        k_pts, k_shift = jax.random.split(k)
        pts = sampler(k_pts, n)
        p = spectrum_of(_samplers.toroidal_shift(k_shift, pts) if shift else pts)
        acc = p if acc is None else acc + p
    return acc / realizations


def expected_power_spectrum(
    sampler,
    n,
    key,
    freqs,
    *,
    realizations: int = 64,
    shift: bool = True,
    method: str = "auto",
    progress: bool = False,
):
    """``<P_S(v)>`` averaged over ``realizations`` independent point sets (shifted by default).

    ``sampler`` is a sampler name or a callable ``(key, n) -> (n, 2)``. Shifting homogenizes the
    pattern (W Sec. 2) without changing each set's spectrum; it matters only for the sets'
    positions, so it is on by default for use with W Eq. 5.
    """
    n = check_int("n", n, minimum=1)
    key = check_key("key", key)
    realizations = check_int("realizations", realizations, minimum=1)
    freqs = check_frequencies("freqs", freqs)
    check_choice("method", method, METHODS)
    return _average_over_realizations(
        sampler, n, key, realizations, shift, progress,
        lambda pts: power_spectrum(pts, freqs, method=method),
    )  # fmt: skip


def expected_power_spectrum_grid(
    sampler, n, key, radius, *, realizations: int = 64, shift: bool = True, progress: bool = False
):
    """``<P_S>`` on the centred grid of half-width ``radius`` (see :func:`power_spectrum_grid`)."""
    n = check_int("n", n, minimum=1)
    key = check_key("key", key)
    realizations = check_int("realizations", realizations, minimum=1)
    radius = check_int("radius", radius, minimum=1)
    return _average_over_realizations(
        sampler, n, key, realizations, shift, progress,
        lambda pts: power_spectrum_grid(pts, radius),
    )  # fmt: skip


# --- profiles -------------------------------------------------------------------------------------


def _grid_coords(grid):
    g = np.asarray(grid)
    if g.ndim != 2 or g.shape[0] != g.shape[1] or g.shape[0] % 2 == 0:
        raise ValueError(f"grid must be a centred (2r+1, 2r+1) spectrum, got shape {g.shape}")
    r = g.shape[0] // 2
    k = np.arange(-r, r + 1)
    vx, vy = np.meshgrid(k, k, indexing="xy")
    return g, r, vx, vy


def radial_profile(grid) -> tuple[np.ndarray, np.ndarray]:
    """Mean of a centred spectrum over rings of integer radius ``round(|v|)``, ``v != 0``.

    Returns ``(radii, means)`` for radii ``1..r``.
    """
    g, r, vx, vy = _grid_coords(grid)
    rad = np.rint(np.hypot(vx, vy)).astype(int)
    mask = (rad >= 1) & (rad <= r)
    sums = np.bincount(rad[mask], weights=g[mask], minlength=r + 1)
    counts = np.bincount(rad[mask], minlength=r + 1)
    radii = np.arange(1, r + 1)
    return radii, sums[1:] / np.maximum(counts[1:], 1)


def angular_profile(
    grid, *, r_min: float = 1.0, r_max: float | None = None, bins: int = 180
) -> tuple[np.ndarray, np.ndarray]:
    """Mean of a centred spectrum per spectral direction (axial, degrees in ``[0, 180)``).

    Only frequencies with ``r_min <= |v| <= r_max`` count. Returns ``(bin centres, means)``;
    empty bins are NaN-free (0 with a count of 0 is reported as 0).
    """
    g, r, vx, vy = _grid_coords(grid)
    bins = check_int("bins", bins, minimum=1)
    r_max = float(r) if r_max is None else float(r_max)
    if not 0 <= r_min < r_max:
        raise ValueError(f"need 0 <= r_min < r_max, got r_min={r_min}, r_max={r_max}")
    rad = np.hypot(vx, vy)
    ang = np.degrees(np.arctan2(vy, vx)) % 180.0
    mask = (rad >= r_min) & (rad <= r_max)
    idx = np.minimum((ang[mask] / 180.0 * bins).astype(int), bins - 1)
    sums = np.bincount(idx, weights=g[mask], minlength=bins)
    counts = np.bincount(idx, minlength=bins)
    centres = (np.arange(bins) + 0.5) * 180.0 / bins
    return centres, sums / np.maximum(counts, 1)


# --- pictures -------------------------------------------------------------------------------------


def save_spectrum_image(path, grid, *, n: int, vmax: float = 2.0, overwrite: bool = False) -> Path:
    """Save a centred spectrum as PNG (``N P_S`` clipped to ``[0, vmax]``, grey) or EXR (``P_S``).

    The picture is upright: ``v_y`` grows upwards, ``v_x`` to the right, ``v = 0`` at the centre.
    """
    from . import io

    path = Path(path)
    g = np.asarray(grid, dtype=np.float64)
    _grid_coords(g)
    n = check_int("n", n, minimum=1)
    vmax = check_positive_float("vmax", vmax)  # vmax <= 0 or NaN gave a blank/garbled picture
    upright = g[::-1]
    if path.suffix == ".exr":
        return io.write_exr(
            path,
            upright.astype(np.float32),
            {"quantity": "P_S (white noise = 1/n)", "n": n},
            overwrite=overwrite,
        )
    if path.suffix == ".png":
        return io.save_png(
            path,
            np.clip(n * upright, 0.0, vmax),
            cmap="gray",
            vmin=0.0,
            vmax=vmax,
            overwrite=overwrite,
        )
    raise ValueError(f"path must end in .png or .exr, got {path.name}")

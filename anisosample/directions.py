"""Principal (spectral) directions of a 2D integrand from a sparse grid of its samples.

W Sec. 5.1-5.3: a gradient-orientation histogram (Gaussian smoothing, Sobel gradients, gradient
magnitude binned by gradient direction), the windows around 0 and 90 degrees zeroed, then the
extra directions found by fitting von Mises-Fisher densities to the histogram with the
mode-seeking reverse KL (W Eq. 18; machinery in :mod:`anisosample.vmf`), a confidence test that
rejects curved or absent discontinuities, and the same per block of pixels, vmapped.

Conventions (DESIGN): grids are ``values[i, j] = f((j + .5)/w, (i + .5)/h)`` (row index = y,
no image flip); a spectral direction ``theta`` is the direction of the image gradient, i.e. the
normal of an edge, in degrees ``[0, 180)``. Directions are axial: the histogram covers
``[0, 180)`` with bins centred on multiples of ``bin_deg`` (so on integer degrees by default;
floor bins would bias every estimate by half a bin), and the vMF machinery works on the
*doubled* angle ``x = 2 theta`` in ``[0, 2 pi)`` (Mardia & Jupp). Every ``kappa`` here is thus the
concentration of the doubled angle: ``kappa = 50`` is a spread of ~8 deg in ``x``, ~4 deg in
``theta``.

Choices the paper leaves open, fixed here and documented:

* Gaussian ``sigma_px = 2`` grid cells, radius ``ceil(3 sigma)``; replicate ("edge") borders so
  the domain boundary creates no fake edges. Sobel normalised to a derivative per grid cell.
  (sigma = 2 rather than 1: staircased edges at 96^2 give far less direction noise.)
* ``zero_window_deg = 2``: bins within 2 degrees (axially) of 0 and of 90 are zeroed, the same
  width as the confidence window (3 degrees found fewer near-axis edges, with no fewer false
  detections, in ``experiments/w_directions_accuracy.py``'s cases).
* ``min_gradient = 0.05``: gradients weaker than 5 % of the grid's value range per grid cell are
  not binned. A step of height ``h`` smoothed with sigma = 1 cell has a peak gradient of ~0.4 h
  per cell (0.2 h at sigma = 2), a smooth bump spanning the block a few hundredths; this keeps
  smooth integrands from voting (an addition to the paper's method; set 0 to disable).
* Fixed-kappa search (W Sec. 5.2): ``kappa = 100`` on the doubled angle (~2.9 deg spread in
  theta; the paper's "kappa ~ 50" does not say which domain), ``floor = 1e-3`` per bin (see
  :mod:`anisosample.vmf`); mu on the bin grid within ``window_deg = 4`` of the highest remaining
  histogram bin; further directions at least ``min_separation_deg = 10`` from those found.
  kappa, floor and sigma were chosen on a sweep of random straight edges at 96^2 (kappa = 50
  with floor 1e-6 gave a 1.3-2 deg median error; kappa = 100 with floor 1e-3 about 0.7 deg).
* Gradient fit (``estimator="gradient"``, W Fig. 4c): starts from the fixed-kappa result and fits
  mu (continuous) and kappa with kappa bounded to ``[kappa_min_fit = 50, 1000]``. Without the
  lower bound the reverse KL of a histogram with a broad background (a polygon's corners) is
  lowest for an almost uniform q and the fit drifts there (with a bound of 10, mu was still
  pulled 3 deg off a sharp mode); a fit that returns to an already found direction is dropped.
  More accurate than the integer search, but much slower (an optimistix BFGS per slot).
* Confidence (W Sec. 5.2): normalised histogram mass within +-2 deg of mu, accepted when
  ``>= threshold`` (default 0.12, chosen on random one- and two-edge steps, disks and bumps; see
  ``experiments/w_directions_accuracy.py``). A grid whose histogram is empty after zeroing
  (constant, smooth, or only axis-aligned edges) has no extra direction.

Near the axes: an edge a few degrees from an axis loses part of its histogram mode to the zeroed
window, and with the floor there the objective repels ``q`` from the window. For the objective
(not for the seeds or the confidence), the zeroed bins are therefore filled with their nearest
kept neighbour's mass, which halved that bias. A bias remains (20 half-planes per offset, 96^2:
mean error 3.05 / 2.05 / 1.1 / 0.4 deg for edges 3 / 4 / 5 / 6 deg from an axis, always pushed
away from it). Treating the windows as unobserved (``vmf.reverse_kl(..., mask=...)``) instead
biased the other way and hurt edges 8 deg away.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Bool

from . import metrics, vmf
from ._types import Array, ArrayLike, Float
from ._validate import check_choice, check_int, check_positive_float, refuse_traced
from .metrics import axial_distance_deg as axial_distance_deg  # moved to metrics; kept here

__all__ = [
    "Estimate",
    "orientation_histogram",
    "zero_axes",
    "fill_zeroed_bins",
    "gradients",
    "estimate",
    "estimate_from_histogram",
    "estimate_blocks",
    "block_grid",
    "default_options",
]

ESTIMATORS = ("fixed", "gradient")


# --- parameters ----------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class _Params:
    """Hashable estimator settings (a static argument of the jitted cores)."""

    sigma_px: float = 2.0
    bin_deg: float = 1.0
    min_gradient: float = 0.05
    zero_window_deg: float = 2.0
    kappa: float = 100.0
    window_deg: float = 4.0
    min_separation_deg: float = 10.0
    confidence_window_deg: float = 2.0
    threshold: float = 0.12
    floor: float = 1e-3
    nodes: int = vmf.DEFAULT_NODES
    estimator: str = "fixed"
    kappa_min_fit: float = 50.0

    @property
    def nbins(self) -> int:
        return int(round(180.0 / self.bin_deg))

    @property
    def radius(self) -> int:
        return max(1, int(math.ceil(3.0 * self.sigma_px)))

    @property
    def min_size(self) -> int:
        return 2 * self.radius + 3


def default_options() -> dict:
    """The estimator's options (the keyword arguments of :func:`estimate` and its relatives)
    with their default values, in declaration order."""
    return dict(_Params().__dict__)


def _params(**kw) -> _Params:
    if "method" in kw:  # the old spelling (docs/design.md, Vocabulary)
        raise TypeError("the direction estimator is chosen by estimator= where it took method= "
                        "(docs/design.md, Vocabulary)")
    known = {f.name for f in dataclasses.fields(_Params)}
    unknown = sorted(set(kw) - known)
    if unknown:  # a misspelled option must not fall back silently to its default
        raise TypeError(f"unknown option(s) {unknown}; known options: {sorted(known)}")
    p = {}
    for name in (
        "sigma_px",
        "bin_deg",
        "kappa",
        "window_deg",
        "min_separation_deg",
        "confidence_window_deg",
        "floor",
        "kappa_min_fit",
    ):
        if name in kw:
            p[name] = check_positive_float(name, kw[name])
    for name in ("min_gradient", "zero_window_deg", "threshold"):
        if name in kw:
            p[name] = check_positive_float(name, kw[name], allow_zero=True)
    if "nodes" in kw:
        p["nodes"] = check_int("nodes", kw["nodes"], minimum=1)
    if "estimator" in kw:
        p["estimator"] = check_choice("estimator", kw["estimator"], ESTIMATORS)
    params = _Params(**p)
    nb = 180.0 / params.bin_deg
    if abs(nb - round(nb)) > 1e-9 or round(nb) < 8:
        raise ValueError(f"bin_deg must divide 180 into at least 8 bins, got {params.bin_deg}")
    if params.zero_window_deg >= 45.0:
        raise ValueError(f"zero_window_deg must be < 45, got {params.zero_window_deg}")
    if params.min_separation_deg > 90.0:
        raise ValueError(f"min_separation_deg must be <= 90, got {params.min_separation_deg}")
    return params


class Estimate(eqx.Module):
    """Per-histogram result with ``k`` slots (leading batch axes for blocks); JAX or NumPy arrays.

    ``directions_deg`` in ``[0, 180)``; a slot with ``valid == False`` holds ``-1.0`` (never NaN).
    ``confidence`` is the normalised histogram mass within +-2 deg of the direction; ``kappa``
    is the fitted concentration (the fixed ``kappa`` for ``estimator="fixed"``).
    """

    directions_deg: Float[ArrayLike, "... k"]
    valid: Bool[ArrayLike, "... k"]
    confidence: Float[ArrayLike, "... k"]
    kappa: Float[ArrayLike, "... k"]


# --- histogram (W Sec. 5.1) -----------------------------------------------------------------------


def _gaussian_taps(sigma: float) -> np.ndarray:
    r = max(1, int(math.ceil(3.0 * sigma)))
    t = np.exp(-0.5 * (np.arange(-r, r + 1) / sigma) ** 2)
    return (t / t.sum()).astype(np.float32)


_SOBEL_SMOOTH = np.array([0.25, 0.5, 0.25])
_SOBEL_DIFF = np.array([-0.5, 0.0, 0.5])


@functools.lru_cache(maxsize=32)
def _filter_matrices(n: int, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """``(S G, D G)`` as ``(n, n)`` matrices: replicate-padded Gaussian then Sobel smoothing
    ``S`` or central difference ``D`` along one axis of length ``n`` (composed in float64)."""

    def op(taps):
        r = (len(taps) - 1) // 2
        m = np.zeros((n, n))
        for i in range(n):
            for k, t in enumerate(taps):
                m[i, min(max(i + k - r, 0), n - 1)] += t
        return m

    g = op(_gaussian_taps(sigma).astype(np.float64))
    return (op(_SOBEL_SMOOTH) @ g).astype(np.float32), (op(_SOBEL_DIFF) @ g).astype(np.float32)


def gradients(values, *, sigma_px: float = 2.0):
    """The gradients W Sec. 5.1 bins: Gaussian smoothing (``sigma_px`` grid cells, radius
    ``ceil(3 sigma_px)``) then Sobel, replicate borders, ``(gx, gy)`` per grid cell (x = columns,
    y = rows) as a derivative per grid cell, each of the grid's shape ``(..., h, w)``."""
    params = _params(sigma_px=sigma_px)
    values = jnp.asarray(values, jnp.float32)
    if values.ndim < 2 or min(values.shape[-2:]) < 1:
        raise ValueError(f"values must be (..., h, w) grids, got shape {values.shape}")
    return _gradients(values, params.sigma_px)


def _gradients(values, sigma):
    """Gaussian smoothing then Sobel: ``(gx, gy)`` per grid cell (x = columns, y = rows).

    The filters are linear and separable, so each is a matrix along each axis:
    ``gx = (S_y G_y) V (D_x G_x)^T``, ``gy = (D_y G_y) V (S_x G_x)^T``. Four small matrix
    products run ~5x faster on CPU than the shifted-slice filters (same result to 1e-7).
    """
    h, w = values.shape[-2:]
    sy, dy = (jnp.asarray(m) for m in _filter_matrices(h, sigma))
    sx, dx = (jnp.asarray(m) for m in _filter_matrices(w, sigma))
    gx = sy @ values @ dx.T
    gy = dy @ values @ sx.T
    return gx, gy


def _histogram(values, params: _Params):
    """Unnormalised orientation histogram of one grid ``(h, w)`` -> ``(nbins,)``."""
    values = values.astype(jnp.float32)
    gx, gy = _gradients(values, params.sigma_px)
    mag = jnp.sqrt(gx * gx + gy * gy)
    value_range = jnp.max(values) - jnp.min(values)
    # below 1e-5 of the largest |value| a gradient is float32 round-off of the filters
    noise = 1e-5 * jnp.max(jnp.abs(values))
    weight = jnp.where(mag >= jnp.maximum(params.min_gradient * value_range, noise), mag, 0.0)
    weight = jnp.where(mag > 0, weight, 0.0)
    theta = jnp.degrees(jnp.arctan2(gy, gx))  # (-180, 180]
    nbins = params.nbins
    idx = jnp.round(theta / params.bin_deg).astype(jnp.int32) % nbins
    return jnp.zeros(nbins, jnp.float32).at[idx.reshape(-1)].add(weight.reshape(-1))


def _check_grid(values, params: _Params, name="values"):
    shape = getattr(values, "shape", None)
    if shape is None:
        values = np.asarray(values)
        shape = values.shape
    if len(shape) != 2:
        raise ValueError(f"{name} must be a 2D (h, w) grid, got shape {tuple(shape)}")
    if min(shape) < params.min_size:
        raise ValueError(
            f"{name} must be at least {params.min_size}x{params.min_size} for sigma_px="
            f"{params.sigma_px} (Gaussian + Sobel support), got shape {tuple(shape)}"
        )
    dtype = np.dtype(values.dtype)
    if not (np.issubdtype(dtype, np.integer) or np.issubdtype(dtype, np.floating)):
        raise TypeError(f"{name} must be a real-valued array, got dtype {values.dtype}")
    if isinstance(values, jax.core.Tracer):
        return refuse_traced(jnp.asarray(values, jnp.float32),
                             ~jnp.all(jnp.isfinite(values)), f"{name} contains NaN or Inf samples")
    if not np.all(np.isfinite(np.asarray(values))):
        raise ValueError(f"{name} contains NaN or Inf samples")
    return jnp.asarray(values, jnp.float32)


def orientation_histogram(
    values, *, sigma_px: float = 2.0, bin_deg: float = 1.0, min_gradient: float = 0.05
):
    """W Sec. 5.1: gradient magnitude binned by gradient direction, ``(180/bin_deg,)`` float32.

    Bin ``i`` is centred at ``i * bin_deg`` degrees (nearest-bin rounding, 180 wraps to 0);
    the gradient direction is the spectral direction (DESIGN). Not normalised, nothing zeroed.
    """
    params = _params(sigma_px=sigma_px, bin_deg=bin_deg, min_gradient=min_gradient)
    values = _check_grid(values, params)
    return _histogram_jit(values, params)


@functools.partial(jax.jit, static_argnums=1)
def _histogram_jit(values, params):
    return _histogram(values, params)


def fill_zeroed_bins(hist, *, bin_deg: float = 1.0, zero_window_deg: float = 2.0):
    """The histogram the vMF objective fits (module docstring, "Near the axes"): the bins
    :func:`zero_axes` zeroes take their nearest kept neighbour's value, the mean of the two
    where both are equally near (a window's centre); kept bins are unchanged."""
    params = _params(bin_deg=bin_deg, zero_window_deg=zero_window_deg)
    hist = jnp.asarray(hist)
    if hist.shape[-1:] != (params.nbins,):
        raise ValueError(
            f"hist must have {params.nbins} bins for bin_deg={bin_deg}, got shape {hist.shape}"
        )
    return _fill(hist, params)


def _fill(p, params: _Params):
    src_a, src_b = _fill_sources(params)
    return 0.5 * (p[..., src_a] + p[..., src_b])


def _keep_mask(params: _Params):
    centres = np.arange(params.nbins) * params.bin_deg
    d0 = np.minimum(centres, 180.0 - centres)
    d90 = np.abs(centres - 90.0)
    return (d0 > params.zero_window_deg) & (d90 > params.zero_window_deg)


@functools.lru_cache(maxsize=16)
def _fill_sources(params: _Params) -> tuple[np.ndarray, np.ndarray]:
    """For every bin, the nearest kept bin on each side (itself where kept): zeroed bins take
    the mean of the two when equidistant (the window's centre), else the nearer one."""
    keep = _keep_mask(params)
    n = params.nbins
    kept = np.flatnonzero(keep)
    a = np.arange(n)
    b = np.arange(n)
    for i in np.flatnonzero(~keep):
        d = (kept - i) % n
        right, left = kept[np.argmin(d)], kept[np.argmax(d)]
        dr, dl = (right - i) % n, (i - left) % n
        a[i] = right if dr <= dl else left
        b[i] = left if dl <= dr else right
    return a, b


def zero_axes(hist, *, bin_deg: float = 1.0, zero_window_deg: float = 2.0):
    """Zero the bins within ``zero_window_deg`` (axially) of 0 and 90 degrees (W Sec. 5.1)."""
    params = _params(bin_deg=bin_deg, zero_window_deg=zero_window_deg)
    hist = jnp.asarray(hist)
    if hist.shape[-1:] != (params.nbins,):
        raise ValueError(
            f"hist must have {params.nbins} bins for bin_deg={bin_deg}, got shape {hist.shape}"
        )
    return jnp.where(jnp.asarray(_keep_mask(params)), hist, 0.0)


# --- estimators (W Sec. 5.2) --------------------------------------------------------------------


def _estimate_hist(hist, k: int, params: _Params) -> Estimate:
    """Fixed-kappa search or gradient fit on one raw histogram ``(nbins,)``; jit/vmap-able."""
    nbins, bdeg = params.nbins, params.bin_deg
    keep = jnp.asarray(_keep_mask(params))
    centres = jnp.arange(nbins, dtype=jnp.float32) * bdeg
    h = jnp.where(keep, hist, 0.0)
    mass = jnp.sum(h)
    has_mass = mass > 1e-6 * jnp.maximum(jnp.sum(hist), 1e-30)
    # Normalised pmf; a uniform stand-in where nothing is left (those slots are invalid anyway).
    p = jnp.where(has_mass, h / jnp.where(has_mass, mass, 1.0), 1.0 / nbins)
    kappa = jnp.float32(params.kappa)
    p_fit = _fill(p, params)  # zeroed windows continue their kept neighbours
    obj = vmf.reverse_kl_all_mu(p_fit, kappa, floor=params.floor, nodes=params.nodes)
    available = keep
    mus, valids, confs, kappas = [], [], [], []
    for _ in range(k):
        # W Sec. 5.2: the highest remaining bin, then the objective's minimum in a window
        seed = jnp.argmax(jnp.where(available, p, -1.0))
        win = available & (axial_distance_deg(centres, centres[seed]) <= params.window_deg)
        mu_deg = centres[jnp.argmin(jnp.where(win, obj, jnp.inf))]
        kap = kappa
        if params.estimator == "gradient":
            # refine (mu, kappa) continuously from the fixed-kappa result (W Fig. 4c)
            fit = vmf.fit_reverse_kl(
                p_fit, jnp.radians(2.0 * mu_deg), kappa, floor=params.floor, nodes=params.nodes,
                kappa_max=1e3, kappa_min=params.kappa_min_fit, rtol=1e-6, atol=1e-6,
                max_steps=100,
            )
            mu_deg = jnp.mod(jnp.degrees(fit.mu) / 2.0, 180.0)
            kap = fit.kappa
        mu_bin = jnp.mod(jnp.round(mu_deg / bdeg) * bdeg, 180.0)
        near = axial_distance_deg(centres, mu_bin) <= params.confidence_window_deg + 1e-4
        conf = jnp.sum(jnp.where(near, p, 0.0))
        ok = has_mass & jnp.any(available) & (conf >= params.threshold)
        for prev, prev_ok in zip(mus, valids, strict=True):  # a fit may return to a found mode
            ok = ok & ~(prev_ok & (axial_distance_deg(mu_deg, prev) < params.min_separation_deg))
        mus.append(jnp.where(ok, mu_deg, -1.0))
        valids.append(ok)
        confs.append(jnp.where(has_mass, conf, 0.0))
        kappas.append(kap)
        available = available & (axial_distance_deg(centres, mu_deg) >= params.min_separation_deg)
    if k == 0:
        z = jnp.zeros((0,), jnp.float32)
        return Estimate(z, jnp.zeros((0,), bool), z, z)
    return Estimate(jnp.stack(mus), jnp.stack(valids), jnp.stack(confs), jnp.stack(kappas))


@functools.partial(jax.jit, static_argnums=(1, 2))
def _estimate_hist_jit(hist, k, params):
    return _estimate_hist(hist, k, params)


@functools.partial(jax.jit, static_argnums=(1, 2))
def _estimate_grid_jit(values, k, params):
    return _estimate_hist(_histogram(values, params), k, params)


_DOC_OPTIONS = """
    Options (keyword-only; defaults in the module docstring): ``estimator`` ("fixed": W Sec. 5.2's
    fixed-kappa integer search; "gradient": optimistix fit of mu and kappa from the histogram
    maxima), ``kappa``, ``window_deg``, ``min_separation_deg``, ``threshold``,
    ``confidence_window_deg``, ``zero_window_deg``, ``floor``, ``nodes``; for grids also
    ``sigma_px``, ``bin_deg``, ``min_gradient``.
"""


def _with_options(fn):
    fn.__doc__ = (fn.__doc__ or "").rstrip() + "\n" + _DOC_OPTIONS
    return fn


@_with_options
def estimate_from_histogram(hist, k: int = 2, **options) -> Estimate:
    """Extra directions from a raw orientation histogram ``(..., 180/bin_deg)`` (W Sec. 5.2).

    The windows around 0 and 90 degrees are zeroed here. Raises ``ValueError`` for an empty,
    all-zero, negative or non-finite histogram.
    """
    k = check_int("k", k, minimum=0)
    params = _params(**options)
    hist = vmf.check_hist(hist)
    if hist.shape[-1] != params.nbins:
        raise ValueError(
            f"hist must have {params.nbins} bins for bin_deg={params.bin_deg}, "
            f"got shape {hist.shape}"
        )
    fn = functools.partial(_estimate_hist_jit, k=k, params=params)
    for _ in range(hist.ndim - 1):
        fn = jax.vmap(fn)
    return fn(hist.astype(jnp.float32))


@_with_options
def estimate(values, k: int = 2, *, details: bool = False, **options):
    """Extra principal directions (degrees, ``[0, 180)``) of the integrand sampled on ``values``.

    ``values`` is a ``(h, w)`` grid in DESIGN's convention. Returns a tuple of at most ``k``
    floats, strongest first -- possibly empty (curved, smooth or absent discontinuities, or only
    axis-aligned ones: 0 and 90 degrees are always handled by the caller). With
    ``details=True`` returns the :class:`Estimate` with all ``k`` slots instead.
    Bad input (NaN samples, grids smaller than the filters, ``k < 0``, ``kappa <= 0``) raises.
    """
    k = check_int("k", k, minimum=0)
    params = _params(**options)
    if isinstance(values, jax.core.Tracer) and not details:
        raise TypeError("values is traced (jit/vmap), but estimate returns a tuple of Python "
                        "floats: pass details=True for the Estimate arrays")
    values = _check_grid(values, params)
    est = _estimate_grid_jit(values, k, params)
    if details:
        return est
    d, v = np.asarray(est.directions_deg), np.asarray(est.valid)
    return tuple(float(x) for x in d[v])


# --- blocks (W Sec. 5.3) ------------------------------------------------------------------------


def block_grid(samples_per_block: int, dtype=jnp.float32):
    """Cell centres ``(s, s, 2)`` of the regular grid used per block: ``x[i, j] = ((j+.5)/s,
    (i+.5)/s)``, matching DESIGN's grid convention."""
    return metrics.midpoint_grid(samples_per_block, dtype=dtype, xp=jnp)


_BATCH = 8
"""Blocks per vectorised step: ``lax.map`` over chunks of a few blocks keeps the intermediates
small (with the shifted-slice filters one ``vmap`` over all blocks was 2-3x slower on CPU; with
the matrix filters the chunk size from 4 to 64 made no measurable difference)."""


@functools.partial(jax.jit, static_argnums=(1, 2, 3))
def _estimate_blocks_array(samples, block, k, params):
    h, w = samples.shape
    by, bx = h // block, w // block
    blocks = samples.reshape(by, block, bx, block).transpose(0, 2, 1, 3)
    blocks = blocks.reshape(by * bx, block, block)
    one = lambda v: _estimate_hist(_histogram(v, params), k, params)
    est = jax.lax.map(one, blocks, batch_size=min(_BATCH, by * bx))
    return jax.tree.map(lambda a: a.reshape(by, bx, *a.shape[1:]), est)


@functools.partial(jax.jit, static_argnums=(0, 1, 2, 3, 4))
def _estimate_blocks_fn(f, blocks, s, k, params):
    by, bx = blocks
    iy, ix = jnp.meshgrid(jnp.arange(by), jnp.arange(bx), indexing="ij")
    idx = jnp.stack([iy.reshape(-1), ix.reshape(-1)], axis=-1)
    x = block_grid(s)

    def one(i):
        v = jnp.asarray(f(i, x), jnp.float32)
        if v.shape != (s, s):
            raise ValueError(
                f"the per-block callable must return shape ({s}, {s}) for x of shape "
                f"({s}, {s}, 2), got {v.shape}"
            )
        return _estimate_hist(_histogram(v, params), k, params), jnp.all(jnp.isfinite(v))

    est, finite = jax.lax.map(one, idx, batch_size=min(_BATCH, by * bx))
    return jax.tree.map(lambda a: a.reshape(by, bx, *a.shape[1:]), (est, finite))


@_with_options
def estimate_blocks(
    samples_or_fn: Array | np.ndarray | Callable,
    k: int = 2,
    *,
    samples_per_block: int = 96,
    blocks: tuple[int, int] | None = None,
    **options,
) -> Estimate:
    """W Sec. 5.3: one shared histogram and estimate per block, vmapped over all blocks.

    * an array ``(H, W)`` of samples: split into ``(H/s) x (W/s)`` blocks of ``s x s`` samples
      (``s = samples_per_block``, default 96: 16x16 pixels at 36 samples per pixel); ``H`` and
      ``W`` must be multiples of ``s``. Block ``(a, b)`` holds rows ``a s .. a s + s - 1``.
    * a callable ``f(block_index, x)`` with ``block_index`` int32 ``(2,)`` = (row, col) and ``x``
      the ``(s, s, 2)`` grid of :func:`block_grid`, returning the ``(s, s)`` samples of that
      block's integrand; needs ``blocks=(rows, cols)``. Must be jax-traceable (it is vmapped).

    Returns an :class:`Estimate` with leading axes ``(rows, cols)``.
    """
    k = check_int("k", k, minimum=0)
    s = check_int("samples_per_block", samples_per_block, minimum=1)
    params = _params(**options)
    if s < params.min_size:
        raise ValueError(
            f"samples_per_block must be >= {params.min_size} for sigma_px="
            f"{params.sigma_px}, got {s}"
        )
    if callable(samples_or_fn):
        if blocks is None:
            raise ValueError("blocks=(rows, cols) is required when passing a callable")
        by = check_int("blocks[0]", blocks[0], minimum=1)
        bx = check_int("blocks[1]", blocks[1], minimum=1)
        est, finite = _estimate_blocks_fn(samples_or_fn, (by, bx), s, k, params)
        if not bool(np.all(np.asarray(finite))):
            raise ValueError("the integrand returned NaN or Inf samples in some blocks")
        return est
    samples = samples_or_fn
    shape = getattr(samples, "shape", None) or np.asarray(samples).shape
    if len(shape) != 2 or shape[0] % s or shape[1] % s or shape[0] == 0 or shape[1] == 0:
        raise ValueError(
            f"samples must be a 2D array whose sides are positive multiples of "
            f"samples_per_block={s}, got shape {tuple(shape)}"
        )
    samples = _check_grid(samples, params, name="samples")
    return _estimate_blocks_array(samples, s, k, params)

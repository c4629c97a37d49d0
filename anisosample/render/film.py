"""Image reconstruction: where a pixel's samples land on the film (Mitsuba 3's ``rfilter``).

Mitsuba 3 draws film positions uniformly over the film and *splats* each sample into every pixel
whose reconstruction filter covers it; a pixel's value is ``sum_i w_i L_i / sum_i w_i`` with
``w_i`` the filter at the sample's offset from the pixel centre (``ImageBlock::put`` and
``HDRFilm::develop``; samples are not taken outside the film unless ``sample_border``). As the
sample count grows this converges to the filter-weighted average of the radiance over the film,

    ``I_q = int_film g(x - c_q) L(x) dx / int_film g(x - c_q) dx``,

with ``c_q`` the centre of pixel ``q`` and ``g`` the separable filter. Splatting would make a
sample feed several pixels (and a pixel a ratio of two sums), which breaks the model the library
rests on: every pixel an independent estimator ``mean_j f_q(x_j)`` of its own 2D integral. So
the renderer computes the same ``I_q`` by *filter importance sampling* (Ernst et al. 2006, as
pbrt-v4's ``FilterSampler``): each sample of pixel ``q`` takes its film position from the
density ``g(x - c_q)`` restricted to the film and normalized, and the pixel's estimate is the
plain mean of its samples. The expectation is ``I_q`` exactly; each pixel keeps its own samples
and its own integrand; only the film dimension's distribution changes (the dimension the
sampler under study does not drive; with ``pixel_center=True`` there is no film dimension).

Filters (Mitsuba 3 ``src/rfilters``):

* ``box`` (radius 1/2 pixel): the film position is uniform in the pixel;
* ``gaussian`` with ``stddev`` (Mitsuba's default filter, ``stddev`` 0.5 pixels): the windowed
  Gaussian ``g(t) = max(0, exp(-t^2 / (2 s^2)) - exp(-r^2 / (2 s^2)))`` per axis, cut off at
  ``r = 4 s`` (2 pixels for the default; ``src/rfilters/gaussian.cpp``), *as Mitsuba's scalar
  variants apply it*: tabulated at ``MI_FILTER_RESOLUTION`` = 31 steps,
  ``g_31(t) = g(r floor(31 |t| / r) / 31)`` (``ReconstructionFilter::init_discretization`` and
  ``eval_discretized``, used by ``ImageBlock::put`` in scalar mode). This is the filter of the
  ``scalar_rgb`` references the tests compare with (they agree within Monte Carlo error; the
  exact ``g`` differs from it by about 1% RMSE on an 8 x 6 image with sharp shadows). Mitsuba's
  JIT variants (``llvm_*``, ``cuda_*``) evaluate the exact ``g`` instead. A step density is
  also sampled exactly by inverting its piecewise-linear CDF, with no iteration.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

RFILTERS = ("box", "gaussian")
GAUSSIAN_STDDEV = 0.5  # Mitsuba 3's default stddev of the gaussian filter, in pixels
FILTER_RESOLUTION = 31  # Mitsuba 3's MI_FILTER_RESOLUTION: steps of the tabulated filter


def check_rfilter(rfilter: str, stddev: float) -> tuple[str, float]:
    """Validate a film's reconstruction filter: ``(name, stddev)``, ``stddev`` in pixels (used by
    ``gaussian`` only). ``ValueError`` naming the parameter and the allowed values."""
    from .._validate import check_choice, check_positive_float

    check_choice("rfilter", rfilter, RFILTERS)
    stddev = check_positive_float("rfilter stddev", stddev)
    return rfilter, stddev


def gaussian_filter(t, stddev: float = GAUSSIAN_STDDEV, *, tabulated: bool = True):
    """Mitsuba 3's windowed Gaussian at offsets ``t`` (pixels, NumPy float64): the 31-step table
    of its scalar variants (default), or with ``tabulated=False`` the exact
    ``max(0, exp(-t^2/(2 s^2)) - exp(-r^2/(2 s^2)))``, ``r = 4 s``."""
    t = np.abs(np.asarray(t, np.float64))
    r = 4.0 * stddev
    if tabulated:
        t = r * np.floor(t * (FILTER_RESOLUTION / r)) / FILTER_RESOLUTION
    alpha = -1.0 / (2.0 * stddev * stddev)
    return np.where(t < r, np.maximum(0.0, np.exp(alpha * t * t) - np.exp(alpha * r * r)), 0.0)


def _gaussian_table(stddev: float) -> tuple[np.ndarray, np.ndarray]:
    """Edges ``(-r ... r)`` of the 62 steps of the tabulated filter and its (unnormalized)
    CDF at them, exact in float64: the CDF is piecewise linear."""
    r = 4.0 * stddev
    half = r * np.arange(FILTER_RESOLUTION + 1) / FILTER_RESOLUTION
    edges = np.concatenate([-half[:0:-1], half])
    steps = gaussian_filter(0.5 * (edges[1:] + edges[:-1]), stddev)
    cdf = np.concatenate([[0.0], np.cumsum(steps * np.diff(edges))])
    return edges, cdf / cdf[-1]


def sample_gaussian_offset(u: Float[Array, "..."], lo: Float[Array, "..."],
                           hi: Float[Array, "..."], stddev: float = GAUSSIAN_STDDEV):
    """Offsets ``t`` in ``[lo, hi]`` (pixels, ``-4 s <= lo < hi <= 4 s``) with density
    proportional to :func:`gaussian_filter` (tabulated) restricted to ``[lo, hi]``: its inverse
    CDF at ``u`` in ``[0, 1)``."""
    edges, cdf = (jnp.asarray(a, jnp.float32) for a in _gaussian_table(stddev))
    c_lo = jnp.interp(lo, edges, cdf)
    c_hi = jnp.interp(hi, edges, cdf)
    return jnp.clip(jnp.interp(c_lo + u * (c_hi - c_lo), cdf, edges), lo, hi)


def film_offsets(rfilter: str, stddev: float, u: Float[Array, "n 2"], col, row, width: int,
                 height: int) -> Float[Array, "n 2"]:
    """Film positions, in pixel units from the image's top-left corner, of ``n`` samples of the
    pixel ``(col, row)`` from uniform ``u``: uniform in the pixel for ``box``; for ``gaussian``
    from the filter centred on the pixel and restricted to the film (Mitsuba samples no
    position outside it), separably per axis."""
    corner = jnp.stack([col, row]).astype(jnp.float32)
    if rfilter == "box":
        return corner[None, :] + u
    r = 4.0 * stddev
    centre = corner + 0.5
    size = jnp.asarray([width, height], jnp.float32)
    lo = jnp.maximum(-r, -centre)
    hi = jnp.minimum(r, size - centre)
    t = sample_gaussian_offset(u, jnp.broadcast_to(lo, u.shape), jnp.broadcast_to(hi, u.shape),
                               stddev)
    return jnp.clip(centre[None, :] + t, 0.0, size[None, :])

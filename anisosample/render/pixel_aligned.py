"""Per-pixel aligned rendering: every pixel its own directions, its estimation samples reused
(beyond W Sec. 5.3-5.4, the way W Sec. 7 points).

``render(scene, key, sampler="aligned-pixel")`` renders each pixel ``q`` in two passes over
one point set of ``spp`` points with one toroidal shift ``s_q`` (the pixel's, W Sec. 5.4):

1. **The prefix** (W Sec. 7: "the first few 16-64 points are always fixed and isotropically
   distributed so that we can use the samples for the principal direction estimation directly
   for the final Monte Carlo estimate"): the ``m`` points of the fixed isotropic prefix
   :func:`pixel_prefix` (``dihedral-<m>``, :mod:`anisosample.prefix`), shifted by ``s_q``, are
   rendered as the first ``m`` samples of the pixel's estimate. The same points drive
   :func:`anisosample.edges.search` on the pixel's own 2D integrand (its centre, luminance, no
   MIS): up to ``k`` spectral directions, strongest first, from the prefix's values plus the
   search's few dozen bisection samples. When the render's samples *are* that integrand
   (``pixel_center=True``, no MIS, no random lens), the prefix values are read, not
   re-evaluated. Pass 1 keeps, per pixel, the prefix's sum and whether the search has a
   candidate there; the search (on candidates only) evaluates their prefix values again, to
   the same bits, rather than any pass holding every pixel's ``m`` values. Each pixel's
   directions are then checked against its neighbours' (:func:`neighbour_consensus`, radius
   ``neighbours``, :data:`NEIGHBOURS`): a first direction its window does not confirm takes the
   window's consensus, an unconfirmed second one is dropped (the search's misses on integrands
   with several parallel edges; 0 keeps each pixel's own).
2. **The rest of the pixel's set**: the directions, rounded by
   :func:`anisosample.selection.table_directions`, pick the table set with the fixed prefix
   (one direction: the 3-direction set, two, a corner: the 4-direction set;
   :func:`anisosample.tables.lookup` with ``prefix``, whose first ``m`` points are the prefix bit
   for bit whatever the directions); points ``m .. spp - 1`` of it, shifted by the same
   ``s_q``, complete the estimate, the mean over all ``spp`` points.
   An edge whose direction rounds onto an axis takes the set one degree off that axis on its
   side (``axis_snap``, the default; W's rule drops it and the pixel takes pmj02bn): on W
   Fig. 8's attic at 256 spp, whose edges lie within about a degree of the axes, this moved the
   per-pixel sampler from 0.835 to 0.702 of pmj02bn's variance (probes apart: 0.838 to 0.631).
3. **A pixel without an edge** (lit, occluded, smooth) takes pmj02bn (``spp`` points, its own
   independent shift and stream counters ``m ..``): aligned sets are worse than pmj02bn on
   smooth integrands (measured on W Fig. 9's lit pixels at 4096: the prefix completed by a
   45-degree set 1.86x pmj02bn's variance), so the prefix enters with the fixed weight
   :func:`prefix_weight` ``= m^2 / (m^2 + spp^2)``, the inverse-variance weight of two
   stratified estimates converging as ``N^-2``.

The search's samples (and, on smooth pixels, the prefix beside pmj02bn's ``spp``) are the cost
beyond ``spp`` (``RenderResult.pixel_estimation_samples``); an edge pixel reuses the prefix's
``m`` samples whole.

**Probes apart** (``reuse=False``, W's accounting): the prefix only drives the search; an edge
pixel renders all ``spp`` points of the table's set *without* a prefix (the plain
:func:`anisosample.selection.aligned_sets`, so no point of it is constrained to be isotropic),
a pixel without an edge pmj02bn's ``spp`` points, both under the pixel's fallback shift (step 3)
on stream counters after the prefix's. The prefix is then estimation cost like W's per-block
probes. Exactly unbiased: the set's choice depends on the prefix's shift, the estimate's points
on an independent one. This separates what the pixel's own directions gain from what the fixed
prefix costs at a given ``spp``.
Unbiasedness: with a uniform shift every point of every set is uniform; the set's choice
depends on the shift only through the rounding of a direction estimated to a fraction of a
degree (and, through the consensus, on whether the pixel's own search agrees with its
neighbours, whose shifts are independent of its own), and the fallback's shift is independent
of the prefix's. The residual bias is tested against the closed form on a rounding boundary
(``tests/render/test_pixel_aligned.py``).
``RenderResult.pixel_directions`` holds each pixel's directions (NaN where none),
``pixel_sampler`` its choice (:data:`PIXEL_CODES` 3-5).
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import edges, selection
from .._validate import check_bool, check_int, check_positive_float
from ._kernel import kernel
from .integrator import pixel_samples, pixel_shift_key, sample_function
from .options import IntegratorOptions
from .scene import LUMINANCE, THINLENS, Scene

__all__ = ["AXIS_SNAP", "CONSENSUS_TOLERANCE_DEG", "FALLBACK", "NEAR_AXIS_DEG", "NEIGHBOURS",
           "PIXEL_SAMPLERS", "PixelEstimates", "SEARCH_CHUNK", "PixelSampler", "apart_chunk",
           "check_pixel_prefix", "choose_sets", "exact_values", "fallback_shift_key",
           "integrand_estimates", "neighbour_consensus",
           "pixel_prefix", "pixel_sampler", "pixel_sets", "prefix_chunk", "prefix_sets",
           "prefix_weight",
           "rest_chunk", "search_chunk", "toroidal_shift_key"]

PIXEL_SAMPLERS = ("aligned-pixel",)
"""Sampler names :func:`anisosample.render.render` resolves with a :class:`PixelSampler`."""

FALLBACK = selection.FALLBACK
"""The sampler of a pixel without an edge (module docstring, step 3):
:data:`anisosample.selection.FALLBACK`."""


NEAR_AXIS_DEG = 12.0
"""The per-pixel sampler's ``near_axis_deg`` (:func:`anisosample.selection.table_directions`):
with ``k = 1`` and two edges found, an edge within this many degrees of an axis yields to the
other. Measured on W Fig. 6's corner integrands (``integrands.edges``, variance over pmj02bn's,
4096 shifts, n = 256 / 1024), the 3-direction set for the edge near the axis against the set for
the other edge at 114 degrees: 2 degrees 0.65 / 0.63 against 0.43 / 0.41, 3: 0.60 / 0.57
against 0.49 / 0.48, 8: 0.65 / 0.56 against 0.55 / 0.48, 12: 0.57 / 0.50 against 0.49 / 0.47,
but 20: 0.45 / 0.47 against 0.52 / 0.53; (5, 60) 0.72 / 0.56 against 0.57 / 0.46, (92, 60)
0.72 / 0.54 against 0.37 / 0.38. So up to 12 degrees the set's axis line serves the near edge
well enough that the other edge's set gains more."""


AXIS_SNAP = True
"""The per-pixel sampler's ``axis_snap`` (:func:`anisosample.selection.table_directions`): an
edge whose direction rounds onto an axis takes the set one degree off it, not pmj02bn (module
docstring, step 2)."""


NEIGHBOURS = 2
"""The per-pixel sampler's ``neighbours``: the radius in pixels of the window over which
:func:`neighbour_consensus` checks each pixel's directions (0: each pixel keeps its own
search's). Measured on W Fig. 8's blinds windows (module docstring of
:func:`neighbour_consensus`)."""

CONSENSUS_TOLERANCE_DEG = 2.0
"""Two directions agree in :func:`neighbour_consensus` when they are at most this many degrees
apart (axially): several times the search's median error on one-edge pixels (0.07-0.09 degrees
on W Fig. 9's), less than the 3-4 degrees that a set keeps only part of its gain over."""


SEARCH_CHUNK = 256
"""Pixels per vmapped chunk of the render's edge search (:func:`search_chunk`), whatever the
``spp``: its cost is the search's arithmetic more than its samples. Cornell at 128^2 x 256 spp,
its 1,340 search pixels, ms per render (one device, load about 1): chunks of 64 / 128 / 256 /
512 / 1024 pixels 36 / 36 / 31 / 38 / 49."""

_STRIP = 32  # rows per strip of neighbour_consensus
_SPARSE_BELOW = 0.4  # below this fraction of pixels with a direction, a strip goes sparse


def _consensus_block(d, radius: int, tol: float, min_support: int, rel: float,
                     sparse: bool = False):
    """:func:`neighbour_consensus` on ``d`` ``(h, w, 2)`` (NaN: none), validated: the
    directions out ``(h, w, 2)`` float64. Arrays are kept as planes ``(slot, component, h, w)``
    so that every operation runs along image rows; ``sparse``: computed at the pixels with a
    first direction only (the others keep theirs: none), each from its window gathered by
    index, the same operations in the same order per pixel, so the same bits, at a cost that
    follows the pixels with directions rather than the image."""
    h, w, _ = d.shape
    r = radius
    # Axial directions as doubled-angle unit vectors (none: the zero vector): two agree within
    # tol exactly when their dot product is at least cos(2 tol); their mean is the axial mean.
    dd = np.moveaxis(d, -1, 0)  # (slot, h, w)
    found = np.isfinite(dd)
    phi = np.radians(2.0 * np.nan_to_num(dd))
    vec = np.where(found[:, None], np.stack([np.cos(phi), np.sin(phi)], 1), 0.0
                   ).astype(np.float32)  # (slot, component, h, w)
    cos2 = np.float32(np.cos(np.radians(2.0 * tol)))
    pad = np.pad(vec, ((0, 0), (0, 0), (r, r), (r, r)))
    offsets = [(dy, dx) for dy in range(-r, r + 1) for dx in range(-r, r + 1) if dy or dx]
    out = d.copy()
    if sparse:
        ys, xs = np.nonzero(found[0])
        if ys.size == 0:
            return out
        wp = w + 2 * r
        at = (ys + r) * wp + (xs + r)  # the pixels in the flat padded planes
        pad = pad.reshape(2, 2, -1)
        sel = (ys, xs)

        def window(a, dy, dx):
            return np.take(a, at + (dy * wp + dx), axis=-1)

        def padded(support):
            full = np.full((2, pad.shape[-1]), -1, np.int32)
            full[:, at] = support
            return full
    else:
        sel = (slice(None), slice(None))

        def window(a, dy, dx):
            return a[..., r + dy:r + dy + h, r + dx:r + dx + w]

        def padded(support):
            return np.pad(support, ((0, 0), (r, r), (r, r)), constant_values=-1)
    own = vec[(slice(None), slice(None), *sel)]
    fnd = found[(slice(None), *sel)]

    def agree(a, b):  # (component, ...) vectors; a zero vector agrees with nothing
        return a[0] * b[0] + a[1] * b[1] >= cos2

    support = np.zeros(fnd.shape, np.int32)
    for dy, dx in offsets:  # a loop over the window's offsets; each step is whole-image
        nb = window(pad, dy, dx)
        for j in range(2):
            support[j] += agree(own[j], nb[0])
            support[j] += agree(own[j], nb[1])
    support = np.where(fnd, support, -1)
    # the consensus: the window's best-supported direction (ties: the first in offset order)
    sup_pad = padded(support)
    best, best_vec = support[0].copy(), own[0].copy()
    for dy, dx in offsets:
        sp, nb = window(sup_pad, dy, dx), window(pad, dy, dx)
        for j in range(2):
            better = sp[j] > best
            best = np.where(better, sp[j], best)
            best_vec = np.where(better, nb[j], best_vec)
    # the consensus direction: the axial mean of the window's directions that agree with it;
    # its support in this pixel's window: the neighbours' directions that agree with it
    total = np.zeros((2, *fnd.shape[1:]), np.float32)
    backing = np.zeros(fnd.shape[1:], np.int32)
    for dy, dx in [(0, 0), *offsets]:
        nb = window(pad, dy, dx)
        for j in range(2):
            ok = agree(nb[j], best_vec)
            total += np.where(ok, nb[j], 0.0)
            if dy or dx:
                backing += ok
    mean = np.degrees(np.arctan2(total[1], total[0])) / 2.0 % 180.0
    confirmed = (support >= min_support) & (support >= rel * backing)
    swap = fnd[0] & ~confirmed[0] & (backing > min_support)
    out[(*sel, 0)] = np.where(swap, mean, d[(*sel, 0)])
    first = np.where(swap, best_vec, own[0])
    drop = ~confirmed[1] | agree(own[1], first)
    out[(*sel, 1)] = np.where(drop, np.nan, d[(*sel, 1)])
    return out


def neighbour_consensus(directions_deg, count, *, radius: int = NEIGHBOURS,
                        tolerance_deg: float = CONSENSUS_TOLERANCE_DEG,
                        min_support: int = 2, relative_support: float = 0.5):
    """Each pixel's directions checked against its neighbours' (beyond W; W Sec. 7: directions
    shared by "merging blocks with similar integrands", here per pixel).

    ``directions_deg`` ``(h, w, 2)`` (strongest first, NaN: none) and ``count`` ``(h, w)`` (how
    many of them the search found) are every pixel's own search result
    (:func:`anisosample.edges.search`). A direction's *support* in a pixel's
    ``(2 radius + 1)^2`` window is the number of the other pixels' directions there that agree
    with it within ``tolerance_deg``. Every pixel's window has a *consensus*: of the directions
    in it (the pixel's own included), the one with the most support in its own pixel's window.
    A pixel's direction is *confirmed* when its support is at least ``min_support`` and at
    least ``relative_support`` times the consensus' support in the same window (the same
    neighbours counted, so that a pixel at the border of an edge's band is judged like one
    inside it). Then, on every pixel with a direction:

    * a first direction that is not confirmed becomes the consensus (the axial mean of the
      window's directions that agree with it), where the consensus' support is more than
      ``min_support``; else it stays;
    * a second direction that is not confirmed, or that agrees with the (new) first, is dropped.

    Pixels without a direction keep none: a window's consensus adds no edge to a pixel whose
    own samples showed none. Why: an edge is a line across the image, so the pixels along it
    share its direction, while the search's misses are the pixel's own. On integrands with
    several parallel edges (blinds' slats) the search fits a line through points of two
    edges now and then: on one 32^2 window of W Fig. 8's blinds at 4096 spp, 16 shifts, 21 % of
    the pixels' first directions were more than 3 degrees from the slats' 135; after the
    consensus 0.04 % (radius 1: 0.5 %; radius 3: none). An earlier variant that confirmed a
    direction by an absolute count of 2 agreeing neighbours alone left 9 % at radius 2:
    spurious directions support each other in a larger window, hence the relative test.
    Returns ``(directions_deg, count)`` as float32 ``(h, w, 2)`` and int32 ``(h, w)``."""
    radius = check_int("radius", radius, minimum=0)
    tol = check_positive_float("tolerance_deg", tolerance_deg)
    if tol >= 90.0:
        raise ValueError(f"tolerance_deg must be below 90 degrees, got {tolerance_deg!r}")
    min_support = check_int("min_support", min_support, minimum=1)
    rel = check_positive_float("relative_support", relative_support, allow_zero=True)
    if rel > 1.0:
        raise ValueError(f"relative_support must be in [0, 1], got {relative_support!r}")
    dirs = np.asarray(directions_deg, np.float64)
    count = np.asarray(count)
    if dirs.ndim != 3 or dirs.shape[-1] != 2:
        raise ValueError(f"directions_deg must have shape (h, w, 2), got {dirs.shape}")
    if count.shape != dirs.shape[:2] or not np.issubdtype(count.dtype, np.integer):
        raise ValueError(f"count must be integers of shape {dirs.shape[:2]}, got "
                         f"{count.dtype} {count.shape}")
    d = np.where(np.arange(2) < np.clip(count, 0, 2)[..., None], dirs, np.nan)
    if radius == 0 or not np.isfinite(d).any():
        return d.astype(np.float32), np.isfinite(d).sum(-1).astype(np.int32)
    # In strips of rows, with the 2 radius rows each side that a strip's result depends on.
    # 1280^2 pixels, every one with an edge, best of 3 on the quiet 2-core machine: 1.07-1.17 s
    # in strips of 32 rows, 1.27-1.37 s whole-image; 7.9 s with the planes' axes last. A strip
    # whose pixels have few directions is computed at those pixels only (the same bits): 1280^2,
    # one run each, load about 1, whole-image planes / at the pixels with a direction, 8 % of
    # the pixels with one 1.2 / 0.57 s, 30 % 1.35 / 0.84 s, 60 % 1.5 / 1.75 s, all 1.2 / 2.5 s.
    h = d.shape[0]
    halo = 2 * radius
    out = np.empty_like(d)
    first = np.isfinite(d[..., 0])
    for y0 in range(0, h, _STRIP):
        lo, hi = max(0, y0 - halo), min(h, y0 + _STRIP + halo)
        part = _consensus_block(d[lo:hi], radius, tol, min_support, rel,
                                sparse=bool(first[lo:hi].mean() < _SPARSE_BELOW))
        out[y0:y0 + _STRIP] = part[y0 - lo:y0 - lo + min(_STRIP, h - y0)]
    return out.astype(np.float32), np.isfinite(out).sum(-1).astype(np.int32)


def prefix_weight(m: int, n: int) -> float:
    """The fixed weight of the ``m``-point prefix's mean beside an ``n``-point pmj02bn estimate
    on a pixel without an edge: ``m^2 / (m^2 + n^2)``, inverse-variance weights for two
    independent stratified estimates whose variance falls as ``N^-2`` (smooth integrands). A
    constant weight keeps the combination unbiased."""
    return m * m / (m * m + n * n)


def pixel_prefix(spp: int) -> str:
    """The prefix of a ``spp``-point pixel set: ``dihedral-<m>``,
    ``m = min(8 (spp // 32), 64, max(32, 8 (spp // 64)))``: a quarter of the set (the prefix
    sets' limit) up to 128 spp, 32 points from 128 to 319 spp, an eighth of the set (a multiple
    of 8) from 320 to 511, 64 from 512 (W Sec. 7's 16-64 points; 16 at 64 spp, the least the
    edge search needs). ``spp >= 64``.
    Measured on W Fig. 9's one-edge pixels (``experiments/beyond_pixel_prefix.py``, 2026-12-07,
    sets of the aligned-only design that the ``"rate"`` design takes below 1024 points): at
    256 spp 32 points were ahead of 64 in all three scenes (geometric mean of the variance over
    pmj02bn's: cornell 0.43 / 0.46, dof 0.40 / 0.42, pillars 0.42 / 0.47), at 512 spp level
    (within 0.01); 16 points were worse everywhere (the search found no direction in 17-32 % of
    the shifts). On the window of W Fig. 8 (256 spp, 16 keys, ad-hoc script) where each
    scene's pmj02bn variance is largest, the ratio to pmj02bn with 64 / 32 points: cornell
    0.406 / 0.389, blinds 0.316 / 0.301, attic 0.699 / 0.697, dof 0.557 / 0.534, pillars
    0.396 / 0.362. Sizes between 320 and 511 spp were not measured."""
    spp = check_int("spp", spp, minimum=64)
    return f"dihedral-{min(8 * (spp // 32), 64, max(32, 8 * (spp // 64)))}"


def check_pixel_prefix(prefix, spp: int) -> str:
    """``prefix`` for a ``spp``-point pixel set: ``None`` gives :func:`pixel_prefix`; else a
    ``"dihedral-<m>"`` name (:mod:`anisosample.prefix`; the table transforms map it onto
    itself) with ``16 <= m <= spp / 4`` (the edge search's least, the prefix sets' most)."""
    if prefix is None:
        return pixel_prefix(spp)
    from ..prefix import prefix_size

    prefix = _check_prefix_name(prefix)
    if not 16 <= prefix_size(prefix) <= spp // 4:
        raise ValueError(f"prefix must be None or 'dihedral-<m>' with m a multiple of 8 from 16 "
                         f"to spp / 4 = {spp // 4}; got {prefix!r}")
    return prefix


def _check_prefix_name(prefix) -> str | None:
    """``prefix`` before the render's ``spp`` is known: ``None`` or a ``"dihedral-<m>"`` name
    (its size is checked against ``spp`` by :func:`check_pixel_prefix` when the render starts)."""
    if prefix is None:
        return None
    from ..prefix import check_prefix

    prefix = check_prefix("prefix", prefix)
    if not prefix.startswith("dihedral-"):
        raise ValueError(f"prefix must be None or 'dihedral-<m>', got {prefix!r}")
    return prefix


@dataclasses.dataclass(frozen=True, eq=False)
class PixelSampler:
    """The per-pixel aligned sampler (module docstring), made by :func:`pixel_sampler` and
    passed as ``render(sampler=...)``: the options of the search and of the table lookup;
    everything per pixel is decided during the render."""

    width: int
    height: int
    k: int = 2
    search: edges.SearchOptions = edges.SearchOptions()
    table: object = None
    build_missing: bool | None = None
    build_options: dict = dataclasses.field(default_factory=dict)
    near_axis_deg: float = NEAR_AXIS_DEG
    reuse: bool = True
    axis_snap: bool = AXIS_SNAP
    neighbours: int = NEIGHBOURS
    prefix: str | None = None

    name = "aligned-pixel"

    def prefix_for(self, spp: int) -> str:
        """The prefix of this sampler's ``spp``-point sets (:func:`check_pixel_prefix`:
        :func:`pixel_prefix` unless the sampler names one)."""
        return check_pixel_prefix(self.prefix, spp)

    def sets(self, requests, spp: int, *, progress: bool = True) -> np.ndarray:
        """The sets for ``requests`` with this sampler's table options, on the host
        (:func:`pixel_sets`)."""
        return pixel_sets(requests, spp, reuse=self.reuse, prefix=self.prefix_for(spp),
                          table=self.table, build_missing=self.build_missing,
                          build_options=self.build_options, progress=progress)

    def settings(self) -> dict:
        """What a render records about the sampler (EXR metadata); the render adds the counts."""
        return dict(point_set="aligned-pixel", k=self.k, fallback=FALLBACK,
                    near_axis_deg=self.near_axis_deg, reuse=self.reuse,
                    axis_snap=self.axis_snap, neighbours=self.neighbours, prefix=self.prefix,
                    search=self.search._asdict())


def prefix_sets(requests, spp: int, *, table=None, build_missing: bool | None = None,
                build_options: dict | None = None, progress: bool = True,
                prefix: str | None = None) -> np.ndarray:
    """The sets with the prefix ``prefix`` (:func:`check_pixel_prefix`; default
    :func:`pixel_prefix`) for ``requests`` (tuples of integer extra directions), stacked
    ``(len(requests), spp, 2)``, each starting with the prefix bit for bit:
    :func:`anisosample.selection.aligned_sets` with the prefix (missing sets built first,
    :func:`anisosample.tables.ensure`, with a progress bar over the sets; then the pure
    lookup), on the host: the render pads them there before one transfer."""
    return selection.aligned_sets(requests, spp, table=table, build_missing=build_missing,
                                  prefix=check_pixel_prefix(prefix, spp), progress=progress,
                                  desc=f"pixel sets n={spp}", as_numpy=True,
                                  **(build_options or {}))


def pixel_sets(requests, spp: int, *, reuse: bool, prefix: str | None = None, table=None,
               build_missing: bool | None = None, build_options: dict | None = None,
               progress: bool = True) -> np.ndarray:
    """The edge pixels' sets for ``requests`` on the host: with ``reuse`` the sets that start
    with the prefix (:func:`prefix_sets`), else (probes apart) the plain table sets, no
    prefix."""
    if reuse:
        return prefix_sets(requests, spp, table=table, build_missing=build_missing,
                           build_options=build_options, progress=progress, prefix=prefix)
    return selection.aligned_sets(requests, spp, table=table, build_missing=build_missing,
                                  progress=progress, desc=f"pixel sets n={spp}", as_numpy=True,
                                  **(build_options or {}))


class PixelEstimates(eqx.Module):
    """:func:`integrand_estimates`: per realization the estimate, the directions found
    ``(R, 2)`` (NaN: none), the search's samples and the choice (:data:`PIXEL_CODES` 3-5)."""

    estimates: np.ndarray
    directions_deg: np.ndarray
    search_samples: np.ndarray
    code: np.ndarray


def integrand_estimates(f, n: int, key, realizations: int, *, k: int = 2, table=None,
                        build_missing: bool | None = None, build_options: dict | None = None,
                        prefix: str | None = None, near_axis_deg: float = NEAR_AXIS_DEG,
                        reuse: bool = True, axis_snap: bool = AXIS_SNAP,
                        **search) -> PixelEstimates:
    """The per-pixel aligned estimator of one 2D integrand ``f`` (the renderer's two passes at
    the level of :func:`anisosample.variance.realization_estimates`): per realization one
    toroidal shift from ``key``, the prefix's values, :func:`anisosample.edges.search`, the set
    (:func:`choose_sets`, :func:`prefix_sets`) and the mean of ``f`` over all ``n`` points,
    the prefix's included. ``prefix``: :func:`check_pixel_prefix` (the renderer's
    :func:`pixel_prefix` by default; another size is for studying the choice). ``reuse=False``:
    probes apart (module docstring), the plain set or pmj02bn under an independent shift."""
    from ..prefix import prefix_points
    from ..samplers import toroidal_shift

    n = check_int("n", n, minimum=64)
    realizations = check_int("realizations", realizations, minimum=1)
    k = check_int("k", k, minimum=1, maximum=2)
    near_axis_deg = selection.check_near_axis(near_axis_deg)
    reuse = check_bool("reuse", reuse)
    o = edges.search_options(**search)
    name = check_pixel_prefix(prefix, n)
    prefix = jnp.asarray(prefix_points(name), jnp.float32)
    m = prefix.shape[0]
    keys = jax.random.split(key, realizations)
    x = jax.vmap(toroidal_shift, in_axes=(0, None))(keys, prefix)
    head = f(x)
    r = jax.vmap(lambda xx, vv: edges.search(f, xx, vv, o))(x, head)
    requests, index, code = choose_sets(r.directions_deg, r.count, k, near_axis_deg, axis_snap)
    head = np.asarray(jnp.sum(head, axis=1), np.float64)
    est = np.empty(realizations, np.float64)
    edge = index >= 0
    own = jax.vmap(lambda kk: jax.random.fold_in(kk, 1))(keys)  # the fallback's shifts
    if edge.any():
        sets = pixel_sets(requests, n, reuse=reuse, prefix=name, table=table,
                          build_missing=build_missing, build_options=build_options,
                          progress=False)[jnp.asarray(index[edge])]
        if reuse:
            rest = jax.vmap(toroidal_shift)(keys[edge], sets[:, m:])
            est[edge] = (head[edge] + np.asarray(jnp.sum(f(rest), axis=1), np.float64)) / n
        else:
            pts = jax.vmap(toroidal_shift)(own[edge], sets)
            est[edge] = np.asarray(jnp.mean(f(pts), axis=1), np.float64)
    if (~edge).any():
        from ..samplers import get

        base = jnp.asarray(get(FALLBACK)(jax.random.fold_in(key, 1), n), jnp.float32)
        pts = jax.vmap(toroidal_shift, in_axes=(0, None))(own[~edge], base)
        w = prefix_weight(m, n) if reuse else 0.0
        est[~edge] = (w * head[~edge] / m
                      + (1 - w) * np.asarray(jnp.mean(f(pts), axis=1), np.float64))
    return PixelEstimates(est, np.asarray(r.directions_deg), np.asarray(r.samples), code)


def pixel_sampler(scene: Scene, *, k: int = 2, table=None, build_missing: bool | None = None,
                  build_options: dict | None = None, near_axis_deg: float = NEAR_AXIS_DEG,
                  reuse: bool = True, axis_snap: bool = AXIS_SNAP, neighbours: int = NEIGHBOURS,
                  prefix: str | None = None, **search) -> PixelSampler:
    """The per-pixel aligned sampler for ``scene``: at most ``k`` (1 or 2) directions per pixel,
    directions within ``near_axis_deg`` of an axis after the others (:data:`NEAR_AXIS_DEG`;
    0: W's rule, strongest first); ``search``: :class:`anisosample.edges.SearchOptions`
    fields; ``table``, ``build_missing``, ``build_options``: the prefix sets' lookup
    (:func:`anisosample.tables.lookup`: missing sets are built into the user cache unless
    ``build_missing=False``); ``reuse``: the prefix's samples in the estimate (True) or probes
    apart (False, module docstring); ``axis_snap``: an edge whose direction rounds onto an axis
    takes the set one degree off it on its side (:func:`anisosample.selection.table_directions`)
    instead of pmj02bn; ``neighbours``: the radius of :func:`neighbour_consensus`'s window
    (:data:`NEIGHBOURS`; 0: every pixel keeps its own search's directions); ``prefix``: the
    sets' fixed prefix, ``"dihedral-<m>"`` (:func:`check_pixel_prefix`, checked against the
    render's ``spp``; ``None``: :func:`pixel_prefix`'s rule)."""
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be an anisosample.render.Scene, got {type(scene).__name__}")
    k = check_int("k", k, minimum=1, maximum=2)
    if build_missing is not None and not isinstance(build_missing, bool):
        raise TypeError(f"build_missing must be None, True or False, got {build_missing!r}")
    if build_options is not None and not isinstance(build_options, dict):
        raise TypeError(f"build_options must be a dict, got {type(build_options).__name__}")
    return PixelSampler(scene.width, scene.height, k, edges.search_options(**search), table,
                        build_missing, dict(build_options or {}),
                        selection.check_near_axis(near_axis_deg), check_bool("reuse", reuse),
                        check_bool("axis_snap", axis_snap),
                        check_int("neighbours", neighbours, minimum=0, maximum=16),
                        _check_prefix_name(prefix))


def exact_values(scene: Scene, options: IntegratorOptions) -> bool:
    """Whether a pixel's render samples (``options`` resolved) are values of its 2D integrand
    (pixel centre, no MIS, no random lens), so the search reads the prefix's samples instead of
    re-evaluating them."""
    lens_random = options.dimension == "light" and scene.camera.projection == THINLENS
    return options.pixel_center and not options.mis and not lens_random


_STATIC = ("spp", "options", "search")


def _pixel_integrand(scene: Scene, options: IntegratorOptions, q):
    """Pixel ``q``'s 2D integrand ``f_q`` (W Eq. 8) as the search samples it: the pixel's
    centre, the lens centre, luminance, no MIS."""
    g0 = sample_function(scene, options.replace(mis=False))
    lum = jnp.asarray(LUMINANCE, jnp.float32)
    w, h = scene.width, scene.height
    centre = jnp.stack([(q % w).astype(jnp.float32) + 0.5,
                        (q // w).astype(jnp.float32) + 0.5]) / jnp.asarray([w, h], jnp.float32)

    def f(y):
        flat = y.reshape(-1, 2)
        half = jnp.full_like(flat, 0.5)
        film = jnp.broadcast_to(centre, flat.shape)
        return (jax.vmap(g0)(flat, film, half, half) @ lum).reshape(y.shape[:-1])

    return f


def _over(one, pixels):
    if pixels.ndim == 1:
        return jax.vmap(one)(pixels)
    return jax.lax.map(jax.vmap(one), pixels)


def _prefix_samples(scene: Scene, g, options: IntegratorOptions, key, q, x, spp: int):
    """Pixel ``q``'s first ``m`` samples at its shifted prefix ``x`` ``(m, 3)`` and its
    integrand's values there ``(m,)`` (read from the samples where :func:`exact_values`): one
    formula for pass 1 and the search, so that both see the same bits."""
    rgb = pixel_samples(scene, g, x, key, q, spp, 0, options)
    if exact_values(scene, options):
        return rgb, rgb @ jnp.asarray(LUMINANCE, jnp.float32)
    return rgb, _pixel_integrand(scene, options, q)(x)


@kernel(static_argnames=_STATIC)
def prefix_chunk(scene: Scene, prefix, key, pixels, *, spp, options: IntegratorOptions,
                 search: edges.SearchOptions):
    """Pass 1 for ``pixels`` (``options``: the render's, resolved): the sum of each pixel's
    first ``m`` samples ``(..., 3)`` and whether the edge search has a candidate there
    (:func:`anisosample.edges.candidate` on the integrand's values at the prefix; where not,
    the search would find nothing and take no sample, so :func:`search_chunk` runs only where
    it has). The values stay on the device: :func:`search_chunk` evaluates them again for the
    candidates only."""
    g = sample_function(scene, options)

    def one(q):
        x = toroidal_shift_key(key, q, prefix)
        rgb, values = _prefix_samples(scene, g, options, key, q, x, spp)
        return jnp.sum(rgb, axis=0), edges.candidate(x, values, search)

    return _over(one, pixels)


@kernel(static_argnames=_STATIC)
def search_chunk(scene: Scene, prefix, key, pixels, *, spp, options: IntegratorOptions,
                 search: edges.SearchOptions):
    """The edge search of pixels with a candidate (:func:`prefix_chunk`), each from its
    integrand's values at its prefix, evaluated here again (the same bits as pass 1's), so that
    no pass holds every pixel's ``m`` values: its directions ``(..., 2)`` (NaN: none), its edge
    count and the search's samples."""
    g = sample_function(scene, options)

    def one(q):
        x = toroidal_shift_key(key, q, prefix)
        _, values = _prefix_samples(scene, g, options, key, q, x, spp)
        r = edges.search(_pixel_integrand(scene, options, q), x, values, search)
        return r.directions_deg, r.count, r.samples

    return _over(one, pixels)


def toroidal_shift_key(key, q, points):
    """``points`` under pixel ``q``'s toroidal shift (the same for its prefix and its rest)."""
    from ..samplers import toroidal_shift

    return toroidal_shift(pixel_shift_key(key, q), points)


@kernel(static_argnames=_STATIC[:-1])
def rest_chunk(scene: Scene, rests, pixel_set, key, pixels, *, spp,
               options: IntegratorOptions):
    """Pass 2 for ``pixels``: the sum of samples ``m .. spp - 1`` ``(..., 3)``, pixel ``q``
    taking ``rests[pixel_set[q]]`` (its set without the prefix) under its shift."""
    g = sample_function(scene, options)
    m = spp - rests.shape[1]

    def one(q):
        x = toroidal_shift_key(key, q, rests[pixel_set[q]])
        rgb = pixel_samples(scene, g, x, key, q, spp, m, options)
        return jnp.sum(rgb, axis=0)

    return _over(one, pixels)


def fallback_shift_key(key, q):
    """The key of pixel ``q``'s shift of the fallback set: independent of its prefix's."""
    return jax.random.fold_in(pixel_shift_key(key, q), 1)


@kernel(static_argnames=(*_STATIC[:-1], "m"))
def apart_chunk(scene: Scene, sets, pixel_set, key, pixels, *, spp, m,
                options: IntegratorOptions):
    """Pass 2 apart from the prefix: the mean ``(..., 3)`` over the ``spp`` points of
    ``sets[pixel_set[q]]`` under pixel ``q``'s own fallback shift, on stream counters
    ``m .. m + spp - 1`` (after the prefix's): pmj02bn on pixels without an edge (``sets`` its
    one set), and with probes apart the edge pixels' plain sets."""
    from ..samplers import toroidal_shift

    g = sample_function(scene, options)

    def one(q):
        x = toroidal_shift(fallback_shift_key(key, q), sets[pixel_set[q]])
        rgb = pixel_samples(scene, g, x, key, q, spp + m, m, options)
        return jnp.mean(rgb, axis=0)

    return _over(one, pixels)


def choose_sets(directions_deg, count, k: int, near_axis_deg: float = 0.0,
                axis_snap: bool = False) -> tuple[list, np.ndarray, np.ndarray]:
    """Per pixel, W Sec. 5.4's table request from its directions (``near_axis_deg``,
    ``axis_snap``: :func:`anisosample.selection.table_directions`): ``(requests, index, code)``
    with ``index`` each pixel's request (-1: none) and ``code`` its
    :data:`~anisosample.render.aligned.PIXEL_CODES` (3: a 3-direction set, 4: a 4-direction
    set, 5: no direction off the axes, the fallback)."""
    dirs = np.asarray(directions_deg, np.float64).reshape(-1, 2)
    count = np.asarray(count).reshape(-1)
    found = np.flatnonzero(count > 0)  # the pixels without a direction take no request
    own = np.where(np.arange(2) < count[found, None], dirs[found], np.nan)
    requests, sub = selection.table_requests(own, k, near_axis_deg=near_axis_deg,
                                             axis_snap=axis_snap)
    index = np.full(count.size, -1, np.int32)
    index[found] = sub
    sizes = np.asarray([len(r) + 2 for r in requests] + [5], np.int8)
    return requests, index, sizes[index].astype(np.int8)

"""Per-integrand edge search: the spectral directions of one discontinuous 2D integrand from a
few dozen samples (beyond W Sec. 5.3; W Sec. 7 asks for directions per integrand).

W estimates the principal directions of a *block* of pixels from a Sobel orientation histogram
over a shared grid (W Sec. 5.3, :mod:`anisosample.directions`); an aligned set keeps its rate
only within about a degree of the integrand's true direction, and a block's pooled direction
misses single pixels by more than that. This module finds one integrand's own edges from the
samples a renderer has already taken (the fixed isotropic prefix of W Sec. 7,
:mod:`anisosample.prefix`) plus a few dozen more, by locating the discontinuity itself:

1. **Is there an edge?** A full cubic polynomial in ``(x, y)`` is fitted by least squares to the
   given values; if no residual exceeds ``smooth_residual`` times the values' range, the
   integrand is taken as smooth (lit, occluded, a horizon crossing) and the search costs
   nothing.
2. **Bracket it.** The ``max_pairs`` pairs of neighbouring points (each point's ``neighbours``
   nearest) with the largest value difference, at least ``jump_fraction`` of the range, are
   bisected ``steps`` times each: the half whose ends differ more keeps the jump. A step
   survives bisection (the difference of the final bracket stays at least ``persist`` times the
   first); a smooth slope halves with every step and is dropped. The largest jump goes first:
   if it does not survive, the integrand is taken as smooth (a peaked smooth integrand, which
   the cubic does not explain, costs ``steps`` samples).
3. **Fit lines.** The located jump points are fitted by total least squares; if their rms
   distance from one line exceeds ``tolerance``, the best line through two of them (most
   inliers) is taken first and a second line fitted to the rest (a corner).
4. **Walk along each line.** ``walk`` short segments of half-width :data:`WIDTH` across each
   tentative line, spread over its extent inside the unit square, are bisected like the pairs:
   jump points far apart along the edge fix its angle far better than the prefix's close
   neighbours. Each line is refitted to its inliers.

The spectral direction of a line is its normal (DESIGN: an edge running at ``theta + 90``
degrees puts its energy along ``theta``); two lines closer than ``min_angle_deg`` are one.
Everything has fixed shapes, so :func:`edge_search` jits and vmaps over integrands (pixels).
The samples it reports are those a sequential implementation would take: none on a smooth
integrand, ``steps`` on one whose largest jump is a slope, else ``steps`` per bracketed pair and
``walk * (steps + 2)`` per tentative line.
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from ._validate import check_int, check_points, check_positive_float

__all__ = ["EdgeSearch", "SearchOptions", "candidate", "search_options", "search",
           "edge_search", "neighbour_pairs", "CANDIDATE_MARGIN", "WIDTH"]

WIDTH = 0.03
"""Half-width of a walk's segment across a tentative line, in units of the square: the line's
error at the walk positions must stay below it (measured: about 0.005 after the pairs)."""


class SearchOptions(NamedTuple):
    """The search's settings (:func:`search_options` validates them; hashable, static under
    ``jit``)."""

    max_pairs: int = 12
    steps: int = 4
    walk: int = 4
    neighbours: int = 4
    jump_fraction: float = 0.1
    persist: float = 0.6
    smooth_residual: float = 0.1
    tolerance: float = 0.01
    min_points: int = 3
    min_angle_deg: float = 10.0


def search_options(**options) -> SearchOptions:
    """A validated :class:`SearchOptions` from keywords (unknown names refused)."""
    unknown = set(options) - set(SearchOptions._fields)
    if unknown:
        raise TypeError(f"unknown edge-search option(s) {sorted(unknown)}; allowed: "
                        f"{list(SearchOptions._fields)}")
    o = SearchOptions(**options)
    ints = dict(max_pairs=(o.max_pairs, 2, 64), steps=(o.steps, 1, 16), walk=(o.walk, 0, 32),
                neighbours=(o.neighbours, 1, 16), min_points=(o.min_points, 2, 64))
    vals = {k: check_int(k, v, minimum=lo, maximum=hi) for k, (v, lo, hi) in ints.items()}
    floats = {}
    for k, hi in (("jump_fraction", 1.0), ("persist", 1.0), ("smooth_residual", 1.0),
                  ("tolerance", 0.5), ("min_angle_deg", 90.0)):
        v = check_positive_float(k, getattr(o, k))
        if v > hi:
            raise ValueError(f"{k} must be at most {hi}, got {v}")
        floats[k] = v
    return SearchOptions(**vals, **floats)


class EdgeSearch(eqx.Module):
    """One integrand's edges (:func:`edge_search`; leading axes when vmapped).

    ``directions_deg``: ``(2,)`` spectral directions in ``[0, 180)``, strongest first, NaN where
    no edge; ``count``: edges found (0, 1, 2); ``samples``: integrand samples the search took
    beyond the given values; ``points``: the located jump points ``(P, 2)``; ``line``: each
    point's line (0, 1; -1: unused or outlier).
    """

    directions_deg: Float[Array, "2"]
    count: Int[Array, ""]
    samples: Int[Array, ""]
    points: Float[Array, "P 2"]
    line: Int[Array, " P"]


def neighbour_pairs(points, neighbours: int = 4) -> tuple[Array, Array, Array]:
    """Each point's ``neighbours`` nearest (Euclidean, not toroidal: a segment between them
    must not wrap around the integrand's domain): ``(i, j, keep)`` over ``m * neighbours``
    directed pairs, ``keep`` false on the second copy of a pair both ends list."""
    p = jnp.asarray(points, jnp.float32)
    m = p.shape[0]
    x, y = p[:, 0], p[:, 1]
    # the two squares added by hand: XLA:CPU vectorises this about 3x better than a sum over a
    # trailing axis of 2 (same bits)
    d2 = (x[:, None] - x[None, :]) ** 2 + (y[:, None] - y[None, :]) ** 2
    d2 = d2 + jnp.where(jnp.eye(m, dtype=bool), jnp.inf, 0.0)
    knn = _nearest(d2, neighbours)
    i = jnp.repeat(jnp.arange(m), neighbours)
    j = knn.reshape(-1)
    mutual = jnp.any(knn[j] == i[:, None], axis=1)
    return i, j, (i < j) | ~mutual


def _nearest(d2, k: int):
    """Per row of the symmetric ``d2`` ``(m, m)``, the columns of its ``k`` smallest entries,
    smallest first, ties to the lower column: ``lax.top_k(-d2, k)``'s indices, the same bits.
    Taken as ``k`` rounds of a minimum and the first index holding it, each over the leading
    axis (``d2`` is symmetric bit for bit: ``(a - b)^2 == (b - a)^2``), so that XLA:CPU
    vectorises every reduction along the contiguous axis; ``top_k`` is a custom call that sorts
    one row at a time, and the same rounds over the trailing axis become windowed reductions.
    The per-pixel sampler's search kernel on 4,096 of pillars' search pixels (128^2, 256 spp),
    best of 5, three alternating runs each (2026-12-07, load 0.5-1.9): ``top_k`` 136-188 ms,
    rounds over the trailing axis 117-149, over the leading axis 85-88. (A running best-4
    insertion over the columns, unrolled, ran in a fifth of the time but compiled in 22 s and
    did not give top_k's bits on 1,024 pixels.)"""
    m = d2.shape[-1]
    index = jnp.arange(m, dtype=jnp.int32)[:, None]
    picks = []
    for _ in range(k):
        low = jnp.min(d2, axis=-2, keepdims=True)
        first = jnp.min(jnp.where(d2 == low, index, m), axis=-2)
        picks.append(first)
        d2 = jnp.where(index == first[None, :], jnp.inf, d2)
    return jnp.stack(picks, axis=-1)


def _bisect(f, a, b, fa, fb, steps: int):
    """``steps`` bisections of each segment ``a -> b`` keeping the half whose ends differ more;
    returns the final bracket's midpoint and its end difference."""

    def step(carry, _):
        a, b, fa, fb = carry
        mid = 0.5 * (a + b)
        fm = f(mid)
        left = jnp.abs(fm - fa) >= jnp.abs(fb - fm)
        a = jnp.where(left[:, None], a, mid)
        fa = jnp.where(left, fa, fm)
        b = jnp.where(left[:, None], mid, b)
        fb = jnp.where(left, fm, fb)
        return (a, b, fa, fb), None

    (a, b, fa, fb), _ = jax.lax.scan(step, (a, b, fa, fb), None, length=steps)
    return 0.5 * (a + b), jnp.abs(fb - fa)


def _tls(p, w):
    """Weighted total-least-squares line: centroid, unit direction, rms distance."""
    tot = jnp.maximum(jnp.sum(w), 1e-12)
    c = jnp.sum(w[:, None] * p, axis=0) / tot
    q = p - c[None, :]
    cov = jnp.einsum("k,ki,kj->ij", w, q, q) / tot
    evals, evecs = jnp.linalg.eigh(cov)
    return c, evecs[:, 1], jnp.sqrt(jnp.maximum(evals[0], 0.0))


def _distance(p, c, e):
    q = p - c[None, :]
    return jnp.abs(q[:, 0] * e[1] - q[:, 1] * e[0])


def _best_line(p, ok, tol):
    """The line through two of the points ``ok`` with the most inliers within ``tol``,
    refitted by TLS to them: ``(c, e, inliers)``."""
    n = p.shape[0]
    ii, jj = jnp.triu_indices(n, 1)
    e = p[jj] - p[ii]
    e = e / jnp.maximum(jnp.linalg.norm(e, axis=1, keepdims=True), 1e-12)
    dist = jax.vmap(lambda c, d: _distance(p, c, d))(p[ii], e)  # (proposals, n)
    inl = (dist < tol) & ok[None, :]
    score = (jnp.sum(inl, axis=1).astype(jnp.float32)
             - jnp.sum(jnp.where(inl, dist, 0.0), axis=1) / (n * tol))
    score = jnp.where(ok[ii] & ok[jj], score, -1.0)
    best = jnp.argmax(score)
    c, d, _ = _tls(p, inl[best].astype(jnp.float32))
    return c, d, ok & (_distance(p, c, d) < tol)


def _extent(c, e):
    """Parameter interval ``[lo, hi]`` of the line ``c + t e`` inside the unit square."""
    safe = jnp.where(jnp.abs(e) < 1e-6, 1e-6, e)
    t0, t1 = (0.0 - c) / safe, (1.0 - c) / safe
    return jnp.max(jnp.minimum(t0, t1)), jnp.min(jnp.maximum(t0, t1))


def _axial_deg(normal):
    return jnp.mod(jnp.degrees(jnp.arctan2(normal[1], normal[0])), 180.0)


def _cubic_basis(p) -> list:
    """The ten monomials ``x^a y^b`` (``a + b <= 3``) of the centred coordinates at ``p``
    ``(m, 2)``, each an ``(m,)`` column."""
    x, y = p[:, 0] - 0.5, p[:, 1] - 0.5
    return [x**a * y**b for a in range(4) for b in range(4 - a)]


def _cubic_residual(p, v):
    """The largest absolute residual of the least-squares cubic in ``(x, y)`` through the
    values ``v`` ``(m,)`` at ``p`` ``(m, 2)``.

    The residual is ``v`` with its projection onto each basis column removed in turn, the
    columns orthonormalized by modified Gram-Schmidt (Golub & Van Loan, Sec. 5.2.8), written
    out column by column: under ``vmap`` every step is a vector operation over pixels, where a
    batched LAPACK QR (``geqrf``) or SVD runs one small matrix at a time. Measured on the
    shifted 64-point prefixes of the 16,384 pixels of cornell, dof and pillars at 128^2 (one
    device, ad-hoc script, load about 1), the largest residual against float64 least squares,
    relative to the values' range, and the time of all pixels' fits: Gram-Schmidt 1.6e-6 /
    5.1e-4 / 1.2e-6 in 37-50 ms; Householder QR 4.9e-6 / 1.6e-3 / 5.5e-6 in 101-120 ms; SVD
    least squares 7.1e-6 / 1.6e-3 / 5.5e-6 in 256-271 ms; the normal equations by Cholesky
    8.2e-6 / 1.3e-3 / 6.5e-6 in 67-91 ms. (The cubic basis on a shifted prefix is well
    conditioned, condition number <= 77, so one Gram-Schmidt pass suffices.)"""
    r = v
    done = []
    for a in _cubic_basis(p):
        for q in done:
            a = a - jnp.sum(q * a) * q
        a = a * jax.lax.rsqrt(jnp.maximum(jnp.sum(a * a), 1e-30))
        r = r - jnp.sum(a * r) * a
        done.append(a)
    return jnp.max(jnp.abs(r))


def _rough(p, v, threshold):
    """Step 1: the values' range, and whether the largest residual of the least-squares cubic
    in ``(x, y)`` (:func:`_cubic_residual`) exceeds ``threshold`` times it."""
    span = jnp.max(v) - jnp.min(v)
    return span, (span > 0) & (_cubic_residual(p, v) > threshold * span)


CANDIDATE_MARGIN = 0.95
""":func:`candidate` flags residuals above this fraction of :func:`search`'s threshold."""


def candidate(points, values, o: SearchOptions):
    """Whether :func:`search` may look for an edge: the cubic's residual (step 1, the same fit)
    exceeds :data:`CANDIDATE_MARGIN` of the search's threshold. Where this is false,
    :func:`search` returns no direction, ``count`` 0 and ``samples`` 0 without sampling ``f``,
    so a renderer runs it only where it is true. The margin below 1 only absorbs float32
    rounding between two compilations of the same fit (a renderer's pass 1 and its search):
    0.05 of the threshold is 0.005 of the values' range at the default ``smooth_residual``, ten
    times the fit's largest error against float64 measured on rendered pixels
    (:func:`_cubic_residual`). On those pixels 0.8 instead of 0.95 flags 3 % more (cornell
    1382 / 1342, dof 1229 / 1223, pillars 4856 / 4850; the search's own test flags 1339 / 1223
    / 4850). A bool; vmaps like :func:`search`."""
    return _rough(jnp.asarray(points, jnp.float32), jnp.asarray(values, jnp.float32),
                  CANDIDATE_MARGIN * o.smooth_residual)[1]


@eqx.filter_jit
def search(f, points, values, o: SearchOptions) -> EdgeSearch:
    """The search's core (module docstring), unvalidated: ``points`` ``(m, 2)`` float32,
    ``values`` ``(m,)``, ``o`` from :func:`search_options`. Pure and shape-fixed: vmap it over
    integrands (an ``eqx.Module`` batch) or call it inside a renderer's kernel."""
    p = jnp.asarray(points, jnp.float32)
    v = jnp.asarray(values, jnp.float32)
    # 1. A cubic in (x, y) explains a smooth integrand.
    span, rough = _rough(p, v, o.smooth_residual)
    # 2. The pairs with the largest jumps, bisected.
    i, j, keep = neighbour_pairs(p, o.neighbours)
    diff = jnp.where(keep, jnp.abs(v[i] - v[j]), -1.0)
    d0, pick = jax.lax.top_k(diff, o.max_pairs)
    bracketed = rough & (d0 >= o.jump_fraction * span)
    pts, d_end = _bisect(f, p[i[pick]], p[j[pick]], v[i[pick]], v[j[pick]], o.steps)
    # The largest jump is bisected first: if it is a smooth slope, the search stops there.
    found = bracketed & (d_end >= o.persist * d0)
    first = found[0]
    found = found & first
    # 3. One line, or the best line and a second through the rest (a corner).
    c1, e1, rms = _tls(pts, found.astype(jnp.float32))
    one = (jnp.sum(found) >= o.min_points) & (rms <= o.tolerance)
    b1c, b1e, in1 = _best_line(pts, found, o.tolerance)
    c1 = jnp.where(one, c1, b1c)
    e1 = jnp.where(one, e1, b1e)
    in1 = jnp.where(one, found, in1)
    b2c, b2e, in2 = _best_line(pts, found & ~in1, o.tolerance)
    tentative = jnp.stack([jnp.sum(in1) >= 2, ~one & (jnp.sum(in2) >= 2)])
    cs, es = jnp.stack([c1, b2c]), jnp.stack([e1, b2e])
    # 4. Walk along each tentative line.
    if o.walk:
        def across(c, e):
            lo, hi = _extent(c, e)
            frac = (jnp.arange(o.walk, dtype=jnp.float32) + 0.5) / o.walk
            t = lo + (hi - lo) * (0.05 + 0.9 * frac)
            q = c[None, :] + t[:, None] * e[None, :]  # walk positions on the line
            nrm = jnp.stack([-e[1], e[0]])
            nrm = WIDTH * nrm[None, :]
            return jnp.clip(q - nrm, 0.0, 1.0), jnp.clip(q + nrm, 0.0, 1.0)

        a, b = jax.vmap(across)(cs, es)
        a, b = a.reshape(-1, 2), b.reshape(-1, 2)
        fa, fb = f(a), f(b)
        w0 = jnp.abs(fb - fa)
        wpts, w_end = _bisect(f, a, b, fa, fb, o.steps)
        wfound = (jnp.repeat(tentative, o.walk) & (w0 >= o.jump_fraction * span)
                  & (w_end >= o.persist * w0))
        pts = jnp.concatenate([pts, wpts])
        jump = jnp.concatenate([d0, w0])
        owner = jnp.concatenate([jnp.where(in1, 0, jnp.where(in2, 1, -1)),
                                 jnp.where(wfound, jnp.repeat(jnp.arange(2), o.walk), -1)])
    else:
        jump = d0
        owner = jnp.where(in1, 0, jnp.where(in2, 1, -1))

    def refit(k, c, e):
        mine = owner == k
        c, e, _ = _tls(pts, mine.astype(jnp.float32))
        near = mine & (_distance(pts, c, e) < 2 * o.tolerance)
        c, e, _ = _tls(pts, near.astype(jnp.float32))
        return c, e, near

    (cs, es, near) = jax.vmap(refit)(jnp.arange(2), cs, es)
    good = tentative & (jnp.sum(near, axis=1) >= o.min_points)
    normals = jnp.stack([-es[:, 1], es[:, 0]], axis=1)
    deg = jax.vmap(_axial_deg)(normals)
    gap = jnp.abs(deg[0] - deg[1])
    gap = jnp.minimum(gap, 180.0 - gap)
    good = good.at[1].set(good[1] & (~good[0] | (gap >= o.min_angle_deg)))
    strength = jnp.where(good, jnp.sum(jnp.where(near, jump[None, :], 0.0), axis=1), -1.0)
    order = jnp.argsort(-strength)
    deg, good, near = deg[order], good[order], near[order]
    directions = jnp.where(good, deg, jnp.nan)
    directions = jnp.where(good[0], directions, jnp.roll(directions, -1))
    label = jnp.where(near[0] & good[0], 0, jnp.where(near[1] & good[1], 1, -1))
    tentative = tentative & first
    more = (jnp.sum(bracketed) - 1) * o.steps + jnp.sum(tentative) * o.walk * (o.steps + 2)
    samples = jnp.where(rough & bracketed[0], o.steps + jnp.where(first, more, 0), 0)
    return EdgeSearch(directions.astype(jnp.float32), jnp.sum(good).astype(jnp.int32),
                      samples.astype(jnp.int32), pts, label.astype(jnp.int32))


def edge_search(f, points, values=None, **options) -> EdgeSearch:
    """The spectral directions of the integrand ``f`` near its discontinuities (module
    docstring), from its samples ``values`` at ``points`` (``(m, 2)`` in the unit square;
    ``values=None`` evaluates them, not counted in ``samples``).

    ``f``: a pure callable over ``(..., 2)`` (a :class:`anisosample.render.PixelIntegrand`, an
    analytic integrand). ``options``: :class:`SearchOptions`' fields. Jit-compiled once per
    ``f`` type and options; :func:`search` is the core to vmap over many integrands.
    """
    if not callable(f):
        raise TypeError(f"f must be a callable over (..., 2), got {type(f).__name__}")
    o = search_options(**options)
    pts = check_points("points", points)
    if pts.shape[0] < 2 * o.neighbours or pts.shape[0] < 10:
        raise ValueError(f"points must hold at least max(10, 2 * neighbours) = "
                         f"{max(10, 2 * o.neighbours)} points, got {pts.shape[0]}")
    pts = jnp.asarray(pts, jnp.float32)
    if values is None:
        values = f(pts)
    values = jnp.asarray(values, jnp.float32)
    if values.shape != (pts.shape[0],):
        raise ValueError(f"values must have shape ({pts.shape[0]},) like points, got "
                         f"{values.shape}")
    if not bool(jnp.all(jnp.isfinite(values))):
        raise ValueError("values must be finite")
    return search(f, pts, values, o)

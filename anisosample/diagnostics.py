"""Where does a pattern's variance come from?  W Eq. 5, one frequency at a time; and a
sampler's expected spectrum (:func:`sampler_power_spectrum`, over :func:`sampler_sets`).

For a fixed point set ``S`` under a random toroidal shift, ``Var(I_N) = sum_{v != 0} P_S(v) P_f(v)``
exactly (W Eq. 5; ``fourier_variance.md`` Sec. 2; :func:`anisosample.metrics.predicted_variance`).
:func:`variance_decomposition` evaluates the terms of that sum
(:func:`anisosample.metrics.variance_terms`) for an integrand with a closed-form spectrum
(``anisosample.integrands``) and groups them

* by **region**: near each spectral direction's line (``|v . d_perp| <= band``, the rays of the
  integrand's edges, the axes 0 and 90 degrees included since the square's border is an edge on
  the torus) versus **elsewhere**;
* by **radius** ``|v|`` in octaves (``[1, 2), [2, 4), ...``).

Each group carries the variance it contributes and what white noise (``P_S = 1/n``) would
contribute there, so "which part of the spectrum is not dark enough" is a table and a picture
(:func:`plot_decomposition`).

The sum is evaluated on a full disk ``|v| <= disk_radius`` (all directions; off the edge rays an
edge's spectrum falls like ``|v|^-4``, so little is missed outside) plus a band of half-width
``band`` along each line out to ``line_length``; the missing tail along each line is estimated
with the pattern taken as white there (the sum of ``P_f`` over ``|v| > L`` on a ``|v|^-2`` ray is
about its sum over ``[L/2, L]``) and reported separately.  Evaluation uses
the one engine, ``anisosample.spectrum.grouped_power_spectrum``, in float64 (per line's group:
lattice-aligned type-1 grids or the rotated type-3 NUFFT for the long bands).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from . import frequencies as _freq
from . import metrics, spectrum
from ._validate import (
    check_directions_deg,
    check_frequencies,
    check_int,
    check_key,
    check_points,
    check_positive_float,
)


def band_energy(points, direction_deg: float, radius: float = 32.0) -> float:
    """Mean ``n P_S(v)`` over the frequencies within one unit of the line at spectral angle
    ``direction_deg``, ``0 < v . d <= radius`` (:func:`anisosample.frequencies.wedge`; white
    noise: 1): how dark a set is along a requested direction."""
    pts = check_points("points", points)
    radius = check_positive_float("radius", radius)
    v = _freq.wedge(float(direction_deg), radius, 1.0)
    if v.shape[0] == 0:
        raise ValueError(f"radius={radius} leaves no frequency on the line; use radius >= 1")
    return float(np.mean(np.asarray(spectrum.power_spectrum(pts, v)))) * pts.shape[0]


def decomposition_frequencies(directions_deg, disk_radius: float, line_length: float,
                              band: float) -> np.ndarray:
    """The frequencies :func:`variance_decomposition` sums W Eq. 5 over: the disk
    ``|v| <= disk_radius`` plus a band of half-width ``band`` along each direction out to
    ``line_length`` (:func:`anisosample.frequencies.wedge`), one of each ``+-v``, sorted
    (:func:`anisosample.frequencies.canonical_half`): ``(m, 2)`` int64."""
    parts = [_freq.disk(disk_radius).astype(np.int64)]
    for t in directions_deg:
        v = _freq.wedge(t, line_length, band, 0.0).astype(np.int64)
        parts.append(v[np.hypot(v[:, 0], v[:, 1]) > disk_radius])  # the disk holds the rest
    return _freq.canonical_half(np.concatenate(parts)).astype(np.int64)


def _power(points64, freqs, dirs):
    """P_S in float64 by the one engine, each frequency in the group of the line it is nearest
    to (lattice-aligned type-1 grids or the rotated type-3 NUFFT: cost ~ the band's length), so
    no long band is put in a huge bounding box."""
    fset = _freq.custom_set(freqs, dirs)
    with jax.enable_x64(True):
        x = jnp.asarray(points64, jnp.float64)
        p = np.asarray(spectrum.grouped_power_spectrum(x, fset, eps=1e-10))
    canon = _freq.canonical_half_rows(fset.freqs)
    order = np.lexsort((canon[:, 1], canon[:, 0]))
    # fset.freqs is a signed permutation of the (sorted, canonical) input: map back
    out = np.empty_like(p)
    want = np.lexsort((freqs[:, 1], freqs[:, 0]))
    out[want] = p[order]
    return out


def variance_decomposition(points, integrand, *, directions_deg=None, disk_radius=None,
                           line_length=None, band=2.0):
    """Terms of W Eq. 5 for ``points`` (fixed set + random shift) and ``integrand``.

    Args:
        points: ``(n, 2)`` in ``[0, 1)^2``.
        integrand: has ``power_spectrum(v)`` (closed form) and ``directions_deg``.
        directions_deg: lines to examine; default ``{0, 90} U integrand.directions_deg``.
        disk_radius: full disk radius (default ``max(32, 4 sqrt(n))``, at most 512).
        line_length: band length along each line (default ``16 n``, at most ``2^17``).
        band: half-width (lattice units) of a line's band.

    Returns:
        dict with ``total`` (sum over the frequencies evaluated, both ``+-v``), ``tail`` (estimate
        beyond ``line_length``), ``predicted = total + tail``, ``white`` (the same sums with
        ``P_S = 1/n``), ``regions`` (name -> variance, white), ``radius_edges`` and
        ``by_radius`` (region -> per-octave variance), and the raw ``freqs``, ``P_S``, ``P_f``,
        ``region`` arrays (one of each ``+-v``).
    """
    check_points("points", points)
    if not callable(getattr(integrand, "power_spectrum", None)) or not hasattr(
            integrand, "directions_deg"):
        raise TypeError("integrand must have a closed-form power_spectrum(v) and directions_deg "
                        "(an anisosample.integrands integrand such as edges([30])), got "
                        f"{type(integrand).__name__}")
    x = np.asarray(points, np.float64)
    n = x.shape[0]
    if directions_deg is None:
        dirs = sorted({0.0, 90.0, *[float(d) % 180.0 for d in integrand.directions_deg]})
    else:
        dirs = list(check_directions_deg("directions_deg", directions_deg))
    band = check_positive_float("band", band)
    r0 = disk_radius if disk_radius is not None else min(512.0, max(32.0, 4 * math.sqrt(n)))
    r0 = check_positive_float("disk_radius", r0)
    length = line_length if line_length is not None else float(min(16 * n, 2**17))
    length = check_positive_float("line_length", length)
    if length <= r0:
        raise ValueError(f"line_length must exceed disk_radius ({r0}), got {length}")

    v = decomposition_frequencies(dirs, r0, length, band)
    ps = _power(x, v, dirs)
    pf = np.asarray(integrand.power_spectrum(v), np.float64)

    # region label: index of the nearest line within `band`, else len(dirs) ("elsewhere")
    label = np.full(v.shape[0], len(dirs))
    best = np.full(v.shape[0], np.inf)
    for i, t in enumerate(dirs):
        th = math.radians(t)
        s = np.abs(v @ np.array([-math.sin(th), math.cos(th)]))
        take = (s <= band + 1e-9) & (s < best)
        label[take] = i
        best = np.where(take, s, best)
    names = [f"line {t:g} deg" for t in dirs] + ["elsewhere"]

    contrib = 2.0 * metrics.variance_terms(ps, pf)  # W Eq. 5's terms, +-v
    white = 2.0 * pf / n
    rad = np.hypot(v[:, 0], v[:, 1])
    kmax = int(math.ceil(math.log2(max(rad.max(), 2.0)))) + 1
    edges = 2.0 ** np.arange(kmax + 1)
    which = np.clip(np.searchsorted(edges, rad, side="right") - 1, 0, kmax - 1)
    by_radius, white_by_radius, regions = {}, {}, {}
    for i, name in enumerate(names):
        sel = label == i
        by_radius[name] = np.bincount(which[sel], contrib[sel], minlength=kmax)
        white_by_radius[name] = np.bincount(which[sel], white[sel], minlength=kmax)
        regions[name] = {"variance": float(contrib[sel].sum()), "white": float(white[sel].sum())}

    # tail beyond the band ends, pattern taken as white there
    tail = 0.0
    t_along = np.zeros(v.shape[0])
    for i, t in enumerate(dirs):
        th = math.radians(t)
        t_along = np.abs(v @ np.array([math.cos(th), math.sin(th)]))
        sel = (label == i) & (t_along > length / 2)
        tail += 2.0 * pf[sel].sum() / n
    total = float(contrib.sum())
    return {
        "n": n,
        "directions_deg": dirs,
        "disk_radius": r0,
        "line_length": length,
        "band": band,
        "total": total,
        "tail": float(tail),
        "predicted": total + float(tail),
        "white": float(white.sum()),
        "regions": regions,
        "radius_edges": edges,
        "by_radius": by_radius,
        "white_by_radius": white_by_radius,
        "freqs": v,
        "P_S": ps,
        "P_f": pf,
        "region": np.asarray(names, dtype=object)[label],
    }


def summary(decomp) -> dict:
    """The JSON-able numbers of a decomposition (no per-frequency arrays)."""
    keep = ("n", "directions_deg", "disk_radius", "line_length", "band", "total", "tail",
            "predicted", "white", "regions")
    out = {k: decomp[k] for k in keep}
    out["radius_edges"] = decomp["radius_edges"].tolist()
    out["by_radius"] = {k: v.tolist() for k, v in decomp["by_radius"].items()}
    out["white_by_radius"] = {k: v.tolist() for k, v in decomp["white_by_radius"].items()}
    return out


def plot_decomposition(ax, decomp, *, title=None):
    """Per-octave variance of each region (solid) against white noise there (dotted)."""
    edges = decomp["radius_edges"]
    mid = np.sqrt(edges[:-1] * edges[1:])
    for i, (name, vals) in enumerate(decomp["by_radius"].items()):
        color = f"C{i}"
        ok = vals > 0
        ax.loglog(mid[ok], vals[ok], "-o", ms=3, color=color, label=name)
        w = decomp["white_by_radius"][name]
        ok = w > 0
        ax.loglog(mid[ok], w[ok], ":", color=color)
    ax.set_xlabel("|v| (octave bins)")
    ax.set_ylabel("variance contributed")
    ax.set_title(title or f"W Eq. 5 terms, n={decomp['n']} (dotted: white noise)")
    ax.legend(fontsize=7)
    return ax


# --- a sampler's realizations and their expected spectrum -----------------------------------------


def sampler_sets(sampler, n, key, realizations: int = 64, *, shift: bool = True):
    """``realizations`` independent sets of a sampler, stacked: ``(R, n, 2)``.

    ``sampler`` is a sampler name or a callable ``(key, n) -> (n, 2)``; set ``r`` is drawn from
    the first half of ``split(split(key, R)[r])`` and, with ``shift`` (the default), moved by a
    toroidal shift drawn from the second. Shifting homogenizes the pattern (W Sec. 2) without
    changing each set's spectrum, as W Eq. 5's ``<P_S>`` wants. The realizations of
    :func:`sampler_power_spectrum` and :func:`sampler_power_spectrum_grid`.
    """
    n = check_int("n", n, minimum=1)
    key = check_key("key", key)
    realizations = check_int("realizations", realizations, minimum=1)
    return _sampler_sets(sampler, n, key, realizations, shift)


def _sampler_sets(sampler, n, key, realizations, shift):
    from . import samplers as _samplers

    if isinstance(sampler, str):
        sampler = _samplers.get(sampler)
    sets = []
    for k in jax.random.split(key, realizations):
        k_pts, k_shift = jax.random.split(k)
        pts = sampler(k_pts, n)
        sets.append(_samplers.toroidal_shift(k_shift, pts) if shift else jnp.asarray(pts))
    return jnp.stack(sets)


def sampler_power_spectrum(sampler, n, key, freqs, *, realizations: int = 64, shift: bool = True,
                           method: str = "auto", progress: bool = False):
    """``<P_S(v)>`` of a sampler (a name or a callable): :func:`anisosample.metrics.
    expected_power_spectrum` of its :func:`sampler_sets` (shifted by default)."""
    n = check_int("n", n, minimum=1)
    key = check_key("key", key)
    realizations = check_int("realizations", realizations, minimum=1)
    freqs = check_frequencies("freqs", freqs)
    method = spectrum.check_method(method)
    return metrics.expected_power_spectrum(_sampler_sets(sampler, n, key, realizations, shift),
                                           freqs, method=method, progress=progress)


def sampler_power_spectrum_grid(sampler, n, key, radius, *, realizations: int = 64,
                                shift: bool = True, progress: bool = False):
    """``<P_S>`` of a sampler on the centred grid of half-width ``radius``
    (:func:`anisosample.metrics.expected_power_spectrum_grid` of its :func:`sampler_sets`)."""
    n = check_int("n", n, minimum=1)
    key = check_key("key", key)
    realizations = check_int("realizations", realizations, minimum=1)
    radius = check_int("radius", radius, minimum=1)
    return metrics.expected_power_spectrum_grid(
        _sampler_sets(sampler, n, key, realizations, shift), radius, progress=progress)

"""Point-set selection (W Sec. 5.4): from estimated principal directions to an aligned set.

W precomputes one optimized set per combination of 1-degree integer principal directions: the
axes 0 and 90 degrees plus one extra direction (the 3-direction table) or two (the 4-direction
table); "if our principal direction algorithm does not find any other directions apart from the
horizontal and vertical axes, e.g., on smooth integrands, we use an existing anisotropic sampling
pattern", and "we decorrelate points across pixels using toroidal shifts" (W Sec. 5.4).

This module is that selection, once, for every caller: the aligned sampler of one integrand
(:func:`aligned_sampler`, also ``samplers.get("aligned", ...)``: ``samplers`` names no module
above it and finds this function through ``anisosample._names.BUILTIN_SAMPLER_FACTORIES``,
imported on first use) and the renderer's per-block
sampler (:mod:`anisosample.render.aligned`).

* **Rounding** (:func:`table_directions`): each estimated direction, strongest first, is rounded
  to the nearest integer degree (halves up) modulo 180; a direction that rounds onto an axis
  (0 or 90, which every set holds) or onto a direction already taken is dropped; at most ``k``
  (1 or 2) remain. Beyond W, ``near_axis_deg`` (the per-pixel sampler's policy) lets a
  direction that close to an axis go after the others: the set's axis line already serves its
  edge in part, so when more directions are found than ``k`` allows, the set for a direction
  off the axes gains more (measured in :data:`anisosample.render.pixel_aligned.NEAR_AXIS_DEG`).
* **The set** (:func:`aligned_set`): one remaining direction takes the 3-direction set, two the
  4-direction set (W's four low-energy directions) -- never the 3-direction set in place of a
  missing 4-direction one. Sets come from :func:`anisosample.tables.lookup` after
  :func:`anisosample.tables.ensure`, the one rule for missing sets: built on demand into the
  user cache, with progress (``build_missing=None``, the default; ``True`` also builds into an
  explicit ``table``); ``build_missing=False`` refuses with ``FileNotFoundError`` naming the
  build command. Any ``n >= 2``.
  No remaining direction: the fallback sampler (:data:`FALLBACK`, pmj02bn).
* **Many requests at once** (:func:`table_requests`, :func:`aligned_sets`): the renderer's
  per-block and per-pixel samplers ask for one set per block or pixel; the distinct requests
  are made available first (:func:`anisosample.tables.ensure`, with a progress bar over the
  sets), then read by the pure lookup. The toroidal shift of each pixel's set (W Sec. 5.4) is
  the renderer's, from the pixel's key; the per-pixel gate (a smooth pixel takes
  :data:`FALLBACK`) is :mod:`anisosample.render.estimation`'s probe.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np

from . import samplers as _samplers
from . import tables as _tables
from ._validate import check_bool, check_choice, check_int
from .metrics import midpoint_grid, off_axis_deg

__all__ = ["FALLBACK", "AlignedSampler", "aligned_sampler", "aligned_sequence_sampler",
           "aligned_set", "aligned_sets", "check_near_axis", "table_directions",
           "table_requests"]

FALLBACK = "pmj02bn"
"""The set of an integrand, block or pixel without a direction off the axes (W Sec. 5.4: "an
existing anisotropic sampling pattern"), and of a gated pixel."""


def table_directions(directions_deg, k: int = 2, *, near_axis_deg: float = 0.0,
                     axis_snap: bool = False) -> tuple[int, ...]:
    """W Sec. 5.4's discretization: the integer extra directions a table set is asked for.

    ``directions_deg``: estimated spectral directions in degrees, strongest first (``None``
    entries are skipped: no direction). Each is rounded to the nearest integer degree, halves
    up, modulo 180; directions that round onto an axis (0, 90) or onto one already kept are
    dropped; the first ``k`` (1 or 2) are returned -- possibly none.

    ``near_axis_deg`` (0, W's rule, to 45): rounded directions at most this many degrees from
    an axis move behind the others before the first ``k`` are taken (each group keeps its
    order); with no other direction they are still used.

    ``axis_snap`` (beyond W): a direction that rounds onto an axis is not dropped but taken as
    the integer direction one degree off that axis on its side (0.3 -> 1, 179.8 -> 179,
    90.2 -> 91), behind every other direction. Measured on W Fig. 6's integrands (edges
    0.1-1 degrees off an axis; variance over shifted pmj02bn's, ad-hoc script): the plain
    1-degree set at n = 256 half-planes 0.99 / 0.90 / 0.68 at 0.2 / 0.5 / 1 degrees, corners
    0.72 / 0.62 at 0.3 / 1; at n = 4096 half-planes 1.06 / 0.98 / 0.87 / 0.71 / 0.64 at
    0.1 / 0.2 / 0.3 / 0.5 / 1, corners 0.82 / 0.75 / 0.71 at 0.1 / 0.3 / 1; a set farther off
    the axis (3 or 5 degrees) lost at 4096 (1.3-1.95 on the half-planes). The 1-degree set with
    the per-pixel sampler's 64-point prefix at n = 256: half-planes 1.17 / 1.01 / 0.68 at
    0.2 / 0.5 / 1 degrees, corners 0.84 / 0.69 at 0.3 / 1.
    """
    return _table_directions(directions_deg, check_int("k", k, minimum=1, maximum=2),
                             check_near_axis(near_axis_deg), check_bool("axis_snap", axis_snap))


def _table_directions(directions_deg, k: int, near_axis_deg: float,
                      axis_snap: bool = False) -> tuple[int, ...]:
    """:func:`table_directions` with ``k``, ``near_axis_deg`` and ``axis_snap`` already
    validated."""
    if directions_deg is None or isinstance(directions_deg, int | float | np.number):
        directions_deg = (directions_deg,)
    out: list[int] = []
    snapped: list[int] = []
    for a in directions_deg:
        if a is None:
            continue
        d = float(a)
        if not math.isfinite(d):
            raise ValueError(f"directions_deg must be finite degrees (or None), got {a!r}")
        r = int(math.floor(d + 0.5)) % 180
        if r not in _tables.AXES_DEG:
            if r not in out:
                out.append(r)
        elif axis_snap:
            side = 1 if (d - r + 90.0) % 180.0 - 90.0 >= 0 else -1
            snapped.append((r + side) % 180)
    if near_axis_deg > 0:
        out.sort(key=lambda r: off_axis_deg(r) <= near_axis_deg)  # stable
    out += [r for i, r in enumerate(snapped) if r not in out and r not in snapped[:i]]
    return tuple(out[:k])


def check_near_axis(near_axis_deg) -> float:
    """A validated ``near_axis_deg`` (:func:`table_directions`): a real number in [0, 45]."""
    if isinstance(near_axis_deg, bool) or not isinstance(near_axis_deg, int | float | np.number):
        raise TypeError(f"near_axis_deg must be a number of degrees, got "
                        f"{type(near_axis_deg).__name__}")
    v = float(near_axis_deg)
    if not 0.0 <= v <= 45.0:
        raise ValueError(f"near_axis_deg must be in [0, 45] degrees, got {near_axis_deg!r}")
    return v


def aligned_set(extra_deg, n: int, key=None, *, table=None, build_missing: bool | None = None,
                **build_options) -> jax.Array:
    """The aligned set of ``n`` points for the integer extra directions ``extra_deg`` (one:
    the 3-direction table, two: the 4-direction table; from :func:`table_directions`),
    toroidally shifted by ``key`` when given (Cranley & Patterson 1976, W Sec. 5.4).

    ``table``, ``build_missing`` and ``build_options`` (``show_progress``, ``seed``, synthesis
    options; ``prefix``, ``sequence_from``) go to :func:`anisosample.tables.ensure`, which builds
    a missing set unless ``build_missing=False``, then to the pure
    :func:`anisosample.tables.lookup`.
    """
    extra = tuple(int(a) for a in np.asarray(extra_deg, np.int64).reshape(-1))
    if not 1 <= len(extra) <= 2 or any(a in _tables.AXES_DEG for a in extra):
        raise ValueError(f"extra_deg must hold one or two integer directions other than the "
                         f"axes (from table_directions), got {list(extra)}")
    n = check_int("n", n, minimum=2)
    where = dict(direction_count=len(extra) + 2, table=table,
                 prefix=build_options.pop("prefix", None),
                 sequence_from=build_options.pop("sequence_from", 0))
    _tables.ensure([extra], n, build_missing=build_missing, **where, **build_options)
    pts = _tables.lookup(extra, n, **where)
    pts = jnp.asarray(pts, jnp.float32)
    return pts if key is None else _samplers.toroidal_shift(key, pts)


def table_requests(directions, k: int = 2, *, near_axis_deg: float = 0.0,
                   axis_snap: bool = False) -> tuple[list, np.ndarray]:
    """The distinct table requests of many items (blocks, pixels): ``directions`` holds each
    item's estimated directions, strongest first (empty: none), rounded by
    :func:`table_directions` (with ``near_axis_deg`` and ``axis_snap``). Returns
    ``(requests, index)``: the distinct non-empty requests in order of first use and each item's
    index into them (``-1``: no direction off the axes, the item takes :data:`FALLBACK`).
    ``directions`` may also be an ``(items, slots)`` float array, NaN where an item has no
    direction in a slot (its directions: its finite entries in order); then the items that
    round alike (every direction to the same integer, an axis's from the same side) are
    rounded once."""
    k = check_int("k", k, minimum=1, maximum=2)
    near_axis_deg = check_near_axis(near_axis_deg)
    axis_snap = check_bool("axis_snap", axis_snap)
    if isinstance(directions, np.ndarray) and directions.ndim == 2:
        return _table_requests_array(directions, k, near_axis_deg, axis_snap)
    requests: list = []
    where: dict = {}
    index = np.full(len(directions), -1, np.int32)
    for i, dirs in enumerate(directions):
        if len(dirs) == 0:
            continue
        extra = _table_directions(tuple(dirs), k, near_axis_deg, axis_snap)
        if not extra:
            continue
        if extra not in where:
            where[extra] = len(requests)
            requests.append(extra)
        index[i] = where[extra]
    return requests, index


def _table_requests_array(directions, k: int, near_axis_deg: float,
                          axis_snap: bool) -> tuple[list, np.ndarray]:
    """:func:`table_requests` of an ``(items, slots)`` array (NaN: none), validated options.
    :func:`_table_directions` depends on a direction only through its integer ``r`` and, on an
    axis, the side it lies on, so each distinct signature of those is rounded once, on the
    first item that has it."""
    d = np.asarray(directions, np.float64)
    if np.isinf(d).any():
        raise ValueError("directions must be finite degrees or NaN (none)")
    ok = ~np.isnan(d)
    r = np.floor(np.where(ok, d, 0.0) + 0.5) % 180
    side = (np.where(ok, d, 0.0) - r + 90.0) % 180.0 - 90.0 >= 0
    signature = np.where(ok, 2 * r.astype(np.int64) + side, -1)
    if d.shape[0] == 0:
        return [], np.full(0, -1, np.int32)
    _, first, inverse = np.unique(signature, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")  # the signatures in order of first use
    requests, of_rep = table_requests([tuple(d[i][ok[i]]) for i in first[order]], k,
                                      near_axis_deg=near_axis_deg, axis_snap=axis_snap)
    of_signature = np.empty(first.size, np.int32)
    of_signature[order] = of_rep
    return requests, of_signature[inverse.reshape(-1)]


def aligned_sets(requests, n: int, *, table=None, build_missing: bool | None = None,
                 prefix: str | None = None, progress: bool = True, desc: str | None = None,
                 as_numpy: bool = False, **build_options) -> jax.Array | np.ndarray:
    """The aligned sets of ``n`` points for ``requests`` (tuples of integer extra directions,
    :func:`table_requests`), stacked ``(len(requests), n, 2)`` float32, unshifted: every
    missing one is built first (:func:`anisosample.tables.ensure`, one progress bar over the
    sets unless ``progress=False``; ``table``, ``build_missing``, ``prefix`` and
    ``build_options`` are its), then all are read by the pure
    :func:`anisosample.tables.lookup_many`. ``as_numpy=True`` returns the host array instead
    (the renderer pads and checks the sets there before one transfer).
    """
    from .progress import progress as bar

    as_numpy = check_bool("as_numpy", as_numpy)
    n = check_int("n", n, minimum=2)
    opts = dict(build_options)
    opts["show_progress"] = False
    # Assembled on the host: eager device ops here would compile once per number of sets,
    # and a per-pixel render asks for a new number with every key (about 0.3 s per render).
    sets = np.zeros((len(requests), n, 2), np.float32)
    for count in sorted({len(e) + 2 for e in requests}):  # 3 or 4: the tables refuse others
        at = [i for i, e in enumerate(requests) if len(e) + 2 == count]
        group = [requests[i] for i in at]
        todo = _tables.missing(group, n, direction_count=count, table=table, prefix=prefix)
        for extra in bar(todo, desc=desc or f"aligned sets n={n}", unit="set",
                         disable=None if progress and len(todo) > 8 else True):
            _tables.ensure([extra], n, direction_count=count, table=table,
                           build_missing=build_missing, prefix=prefix, **opts)
        sets[np.asarray(at)] = _tables.lookup_many(group, n, direction_count=count, table=table,
                                                   prefix=prefix, as_numpy=True)
    if as_numpy:
        return sets
    return jax.device_put(sets)  # not jnp.asarray: that compiles a staging copy per shape


@dataclasses.dataclass(frozen=True)
class AlignedSampler(_samplers.Sampler):
    """The aligned sampler of one integrand: a :class:`~anisosample.samplers.Sampler` with
    ``directions_deg`` (the integer extra directions used, empty for the fallback),
    ``estimated_deg`` (the raw estimates) and ``canonical`` (the table set, or None)."""

    directions_deg: tuple[int, ...] = ()
    estimated_deg: tuple[float, ...] = ()
    canonical: _tables.Canonical | None = None


def _grid_of(f, size: int) -> np.ndarray:
    xy = midpoint_grid(size, xp=jnp)  # values[i, j] = f((j + .5)/w, (i + .5)/h)
    return np.asarray(f(xy), dtype=np.float32)


def aligned_sampler(*, integrand=None, values=None, directions_deg=None, k: int = 2,
                    grid_size: int = 96, fallback: str = FALLBACK, table=None,
                    build_missing: bool | None = None, estimate_options: dict | None = None,
                    **build_options) -> AlignedSampler:
    """The aligned sampler of W Sec. 5.4 for one integrand.

    Give one of: ``integrand`` (a callable ``f(x)`` over ``(..., 2)``, sampled on a
    ``grid_size``-squared grid), ``values`` (an ``(h, w)`` grid of its samples, DESIGN's
    convention) or ``directions_deg`` (the extra directions, skipping estimation). At most ``k``
    (1 or 2) extra directions are estimated with :func:`anisosample.directions.estimate` and
    discretized by :func:`table_directions`; none -> ``fallback`` (an option-free baseline,
    default ``pmj02bn``). ``sampler(key, n)`` is :func:`aligned_set` for ``n`` points shifted
    by ``key`` (``table``, ``build_missing``, ``build_options``: the table lookup's; a missing
    set is built on demand, with progress unless ``show_progress=False``, and refused only with
    ``build_missing=False``).
    """
    given = [v is not None for v in (integrand, values, directions_deg)]
    if sum(given) != 1:
        raise ValueError("aligned sampler needs exactly one of integrand=, values= or "
                         "directions_deg=")
    k = check_int("k", k, minimum=1, maximum=2)
    check_choice("fallback", fallback, _samplers.BASELINES)  # option-free samplers only
    if build_missing is not None and not isinstance(build_missing, bool):
        raise TypeError(f"build_missing must be None, True or False, got {build_missing!r}")
    if directions_deg is not None:
        if isinstance(directions_deg, int | float | np.number):
            directions_deg = (directions_deg,)
        raw = tuple(float(a) for a in np.asarray(directions_deg, np.float64).reshape(-1))
        if not all(np.isfinite(raw)) or any(a < 0 or a >= 180 for a in raw):
            raise ValueError(f"directions_deg must lie in [0, 180) degrees, got {list(raw)}")
    else:
        from . import directions as _directions

        if integrand is not None:
            if not callable(integrand):
                raise TypeError(f"integrand must be a callable f(x) over (..., 2), got "
                                f"{type(integrand).__name__}")
            grid_size = check_int("grid_size", grid_size, minimum=16)
            values = _grid_of(integrand, grid_size)
        raw = tuple(_directions.estimate(values, k=k, **(estimate_options or {})))
    extra = table_directions(raw, k)
    if not extra:
        fb = _samplers.get(fallback)
        return AlignedSampler(f"aligned(fallback {fallback})", fb.fn, fb.jittable,
                              fb.power_of_two, (), raw, None)

    def fn(key, n):
        return aligned_set(extra, n, key, table=table, build_missing=build_missing,
                           **build_options)

    return AlignedSampler(f"aligned{list(extra)}", fn, False, False, extra, raw,
                          _tables.canonicalize(extra))


def aligned_sequence_sampler(*, length: int = 4096, sequence_from: int = 256,
                             **options) -> AlignedSampler:
    """The progressive aligned sampler (W Sec. 7): ``sampler(key, n)`` is the first ``n`` points
    of the aligned sequence of ``length`` points (:func:`anisosample.synthesis.
    synthesize_sequence`: every power-of-two prefix from ``sequence_from`` up is an aligned set)
    for the directions, with one toroidal shift per key; a renderer may stop at any ``n`` and
    the points it took stay part of the larger estimate. Directions, estimation, fallback,
    ``table``, ``build_missing`` and the lookup's options (``prefix``, ...) as in
    :func:`aligned_sampler`; ``n`` must lie in ``[1, length]``."""
    length = check_int("length", length, minimum=2)
    sequence_from = check_int("sequence_from", sequence_from, minimum=2)
    if sequence_from > length:
        raise ValueError(f"sequence_from must be at most length={length}, got {sequence_from}")
    base = aligned_sampler(**options, sequence_from=sequence_from)
    if not base.directions_deg:
        return base
    set_fn = base.fn

    def fn(key, n):
        n = check_int("n", n, minimum=1)
        if n > length:
            raise ValueError(f"n must be at most the sequence length {length}, got {n}; make the "
                             "sampler with a larger length=")
        seq = set_fn(None, length)
        pts = seq[:n]
        return pts if key is None else _samplers.toroidal_shift(key, pts)

    return AlignedSampler(f"aligned-sequence{list(base.directions_deg)}", fn, False, False,
                          base.directions_deg, base.estimated_deg, base.canonical)


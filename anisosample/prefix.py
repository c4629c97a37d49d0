"""Fixed isotropic prefixes of aligned sets (W Sec. 7): the first ``m`` points every set shares.

W's Sec. 7 proposes sets whose "first few 16-64 points are always fixed and isotropically
distributed so that we can use the samples for the principal direction estimation directly for
the final Monte Carlo estimate". A renderer reads those ``m`` samples *before* it knows the
pixel's directions, so every aligned set it may later pick must start with the same ``m``
points. This module names the prefixes, makes them, and keeps that promise through the tables'
symmetry reduction.

Two kinds (a *spec* string names one; :func:`check_prefix`):

``"pmj02bn-<m>"``
    The first ``m`` points of pmj02bn (Christensen et al. 2018) with key :data:`PMJ_KEY`:
    progressive, so every power-of-two head of the prefix is (0,2)-stratified blue noise. Good
    for a standalone set; **not** for the tables: a table stores one canonical set per orbit of
    the square's symmetries (W Sec. 5.4) and serves the other directions by mirroring, swapping
    or rotating it, which would mirror the prefix too.
``"dihedral-<m>"`` (``m`` a multiple of 8)
    ``m / 8`` representative points and their 8 images under the square's symmetry group
    (mirror ``(x, 1 - y)``, swap ``(y, x)`` and what they generate), placed by a deterministic
    repulsion optimization (:func:`dihedral_points`) and rounded to multiples of ``2^-16`` so
    that every image is exact in float32. The set is invariant under every transform a table
    applies, so a looked-up set's first ``m`` points are the same points for every direction,
    reordered to the prefix's order by :func:`align_prefix`. The tables' prefix.

``"points-<sha256>-<m>"`` names explicit points a caller gave :func:`anisosample.synthesize`.
:data:`DEFAULT_PREFIX` is the renderer's and tables' choice; its measurement is in
``experiments/beyond_prefix_sets.py``.
"""

from __future__ import annotations

import functools
import hashlib

import jax
import numpy as np

from ._validate import check_int, check_points

__all__ = ["KINDS", "DEFAULT_PREFIX", "PMJ_KEY", "check_prefix", "prefix_size", "prefix_points",
           "explicit_prefix_name", "is_symmetric", "dihedral_points", "place_prefix",
           "align_prefix", "check_table_prefix", "restore_prefix"]

KINDS = ("pmj02bn", "dihedral")
"""The named prefix kinds."""
PMJ_KEY = 0
"""The key of a ``"pmj02bn-<m>"`` prefix: one fixed prefix per ``m``."""
DEFAULT_PREFIX = "dihedral-32"
"""The prefix tables and the renderer take when asked for one without a name (the measurement
behind 32 and the dihedral kind: ``experiments/beyond_prefix_sets.py``)."""
_EXPLICIT = "points"
_GRID = 2.0**-16  # dihedral coordinates are multiples of this: 1 - t is exact in float32


def check_prefix(name: str, prefix) -> str:
    """A prefix spec: ``"none"``, ``"pmj02bn-<m>"`` (``m >= 1``), ``"dihedral-<m>"`` (``m`` a
    positive multiple of 8) or ``"points-<sha256>-<m>"``; anything else is a ``ValueError``
    naming ``name``."""
    if not isinstance(prefix, str):
        raise TypeError(f"{name} must be a string ('none', 'dihedral-<m>', 'pmj02bn-<m>') or, "
                        f"in synthesize, an (m, 2) array; got {type(prefix).__name__}")
    if prefix == "none":
        return prefix
    head, _, m = prefix.rpartition("-")
    ok = m.isdigit() and str(int(m)) == m and int(m) >= 1
    if ok and head == "dihedral":
        ok = int(m) % 8 == 0
    elif ok and head != "pmj02bn":
        kind, _, digest = head.partition("-")
        ok = kind == _EXPLICIT and len(digest) == 64
    if not ok:
        raise ValueError(f"{name} must be 'none', 'dihedral-<m>' (m a multiple of 8) or "
                         f"'pmj02bn-<m>' (m >= 1), e.g. {DEFAULT_PREFIX!r}; got {prefix!r}")
    return prefix


def prefix_size(prefix: str) -> int:
    """``m``, the number of fixed points of a prefix spec (0 for ``"none"``)."""
    return 0 if check_prefix("prefix", prefix) == "none" else int(prefix.rpartition("-")[2])


def prefix_points(prefix: str) -> np.ndarray:
    """The ``(m, 2)`` float32 points of a named prefix; ``(0, 2)`` for ``"none"``. An explicit
    ``"points-..."`` prefix is not reproducible from its name (``ValueError``: pass the points)."""
    m = prefix_size(prefix)
    if m == 0:
        return np.zeros((0, 2), np.float32)
    kind = prefix.rpartition("-")[0]
    if kind == "pmj02bn":
        return _pmj(m).copy()
    if kind == "dihedral":
        return dihedral_points(m)
    raise ValueError(f"prefix {prefix!r} names explicit points by their checksum; pass the "
                     "points themselves")


@functools.lru_cache(maxsize=16)
def _pmj(m: int) -> np.ndarray:
    from . import samplers

    pts = np.asarray(samplers.get("pmj02bn")(jax.random.key(PMJ_KEY), m), np.float32)
    pts.setflags(write=False)
    return pts


def explicit_prefix_name(points) -> str:
    """The spec of explicit prefix points: ``"points-<sha256 of their float32 bytes>-<m>"``."""
    pts = np.ascontiguousarray(np.asarray(points, np.float32))
    digest = hashlib.sha256(pts.astype("<f4").tobytes()).hexdigest()
    return f"{_EXPLICIT}-{digest}-{len(pts)}"


# --- the dihedral prefix ---------------------------------------------------------------------


def _orbit(p: np.ndarray) -> np.ndarray:
    """The 8 images ``(+-x, +-y)``, ``(+-y, +-x)`` (mod 1) of points ``p`` ``(k, 2)``:
    ``(8k, 2)``, orbit by orbit."""
    x, y = p[:, 0], p[:, 1]
    fx, fy = np.mod(-x, 1.0), np.mod(-y, 1.0)
    images = [(x, y), (fx, y), (x, fy), (fx, fy), (y, x), (fy, x), (y, fx), (fy, fx)]
    return np.stack([np.stack(im, -1) for im in images], 1).reshape(-1, 2)


_IMAGES = np.array([[[1, 0], [0, 1]], [[-1, 0], [0, 1]], [[1, 0], [0, -1]], [[-1, 0], [0, -1]],
                    [[0, 1], [1, 0]], [[0, -1], [1, 0]], [[0, 1], [-1, 0]], [[0, -1], [-1, 0]]],
                   np.float64)
"""The square's 8 symmetries as matrices on a point (the order of :func:`_orbit`'s images)."""


def _repulsion(reps_flat: np.ndarray, k: int, sigma: float):
    """Gaussian repulsion energy ``sum_{a<b} exp(-|p_a - p_b|^2 / 2 sigma^2)`` (minimal-image
    toroidal differences) of the symmetrized set, and its gradient in the representatives."""
    r = reps_flat.reshape(k, 2)
    pts = np.einsum("gij,kj->gki", _IMAGES, r)  # (8, k, 2), image g of representative k
    flat = pts.reshape(-1, 2)
    d = flat[:, None, :] - flat[None, :, :]
    d -= np.round(d)
    e = np.exp(-(d**2).sum(-1) / (2 * sigma**2))
    np.fill_diagonal(e, 0.0)
    grad_pts = -(e[:, :, None] * d).sum(1) / sigma**2  # dE/dp_a (each pair counted once in E)
    grad = np.einsum("gij,gki->kj", _IMAGES, grad_pts.reshape(8, k, 2))
    return float(e.sum() / 2), grad.ravel()


def _min_distance(pts: np.ndarray) -> float:
    d = np.abs(pts[:, None, :] - pts[None, :, :])
    d = np.minimum(d, 1.0 - d)
    r = np.sqrt((d**2).sum(-1))
    np.fill_diagonal(r, np.inf)
    return float(r.min())


@functools.lru_cache(maxsize=16)
def _dihedral(m: int) -> np.ndarray:
    from scipy.optimize import minimize

    k = m // 8
    sigma = 0.5 / np.sqrt(m)
    rng = np.random.default_rng(20261202)  # fixed: one prefix per m, the same everywhere
    best, best_d = None, -1.0
    for _ in range(24):
        # representatives in the fundamental triangle 0 < y < x < 1/2
        r = np.sort(rng.uniform(0.02, 0.48, (k, 2)), axis=1)[:, ::-1]
        res = minimize(_repulsion, r.ravel(), args=(k, sigma), jac=True, method="L-BFGS-B",
                       options={"maxiter": 500})
        reps = np.round(np.mod(res.x.reshape(k, 2), 1.0) / _GRID) * _GRID
        pts = _orbit(np.mod(reps, 1.0))
        d = _min_distance(pts)
        if d > best_d:
            best, best_d = pts, d
    out = best.astype(np.float32)
    out.setflags(write=False)
    return out


def dihedral_points(m: int) -> np.ndarray:
    """The ``"dihedral-<m>"`` prefix: ``(m, 2)`` float32, ``m`` a multiple of 8, invariant as a
    set under every symmetry of the square on the torus (:func:`is_symmetric`).

    ``m / 8`` representatives are placed by minimizing a Gaussian repulsion energy (width
    ``0.5 / sqrt(m)``) of their symmetrized set with L-BFGS from 24 fixed random starts, the start
    whose rounded set has the largest minimum toroidal distance kept; coordinates are rounded to
    multiples of ``2^-16`` (so ``(-t) mod 1`` is exact in float32) and listed orbit by orbit.
    Deterministic: a fixed seed, float64, one machine."""
    m = check_int("m", m, minimum=8)
    if m % 8:
        raise ValueError(f"m must be a multiple of 8 (8 images per representative), got {m}")
    pts = _dihedral(m).copy()
    if len({tuple(p) for p in pts.tolist()}) != m:
        raise RuntimeError(f"dihedral prefix of {m} points has coinciding images")  # not reached
    return pts


def _transform(points: np.ndarray, transform: str) -> np.ndarray:
    from ._table_store import transform_points

    return transform_points(np.asarray(points, np.float32), transform)


def is_symmetric(points) -> bool:
    """Whether a float32 point set maps onto itself (as a set, bit for bit) under every
    transform of the tables' symmetry reduction (``mirror``, ``swap``, ``rotate90``)."""
    pts = np.asarray(points, np.float32)
    own = {tuple(p) for p in pts.tolist()}
    return all({tuple(p) for p in _transform(pts, t).tolist()} == own
               for t in ("mirror", "swap", "rotate90"))


# --- prefixes in a set ----------------------------------------------------------------------


def place_prefix(points, prefix_pts) -> np.ndarray:
    """An initial set that starts with ``prefix_pts`` ``(m, 2)``: ``points`` ``(n, 2)`` with, for
    each prefix point in order, the nearest remaining point (toroidal distance) removed, and the
    prefix put in front. The result keeps ``n`` points and the density of ``points``, so an
    optimizer starts without near-duplicates of the fixed points. A set that already starts with
    the prefix (a warm start from a set with the same prefix) comes back as it is (float64)."""
    x = np.asarray(points, np.float64)
    p = np.asarray(prefix_pts, np.float64)
    m = len(p)
    if m == 0 or np.array_equal(x[:m], p):
        return x.copy()
    alive = np.ones(len(x), bool)
    for q in p:
        d = np.abs(x - q)
        d = np.minimum(d, 1.0 - d)
        alive[int(np.argmin(np.where(alive, (d * d).sum(1), np.inf)))] = False
    return np.concatenate([p, x[alive]])


def align_prefix(points, prefix_pts) -> np.ndarray:
    """``points`` ``(n, 2)`` with its first ``m`` points reordered into the order of
    ``prefix_pts`` ``(m, 2)``; they must be the same points as a set (a symmetric prefix after a
    table's transform), else ``ValueError``. Returns float32."""
    pts = np.array(check_points("points", points), np.float32)
    pre = np.asarray(prefix_pts, np.float32)
    m = len(pre)
    index = {tuple(p): i for i, p in enumerate(pts[:m].tolist())}
    try:
        order = [index[tuple(p)] for p in pre.tolist()]
    except KeyError:
        raise ValueError("points do not start with the prefix's points (as a set); a table's "
                         "symmetry keeps only a symmetric prefix (dihedral-<m>)") from None
    pts[:m] = pts[:m][order]
    return pts


# --- prefixes in tables -------------------------------------------------------------------------


def check_table_prefix(prefix) -> str:
    """A prefix a table can hold: ``None``/``"none"`` or a symmetric ``"dihedral-<m>"`` (a table
    serves most directions by mirroring, swapping or rotating a canonical set, which keeps only a
    prefix that the square's symmetries map onto itself)."""
    spec = check_prefix("prefix", "none" if prefix is None else prefix)
    if spec != "none" and not spec.startswith("dihedral-"):
        raise ValueError(f"prefix {spec!r} cannot be held by a table: its symmetry reduction "
                         "mirrors, swaps and rotates sets, which keeps only a symmetric prefix; "
                         f"use 'dihedral-<m>' (e.g. {DEFAULT_PREFIX!r}) or 'none'")
    return spec


def restore_prefix(points: np.ndarray, prefix: str) -> np.ndarray:
    """A transformed set of a table with a (symmetric) ``prefix``: its first ``m`` points are
    the prefix's points in another order; put them back in the prefix's order, so every set a
    table serves starts with the prefix bit for bit (:func:`align_prefix`)."""
    if prefix == "none":
        return points
    return align_prefix(points, prefix_points(prefix))

"""What measures a point set or an estimator, and the grids such measures are taken on.

* :func:`axial_distance_deg`: the distance between two directions modulo 180 degrees (the
  error of an estimated spectral direction, the gap between two edge normals).
* :func:`nearest_neighbour_distance`: each point's distance to its nearest other point on the
  unit torus (how blue-noise-like a point set is).
* :func:`midpoint_grid`: the ``n x n`` cell centres ``(i + 0.5) / n`` of the unit square, the
  midpoint rule's nodes and DESIGN's grid convention (``values[i, j] = f((j + .5)/n,
  (i + .5)/n)`` with ``indexing="xy"``).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ._validate import check_choice, check_int, check_points

__all__ = ["axial_distance_deg", "nearest_neighbour_distance", "midpoint_grid"]

INDEXINGS = ("xy", "ij")


def axial_distance_deg(a, b, *, xp=jnp):
    """Axial distance ``min(|a - b| mod 180, 180 - |a - b| mod 180)`` in degrees.

    ``a - b`` is taken as the operands' own subtraction; the rest in the array namespace ``xp``:
    ``jax.numpy`` (the default: traceable, float32 unless JAX's x64 mode is on) or ``numpy``
    (float64 for Python floats and float64 arrays). Broadcasts like ``a - b``.
    """
    if xp is not jnp and xp is not np:
        raise ValueError(f"xp must be jax.numpy or numpy, got {xp!r}")
    d = xp.mod(xp.abs(a - b), 180.0)
    return xp.minimum(d, 180.0 - d)


def nearest_neighbour_distance(points) -> np.ndarray:
    """Each point's distance (float64, shape ``(n,)``) to its nearest other point of ``points``
    (shape ``(n, 2)``, ``n >= 2``, in ``[0, 1)^2``), measured on the unit torus (wrap-around in
    both axes, as the point sets tile)."""
    from scipy.spatial import cKDTree

    check_points("points", points)
    p = np.asarray(points, dtype=np.float64)
    if p.shape[0] < 2:
        raise ValueError(f"points must hold at least 2 points, got {p.shape[0]}")
    d, _ = cKDTree(p, boxsize=1.0).query(p, k=2)
    return d[:, 1]


def midpoint_grid(n: int, *, indexing: str = "xy", dtype=np.float32, xp=np):
    """The ``n x n`` cell centres of the unit square, shape ``(n, n, 2)``.

    ``indexing="xy"``: ``grid[i, j] = ((j + .5)/n, (i + .5)/n)`` (row index = y, DESIGN's grid
    convention); ``"ij"``: ``grid[i, j] = ((i + .5)/n, (j + .5)/n)``. ``reshape(-1, 2)`` gives
    the ``n^2`` points.

    ``xp=numpy`` (default): a NumPy array, computed in float64 and rounded once to ``dtype`` (for
    float32 the same as dividing in float32: a float64 quotient rounds to the correctly rounded
    float32 one). ``xp=jax.numpy``: a JAX array, ``(arange(n) + 0.5) / n`` divided by XLA in
    ``dtype``, which need not round the same in the last bit.
    """
    if xp is not jnp and xp is not np:
        raise ValueError(f"xp must be numpy or jax.numpy, got {xp!r}")
    n = check_int("n", n, minimum=1)
    indexing = check_choice("indexing", indexing, INDEXINGS)
    if xp is jnp:
        c = (jnp.arange(n, dtype=dtype) + 0.5) / n
        return jnp.stack(jnp.meshgrid(c, c, indexing=indexing), axis=-1)
    c = (np.arange(n, dtype=np.float64) + 0.5) / n
    return np.stack(np.meshgrid(c, c, indexing=indexing), -1).astype(dtype)

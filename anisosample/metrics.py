"""What measures a point set or an estimator, and the grids such measures are taken on.

* :func:`axial_distance_deg`: the distance between two directions modulo 180 degrees (the
  error of an estimated spectral direction, the gap between two edge normals).
* :func:`nearest_neighbour_distance`: each point's distance to its nearest other point on the
  unit torus (how blue-noise-like a point set is).
* :func:`midpoint_grid`: the ``n x n`` cell centres ``(i + 0.5) / n`` of the unit square, the
  midpoint rule's nodes and DESIGN's grid convention (``values[i, j] = f((j + .5)/n,
  (i + .5)/n)`` with ``indexing="xy"``).
* :func:`off_axis_deg`: a direction's distance to the nearer axis; :func:`grid_values`: an
  integrand on the midpoint grid.
* :func:`image_error`, :func:`mse_ratio`, :func:`efficiency`: a rendering technique's MSE (or
  MRSE) against a reference, the paired ratio of two MSEs, Monte Carlo efficiency, each with its
  standard error (H Sec. 4).
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from ._validate import check_choice, check_int, check_points

__all__ = ["axial_distance_deg", "nearest_neighbour_distance", "midpoint_grid", "off_axis_deg",
           "grid_values", "ImageError", "image_error", "mse_ratio", "efficiency"]

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


# --- image errors and efficiency (issue 26: from experiments/_h_render.py) -----------------------
# H Sec. 4's measures of a rendering technique: the MSE of its images against a converged
# reference (or the MRSE, each pixel's squared error over ``ref^2 + 0.01``), with standard errors
# from the spread over independent realizations; the paired ratio of two techniques' MSE; Monte
# Carlo efficiency ``1 / (MSE x time)``. All in float64 NumPy.
# Also here: off_axis_deg, a direction's distance to the nearer axis (W Figs. 7 and 9), and
# grid_values, an integrand sampled on the midpoint grid (W Fig. 12).

MRSE_EPSILON = 0.01
"""H's MRSE: each pixel's squared error divided by ``ref^2 + MRSE_EPSILON``."""


def off_axis_deg(d) -> np.ndarray:
    """Distance (degrees, float64 NumPy) of each direction ``d`` to the nearer of the two axes
    (0 and 90 degrees, modulo 90): ``min(d mod 90, 90 - d mod 90)``."""
    d = np.asarray(d) % 90.0
    return np.minimum(d, 90.0 - d)


def grid_values(f, n: int) -> np.ndarray:
    """``f`` (a callable over ``(..., 2)``, an equinox module or a plain function) on the
    :func:`midpoint_grid` of side ``n``: the ``(n, n)`` NumPy array ``values[i, j] = f((j + .5) /
    n, (i + .5) / n)`` (DESIGN's grid convention), evaluated in one jitted call."""
    import equinox as eqx

    xy = midpoint_grid(n)
    return np.asarray(eqx.filter_jit(lambda g, x: g(x))(f, jnp.asarray(xy)))


class ImageError(NamedTuple):
    """The error of ``R`` realizations of an image of ``P`` pixels (:func:`image_error`).

    ``image``: ``(P,)`` per-pixel mean squared error over the realizations; ``per_realization``:
    ``(R,)`` each realization's image MSE; ``mse``: the mean of ``image``; ``mse_stderr``: the
    standard error of ``mse`` (the spread of ``per_realization``); ``mse_from_variance``: the
    mean over pixels of the realizations' variance (``ddof=1``), which equals ``mse`` for an
    unbiased technique up to noise; ``mean_error`` and ``mean_error_stderr``: the mean signed
    error over all pixels and realizations and its standard error (a bias check). With
    ``relative``, every squared error and variance is divided by ``ref^2 + 0.01`` (MRSE).
    """

    image: np.ndarray
    per_realization: np.ndarray
    mse: float
    mse_stderr: float
    mse_from_variance: float
    mean_error: float
    mean_error_stderr: float

    def as_dict(self) -> dict:
        """The scalar fields (``mse`` ... ``mean_error_stderr``)."""
        return {k: getattr(self, k) for k in ("mse", "mse_stderr", "mse_from_variance",
                                              "mean_error", "mean_error_stderr")}


def image_error(estimates, reference, *, relative: bool = False) -> ImageError:
    """The MSE (``relative``: MRSE) of ``estimates`` (``(R, P)``: ``R >= 2`` realizations of
    ``P`` pixel values) against ``reference`` (``(P,)``), with standard errors
    (:class:`ImageError`)."""
    est = np.asarray(estimates, np.float64)
    ref = np.asarray(reference, np.float64)
    if est.ndim != 2 or ref.shape != est.shape[1:] or est.shape[0] < 2:
        raise ValueError(f"estimates must be (R >= 2, P) and reference (P,), got "
                         f"{est.shape} and {ref.shape}")
    r = est.shape[0]
    denom = ref**2 + MRSE_EPSILON if relative else np.ones_like(ref)
    err = est - ref[None, :]
    image = np.mean(err**2 / denom[None, :], axis=0)
    var_img = np.var(est, axis=0, ddof=1) / denom
    per_real = np.mean(err**2 / denom[None, :], axis=1)
    return ImageError(
        image=image,
        per_realization=per_real,
        mse=float(np.mean(image)),
        mse_stderr=float(np.std(per_real, ddof=1) / np.sqrt(r)),
        mse_from_variance=float(np.mean(var_img)),
        mean_error=float(np.mean(err)),
        mean_error_stderr=float(np.std(np.mean(err, axis=1), ddof=1) / np.sqrt(r)),
    )


def mse_ratio(error: ImageError, base: ImageError) -> tuple[float, float]:
    """``(error.mse / base.mse, its standard error)``: the realizations paired (the same keys
    for both techniques), the delta method's error of a ratio of means,
    ``std(a_r - ratio b_r) / sqrt(R) / mean(b)``."""
    a, b = error.per_realization, base.per_realization
    if a.shape != b.shape:
        raise ValueError(f"paired realizations must match, got {a.shape} and {b.shape}")
    ratio = error.mse / base.mse
    resid = a - ratio * b
    return ratio, float(np.std(resid, ddof=1) / np.sqrt(len(a)) / base.mse)


def efficiency(mse: float, seconds: float, mse_stderr: float | None = None):
    """Monte Carlo efficiency ``1 / (mse x seconds)`` (H Sec. 4); with ``mse_stderr``,
    ``(efficiency, its standard error)`` by the delta method, the time taken as exact:
    ``efficiency x mse_stderr / mse``."""
    eff = 1.0 / (mse * seconds)
    if mse_stderr is None:
        return eff
    return eff, eff * mse_stderr / mse

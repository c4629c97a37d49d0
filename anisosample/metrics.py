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
* :func:`expected_power_spectrum`, :func:`expected_power_spectrum_grid`: ``<P_S>`` over a stack
  of point sets ``(R, n, 2)`` by the one engine (:mod:`anisosample.spectrum`); a sampler's
  realizations: :func:`anisosample.diagnostics.sampler_sets`.
* :func:`radial_profile`, :func:`angular_profile`: a centred spectrum's means over rings and
  over directions.
* :func:`variance_terms`, :func:`predicted_variance`: W Eq. 5, an estimator's variance from the
  pattern's and the integrand's spectra (the one implementation; ``diagnostics`` splits it by
  region).
* :func:`wraparound_discrepancy`: Hickernell's wrap-around L2 discrepancy, a shift-invariant
  uniformity score (itself W Eq. 5's sum for one fixed spectral weight).
"""

from __future__ import annotations

import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._validate import check_choice, check_int, check_points

__all__ = ["axial_distance_deg", "nearest_neighbour_distance", "midpoint_grid", "off_axis_deg",
           "grid_values", "ImageError", "image_error", "mse_ratio", "efficiency",
           "geometric_mean",
           "expected_power_spectrum", "expected_power_spectrum_grid", "radial_profile",
           "angular_profile", "variance_terms", "predicted_variance",
           "wraparound_discrepancy"]

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


def off_axis_deg(d) -> np.ndarray | np.floating:
    """Distance (degrees, float64 NumPy; a NumPy scalar for a scalar ``d``) of each direction
    ``d`` to the nearer of the two axes (0 and 90 degrees, modulo 90):
    ``min(d mod 90, 90 - d mod 90)``."""
    d = np.asarray(d) % 90.0
    return np.minimum(d, 90.0 - d)


def grid_values(f, n: int) -> np.ndarray:
    """``f`` (a callable over ``(..., 2)``, an equinox module or a plain function) on the
    :func:`midpoint_grid` of side ``n``: the ``(n, n)`` NumPy array ``values[i, j] = f((j + .5) /
    n, (i + .5) / n)`` (DESIGN's grid convention), evaluated in one jitted call."""
    import equinox as eqx

    xy = midpoint_grid(n)
    return np.asarray(eqx.filter_jit(lambda g, x: g(x))(f, jnp.asarray(xy)))


class ImageError(eqx.Module):
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


def geometric_mean(ratios) -> tuple[float, float]:
    """``(g, its standard error)`` of positive ratios (e.g. per-pixel variance ratios, every
    pixel weighing the same): ``g = exp(mean(log r))`` and ``g sd(log r) / sqrt(n)`` (the delta
    method on the mean of the logs: the items' spread and each ratio's own noise together).
    ``ValueError`` for fewer than two ratios or one that is not finite and positive."""
    r = np.asarray(ratios, float)
    if r.ndim != 1 or r.size < 2 or not np.all(np.isfinite(r) & (r > 0)):
        raise ValueError(f"ratios must be at least two finite positive numbers, got {ratios!r:.80}")
    lr = np.log(r)
    g = float(np.exp(lr.mean()))
    return g, g * float(lr.std(ddof=1)) / lr.size ** 0.5


# --- power spectra of stacks of sets, and their profiles ------------------------------------------


def _check_sets(sets):
    """A stack of point sets ``(R, n, 2)``, ``R >= 1`` (each set is checked by the engine)."""
    shape = getattr(sets, "shape", None)
    if shape is None:
        sets = np.asarray(sets)
        shape = sets.shape
    if len(shape) != 3 or shape[-1] != 2 or shape[0] < 1 or shape[1] < 1:
        raise ValueError("sets must be a stack of point sets of shape (R, n, 2) with R, n >= 1, "
                         f"got shape {tuple(shape)}")
    return sets


def _mean_over_sets(sets, spectrum_of, progress):
    """``mean_r spectrum_of(sets[r])``, summed in the stack's order, then divided by ``R``."""
    from .progress import progress as _progress

    acc = None
    for pts in _progress(sets, desc="expected spectrum", disable=not progress):
        p = spectrum_of(pts)
        acc = p if acc is None else acc + p
    return acc / sets.shape[0]


def expected_power_spectrum(sets, freqs, *, method: str = "auto", progress: bool = False):
    """``<P_S(v)>``: the mean of :func:`anisosample.spectrum.power_spectrum` over a stack of
    point sets ``sets`` ``(R, n, 2)`` (realizations of a sampler, e.g.
    :func:`anisosample.diagnostics.sampler_sets`), at integer ``freqs`` ``(m, 2)``: ``(m,)``.
    Shifted realizations give the homogenized pattern's spectrum, the ``<P_S>`` of W Eq. 5."""
    from . import spectrum
    from ._validate import check_frequencies

    sets = _check_sets(sets)
    freqs = check_frequencies("freqs", freqs)
    method = spectrum.check_method(method)
    return _mean_over_sets(sets, lambda pts: spectrum.power_spectrum(pts, freqs, method=method),
                           progress)


def expected_power_spectrum_grid(sets, radius: int, *, method: str = "auto",
                                 progress: bool = False):
    """``<P_S>`` over a stack of sets ``(R, n, 2)`` on the centred grid of half-width
    ``radius`` (:func:`anisosample.spectrum.power_spectrum_grid`'s layout)."""
    from . import spectrum

    sets = _check_sets(sets)
    radius = check_int("radius", radius, minimum=1)
    method = spectrum.check_method(method)
    return _mean_over_sets(
        sets, lambda pts: spectrum.power_spectrum_grid(pts, radius, method=method), progress)


def _grid_coords(grid):
    from ._validate import check_spectrum_grid

    g = check_spectrum_grid("grid", grid)
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


# --- W Eq. 5: an estimator's variance from the spectra --------------------------------------------


def variance_terms(P_S, P_f, freqs=None, *, xp=np):
    """The terms ``<P_S(v)> P_f(v)`` of W Eq. 5, one per frequency given.

    ``P_S``: the (expected) power spectrum of the pattern (``P_S(0) = 1``, white noise ``1/N``);
    ``P_f``: the integrand's ``|F_f(v)|^2`` (e.g. ``f.power_spectrum(freqs)``), the same shape.
    ``xp=numpy`` (default): checked (same shape, finite, non-negative), in float64; with
    ``freqs`` (shape ``P_S.shape + (2,)``) the zero frequency's term is dropped. ``xp=jax.numpy``:
    traceable and unchecked, in the inputs' precision; with ``freqs`` the zero frequency's term is
    0 (the shape stays).
    """
    if xp is jnp:
        t = jnp.asarray(P_S) * jnp.asarray(P_f)
        if freqs is not None:
            t = jnp.where(jnp.any(jnp.asarray(freqs) != 0, axis=-1), t, 0)
        return t
    if xp is not np:
        raise ValueError(f"xp must be numpy or jax.numpy, got {xp!r}")
    ps = np.asarray(P_S, dtype=np.float64)
    pf = np.asarray(P_f, dtype=np.float64)
    if ps.shape != pf.shape:
        raise ValueError(f"P_S and P_f must have the same shape, got {ps.shape} and {pf.shape}")
    if not (np.all(np.isfinite(ps)) and np.all(np.isfinite(pf))):
        raise ValueError("P_S and P_f must be finite")
    if np.any(ps < 0) or np.any(pf < 0):
        raise ValueError("P_S and P_f must be non-negative (they are power spectra)")
    if freqs is not None:
        v = np.asarray(freqs)
        if v.shape != ps.shape + (2,):
            raise ValueError(f"freqs must have shape {ps.shape + (2,)}, got {v.shape}")
        keep = np.any(v != 0, axis=-1)
        ps, pf = ps[keep], pf[keep]
    return ps * pf


def predicted_variance(P_S, P_f, freqs=None, *, xp=np):
    """W Eq. 5: ``Var(I_N) = sum_{v != 0} <P_S(v)> P_f(v)`` over the given frequencies: the sum
    of :func:`variance_terms` (a float with ``xp=numpy``; a traceable scalar with
    ``xp=jax.numpy``, e.g. to differentiate the prediction through a synthesis).

    Exact for a fixed set under a random toroidal shift (``fourier_variance.md`` Sec. 2). The
    sum is truncated to the frequencies given: for a jump integrand the missing tail beyond
    radius ``K`` is about ``(edge length)^2 / (2 pi^2 N K)`` for a pattern that is white there.
    Without ``freqs`` the caller must have left the zero frequency out.
    """
    t = variance_terms(P_S, P_f, freqs, xp=xp)
    return jnp.sum(t) if xp is jnp else float(np.sum(t))


def wraparound_discrepancy(points, *, block: int = 1024) -> float:
    """Hickernell's wrap-around L2 discrepancy of ``points`` ``(n, 2)`` in ``[0, 1)^2`` (float64):

    ``WD^2 = -(4/3)^2 + (1/n^2) sum_{i,j} prod_k (3/2 - |d_ijk| (1 - |d_ijk|))``,
    ``d_ijk = x_ik - x_jk``. Invariant under toroidal shifts; in spectral form it is
    ``sum_{v != 0} P_S(v) c(v_x) c(v_y)`` with ``c(0) = 4/3``, ``c(k) = 1 / (2 pi^2 k^2)`` (the
    Fourier series of ``t (1 - t)``), i.e. W Eq. 5 for that weight. ``O(n^2)`` work in row blocks
    of ``block`` points."""
    check_points("points", points)
    block = check_int("block", block, minimum=1)
    p = np.asarray(points, dtype=np.float64)
    n = p.shape[0]
    total = 0.0
    for a in range(0, n, block):
        d = np.abs(p[a:a + block, None, :] - p[None, :, :])
        total += float(np.sum(np.prod(1.5 - d * (1.0 - d), axis=-1)))
    return math.sqrt(max(total / (n * n) - (4.0 / 3.0) ** 2, 0.0))

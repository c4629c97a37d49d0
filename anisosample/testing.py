"""A reusable chi-square goodness-of-fit test for warps (STYLE: Mitsuba 3's ``chi2.py``).

Draw ``n`` samples through ``warp.sample``, histogram them on an odd-resolution grid laid over
the output domain through a *chart* (a map from ``[0, 1]^2`` onto the domain), integrate the
warp's ``pdf`` over every cell (``k x k`` midpoints per cell, times the chart's area element),
pool the cells whose expected count is below ``min_expected``, and compare with Pearson's
chi-square. The significance level is corrected for the number of tests a caller runs (Sidak:
``1 - (1 - alpha)^(1/n_tests)``). On failure a picture of histogram vs. expected counts is
written and its path is in the result.

Charts by output measure:

* ``"area [0,1]^2"``: the unit square itself;
* ``"area disk"``: the square ``[-1, 1]^2`` (area element 4);
* ``"solid angle"``: the sphere by ``(z, phi) = (2 s - 1, 2 pi t)`` (area element ``4 pi``;
  equal-area cells);
* ``"area"`` (points on a surface in R^3): pass ``chart=(from_square, to_square)`` yourself,
  e.g. the surface's parameterization; the area element is ``|d from_square/ds x d/dt|``
  by ``jax.jacfwd``.

Example::

    from anisosample.testing import chi2_test
    result = chi2_test(my_warp, jax.random.key(0))
    assert result.passed, result
"""

from __future__ import annotations

import tempfile
from collections.abc import Callable
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from scipy import stats

from ._validate import check_int, check_key, check_positive_float
from .metrics import midpoint_grid

Chart = tuple[Callable, Callable]


class Chi2Result(eqx.Module):
    """The verdict of :func:`chi2_test`, an ``equinox.Module`` like the library's other results
    (the measured values are leaves; ``dof``, ``significance`` and ``figure`` are static).
    No solver stands behind it, so it has no optimistix status: ``passed`` is the verdict."""

    passed: bool
    p_value: float
    statistic: float
    dof: int = eqx.field(static=True)
    significance: float = eqx.field(static=True)
    pdf_integral: float
    """Integral of the pdf over the domain (should be ~1; a check of the pdf's normalisation)."""
    outside: int = 0
    """Samples in cells where the pdf's quadrature found no support (fails beyond a handful)."""
    figure: str | None = eqx.field(default=None, static=True)

    def __str__(self):
        verdict = "passed" if self.passed else "FAILED"
        fig = f"; histogram vs pdf: {self.figure}" if self.figure else ""
        return (
            f"chi-square {verdict}: p = {self.p_value:.3g} (significance {self.significance:.3g}),"
            f" statistic {self.statistic:.1f} on {self.dof} dof, pdf integral"
            f" {self.pdf_integral:.5f}, {self.outside} samples off the support{fig}"
        )


def _sphere_from_square(s):
    z = 2.0 * s[0] - 1.0
    phi = 2.0 * jnp.pi * s[1]
    r = jnp.sqrt(jnp.maximum(1.0 - z * z, 0.0))
    return jnp.stack([r * jnp.cos(phi), r * jnp.sin(phi), z])


def _sphere_to_square(w):
    w = w / jnp.linalg.norm(w)
    phi = jnp.arctan2(w[1], w[0])
    phi = jnp.where(phi < 0, phi + 2.0 * jnp.pi, phi)
    return jnp.stack([(w[2] + 1.0) / 2.0, phi / (2.0 * jnp.pi)])


def default_chart(measure: str) -> tuple[Callable, Callable, Callable]:
    """``(from_square, to_square, area_element)`` for a warp's output measure."""
    one = lambda s: jnp.ones((), jnp.float32)  # noqa: E731
    if measure == "area [0,1]^2":
        return (lambda s: s), (lambda x: x), one
    if measure == "area disk":
        return (lambda s: 2.0 * s - 1.0), (lambda x: (x + 1.0) / 2.0), (lambda s: 4.0 * one(s))
    if measure == "solid angle":
        return _sphere_from_square, _sphere_to_square, (lambda s: 4.0 * jnp.pi * one(s))
    raise ValueError(
        f"warps with output measure {measure!r} need chart=(from_square, to_square): a"
        " parameterization of the output surface and its inverse"
    )


def _chart_area(from_square):
    def area(s):
        jac = jax.jacfwd(from_square)(s)
        if jac.shape[0] == 2:
            return jnp.abs(jnp.linalg.det(jac))
        return jnp.linalg.norm(jnp.cross(jac[:, 0], jac[:, 1]))

    return area


def chi2_test(
    warp,
    key,
    *,
    n: int = 1_000_000,
    res: int = 51,
    subdivisions: int = 8,
    chart: Chart | None = None,
    alpha: float = 0.01,
    n_tests: int = 1,
    min_expected: float = 5.0,
    figure_path: str | Path | None = None,
) -> Chi2Result:
    """Pearson chi-square test of ``warp.sample`` against ``warp.pdf`` (see module docstring).

    ``res`` (odd, so that no cell edge sits on a symmetry axis of the domain) cells per side,
    ``subdivisions`` midpoints per cell side for the pdf integral, ``alpha`` the significance
    before the correction for ``n_tests`` tests.
    """
    key = check_key("key", key)
    n = check_int("n", n, minimum=1000)
    res = check_int("res", res, minimum=3)
    if res % 2 == 0:
        raise ValueError(f"res must be odd, got {res}")
    subdivisions = check_int("subdivisions", subdivisions, minimum=1)
    n_tests = check_int("n_tests", n_tests, minimum=1)
    alpha = check_positive_float("alpha", alpha)
    if alpha >= 1:
        raise ValueError(f"alpha must lie in (0, 1), got {alpha}")
    if chart is None:
        from_sq, to_sq, area = default_chart(warp.measure)
    else:
        from_sq, to_sq = chart
        area = _chart_area(from_sq)

    u = jax.random.uniform(key, (n, 2), dtype=jnp.float32)
    s = np.asarray(jax.jit(jax.vmap(lambda v: to_sq(warp.sample(v))))(u), np.float64)
    if not np.all(np.isfinite(s)):
        raise ValueError("the warp's sample returned NaN or Inf")
    # Zoom the grid onto the samples' bounding box in chart coordinates (padded by 2% of the
    # chart): small supports (a light seen from afar) still get res x res cells.
    lo = np.clip(s.min(axis=0) - 0.02, 0.0, 1.0)
    hi = np.clip(s.max(axis=0) + 0.02, 0.0, 1.0)
    observed, _, _ = np.histogram2d(
        s[:, 0], s[:, 1], bins=res, range=[[lo[0], hi[0]], [lo[1], hi[1]]]
    )
    # Mass outside the box (none if the sample's extremes bound the support) is checked below.
    cell_density = jax.jit(jax.vmap(lambda v: warp.pdf(from_sq(v)) * area(v)))

    def integrate(cells, k):
        """Mean of the density over k x k midpoints of each (row, col) cell, in box units."""
        sub = midpoint_grid(k, indexing="ij", dtype=np.float64).reshape(-1, 2)
        size = (hi - lo) / res
        pts = lo + (cells[:, None, :] + sub[None, :, :]) * size
        vals = cell_density(jnp.asarray(pts.reshape(-1, 2), jnp.float32))
        vals = np.asarray(vals, np.float64).reshape(len(cells), k * k)
        if not np.all(np.isfinite(vals)):
            raise ValueError("the warp's pdf returned NaN or Inf inside the domain")
        return vals

    idx = np.stack(np.meshgrid(np.arange(res), np.arange(res), indexing="ij"), -1).reshape(-1, 2)
    vals = integrate(idx, subdivisions)
    mean = vals.mean(axis=1)
    # Cells cut by the support's boundary (some midpoints in, some out), or holding samples
    # where no midpoint saw the support: integrate again with 8x finer midpoints.
    mixed = (vals.min(axis=1) == 0) & ((vals.max(axis=1) > 0) | (observed.reshape(-1) > 0))
    # ... and cells where the pdf jumps (piecewise-constant tables, kinks): same treatment.
    mixed |= (vals.max(axis=1) - vals.min(axis=1)) > 0.1 * np.maximum(mean, 1e-300)
    if np.any(mixed):
        mean[mixed] = integrate(idx[mixed], 8 * subdivisions).mean(axis=1)
    box_area = float(np.prod(hi - lo))
    expected = (mean * box_area / res**2 * n).reshape(res, res)
    pdf_integral = float(expected.sum() / n)

    obs, exp = observed.reshape(-1), expected.reshape(-1)
    # Samples in cells where even the fine quadrature saw no support: a sliver of a cell cut by
    # the support's boundary, or a sampler leaving its support. Tolerate a handful (quadrature),
    # fail beyond max(10, 1e-5 n).
    outside = int(obs[exp == 0].sum())
    small = exp < min_expected
    bins_obs = np.append(obs[~small], obs[small].sum())
    bins_exp = np.append(exp[~small], exp[small].sum())
    if bins_exp[-1] == 0:
        bins_obs, bins_exp = bins_obs[:-1], bins_exp[:-1]
    else:
        bins_obs[-1] -= outside
    # Normalise expected counts to the observed total so a tiny normalisation error of the
    # quadrature does not dominate; pdf_integral reports it separately.
    bins_exp = bins_exp * bins_obs.sum() / bins_exp.sum()
    stat = float(np.sum((bins_obs - bins_exp) ** 2 / bins_exp))
    dof = int(len(bins_obs) - 1)
    p = float(stats.chi2.sf(stat, dof))
    if outside > max(10, 1e-5 * n):
        p = 0.0
    significance = 1.0 - (1.0 - alpha) ** (1.0 / n_tests)
    passed = bool(p >= significance) and abs(pdf_integral - 1.0) < 1e-2
    figure = None
    if not passed:
        figure = str(_plot(observed, expected, figure_path, warp))
    return Chi2Result(passed=passed, p_value=p, statistic=stat, dof=dof,
                      significance=significance, pdf_integral=pdf_integral,
                      outside=outside, figure=figure)


def _plot(observed, expected, figure_path, warp) -> Path:
    # No matplotlib.use(): without a display pyplot falls back to Agg by itself, and with one
    # the user's backend stays as it is.
    import matplotlib.pyplot as plt

    if figure_path is None:
        figure_path = Path(tempfile.mkdtemp(prefix="chi2_")) / f"{type(warp).__name__}.png"
    figure_path = Path(figure_path)
    figure_path.parent.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(1, 3, figsize=(12, 4))
    vmax = max(observed.max(), expected.max())
    for ax, img, title in (
        (axes[0], observed, "histogram"),
        (axes[1], expected, "integrated pdf"),
    ):
        im = ax.imshow(img.T, origin="lower", extent=(0, 1, 0, 1), vmin=0, vmax=vmax)
        ax.set_title(title)
        fig.colorbar(im, ax=ax)
    diff = (observed - expected) / np.sqrt(np.maximum(expected, 1.0))
    im = axes[2].imshow(diff.T, origin="lower", extent=(0, 1, 0, 1), cmap="RdBu_r", vmin=-5, vmax=5)
    axes[2].set_title("(obs - exp) / sqrt(exp)")
    fig.colorbar(im, ax=axes[2])
    fig.suptitle(f"chi-square test of {type(warp).__name__}")
    fig.savefig(figure_path, dpi=80)
    plt.close(fig)
    return figure_path

"""Matplotlib helpers shared by the experiment scripts, so every figure reads the same way."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

__all__ = ["new_figure", "spectrum_panel", "points_panel", "convergence_panel", "save_figure",
           "save_points_figure", "direction_rgb", "save_direction_map"]


def _plt():
    # No matplotlib.use(): without a display pyplot falls back to Agg by itself, and with one
    # the user's backend stays as it is.
    import matplotlib.pyplot as plt

    return plt


def new_figure(nrows: int = 1, ncols: int = 1, *, size: float = 3.2, squeeze: bool = False, **kw):
    """A figure with ``nrows x ncols`` panels of ``size`` inches each: ``(fig, axes)``."""
    plt = _plt()
    fig, axes = plt.subplots(
        nrows,
        ncols,
        figsize=(size * ncols, size * nrows),
        squeeze=squeeze,
        layout="constrained",
        **kw,
    )
    return fig, axes


def spectrum_panel(
    ax,
    grid,
    *,
    n: int,
    title: str | None = None,
    vmax: float = 2.0,
    directions_deg: Sequence[float] = (),
):
    """Show ``N P_S`` of a centred spectrum grid (rows ``v_y``) upright, white noise at 1.

    ``directions_deg`` marks the spectral directions a set was made for with short red ticks at
    the border, leaving the spectrum itself visible.
    """
    g = np.asarray(grid)
    r = g.shape[0] // 2
    im = ax.imshow(
        n * g,
        origin="lower",
        cmap="gray",
        vmin=0.0,
        vmax=vmax,
        extent=(-r - 0.5, r + 0.5, -r - 0.5, r + 0.5),
        interpolation="nearest",
    )
    for d in directions_deg:
        t = np.radians(d)
        ends = np.array([0.86, 1.0]) * r
        for sign in (-1.0, 1.0):
            ax.plot(sign * ends * np.cos(t), sign * ends * np.sin(t), color="tab:red", lw=1.5)
    ax.set_xlim(-r - 0.5, r + 0.5)
    ax.set_ylim(-r - 0.5, r + 0.5)
    ax.set_xticks([])
    ax.set_yticks([])
    if title:
        ax.set_title(title, fontsize=9)
    return im


def points_panel(ax, points, *, title: str | None = None, color: str = "k",
                 marker_size: float | None = None):
    """Scatter a point set ``(n, 2)`` on the unit square, ``y`` upwards, equal aspect.

    The marker area shrinks with ``n`` (``marker_size`` overrides it, in points^2) so that the
    set's structure stays visible from 16 to 2^16 points.
    """
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2:
        raise ValueError(f"points must have shape (n, 2), got {p.shape}")
    if not np.all(np.isfinite(p)):
        raise ValueError("points contains NaN or Inf")
    n = p.shape[0]
    size = marker_size if marker_size is not None else float(np.clip(2000.0 / max(n, 1), 0.05, 16))
    art = ax.scatter(p[:, 0], p[:, 1], s=size, c=color, linewidths=0)
    ax.set_xlim(0.0, 1.0)
    ax.set_ylim(0.0, 1.0)
    ax.set_aspect("equal")
    ax.set_xticks([0.0, 0.5, 1.0])
    ax.set_yticks([0.0, 0.5, 1.0])
    ax.tick_params(labelsize=7)
    if title:
        ax.set_title(title, fontsize=9)
    return art


def convergence_panel(
    ax,
    ns,
    variances,
    *,
    label: str,
    slope: float | None = None,
    slope_ci: tuple[float, float] | None = None,
    lower=None,
    upper=None,
    **line_kw,
):
    """Log-log variance against ``n`` with the fitted slope (and its interval) in the legend."""
    ns = np.asarray(ns, dtype=float)
    v = np.asarray(variances, dtype=float)
    text = label
    if slope is not None:
        text += f" ({slope:+.2f}"
        if slope_ci is not None:
            text += f" [{slope_ci[0]:+.2f}, {slope_ci[1]:+.2f}]"
        text += ")"
    (line,) = ax.loglog(ns, v, marker="o", ms=3, lw=1.2, label=text, **line_kw)
    if lower is not None and upper is not None:
        ax.fill_between(ns, lower, upper, color=line.get_color(), alpha=0.15, lw=0)
    ax.set_xscale("log", base=2)
    ax.set_xlabel("N")
    ax.set_ylabel("Var")
    ax.grid(True, which="both", alpha=0.25)
    return line


def save_figure(fig, path, *, formats: Sequence[str] = ("png",), dpi: int = 150,
                overwrite: bool = True) -> list[Path]:
    """Save ``fig`` as ``path`` with each suffix in ``formats`` (atomic), and close it.

    Experiment scripts own their ``results/<name>/`` folder and rewrite their figures there
    (``overwrite=True``, the default); user-facing callers pass ``overwrite=False``.
    """
    from .io import atomic_path

    plt = _plt()
    out = []
    base = Path(path)
    for fmt in formats:
        p = base.with_suffix("." + fmt)
        with atomic_path(p, overwrite=overwrite) as tmp:
            fig.savefig(tmp, format=fmt, dpi=dpi, bbox_inches="tight")
        out.append(p)
    plt.close(fig)
    return out


def save_points_figure(path, points, *, title: str | None = None, size: float = 4.0,
                       overwrite: bool = False) -> Path:
    """Draw a point set (:func:`points_panel`) into one PNG or PDF/SVG figure at ``path``;
    refuses to replace an existing file unless ``overwrite``."""
    path = Path(path)
    fmt = path.suffix.lower().lstrip(".")
    if fmt not in ("png", "pdf", "svg"):
        raise ValueError(f"figure file name must end in .png, .pdf or .svg, got {path.name}")
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists; pass overwrite=True (CLI: --force) to replace it")
    fig, axes = new_figure(size=size)
    points_panel(axes[0, 0], points, title=title)
    (out,) = save_figure(fig, path, formats=(fmt,), overwrite=overwrite)
    return out


# --- per-block direction maps (W Fig. 7) ----------------------------------------------------------


def direction_rgb(directions_deg, valid, *, none=0.5) -> np.ndarray:
    """Colours ``(..., 3)`` for directions: hue = direction / 180 (a cyclic map for axial
    angles), grey ``none`` where ``valid`` is false."""
    import matplotlib

    d, v = np.asarray(directions_deg), np.asarray(valid)
    rgb = matplotlib.colormaps["hsv"](np.clip(d, 0, 180) / 180.0)[..., :3]
    return np.where(v[..., None], rgb, none)


def save_direction_map(path, estimate, *, overwrite: bool = False) -> Path:
    """PNG of per-block directions at the image's size (row 0 on top, like the render): one
    panel per estimate slot, hue = direction / 180, black where there is none.

    ``estimate``: a :class:`anisosample.render.estimation.BlockEstimate` or a
    :class:`anisosample.render.aligned.BlockSampler` holding one."""
    from . import io

    path = Path(path)
    if path.suffix != ".png":
        raise ValueError(f"the direction map must end in .png, got {path.name}")
    inner = getattr(estimate, "estimate", None)
    if hasattr(estimate, "method") and hasattr(estimate, "block_px"):  # a BlockSampler
        if inner is None:
            raise ValueError("this sampler holds no estimate to draw")
        estimate, inner = inner, getattr(inner, "estimate", None)
    if not (hasattr(estimate, "block_px") and hasattr(inner, "directions_deg")):
        raise TypeError(f"estimate must be a BlockEstimate or BlockSampler, got "
                        f"{type(estimate).__name__}")
    bp = estimate.block_px
    rgb = direction_rgb(inner.directions_deg, inner.valid, none=0.0)  # (rows, cols, k, 3)
    panels = [np.kron(rgb[:, :, s], np.ones((bp, bp, 1)))[:estimate.height, :estimate.width]
              for s in range(rgb.shape[2])]
    panels = [np.pad(p, ((0, 0), (0, 2), (0, 0)), constant_values=1.0) for p in panels]
    return io.save_png(path, np.clip(np.concatenate(panels, axis=1)[:, :-2], 0, 1),
                       overwrite=overwrite)

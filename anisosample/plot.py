"""Matplotlib helpers shared by the experiment scripts, so every figure reads the same way, and
the pictures of spectra (:func:`save_spectrum_figure`, a figure; :func:`save_spectrum_image`,
one pixel per frequency or the raw grid as EXR)."""

from __future__ import annotations

import numbers
from collections.abc import Sequence
from pathlib import Path

import numpy as np

__all__ = ["new_figure", "spectrum_image", "spectrum_panel", "save_spectrum_figure",
           "save_spectrum_image", "points_panel",
           "convergence_panel", "save_figure", "save_points_figure", "direction_rgb",
           "axial_colormap", "direction_map_rgb", "direction_map_panel", "direction_legend",
           "save_direction_map", "SPECTRUM_SCALES", "LOG_FLOOR", "NO_ESTIMATE_RGB"]


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


SPECTRUM_SCALES = ("linear", "log")
"""The colour scales of :func:`spectrum_panel`: linear, or logarithmic (``LogNorm``)."""

LOG_FLOOR = 1e-3
"""Default bottom of the log scale, in units of white noise (``N P_S``): darker is shown at it."""


def _check_clip(clip) -> float | None:
    """``clip``: None (no clipping) or a finite multiple of the white-noise level > 0."""
    if clip is None:
        return None
    if isinstance(clip, bool) or not isinstance(clip, numbers.Real):
        raise TypeError(f"clip must be None (no clipping) or a number (a multiple of the "
                        f"white-noise level), got {type(clip).__name__} {clip!r}")
    c = float(clip)
    if not (np.isfinite(c) and c > 0):
        raise ValueError(f"clip must be None (no clipping) or a finite multiple of the "
                         f"white-noise level > 0, got {clip!r}")
    return c


def spectrum_image(grid, *, n: int, scale: str = "linear", clip: float | None = 2.0,
                   log_floor: float = LOG_FLOOR) -> np.ndarray:
    """The array :func:`spectrum_panel` shows: ``N P_S`` of a centred spectrum grid, so that
    white noise is 1 (W Eq. 6 normalises ``P_S(0) = 1``, white noise ``1/N``).

    ``grid`` is :func:`anisosample.spectrum.power_spectrum_grid`'s ``(2r+1, 2r+1)`` array,
    ``grid[i, j] = P_S(j - r, i - r)`` (rows ``v_y``); the result keeps that layout, to be shown
    with ``origin="lower"``. ``clip`` (a multiple of white noise, or None) caps the values;
    ``scale="log"`` also raises them to ``log_floor`` (the log scale's bottom), nothing else.
    """
    from ._validate import check_choice, check_int, check_positive_float, check_spectrum_grid

    g = check_spectrum_grid("grid", grid)
    n = check_int("n", n, minimum=1)
    scale = check_choice("scale", scale, SPECTRUM_SCALES)
    clip = _check_clip(clip)
    img = n * g
    if scale == "log":
        floor = check_positive_float("log_floor", log_floor)
        if clip is not None and floor >= clip:
            raise ValueError(f"log_floor must be below clip={clip:g}, got {floor:g}")
        img = np.maximum(img, floor)
    if clip is not None:
        img = np.minimum(img, clip)
    return img


def spectrum_panel(
    ax,
    grid,
    *,
    n: int,
    title: str | None = None,
    scale: str = "linear",
    clip: float | None = 2.0,
    directions_deg: Sequence[float] = (),
    colorbar: bool = True,
    log_floor: float = LOG_FLOOR,
    cmap: str = "gray",
):
    """Show ``N P_S`` of a centred spectrum grid (:func:`spectrum_image`; white noise at 1) on
    integer frequency axes centred at 0, ``v_x`` to the right and ``v_y`` up, with a colour bar.

    ``scale``: ``"linear"`` (from 0) or ``"log"`` (``LogNorm`` from ``log_floor``). ``clip``: the
    top of the colour range as a multiple of white noise, values above it shown at it (the
    colour bar's arrow says so); ``None`` clips nothing and scales to the largest value away from
    ``v = 0`` (``N P_S(0) = N`` always, and would leave the rest black). ``directions_deg``:
    spectral directions marked as dashed lines through the origin along ``(cos t, sin t)``
    (DESIGN's convention), so that a set dark along them shows its dark line under the dashes.
    Returns the image artist.
    """
    import matplotlib.colors as mcolors
    from matplotlib.ticker import MaxNLocator

    from ._validate import check_directions_deg

    img = spectrum_image(grid, n=n, scale=scale, clip=clip, log_floor=log_floor)
    dirs = check_directions_deg("directions_deg", directions_deg, allow_empty=True)
    r = img.shape[0] // 2
    if clip is not None:
        top = float(clip)
    else:
        away = img.copy()
        away[r, r] = -np.inf
        top = float(away.max()) if img.size > 1 else float(img.max())
    if scale == "log":
        top = max(top, 10.0 * log_floor)
        norm = mcolors.LogNorm(vmin=log_floor, vmax=top)
    else:
        norm = mcolors.Normalize(vmin=0.0, vmax=top if top > 0 else 1.0)
    lim = (-r - 0.5, r + 0.5)
    im = ax.imshow(img, origin="lower", cmap=cmap, norm=norm, extent=(*lim, *lim),
                   interpolation="nearest")
    for d in dirs:
        t = np.radians(d)
        ends = np.array([-1.0, 1.0]) * 2.0 * (r + 1)
        ax.plot(ends * np.cos(t), ends * np.sin(t), color="tab:red", lw=0.8, ls=(0, (4, 4)),
                alpha=0.75)
    ax.set_xlim(*lim)
    ax.set_ylim(*lim)
    ax.set_aspect("equal")
    for axis in (ax.xaxis, ax.yaxis):
        axis.set_major_locator(MaxNLocator(nbins=5, integer=True, symmetric=True))
    ax.tick_params(labelsize=7)
    ax.set_xlabel(r"frequency $\nu_x$", fontsize=7, labelpad=1)
    ax.set_ylabel(r"frequency $\nu_y$", fontsize=7, labelpad=1)
    if title:
        ax.set_title(title, fontsize=9)
    if colorbar:
        extend = {(False, False): "neither", (True, False): "min", (False, True): "max",
                  (True, True): "both"}[(scale == "log", clip is not None)]
        label = r"$N\,P_S$ (white noise = 1)" + ("" if clip is None else f", clipped at {clip:g}")
        cb = ax.figure.colorbar(im, ax=ax, extend=extend, shrink=0.85, pad=0.02)
        cb.set_label(label, fontsize=7)
        cb.ax.tick_params(labelsize=6)
    return im


def _figure_path(path, overwrite: bool, what: str = "figure file name") -> tuple[Path, str]:
    """``(path, format)`` of a figure about to be written: a ``.png``, ``.pdf`` or ``.svg``
    name, and no existing file unless ``overwrite``."""
    path = Path(path)
    fmt = path.suffix.lower().lstrip(".")
    if fmt not in ("png", "pdf", "svg"):
        raise ValueError(f"{what} must end in .png, .pdf or .svg, got {path.name}")
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists; pass overwrite=True (CLI: --force) to replace it")
    return path, fmt


def save_spectrum_figure(path, grid, *, n: int, scale: str = "linear",
                         clip: float | None = 2.0, directions_deg: Sequence[float] = (),
                         title: str | None = None, size: float = 4.0,
                         overwrite: bool = False) -> Path:
    """Draw a centred spectrum grid (:func:`spectrum_panel`: axes, colour bar, marked
    directions) into one PNG, PDF or SVG figure at ``path``; refuses to replace an existing file
    unless ``overwrite``. ``anisosample spectrum PTS -o s.png`` writes this picture."""
    path, fmt = _figure_path(path, overwrite)
    spectrum_image(grid, n=n, scale=scale, clip=clip)  # bad input before a figure is opened
    fig, axes = new_figure(size=size)
    try:
        spectrum_panel(axes[0, 0], grid, n=n, title=title, scale=scale, clip=clip,
                       directions_deg=directions_deg)
    except BaseException:
        _plt().close(fig)
        raise
    (out,) = save_figure(fig, path, formats=(fmt,), overwrite=overwrite)
    return out


def save_spectrum_image(path, grid, *, n: int, vmax: float = 2.0, overwrite: bool = False) -> Path:
    """Save a centred spectrum as PNG (``N P_S`` clipped to ``[0, vmax]``, grey) or EXR (``P_S``).

    The PNG is a picture, upright: ``v_y`` grows upwards, ``v_x`` to the right, ``v = 0`` at the
    centre. The EXR is data: the grid itself, ``values[i, j] = P_S(j - r, i - r)`` (DESIGN's
    grid convention, no flip: ``io.read_exr`` / ``io.load_grid`` give back ``grid``, and an EXR
    viewer shows ``v_y`` growing downwards), with ``n``, ``radius`` and that layout in its
    metadata (``io.read_exr(path, metadata=True)``). The PNG is one pixel per frequency, without
    axes; :func:`save_spectrum_figure` draws the figure a person reads (frequency
    axes, colour bar, linear or log scale, optional clip, marked directions).
    """
    from . import io
    from ._validate import check_int, check_positive_float, check_spectrum_grid

    path = Path(path)
    g = check_spectrum_grid("grid", grid)
    n = check_int("n", n, minimum=1)
    vmax = check_positive_float("vmax", vmax)  # vmax <= 0 or NaN gave a blank/garbled picture
    upright = g[::-1]
    if path.suffix == ".exr":
        return io.write_exr(
            path,
            g.astype(np.float32),  # the grid, not the upright picture (issue 27)
            {"quantity": "P_S (white noise = 1/n)", "n": n, "radius": (g.shape[0] - 1) // 2,
             "layout": "values[i, j] = P_S(v_x = j - radius, v_y = i - radius); row 0 is "
                       "v_y = -radius (DESIGN grid, no image flip)"},
            overwrite=overwrite,
        )
    if path.suffix == ".png":
        return io.save_png(
            path,
            np.clip(n * upright, 0.0, vmax),
            cmap="gray",
            vmin=0.0,
            vmax=vmax,
            overwrite=overwrite,
        )
    raise ValueError(f"path must end in .png or .exr, got {path.name}")


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
    path, fmt = _figure_path(path, overwrite)
    fig, axes = new_figure(size=size)
    points_panel(axes[0, 0], points, title=title)
    (out,) = save_figure(fig, path, formats=(fmt,), overwrite=overwrite)
    return out


# --- per-block direction maps (W Fig. 7) ----------------------------------------------------------

NO_ESTIMATE_RGB = (0.62, 0.62, 0.62)
"""Colour of blocks without an estimate: a neutral grey, which the fully saturated hues of
:func:`direction_rgb` never produce (the maps also hatch those blocks)."""


def direction_rgb(directions_deg, valid, *, none=NO_ESTIMATE_RGB) -> np.ndarray:
    """Colours ``(..., 3)`` for axial spectral directions: hue = ``2 theta`` on the hue circle
    (full saturation and value), ``none`` (an RGB triple or a grey level) where ``valid`` is false.

    Doubling the angle is the standard colour code for axial data: ``theta`` and
    ``theta + 180`` are one direction and get one colour *on purpose*, and perpendicular
    directions get opposite hues (0: red, 45: yellow-green, 90: cyan, 135: violet). NaN
    directions must be marked invalid (they are coloured ``none``, never NaN).
    """
    from matplotlib.colors import hsv_to_rgb

    d = np.asarray(directions_deg, dtype=np.float64)
    v = np.asarray(valid, dtype=bool)
    finite = np.isfinite(d)
    if np.any(~finite & v):
        raise ValueError("directions_deg holds NaN or Inf where valid is true")
    hue = np.mod(2.0 * np.where(finite, d, 0.0), 360.0) / 360.0
    rgb = hsv_to_rgb(np.stack([hue, np.ones_like(hue), np.ones_like(hue)], axis=-1))
    fill = np.broadcast_to(np.asarray(none, dtype=np.float64), (3,))
    return np.where(v[..., None], rgb, fill)


def axial_colormap(samples: int = 360):
    """The :func:`direction_rgb` colours as a matplotlib colormap over ``[0, 180]`` degrees (for
    colour bars: ``ScalarMappable(Normalize(0, 180), axial_colormap())``)."""
    from matplotlib.colors import ListedColormap

    t = np.linspace(0.0, 180.0, samples, endpoint=False)
    return ListedColormap(direction_rgb(t, np.ones_like(t, dtype=bool)), name="axial")


def direction_map_rgb(directions_deg, valid, *, block: int, shape: tuple[int, int],
                      none=NO_ESTIMATE_RGB) -> np.ndarray:
    """Per-block directions painted over their pixels: ``(k, h, w, 3)``.

    ``directions_deg``, ``valid``: ``(rows, cols, k)`` (an estimate's arrays; ``(rows, cols)``
    counts as ``k = 1``); block ``(a, b)`` covers rows ``a block .. a block + block - 1`` and the
    same columns (nearest upsampling), cropped to ``shape = (h, w)``. Rows stay in the
    estimate's order: show row 0 at the bottom for DESIGN's grids, at the top for images.
    """
    from ._validate import check_int

    block = check_int("block", block, minimum=1)
    d = np.asarray(directions_deg, dtype=np.float64)
    v = np.asarray(valid, dtype=bool)
    if d.ndim == 2:
        d, v = d[..., None], v[..., None]
    if d.ndim != 3 or v.shape != d.shape:
        raise ValueError(f"directions_deg and valid must both have shape (rows, cols, k), got "
                         f"{d.shape} and {v.shape}")
    h, w = (check_int("shape[0]", shape[0], minimum=1), check_int("shape[1]", shape[1], minimum=1))
    rows, cols = d.shape[:2]
    if not (rows * block >= h > (rows - 1) * block and cols * block >= w > (cols - 1) * block):
        raise ValueError(f"shape {(h, w)} does not fit {rows}x{cols} blocks of {block}")
    rgb = direction_rgb(d, v, none=none)  # (rows, cols, k, 3)
    up = np.repeat(np.repeat(rgb, block, axis=0), block, axis=1)[:h, :w]
    return np.moveaxis(up, 2, 0)


def direction_map_panel(ax, directions_deg, valid, *, block: int, shape: tuple[int, int],
                        origin: str = "lower", title: str | None = None):
    """One slot of a per-block direction map on ``ax``: :func:`direction_map_rgb` at the image's
    size, blocks without an estimate grey and hatched.

    ``directions_deg``, ``valid``: ``(rows, cols)``. ``origin="lower"``: DESIGN's grids (row 0,
    the smallest y, at the bottom; axes in grid cells); ``"upper"``: rendered images (row 0 on
    top; axes in pixels). Hue is the direction in the integrand's own square (y up) either way.
    """
    from matplotlib.collections import PatchCollection
    from matplotlib.patches import Rectangle

    from ._validate import check_choice

    origin = check_choice("origin", origin, ("lower", "upper"))
    d, v = np.asarray(directions_deg), np.asarray(valid, dtype=bool)
    (rgb,) = direction_map_rgb(d, v, block=block, shape=shape)
    h, w = rgb.shape[:2]
    extent = (0, w, 0, h) if origin == "lower" else (0, w, h, 0)
    im = ax.imshow(rgb, origin=origin, extent=extent, interpolation="nearest")
    rects = [Rectangle((b * block, a * block), min(block, w - b * block), min(block, h - a * block))
             for a, b in zip(*np.nonzero(~v), strict=True)]
    if rects:
        ax.add_collection(PatchCollection(rects, facecolor="none", edgecolor=(0.3, 0.3, 0.3),
                                          hatch="////", linewidth=0.0))
    ax.set_xlim(0, w)
    ax.set_ylim(*((0, h) if origin == "lower" else (h, 0)))
    ax.set_aspect("equal")
    ax.tick_params(labelsize=7)
    if origin == "lower":
        ax.set_xlabel("x (grid column)", fontsize=7)
        ax.set_ylabel("y (grid row)", fontsize=7)
    else:
        ax.set_xlabel("pixel column", fontsize=7)
        ax.set_ylabel("pixel row (top down)", fontsize=7)
    if title:
        ax.set_title(title, fontsize=9)
    return im


def direction_legend(ax) -> None:
    """The key of :func:`direction_rgb` on ``ax``: a half wheel whose wedge at angle ``theta``
    (from +x towards +y) has that direction's colour, a note that 0 and 180 degrees share their
    colour on purpose (axial directions), and the grey hatched swatch of "no estimate"."""
    from matplotlib.patches import Rectangle, Wedge

    step = 2.0
    for t in np.arange(0.0, 180.0, step):
        ax.add_patch(Wedge((0, 0), 1.0, t, t + step, width=0.45, linewidth=0,
                           facecolor=direction_rgb(t + step / 2, True)))
    for t in (0, 45, 90, 135, 180):
        c, s = np.cos(np.radians(t)), np.sin(np.radians(t))
        ax.plot([1.0 * c, 1.08 * c], [1.0 * s, 1.08 * s], color="k", lw=0.8)
        ax.text(1.22 * c, 1.22 * s, f"{t}°", ha="center", va="center", fontsize=7)
    ax.text(0, 0.12, "spectral\ndirection", ha="center", va="bottom", fontsize=7)
    ax.text(0, -0.12, "hue = 2θ: 0° and 180° are\none axial direction, one\ncolour "
            "on purpose", ha="center", va="top", fontsize=6.5)
    ax.add_patch(Rectangle((-1.0, -1.25), 0.3, 0.22, facecolor=NO_ESTIMATE_RGB,
                           edgecolor=(0.3, 0.3, 0.3), hatch="////", linewidth=0.6))
    ax.text(-0.6, -1.14, "no estimate", ha="left", va="center", fontsize=7)
    ax.set_xlim(-1.4, 1.4)
    ax.set_ylim(-1.35, 1.4)
    ax.set_aspect("equal")
    ax.axis("off")


def _map_arrays(estimate, block, shape, origin):
    """``(directions (rows, cols, k), valid, block, shape, origin)`` from what
    :func:`save_direction_map` accepts."""
    inner = getattr(estimate, "estimate", None)
    if hasattr(estimate, "point_set") and hasattr(estimate, "block_px"):  # a BlockSampler
        if inner is None:
            raise ValueError("this sampler holds no estimate to draw")
        estimate, inner = inner, getattr(inner, "estimate", None)
    if hasattr(estimate, "block_px") and hasattr(inner, "directions_deg"):  # a BlockEstimate
        return (inner.directions_deg, inner.valid, estimate.block_px,
                (estimate.height, estimate.width), origin or "upper")
    if hasattr(estimate, "directions_deg") and hasattr(estimate, "valid"):  # estimate_blocks
        if block is None or shape is None:
            raise ValueError("a directions.estimate_blocks result needs block= (its "
                             "samples_per_block) and shape= (the grid's (h, w))")
        return estimate.directions_deg, estimate.valid, block, shape, origin or "lower"
    raise TypeError(f"estimate must be a render BlockEstimate or BlockSampler, or a "
                    f"directions.estimate_blocks result, got {type(estimate).__name__}")


def save_direction_map(path, estimate, *, block: int | None = None,
                       shape: tuple[int, int] | None = None, origin: str | None = None,
                       overwrite: bool = False) -> Path:
    """PNG (or PDF/SVG) of per-block directions at the image's size: one panel per estimate
    slot (strongest first), each block painted over its pixels with :func:`direction_rgb`'s
    axial hue, blocks without an estimate grey and hatched, and the half-wheel key
    (:func:`direction_legend`). Refuses to replace an existing file unless ``overwrite``.

    ``estimate``: a render :class:`~anisosample.render.estimation.BlockEstimate` or
    :class:`~anisosample.render.aligned.BlockSampler` (row 0 on top, like the image), or the
    :func:`anisosample.directions.estimate_blocks` result for a DESIGN grid, which needs
    ``block`` (its ``samples_per_block``) and ``shape`` (the grid's ``(h, w)``) and is shown
    with row 0 (the smallest y) at the bottom. ``origin`` overrides that choice.
    """
    path, fmt = _figure_path(path, overwrite, what="the direction map")
    d, v, block, shape, origin = _map_arrays(estimate, block, shape, origin)
    d, v = np.asarray(d), np.asarray(v, dtype=bool)
    if d.ndim == 2:
        d, v = d[..., None], v[..., None]
    k = d.shape[-1]
    if k == 0:
        raise ValueError("the estimate holds no direction slots (k = 0): nothing to draw")
    direction_map_rgb(d, v, block=block, shape=shape)  # bad shapes before a figure is opened
    h, w = shape
    side = float(np.clip(max(h, w) / 150.0, 3.2, 8.0))  # about one screen pixel per pixel
    panel_w = side * w / max(h, w)
    fig, axes = new_figure(1, k + 1, size=side, gridspec_kw={"width_ratios": [w / max(h, w)] * k
                                                                 + [2.6 / side]})
    fig.set_size_inches(panel_w * k + 2.6, side * h / max(h, w) + 0.6)
    try:
        for s in range(k):
            title = "strongest direction" if s == 0 else f"direction {s + 1}"
            direction_map_panel(axes[0, s], d[..., s], v[..., s], block=block, shape=shape,
                                origin=origin, title=title)
        direction_legend(axes[0, k])
    except BaseException:
        _plt().close(fig)
        raise
    (out,) = save_figure(fig, path, formats=(fmt,), overwrite=overwrite)
    return out

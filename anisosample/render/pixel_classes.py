"""Pixel classes: what kind of 2D integrand each pixel's light (or lens) sample sees (W Sec. 6.2).

W's rendered gain lives on pixels whose light integrand has a straight discontinuity (a
penumbra), not on fully lit or fully dark ones, where every good sampler already converges at
its smooth-integrand rate. To measure the claim where it lives, each pixel's integrand
``f_q`` (:func:`anisosample.render.pixel_integrand`) is sampled on a dense ``g x g`` grid
(DESIGN's grid convention: ``values[i, j] = f_q((j + .5) / g, (i + .5) / g)``) and classified:

* ``"lit"``: no jump anywhere (the light fully visible; a horizon crossing, where the cosine
  goes to zero continuously, is no jump);
* ``"occluded"``: constant: zero (the light hidden, facing away, or no surface hit), or an
  emitter seen directly whose light integrand is zero (nothing varies: zero variance);
* ``"one-edge"``: the jumps lie on one straight line (within ``tolerance_cells`` grid cells);
  its *spectral direction* is the line's normal (DESIGN: an edge running at ``theta + 90`` puts
  its energy along ``theta``);
* ``"corner"``: the jumps lie on two straight lines at least ``min_angle_deg`` apart (two
  edges, a corner of an occluder or two occluders): two spectral directions, the line with
  more jump cells first;
* ``"other"``: anything else (curved edges, several occluders, a textured pattern, too few
  jump cells to fit a line).

A *jump* is a pair of neighbouring grid cells whose difference exceeds ``jump`` times the
grid's largest value and ``ratio`` times the median difference of the five pairs around it
along the same axis: a step stands out from its neighbours, a steep smooth slope does not.
The jump points are the pairs' midpoints; lines are fitted by total least squares.
"""

from __future__ import annotations

import math
from pathlib import Path

import equinox as eqx
import numpy as np

from .._validate import check_int, check_positive_float
from ..metrics import axial_distance_deg
from .options import IntegratorOptions
from .scene import Scene

__all__ = [
    "CLASSES", "GridClass", "PixelClasses", "class_rgb", "classify_grid", "pixel_classes",
    "pixel_grids", "save_class_map",
]

CLASSES = ("lit", "occluded", "one-edge", "corner", "other")
"""Class names; :attr:`PixelClasses.classes` holds indices into this tuple."""

_COLOURS = np.array([
    [1.00, 0.90, 0.45],  # lit: light yellow
    [0.15, 0.15, 0.15],  # occluded: dark grey
    [0.20, 0.45, 0.95],  # one-edge: blue
    [0.90, 0.20, 0.20],  # corner: red
    [0.70, 0.40, 0.85],  # other: purple
], np.float32)


class GridClass(eqx.Module):
    """The class of one sampled integrand (:func:`classify_grid`).

    ``directions_deg``: the spectral directions in ``[0, 180)`` (one for ``"one-edge"``, two for
    ``"corner"``, none otherwise); ``jump_cells``: how many neighbouring pairs jump;
    ``residual_cells``: the largest distance of a jump point from its fitted line, in grid cells
    (0 when no line was fitted).
    """

    name: str = eqx.field(static=True)
    directions_deg: tuple[float, ...] = eqx.field(static=True)
    jump_cells: int = eqx.field(static=True)
    residual_cells: float


def _median5(d: np.ndarray, axis: int) -> np.ndarray:
    """Median of ``d`` over a window of 5 along ``axis`` (edge-replicated)."""
    pad = [(0, 0)] * d.ndim
    pad[axis] = (2, 2)
    p = np.pad(d, pad, mode="edge")
    n = d.shape[axis]
    win = np.stack([np.take(p, np.arange(k, k + n), axis=axis) for k in range(5)])
    return np.median(win, axis=0)


def jump_points(values, *, jump: float = 0.01, ratio: float = 3.0) -> np.ndarray:
    """Midpoints ``(m, 2)`` in ``[0, 1]^2`` (x, y) of the neighbouring grid pairs that jump
    (module docstring); ``values`` is a ``(g, g)`` grid."""
    v = np.asarray(values, np.float64)
    g = v.shape[0]
    scale = float(np.max(np.abs(v)))
    if scale == 0.0:
        return np.zeros((0, 2))
    pts = []
    for axis in (1, 0):  # x neighbours (along a row), then y neighbours
        d = np.abs(np.diff(v, axis=axis))
        hit = (d > jump * scale) & (d > ratio * _median5(d, axis))
        i, j = np.nonzero(hit)
        if axis == 1:
            pts.append(np.stack([(j + 1.0) / g, (i + 0.5) / g], -1))
        else:
            pts.append(np.stack([(j + 0.5) / g, (i + 1.0) / g], -1))
    return np.concatenate(pts)


def _line_fit(p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Total-least-squares line through ``p``: (centre, unit normal, signed distances)."""
    c = p.mean(axis=0)
    _, vecs = np.linalg.eigh(np.cov((p - c).T) if len(p) > 1 else np.eye(2))
    normal = vecs[:, 0]  # eigenvector of the smallest eigenvalue
    return c, normal, (p - c) @ normal


def _axial_deg(normal: np.ndarray) -> float:
    return float(np.degrees(math.atan2(normal[1], normal[0])) % 180.0)


def _local_angles(p: np.ndarray, k: int) -> np.ndarray:
    """Each point's local spectral direction: the normal of the line through its k nearest."""
    d2 = ((p[:, None, :] - p[None, :, :]) ** 2).sum(-1)
    near = np.argsort(d2, axis=1)[:, :k]
    q = p[near] - p[near].mean(axis=1, keepdims=True)  # (m, k, 2)
    cov = np.einsum("mki,mkj->mij", q, q)
    _, vecs = np.linalg.eigh(cov)
    n = vecs[:, :, 0]
    return np.degrees(np.arctan2(n[:, 1], n[:, 0])) % 180.0


def _two_lines(p: np.ndarray, tol: float, min_angle_deg: float, min_points: int):
    """Two lines through the jump points: the first through the points whose local direction
    is near the strongest one, the second through the rest, then alternate re-assignment by
    distance and re-fitting (k-lines). None when the two lines do not explain every point."""
    ang = _local_angles(p, min(7, len(p)))
    # the staircase of a digitised line spreads local directions over about +-5 degrees
    hist = np.bincount(np.round(ang).astype(int) % 180, minlength=180).astype(float)
    first = int(np.argmax(sum(np.roll(hist, s) for s in range(-5, 6))))
    near = axial_distance_deg(ang, first, xp=np) <= 10.0
    if near.sum() < 2:
        return None
    c, n, _ = _line_fit(p[near])
    assign = np.abs((p - c) @ n) <= tol
    fits = None
    for _ in range(8):
        if assign.sum() < 2 or (~assign).sum() < 2:
            return None
        fits = [_line_fit(p[assign]), _line_fit(p[~assign])]
        dist = np.stack([np.abs((p - c) @ n) for c, n, _ in fits])
        new = dist[0] <= dist[1]
        if np.array_equal(new, assign):
            break
        assign = new
    resid = dist.min(axis=0)
    counts = (int(assign.sum()), int((~assign).sum()))
    dirs = [_axial_deg(fits[0][1]), _axial_deg(fits[1][1])]
    if (min(counts) < min_points or resid.max() > tol
            or axial_distance_deg(dirs[0], dirs[1], xp=np) < min_angle_deg):
        return None
    if counts[1] > counts[0]:
        dirs = dirs[::-1]
    return tuple(dirs), float(resid.max())


def classify_grid(
    values,
    *,
    jump: float = 0.01,
    ratio: float = 3.0,
    tolerance_cells: float = 1.0,
    min_angle_deg: float = 10.0,
    min_points: int = 8,
) -> GridClass:
    """The class of one ``(g, g)`` grid of an integrand (module docstring for the classes).

    ``tolerance_cells``: the largest distance, in grid cells, of a jump point from its line for
    the edge to count as straight; ``min_points``: the fewest jump points a line is fitted to;
    ``min_angle_deg``: the least angle between a corner's two edges.
    """
    v = np.asarray(values, np.float64)
    if v.ndim != 2 or v.shape[0] != v.shape[1] or v.shape[0] < 8:
        raise ValueError(f"values must be a square (g, g) grid with g >= 8, got shape {v.shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError("values must be finite (the grid holds NaN or inf)")
    check_positive_float("jump", jump)
    check_positive_float("ratio", ratio)
    check_positive_float("tolerance_cells", tolerance_cells)
    check_positive_float("min_angle_deg", min_angle_deg)
    min_points = check_int("min_points", min_points, minimum=2)
    g = v.shape[0]
    if np.ptp(v) <= 1e-6 * np.max(np.abs(v)):  # constant (zero, or emission seen directly)
        return GridClass("occluded", (), 0, 0.0)
    p = jump_points(v, jump=jump, ratio=ratio)
    m = len(p)
    if m == 0:
        return GridClass("lit", (), 0, 0.0)
    if m < min_points:
        return GridClass("other", (), m, 0.0)
    tol = tolerance_cells / g
    _, normal, dist = _line_fit(p)
    if np.abs(dist).max() <= tol:
        return GridClass("one-edge", (_axial_deg(normal),), m, float(np.abs(dist).max() * g))
    two = _two_lines(p, tol, min_angle_deg, min_points)
    if two is not None:
        return GridClass("corner", two[0], m, two[1] * g)
    return GridClass("other", (), m, 0.0)


class PixelClasses(eqx.Module):
    """Per-pixel classes of an image (row 0 at the top, like the render).

    ``classes``: ``(h, w)`` int8 indices into :data:`CLASSES`; ``directions_deg``: ``(h, w, 2)``
    spectral directions, valid where ``num_directions`` (``(h, w)``: 1 for one-edge, 2 for corner
    pixels, else 0) says; ``evaluated``: ``(h, w)`` bool, the pixels that were classified (others
    hold class ``"other"`` and no direction); ``grid``: the grid side ``g``; ``dimension`` and
    ``technique``: the integrand whose primary sample space the grids live in.
    """

    classes: np.ndarray
    directions_deg: np.ndarray
    num_directions: np.ndarray
    evaluated: np.ndarray
    grid: int = eqx.field(static=True)
    dimension: str = eqx.field(static=True)
    technique: str = eqx.field(static=True)

    def mask(self, name: str) -> np.ndarray:
        """``(h, w)`` bool: the evaluated pixels of class ``name``."""
        if name not in CLASSES:
            raise ValueError(f"name must be one of {CLASSES}, got {name!r}")
        return (self.classes == CLASSES.index(name)) & self.evaluated

    def pixels(self, name: str) -> np.ndarray:
        """``(m, 2)`` ``[column, row]`` of the pixels of class ``name``, in row-major order (the
        pixel convention of :func:`anisosample.render.pixel_integrand`)."""
        rows, cols = np.nonzero(self.mask(name))
        return np.stack([cols, rows], -1)

    def counts(self) -> dict[str, int]:
        """Evaluated pixels per class."""
        return {c: int(self.mask(c).sum()) for c in CLASSES}


def _check_pixels(scene: Scene, pixels) -> np.ndarray:
    if pixels is None:
        rows, cols = np.mgrid[0:scene.height, 0:scene.width]
        return np.stack([cols.ravel(), rows.ravel()], -1)
    arr = np.asarray(pixels)
    if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] == 0:
        raise ValueError(f"pixels must be a non-empty (m, 2) array of [column, row], got shape "
                         f"{arr.shape}")
    if not np.issubdtype(arr.dtype, np.integer):
        raise TypeError(f"pixels must hold integers, got dtype {arr.dtype}")
    if (arr[:, 0].min() < 0 or arr[:, 0].max() >= scene.width or arr[:, 1].min() < 0
            or arr[:, 1].max() >= scene.height):
        raise ValueError(f"pixels must lie in the {scene.width}x{scene.height} image "
                         f"(column < {scene.width}, row < {scene.height})")
    return arr.astype(np.int64)


def pixel_grids(
    scene: Scene,
    pixels=None,
    *,
    grid: int = 64,
    options: IntegratorOptions | None = None,
    chunk: int = 64,
):
    """Dense grids ``(m, g, g)`` (float32) of the integrands of ``pixels`` (``(m, 2)`` of
    ``[column, row]``; default every pixel), each at its pixel centre, in DESIGN's grid
    convention (``options``: the integrand's :class:`~anisosample.render.options.
    IntegratorOptions`, default the defaults; no MIS, no light warp: the estimation's
    integrand, :func:`anisosample.render.estimation.estimation_options`):
    :func:`anisosample.render.estimation.pixel_probes` with ``probe = grid``, as a
    generator of ``(start, grids)`` chunks of ``chunk`` pixels, so that a large image is never
    held at once."""
    from .estimation import estimation_options, pixel_probes

    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be an anisosample.render.Scene, got {type(scene).__name__}")
    grid = check_int("grid", grid, minimum=3, maximum=1024)
    chunk = check_int("chunk", chunk, minimum=1)
    px = _check_pixels(scene, pixels)
    options = estimation_options(options).for_scene(scene)
    for s in range(0, len(px), chunk):
        yield s, pixel_probes(scene, grid, pixels=px[s:s + chunk], options=options)


def pixel_classes(
    scene: Scene,
    pixels=None,
    *,
    grid: int = 64,
    options: IntegratorOptions | None = None,
    progress: bool = False,
    **classify_options,
) -> PixelClasses:
    """Classify the 2D integrand of every pixel in ``pixels`` (default: all) from a dense
    ``grid x grid`` sample of it (module docstring). ``options`` (an
    :class:`~anisosample.render.options.IntegratorOptions`: its ``dimension``, ``technique``
    and ``square_aperture``) choose the integrand as :func:`pixel_grids` does
    (``dimension="auto"``: the light sample where the scene has area lights, else the lens
    sample); ``classify_options`` go to :func:`classify_grid`.
    """
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be an anisosample.render.Scene, got {type(scene).__name__}")
    px = _check_pixels(scene, pixels)
    classify_grid(np.ones((8, 8)), **classify_options)  # validate them once, before any work
    from .estimation import estimation_options

    options = estimation_options(options).for_scene(scene)
    h, w = scene.height, scene.width
    classes = np.full((h, w), CLASSES.index("other"), np.int8)
    dirs = np.zeros((h, w, 2), np.float32)
    num = np.zeros((h, w), np.int8)
    done = np.zeros((h, w), bool)
    from ..progress import progress as bar

    chunks = pixel_grids(scene, px, grid=grid, options=options)
    total = -(-len(px) // 64)
    for start, grids in bar(chunks, total=total, desc="pixel classes", unit="chunk",
                            disable=None if progress else True, leave=False):
        if not np.all(np.isfinite(grids)):
            raise FloatingPointError("a pixel integrand returned NaN or inf (a bug: please report)")
        for k, values in enumerate(grids):
            col, row = px[start + k]
            r = classify_grid(values, **classify_options)
            classes[row, col] = CLASSES.index(r.name)
            num[row, col] = len(r.directions_deg)
            dirs[row, col, :len(r.directions_deg)] = r.directions_deg
            done[row, col] = True
    return PixelClasses(classes, dirs, num, done, grid, options.dimension, options.technique)


def class_rgb(classes: PixelClasses, *, unevaluated=1.0) -> np.ndarray:
    """``(h, w, 3)`` colours of the classes (lit yellow, occluded dark grey, one-edge blue,
    corner red, other purple; pixels not evaluated ``unevaluated`` grey)."""
    if not isinstance(classes, PixelClasses):
        raise TypeError(f"classes must be a PixelClasses, got {type(classes).__name__}")
    rgb = _COLOURS[classes.classes.astype(int)]
    return np.where(classes.evaluated[..., None], rgb, np.float32(unevaluated))


def save_class_map(path, classes: PixelClasses, *, overwrite: bool = False) -> Path:
    """PNG of :func:`class_rgb` at the image's size (row 0 on top, like the render)."""
    from .. import io

    path = Path(path)
    if path.suffix != ".png":
        raise ValueError(f"the class map must end in .png, got {path.name}")
    return io.save_png(path, class_rgb(classes), overwrite=overwrite)

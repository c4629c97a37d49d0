"""Aligned sampling in the renderer: per-block direction estimates and per-block point sets
(W Sec. 5.3-5.4).

* **Estimation (W Sec. 5.3).** The image is cut into blocks of ``B x B`` pixels (W: ``B = 16``).
  Each block gets one ``s x s`` grid of integrand samples (W: ``s = 96``, i.e. ``(s/B)^2 = 36``
  samples per pixel): grid sample ``(i, j)`` at ``x = ((j + .5)/s, (i + .5)/s)`` is taken by
  pixel ``(row0 + i // t, col0 + j // t)`` of the block, ``t = s / B``. Each pixel fills one
  ``t x t`` tile of the grid (its own part of the sample domain) and neighbouring tiles come from
  neighbouring pixels, so the grid pieces together one integrand from the block's structurally
  similar ones. W does not say how pixels share the grid; an interleaved layout (``i mod B``)
  puts jumps between far pixels every ``B`` samples. The pixel integrands are the papers'
  fixed-primary-hit ones (pixel centre, luminance, no MIS; W Sec. 6.2), whatever the render's
  own film and MIS settings. One orientation histogram and estimate per block:
  :func:`anisosample.directions.estimate_blocks`. An image whose sides are not multiples of ``B``
  is *padded*: the last row and column of blocks reach past the image and their missing pixels
  repeat the image's last row or column (edge replication).
* **Selection (W Sec. 5.4).** A block whose strongest extra direction ``d`` rounds to an integer
  direction other than the axes gets the aligned 3-direction set ``{0, 90, round(d)}`` of
  :mod:`anisosample.tables`; every other block falls back to pmj02bn (W: "an existing
  anisotropic sampling pattern"). For comparisons, ``method="sheared"`` gives pmj02bn sheared to
  ``d`` (Singh & Jarosz 2017) instead.
* **Decorrelation (W Sec. 5.4).** Every pixel uses its block's set with its own toroidal shift
  (Cranley & Patterson 1976), drawn from the pixel's key in each realization -- the same key
  :func:`anisosample.render.render` gives every sampler. A uniform shift makes every point
  uniform on the torus, so each pixel's estimator stays unbiased whatever set its block gets
  (the choice depends only on the deterministic estimation grid).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
from pathlib import Path
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._validate import check_choice, check_int, check_key
from .scene import Scene

__all__ = [
    "BLOCK_SAMPLERS", "METHODS", "BlockEstimate", "BlockSampler", "aligned_set",
    "block_grid_values", "block_sampler", "block_sets", "direction_rgb", "estimate_blocks",
    "estimation_grid", "save_direction_map", "strongest_directions", "table_direction",
]

METHODS = ("aligned", "sheared", "pmj02bn")
"""Per-block point-set choices: the aligned table set, pmj02bn sheared to the block's strongest
direction (Singh & Jarosz 2017), plain pmj02bn (W Sec. 5.4, Figs. 8-9)."""

BLOCK_SAMPLERS = ("aligned", "sheared")
"""Sampler names :func:`anisosample.render.render` resolves with a per-block estimate."""


class BlockEstimate(NamedTuple):
    """Per-block principal directions of an image (W Sec. 5.3); leading axes ``(rows, cols)``.

    ``strength`` (or None when not asked for): each block's orientation-histogram mass outside
    the zeroed axis windows (W Sec. 5.1), a measure of how much edge there is to align with.
    ``seconds``: wall time of the integrand samples and the estimate (not of ``strength``);
    ``integrand_samples``: the samples it took, ``rows * cols * s^2`` (W Fig. 10 counts them).
    """

    estimate: object  # anisosample.directions.Estimate, leading axes (rows, cols)
    strength: np.ndarray | None
    block_px: int
    samples: int
    width: int
    height: int
    seconds: float
    integrand_samples: int

    @property
    def blocks(self) -> tuple[int, int]:
        return tuple(np.asarray(self.estimate.valid).shape[:2])

    @property
    def samples_per_pixel(self) -> float:
        """Estimation samples per image pixel (36 for W's ``s = 96``, ``B = 16``)."""
        return self.integrand_samples / (self.width * self.height)


# --- estimation (W Sec. 5.3) ----------------------------------------------------------------------


def _check_blocks(scene: Scene, block_px, samples, options: dict) -> tuple[int, int]:
    from .. import directions

    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be an anisosample.render.Scene, got {type(scene).__name__}")
    block_px = check_int("block_px", block_px, minimum=1)
    samples = check_int("samples", samples, minimum=1)
    if samples % block_px:
        raise ValueError(
            f"samples (grid samples per block side) must be a multiple of block_px={block_px} "
            f"(each pixel fills a (samples/block_px)^2 tile), got {samples}"
        )
    min_size = directions._params(**options).min_size
    if samples < min_size:
        raise ValueError(
            f"samples must be >= {min_size} for the estimator's filters, got {samples}"
        )
    return block_px, samples


def _base_integrand(scene, integrand, dimension, technique, square_aperture):
    from .integrator import PixelIntegrand, pixel_integrand

    if integrand is None:
        return pixel_integrand(scene, (0, 0), dimension=dimension, technique=technique,
                               square_aperture=square_aperture)
    if not isinstance(integrand, PixelIntegrand):
        raise TypeError(f"integrand must be a render.PixelIntegrand (its film is replaced per "
                        f"pixel), got {type(integrand).__name__}")
    return integrand


@eqx.filter_jit
def _films_eval(base, films, x):
    """``f_q(x_i)`` with pixel ``q``'s film position ``films[i]`` (vmapped)."""
    return jax.vmap(lambda film, xy: eqx.tree_at(lambda g: g.film, base, film)(xy))(films, x)


def _cell_centres(samples: int) -> np.ndarray:
    c = (np.arange(samples) + 0.5) / samples
    return np.stack(np.meshgrid(c, c, indexing="xy"), -1).reshape(-1, 2).astype(np.float32)


def estimation_grid(
    scene: Scene,
    block_px: int = 16,
    samples: int = 96,
    *,
    integrand=None,
    dimension: str = "auto",
    technique: str = "area",
    square_aperture: bool = False,
    progress: bool = False,
) -> np.ndarray:
    """All blocks' estimation grids as one ``(rows * s, cols * s)`` float32 array (W Sec. 5.3).

    Block ``(a, b)`` (row ``a`` from the image top) holds rows ``a s .. a s + s - 1`` and columns
    ``b s .. b s + s - 1``, the layout of :func:`anisosample.directions.estimate_blocks`; inside
    it DESIGN's grid convention in the sample domain. Pixel tiles: module docstring.
    ``integrand``: the :class:`~anisosample.render.PixelIntegrand` whose film is moved to each
    pixel centre (default: :func:`~anisosample.render.pixel_integrand` with ``dimension``,
    ``technique``, ``square_aperture``). Computed one row of blocks per jitted call.
    """
    block_px, samples = _check_blocks(scene, block_px, samples, {})
    base = _base_integrand(scene, integrand, dimension, technique, square_aperture)
    w, h = scene.width, scene.height
    by, bx = -(-h // block_px), -(-w // block_px)
    t = samples // block_px
    ii, jj = np.meshgrid(np.arange(samples), np.arange(samples), indexing="ij")
    ii, jj = ii // t, jj // t  # the pixel of each grid sample inside its block
    xs = jnp.asarray(np.tile(_cell_centres(samples), (bx, 1)))
    out = np.empty((by * samples, bx * samples), np.float32)
    from ..progress import progress as bar

    for a in bar(range(by), desc="directions", disable=None if progress else True,
                 unit="block row", leave=False):
        row = np.minimum(a * block_px + ii, h - 1)  # padding: edge replication
        films = np.concatenate([
            np.stack([(np.minimum(b * block_px + jj, w - 1) + 0.5) / w, (row + 0.5) / h], -1)
            .reshape(-1, 2) for b in range(bx)]).astype(np.float32)
        vals = np.asarray(_films_eval(base, jnp.asarray(films), xs))
        out[a * samples:(a + 1) * samples] = (
            vals.reshape(bx, samples, samples).transpose(1, 0, 2).reshape(samples, -1))
    if not np.all(np.isfinite(out)):
        raise FloatingPointError("the estimation samples hold NaN or Inf (a bug: please report)")
    return out


def block_grid_values(
    scene: Scene,
    block: tuple[int, int],
    block_px: int = 16,
    samples: int = 96,
    *,
    integrand=None,
    dimension: str = "auto",
    technique: str = "area",
    square_aperture: bool = False,
) -> np.ndarray:
    """The ``(s, s)`` estimation grid of one block ``(row, col)``: what its histogram is built
    from (equal to that block of :func:`estimation_grid`)."""
    block_px, samples = _check_blocks(scene, block_px, samples, {})
    base = _base_integrand(scene, integrand, dimension, technique, square_aperture)
    w, h = scene.width, scene.height
    a = check_int("block[0] (row)", block[0], minimum=0, maximum=-(-h // block_px) - 1)
    b = check_int("block[1] (column)", block[1], minimum=0, maximum=-(-w // block_px) - 1)
    ii, jj = np.meshgrid(np.arange(samples), np.arange(samples), indexing="ij")
    t = samples // block_px
    row = np.minimum(a * block_px + ii // t, h - 1)
    col = np.minimum(b * block_px + jj // t, w - 1)
    films = np.stack([(col + 0.5) / w, (row + 0.5) / h], -1).reshape(-1, 2).astype(np.float32)
    x = jnp.asarray(_cell_centres(samples))
    return np.asarray(_films_eval(base, jnp.asarray(films), x)).reshape(samples, samples)


@functools.partial(jax.jit, static_argnums=(1, 2))
def _strength(blocks, params, bin_deg_window):
    from .. import directions

    bin_deg, window = bin_deg_window

    def one(v):
        return jnp.sum(directions.zero_axes(directions._histogram(v, params), bin_deg=bin_deg,
                                            zero_window_deg=window))

    return jax.lax.map(one, blocks)


def estimate_blocks(
    scene: Scene,
    block_px: int = 16,
    samples: int = 96,
    k: int = 2,
    *,
    integrand=None,
    dimension: str = "auto",
    technique: str = "area",
    square_aperture: bool = False,
    strength: bool = False,
    progress: bool = False,
    **estimate_options,
) -> BlockEstimate:
    """W Sec. 5.3: the principal directions of every ``block_px``-pixel block of ``scene``.

    One ``samples x samples`` grid per block (:func:`estimation_grid`; W: 96 and 16) feeds
    :func:`anisosample.directions.estimate_blocks` (``k`` extra directions, 1 or 2;
    ``estimate_options`` go to it). ``strength=True`` also returns each block's histogram mass
    outside the zeroed axis windows. Image sides that are not multiples of ``block_px`` are
    padded (module docstring).
    """
    from .. import directions

    k = check_int("k", k, minimum=1, maximum=2)
    block_px, samples = _check_blocks(scene, block_px, samples, estimate_options)
    t0 = time.perf_counter()
    grid = estimation_grid(scene, block_px, samples, integrand=integrand, dimension=dimension,
                           technique=technique, square_aperture=square_aperture,
                           progress=progress)
    est = directions.estimate_blocks(grid, k=k, samples_per_block=samples, **estimate_options)
    jax.block_until_ready(est)
    seconds = time.perf_counter() - t0
    by, bx = grid.shape[0] // samples, grid.shape[1] // samples
    power = None
    if strength:
        params = directions._params(**estimate_options)
        blocks = grid.reshape(by, samples, bx, samples).transpose(0, 2, 1, 3)
        power = np.asarray(_strength(jnp.asarray(blocks.reshape(by * bx, samples, samples)),
                                     params, (params.bin_deg, params.zero_window_deg)),
                           np.float64).reshape(by, bx)
    return BlockEstimate(est, power, block_px, samples, scene.width, scene.height, seconds,
                         by * bx * samples * samples)


def strongest_directions(estimate) -> tuple[np.ndarray, np.ndarray]:
    """``(directions_deg, valid)``, both ``(rows, cols)``: each block's strongest extra
    direction (slot 0 of the estimate) and whether it has one (``directions_deg`` is -1 where
    not). Takes a :class:`BlockEstimate` or an :class:`anisosample.directions.Estimate`."""
    est = getattr(estimate, "estimate", estimate)
    d = np.asarray(est.directions_deg, np.float64)[..., 0]
    v = np.asarray(est.valid)[..., 0]
    return np.where(v, d, -1.0), v


# --- selection (W Sec. 5.4) -----------------------------------------------------------------------


def table_direction(direction_deg) -> int | None:
    """The integer direction the 3-direction table is asked for (``round(d) mod 180``), or None:
    no direction, or one that rounds onto an axis (0 or 90 degrees, which every set has)."""
    from .. import tables

    if direction_deg is None:
        return None
    d = float(direction_deg)
    if not math.isfinite(d):
        raise ValueError(f"direction_deg must be finite degrees or None, got {direction_deg!r}")
    r = int(round(d)) % 180
    return None if r in tables.AXES_DEG else r


def aligned_set(direction_deg: int, n: int, key=None, *, table=None,
                build_missing: bool = False) -> jax.Array:
    """The aligned 3-direction set ``{0, 90, direction_deg}`` of ``n`` points (W Sec. 5.4,
    :func:`anisosample.tables.lookup`), toroidally shifted by ``key`` when given.

    Missing tables raise ``FileNotFoundError`` naming the build command, unless
    ``build_missing`` (the set is synthesized into ``table`` or the user cache).
    """
    from .. import samplers, tables

    n = check_int("n", n, minimum=2)
    pts = tables.lookup((direction_deg,), n, kind=3, table=table, build_missing=build_missing)
    pts = jnp.asarray(pts, jnp.float32)
    return pts if key is None else samplers.toroidal_shift(key, pts)


def block_sets(direction_deg: float | None, n: int, key, *, table=None,
               build_missing: bool = False) -> dict[str, jax.Array]:
    """The point set of every method in :data:`METHODS` for a block whose strongest direction
    is ``direction_deg`` (None: no extra direction).

    ``key`` is split into two: pmj02bn from the first (the fallback, and the set the ``sheared``
    method shears), the aligned set's toroidal shift from the second. Without a direction (or
    one that rounds onto an axis, for ``aligned``) a method falls back to the pmj02bn set.
    """
    from .. import samplers

    key = check_key("key", key)
    n = check_int("n", n, minimum=2)
    k_pmj, k_al = jax.random.split(key)
    pmj = jnp.asarray(samplers.get("pmj02bn")(k_pmj, n), jnp.float32)
    out = {"pmj02bn": pmj}
    out["sheared"] = pmj if direction_deg is None else samplers.shear(pmj, direction_deg)
    d = table_direction(direction_deg)
    out["aligned"] = pmj if d is None else aligned_set(d, n, k_al, table=table,
                                                       build_missing=build_missing)
    return out


# --- the renderer's per-block sampler -------------------------------------------------------------


@dataclasses.dataclass(frozen=True, eq=False)
class BlockSampler:
    """Per-pixel point sets for :func:`anisosample.render.render` (W Sec. 5.4).

    Made by :func:`block_sampler`. ``directions_deg``/``valid``: each block's strongest extra
    direction; ``estimate``: the :class:`BlockEstimate` it came from. Per realization,
    :meth:`point_sets` gives the distinct sets and each pixel's index into them; the renderer
    shifts each pixel's set toroidally with the pixel's own key.
    """

    method: str
    block_px: int
    width: int
    height: int
    directions_deg: np.ndarray  # (rows, cols) float64, -1 where there is none
    valid: np.ndarray  # (rows, cols) bool
    estimate: BlockEstimate | None = None
    dimension: str = "light"
    technique: str = "area"
    square_aperture: bool = False
    base: str = "pmj02bn"
    table: object = None
    build_missing: bool = False

    @property
    def name(self) -> str:
        """The sampler's name in render settings: the method."""
        return self.method

    def _set_ids(self) -> list:
        """Per block (row-major) the identity of its set: None (base), an int (aligned) or a
        float direction (sheared)."""
        ids = []
        for d, v in zip(self.directions_deg.reshape(-1), self.valid.reshape(-1), strict=True):
            if not v:
                ids.append(None)
            elif self.method == "aligned":
                ids.append(table_direction(d))
            else:
                ids.append(float(d))
        return ids

    @property
    def table_directions(self) -> tuple[int, ...]:
        """The distinct aligned table directions this sampler needs (empty unless aligned)."""
        if self.method != "aligned":
            return ()
        return tuple(sorted({i for i in self._set_ids() if i is not None}))

    def check_tables(self, n: int) -> None:
        """Load every aligned set needed for ``n`` points now (``FileNotFoundError`` listing
        the missing directions and the build command, before any rendering)."""
        from .. import tables

        n = check_int("n (spp)", n, minimum=2)
        missing = []
        for d in self.table_directions:
            try:
                tables.lookup((d,), n, kind=3, table=self.table, build_missing=self.build_missing)
            except FileNotFoundError:
                missing.append(d)
        if missing:
            raise FileNotFoundError(
                f"the aligned sampler needs 3-direction sets for n={n} and directions {missing} "
                f"deg that no installed table holds; build them with `anisosample tables build "
                f"--n {n} --directions 3` (Python: build_missing=True), or pick --spp among the "
                f"tables' sizes"
            )

    def point_sets(self, key, n: int) -> tuple[jax.Array, np.ndarray]:
        """``(sets, pixel_set)``: ``sets`` ``(m, n, 2)`` float32, the distinct sets of one
        realization (``sets[0]`` is the base sampler's set drawn from ``key``, every other set
        derives from it or from the tables), and ``pixel_set`` ``(height * width,)`` int32, each
        pixel's (row-major) index into ``sets``."""
        from .. import samplers

        key = check_key("key", key)
        n = check_int("n (spp)", n, minimum=2)
        base = jnp.asarray(samplers.get(self.base)(key, n), jnp.float32)
        ids = self._set_ids()
        distinct = [None] + sorted({i for i in ids if i is not None})
        where = {i: j for j, i in enumerate(distinct)}
        sets = [base]
        for i in distinct[1:]:
            if self.method == "aligned":
                sets.append(aligned_set(i, n, table=self.table, build_missing=self.build_missing))
            else:
                sets.append(samplers.shear(base, i))
        by, bx = self.valid.shape
        block_set = np.asarray([where[i] for i in ids], np.int32).reshape(by, bx)
        rows = np.arange(self.height) // self.block_px
        cols = np.arange(self.width) // self.block_px
        return jnp.stack(sets), block_set[rows[:, None], cols[None, :]].reshape(-1)

    def settings(self) -> dict:
        """What a render records about the sampler (EXR metadata)."""
        s = dict(method=self.method, base=self.base, block_px=self.block_px,
                 blocks_with_direction=int(self.valid.sum()), blocks=int(self.valid.size))
        if self.method == "aligned":
            s["table_directions_deg"] = list(self.table_directions)
        if self.estimate is not None:
            s.update(estimation_samples=self.estimate.samples,
                     estimation_integrand_samples=self.estimate.integrand_samples,
                     estimation_samples_per_pixel=self.estimate.samples_per_pixel,
                     estimation_seconds=round(self.estimate.seconds, 4))
        return s


def block_sampler(
    scene: Scene,
    method: str = "aligned",
    *,
    block_px: int = 16,
    samples: int = 96,
    k: int = 2,
    estimate: BlockEstimate | None = None,
    table=None,
    build_missing: bool = False,
    base: str = "pmj02bn",
    dimension: str = "auto",
    technique: str = "area",
    square_aperture: bool = False,
    progress: bool = False,
    **estimate_options,
) -> BlockSampler:
    """The per-block sampler of W Sec. 5.4 for ``scene``, to pass as ``render(sampler=...)``.

    ``method``: ``"aligned"`` (the 3-direction table set for each block's strongest direction,
    rounded; ``base`` elsewhere) or ``"sheared"`` (``base`` sheared to it, Singh & Jarosz 2017).
    Estimates the directions with :func:`estimate_blocks` (``block_px``, ``samples``, ``k``,
    ``estimate_options``; W: 16, 96) unless a finished ``estimate`` is given. ``dimension``,
    ``technique`` and ``square_aperture`` must be the render's. Aligned sets come from
    ``table`` (default: the installed tables); ``build_missing`` synthesizes missing ones.
    """
    from .. import samplers
    from .integrator import _check_options

    check_choice("method", method, BLOCK_SAMPLERS)
    check_choice("base", base, samplers.BASELINES)
    dimension = _check_options(scene, dimension, technique)
    if estimate is None:
        estimate = estimate_blocks(scene, block_px, samples, k, dimension=dimension,
                                   technique=technique, square_aperture=square_aperture,
                                   progress=progress, **estimate_options)
    elif not isinstance(estimate, BlockEstimate):
        raise TypeError(f"estimate must be a BlockEstimate from estimate_blocks, got "
                        f"{type(estimate).__name__}")
    elif (estimate.width, estimate.height) != (scene.width, scene.height):
        raise ValueError(f"estimate is for a {estimate.width}x{estimate.height} image, the "
                         f"scene is {scene.width}x{scene.height}")
    d, v = strongest_directions(estimate)
    return BlockSampler(method, estimate.block_px, scene.width, scene.height, d, v, estimate,
                        dimension, technique, bool(square_aperture), base, table,
                        bool(build_missing))


def _resolve(scene: Scene, sampler, options: dict | None, *, dimension: str, technique: str,
            square_aperture: bool) -> BlockSampler | None:
    """The renderer's hook: a :class:`BlockSampler` for ``sampler`` (one, or a name in
    :data:`BLOCK_SAMPLERS` built with ``options``), None for ordinary samplers."""
    if isinstance(sampler, str) and sampler in BLOCK_SAMPLERS:
        opts = dict(options or {})
        return block_sampler(scene, sampler, dimension=dimension, technique=technique,
                             square_aperture=square_aperture, **opts)
    if options:
        what = "a finished BlockSampler" if isinstance(sampler, BlockSampler) else repr(sampler)
        raise ValueError(f"sampler_options are for the per-block samplers given by name "
                         f"{list(BLOCK_SAMPLERS)}, not {what}")
    if not isinstance(sampler, BlockSampler):
        return None
    if (sampler.width, sampler.height) != (scene.width, scene.height):
        raise ValueError(f"sampler was made for a {sampler.width}x{sampler.height} image, the "
                         f"scene is {scene.width}x{scene.height}")
    mine = (sampler.dimension, sampler.technique, sampler.square_aperture)
    if mine != (dimension, technique, bool(square_aperture)):
        raise ValueError(f"sampler estimated its directions with (dimension, technique, "
                         f"square_aperture) = {mine}, the render uses "
                         f"{(dimension, technique, bool(square_aperture))}")
    return sampler


@functools.partial(
    jax.jit, static_argnames=("dimension", "technique", "mis", "pixel_center", "square_aperture")
)
def _render_chunk_sets(scene: Scene, sets, pixel_set, key, pixels, **opts):
    """:func:`anisosample.render.integrator._render_chunk` with per-pixel point sets: pixel
    ``q`` uses ``sets[pixel_set[q]]`` (and, as there, its own shift from ``fold_in(key, q)``)."""
    from .integrator import _render_chunk

    def one(q):
        return _render_chunk(scene, sets[pixel_set[q]], key, q[None], **opts)[0]

    if pixels.ndim == 1:
        return jax.vmap(one)(pixels)
    return jax.lax.map(jax.vmap(one), pixels)


# --- pictures -------------------------------------------------------------------------------------


def direction_rgb(directions_deg, valid, *, none=0.5) -> np.ndarray:
    """Colours ``(..., 3)`` for directions: hue = direction / 180 (a cyclic map for axial
    angles), grey ``none`` where ``valid`` is false."""
    import matplotlib

    d, v = np.asarray(directions_deg), np.asarray(valid)
    rgb = matplotlib.colormaps["hsv"](np.clip(d, 0, 180) / 180.0)[..., :3]
    return np.where(v[..., None], rgb, none)


def save_direction_map(path, estimate, *, overwrite: bool = False) -> Path:
    """PNG of the per-block directions at the image's size (row 0 on top, like the render):
    one panel per estimate slot, hue = direction / 180, black where there is none."""
    from .. import io

    path = Path(path)
    if path.suffix != ".png":
        raise ValueError(f"the direction map must end in .png, got {path.name}")
    if isinstance(estimate, BlockSampler):
        if estimate.estimate is None:
            raise ValueError("this sampler holds no estimate to draw")
        estimate = estimate.estimate
    if not isinstance(estimate, BlockEstimate):
        raise TypeError(f"estimate must be a BlockEstimate or BlockSampler, got "
                        f"{type(estimate).__name__}")
    e, bp = estimate.estimate, estimate.block_px
    rgb = direction_rgb(e.directions_deg, e.valid, none=0.0)  # (rows, cols, k, 3)
    panels = [np.kron(rgb[:, :, s], np.ones((bp, bp, 1)))[:estimate.height, :estimate.width]
              for s in range(rgb.shape[2])]
    panels = [np.pad(p, ((0, 0), (0, 2), (0, 0)), constant_values=1.0) for p in panels]
    return io.save_png(path, np.clip(np.concatenate(panels, axis=1)[:, :-2], 0, 1),
                       overwrite=overwrite)

"""Per-block direction estimation in the renderer (W Sec. 5.3) and the per-pixel gate.

* **The block grid.** The image is cut into blocks of ``B x B`` pixels (W: ``B = 16``). Each
  block gets one ``s x s`` grid of integrand samples (W: ``s = 96``, i.e. ``(s/B)^2 = 36``
  samples per pixel): grid sample ``(i, j)`` at ``x = ((j + .5)/s, (i + .5)/s)`` is taken by
  pixel ``(row0 + i // t, col0 + j // t)`` of the block, ``t = s / B``. Each pixel fills one
  ``t x t`` tile of the grid (its own part of the sample domain) and neighbouring tiles come from
  neighbouring pixels, so the grid pieces together one integrand from the block's structurally
  similar ones. W does not say how pixels share the grid; an interleaved layout (``i mod B``)
  puts jumps between far pixels every ``B`` samples. The pixel integrands are the papers'
  fixed-primary-hit ones (pixel centre, luminance, no MIS, the base light technique without
  its warp chain; W Sec. 6.2), whatever the render's own film, MIS and light-warp settings
  (:func:`estimation_options`). One orientation histogram and estimate per block:
  :func:`anisosample.directions.estimate_blocks`. An image whose sides are not multiples of ``B``
  is *padded*: the last row and column of blocks reach past the image and their missing pixels
  repeat the image's last row or column (edge replication).
* **The per-pixel gate (beyond W).** W gives every pixel of a block the block's set; pixels
  whose own integrand is smooth (fully lit, fully occluded) then get an aligned set, which
  converges more slowly than pmj02bn on smooth integrands. A pixel's tile covers only ``1/B^2``
  of its sample domain, so it cannot tell whether the pixel's integrand has an edge elsewhere
  (on the occluder-edge scene of ``tests/render/test_gate.py``, 8-pixel blocks: the jump test
  on each pixel's own tile flags 10 % of the penumbra pixels, on the probe 85 %, with no lit or
  umbra pixel flagged by either); the gate therefore looks at a *probe*: ``m x m`` midpoint
  samples of the pixel's integrand over the whole domain (default ``m = 6``, as many samples as
  the pixel's tile at W's settings), and calls the pixel discontinuous when some step between
  neighbouring probe samples is a jump
  (:func:`probe_discontinuous`). Deterministic, like the grid, so the choice of set does not
  depend on the render's random numbers and every pixel's estimator stays unbiased.
"""

from __future__ import annotations

import dataclasses
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._validate import check_int, check_positive_float
from ..metrics import midpoint_grid
from ._kernel import kernel
from .integrator import PixelIntegrand, pixel_integrand
from .options import IntegratorOptions
from .scene import Scene

__all__ = [
    "BlockEstimate", "block_grid_values", "estimate_blocks", "estimation_grid",
    "estimation_options", "gate_estimate", "pixel_probes", "probe_discontinuous",
    "strongest_directions", "window_grid_values",
]

JUMP_RATIO = 3.0
"""A step between neighbouring probe samples is a jump when it exceeds ``JUMP_RATIO`` times the
larger of the steps next to it on the same probe row or column (a smooth integrand's steps change
gradually) ..."""

JUMP_FRACTION = 0.25
"""... and ``JUMP_FRACTION`` of the probe's value range (small wiggles of a constant are not
edges)."""


class BlockEstimate(eqx.Module):
    """Per-block principal directions of an image (W Sec. 5.3); leading axes ``(rows, cols)``.

    ``strength`` (or None when not asked for): each block's orientation-histogram mass outside
    the zeroed axis windows (W Sec. 5.1), a measure of how much edge there is to align with.
    ``seconds``: wall time of the integrand samples and the estimate (not of ``strength``);
    ``integrand_samples``: the samples it took, ``rows * cols * s^2`` (W Fig. 10 counts them).
    ``discontinuous`` (or None without the gate): ``(height, width)`` bool, whether each pixel's
    probe shows a jump; ``probe``: the probe's side ``m``; ``probe_seconds``: its wall time.
    """

    estimate: object  # anisosample.directions.Estimate, leading axes (rows, cols)
    strength: np.ndarray | None
    block_px: int = eqx.field(static=True)
    samples: int = eqx.field(static=True)
    width: int = eqx.field(static=True)
    height: int = eqx.field(static=True)
    seconds: float
    integrand_samples: int = eqx.field(static=True)
    discontinuous: np.ndarray | None = None
    probe: int = eqx.field(static=True, default=0)
    probe_seconds: float = 0.0

    @property
    def blocks(self) -> tuple[int, int]:
        return tuple(np.asarray(self.estimate.valid).shape[:2])

    @property
    def samples_per_pixel(self) -> float:
        """Estimation samples per image pixel (36 for W's ``s = 96``, ``B = 16``; the gate's
        probe not included)."""
        return self.integrand_samples / (self.width * self.height)


def _check_blocks(scene: Scene, block_px, samples) -> tuple[int, int]:
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be an anisosample.render.Scene, got {type(scene).__name__}")
    block_px = check_int("block_px", block_px, minimum=1)
    samples = check_int("samples", samples, minimum=1)
    if samples % block_px:
        raise ValueError(
            f"samples (grid samples per block side) must be a multiple of block_px={block_px} "
            f"(each pixel fills a (samples/block_px)^2 tile), got {samples}"
        )
    return block_px, samples


def estimation_options(options: IntegratorOptions | None) -> IntegratorOptions:
    """The options of the estimation's pixel integrands for a render with ``options`` (None:
    the defaults): its dimension, technique and aperture; the film at the pixel centre, no
    MIS and no light warp (module docstring)."""
    if options is None:
        options = IntegratorOptions()
    elif not isinstance(options, IntegratorOptions):
        raise TypeError(f"options must be a render.IntegratorOptions, got "
                        f"{type(options).__name__}")
    return options.integrand().replace(light_warp="none")


def _base_integrand(scene, integrand, options):
    if integrand is None:
        return pixel_integrand(scene, (0, 0), options=estimation_options(options))
    if options is not None:
        raise ValueError("give integrand= or options=, not both (the integrand holds its "
                         "options)")
    if not isinstance(integrand, PixelIntegrand):
        raise TypeError(f"integrand must be a render.PixelIntegrand (its film is replaced per "
                        f"pixel), got {type(integrand).__name__}")
    return integrand


@kernel(jit=eqx.filter_jit)
def _films_eval(base, films, x):
    """``f_q(x_i)`` with pixel ``q``'s film position ``films[i]`` (vmapped)."""
    return jax.vmap(lambda film, xy: eqx.tree_at(lambda g: g.film, base, film)(xy))(films, x)


def _cell_centres(samples: int) -> np.ndarray:
    return midpoint_grid(samples).reshape(-1, 2)


def _bar(iterable, desc, progress, unit):
    from ..progress import progress as bar

    return bar(iterable, desc=desc, disable=None if progress else True, unit=unit, leave=False)


def estimation_grid(
    scene: Scene,
    block_px: int = 16,
    samples: int = 96,
    *,
    integrand=None,
    options: IntegratorOptions | None = None,
    progress: bool = False,
) -> np.ndarray:
    """All blocks' estimation grids as one ``(rows * s, cols * s)`` float32 array (W Sec. 5.3).

    Block ``(a, b)`` (row ``a`` from the image top) holds rows ``a s .. a s + s - 1`` and columns
    ``b s .. b s + s - 1``, the layout of :func:`anisosample.directions.estimate_blocks`; inside
    it DESIGN's grid convention in the sample domain. Pixel tiles: module docstring.
    ``integrand``: the :class:`~anisosample.render.PixelIntegrand` whose film is moved to each
    pixel centre (default: :func:`~anisosample.render.pixel_integrand` with
    :func:`estimation_options` of ``options``, the render's
    :class:`~anisosample.render.options.IntegratorOptions`). Computed one row of blocks per
    jitted call.
    """
    block_px, samples = _check_blocks(scene, block_px, samples)
    base = _base_integrand(scene, integrand, options)
    w, h = scene.width, scene.height
    by, bx = -(-h // block_px), -(-w // block_px)
    t = samples // block_px
    ii, jj = np.meshgrid(np.arange(samples), np.arange(samples), indexing="ij")
    ii, jj = ii // t, jj // t  # the pixel of each grid sample inside its block
    xs = jnp.asarray(np.tile(_cell_centres(samples), (bx, 1)))
    out = np.empty((by * samples, bx * samples), np.float32)
    for a in _bar(range(by), "directions", progress, "block row"):
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
    options: IntegratorOptions | None = None,
) -> np.ndarray:
    """The ``(s, s)`` estimation grid of one block ``(row, col)``: what its histogram is built
    from (equal to that block of :func:`estimation_grid`)."""
    block_px, samples = _check_blocks(scene, block_px, samples)
    base = _base_integrand(scene, integrand, options)
    w, h = scene.width, scene.height
    a = check_int("block[0] (row)", block[0], minimum=0, maximum=-(-h // block_px) - 1)
    b = check_int("block[1] (column)", block[1], minimum=0, maximum=-(-w // block_px) - 1)
    return _tile_grid(scene, base, a * block_px, b * block_px, block_px, samples)


def _tile_grid(scene, base, row0: int, col0: int, block_px: int, samples: int) -> np.ndarray:
    """The ``(s, s)`` grid of the ``block_px^2`` pixels from ``(row0, col0)``, each filling a
    tile of ``s / block_px`` cells (rows and columns clamped to the image: edge replication)."""
    w, h = scene.width, scene.height
    ii, jj = np.meshgrid(np.arange(samples), np.arange(samples), indexing="ij")
    t = samples // block_px
    row = np.clip(row0 + ii // t, 0, h - 1)
    col = np.clip(col0 + jj // t, 0, w - 1)
    films = np.stack([(col + 0.5) / w, (row + 0.5) / h], -1).reshape(-1, 2).astype(np.float32)
    x = jnp.asarray(_cell_centres(samples))
    return np.asarray(_films_eval(base, jnp.asarray(films), x)).reshape(samples, samples)


def window_grid_values(
    scene: Scene,
    pixel: tuple[int, int],
    window_px: int = 16,
    samples: int = 96,
    *,
    integrand=None,
    options: IntegratorOptions | None = None,
) -> np.ndarray:
    """W's estimation grid (Sec. 5.3) on a *sliding* window: the ``window_px^2`` pixels centred
    on ``pixel = (column, row)`` instead of the fixed block holding it, each pixel filling its
    tile as in :func:`estimation_grid` (so the window is a crop of the whole image's grid:
    no samples beyond W's per pixel). Feeding it to :func:`anisosample.directions.estimate`
    gives the pixel a direction pooled only over its own neighbourhood."""
    window_px, samples = _check_blocks(scene, window_px, samples)
    base = _base_integrand(scene, integrand, options)
    col = check_int("pixel[0] (column)", pixel[0], minimum=0, maximum=scene.width - 1)
    row = check_int("pixel[1] (row)", pixel[1], minimum=0, maximum=scene.height - 1)
    half = window_px // 2
    return _tile_grid(scene, base, row - half, col - half, window_px, samples)


# --- the per-pixel gate ---------------------------------------------------------------------------


def probe_discontinuous(values, *, jump_ratio: float = JUMP_RATIO,
                        jump_fraction: float = JUMP_FRACTION) -> np.ndarray:
    """Whether each ``(..., m, m)`` probe grid (DESIGN's grid convention) shows a jump.

    Along every probe row and column, the step ``d_i = v_{i+1} - v_i`` is a jump when
    ``|d_i| > jump_ratio * max(|d_{i-1}|, |d_{i+1}|)`` (the steps beside it on the same line;
    one at the line's ends) and ``|d_i| > jump_fraction * (max v - min v)``. A smooth integrand
    sampled at spacing ``h`` has steps ``f' h`` that change by ``f'' h^2`` from one to the next;
    a step edge crossing the line puts its whole height into one step. Constant grids (fully
    occluded pixels) have no jump, nor have steps below ``1e-4`` of the largest ``|v|``
    (float32 round-off of the integrand). Returns a bool array of the leading shape.
    """
    v = np.asarray(values, np.float64)
    if v.ndim < 2 or v.shape[-1] != v.shape[-2] or v.shape[-1] < 3:
        raise ValueError(f"values must be (..., m, m) probe grids with m >= 3, got {v.shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError("values hold NaN or Inf")
    jump_ratio = check_positive_float("jump_ratio", jump_ratio)
    jump_fraction = check_positive_float("jump_fraction", jump_fraction)
    span = v.max(axis=(-2, -1)) - v.min(axis=(-2, -1))
    scale = np.abs(v).max(axis=(-2, -1))  # steps below 1e-4 of it are float32 round-off
    found = np.zeros(v.shape[:-2], bool)
    for d in (np.abs(np.diff(v, axis=-1)), np.swapaxes(np.abs(np.diff(v, axis=-2)), -1, -2)):
        pad = np.zeros(d.shape[:-1] + (1,))
        left = np.concatenate([pad, d[..., :-1]], -1)
        right = np.concatenate([d[..., 1:], pad], -1)
        floor = np.maximum(jump_fraction * span, 1e-4 * scale)[..., None, None]
        jump = (d > jump_ratio * np.maximum(left, right)) & (d > floor)
        found |= jump.any(axis=(-2, -1))
    return found


PROBE_CALL_SAMPLES = 2**17
"""The most samples one jitted call of :func:`pixel_probes` evaluates. Its calls were one image
row each (128 pixels x 36 samples at 128^2): on cornell's aligned render (128^2, 64 spp, one
device) the probes took 98 ms (cProfile); batched, the whole render fell from 253 to 196 ms
(best of 5 each, the same machine at load 0-0.4)."""


def _probe_batch(pixels: int, m: int) -> int:
    """Pixels per call of :func:`pixel_probes`: a power of two (few compiled shapes), at most
    :data:`PROBE_CALL_SAMPLES` samples and no more than the ``pixels`` asked for need."""
    cap = max(1, PROBE_CALL_SAMPLES // (m * m))
    cap = 1 << (cap.bit_length() - 1)
    return min(cap, 1 << max(0, (max(pixels, 1) - 1).bit_length()))


def pixel_probes(
    scene: Scene,
    probe: int = 6,
    *,
    pixels=None,
    integrand=None,
    options: IntegratorOptions | None = None,
    progress: bool = False,
) -> np.ndarray:
    """Pixel probes: each pixel's integrand (film at the pixel centre, as :func:`estimation_grid`)
    at the ``m x m`` midpoints of the whole sample domain, ``[..., i, j] = f((j + .5)/m,
    (i + .5)/m)``, float32. ``pixels``: ``(p, 2)`` ``[column, row]`` -> ``(p, m, m)``; default
    every pixel -> ``(height, width, m, m)``. Up to :data:`PROBE_CALL_SAMPLES` samples per
    jitted call (:func:`_probe_batch`)."""
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be an anisosample.render.Scene, got {type(scene).__name__}")
    m = check_int("probe", probe, minimum=3)
    base = _base_integrand(scene, integrand, options)
    w, h = scene.width, scene.height
    if pixels is None:
        rows, cols = np.mgrid[0:h, 0:w]
        px = np.stack([cols.ravel(), rows.ravel()], -1)
    else:
        px = np.asarray(pixels)
        if px.ndim != 2 or px.shape[1] != 2 or not np.issubdtype(px.dtype, np.integer):
            raise ValueError(f"pixels must be an (p, 2) integer array of [column, row], got "
                             f"{px.dtype} {px.shape}")
        if px.size and ((px < 0).any() or (px[:, 0] >= w).any() or (px[:, 1] >= h).any()):
            raise ValueError(f"pixels must lie in the {w}x{h} image")
    per = _probe_batch(len(px), m)
    xs = jnp.asarray(np.tile(_cell_centres(m), (per, 1)))
    out = np.empty((len(px), m, m), np.float32)
    for s in _bar(range(0, len(px), per), "gate", progress, "chunk"):
        chunk = px[s:s + per]
        films = np.repeat((chunk + 0.5) / np.array([w, h]), m * m, axis=0)
        films = np.concatenate([films, np.repeat(films[-1:], (per - len(chunk)) * m * m, 0)])
        vals = np.asarray(_films_eval(base, jnp.asarray(films, jnp.float32), xs))
        out[s:s + len(chunk)] = vals.reshape(per, m, m)[:len(chunk)]
    if not np.all(np.isfinite(out)):
        raise FloatingPointError("the probe samples hold NaN or Inf (a bug: please report)")
    return out.reshape(h, w, m, m) if pixels is None else out


# --- the estimate ---------------------------------------------------------------------------------

_GRID_OPTIONS = ("sigma_px", "bin_deg", "min_gradient")


def _strength(blocks, options: dict) -> np.ndarray:
    """Each block's orientation-histogram mass outside the zeroed axis windows (W Sec. 5.1)."""
    from .. import directions

    grid_opts = {k: options[k] for k in _GRID_OPTIONS if k in options}
    axis_opts = {k: options[k] for k in ("bin_deg", "zero_window_deg") if k in options}

    @jax.jit
    def mass(v):
        return jnp.sum(directions.zero_axes(directions.orientation_histogram(v, **grid_opts),
                                            **axis_opts))

    return np.asarray(jax.lax.map(mass, jnp.asarray(blocks)), np.float64)


def estimate_blocks(
    scene: Scene,
    block_px: int = 16,
    samples: int = 96,
    k: int = 2,
    *,
    integrand=None,
    options: IntegratorOptions | None = None,
    strength: bool = False,
    gate: bool = False,
    probe: int = 6,
    progress: bool = False,
    **estimate_options,
) -> BlockEstimate:
    """W Sec. 5.3: the principal directions of every ``block_px``-pixel block of ``scene``.

    One ``samples x samples`` grid per block (:func:`estimation_grid`; W: 96 and 16) feeds
    :func:`anisosample.directions.estimate_blocks` (``k`` extra directions, 1 or 2;
    ``estimate_options`` go to it). ``strength=True`` also returns each block's histogram mass
    outside the zeroed axis windows; ``gate=True`` each pixel's :func:`probe_discontinuous` of
    its ``probe x probe`` :func:`pixel_probes` (probed only in blocks with a direction: False
    elsewhere, where the base sampler is used anyway). Image sides that are not multiples of
    ``block_px`` are padded (module docstring).
    """
    from .. import directions

    k = check_int("k", k, minimum=1, maximum=2)
    block_px, samples = _check_blocks(scene, block_px, samples)
    probe = check_int("probe", probe, minimum=3)
    t0 = time.perf_counter()
    grid = estimation_grid(scene, block_px, samples, integrand=integrand, options=options,
                           progress=progress)
    try:
        est = directions.estimate_blocks(grid, k=k, samples_per_block=samples,
                                         **estimate_options)
    except ValueError as exc:  # name this function's parameter, not the estimator's
        raise ValueError(str(exc).replace("samples_per_block", "samples")) from None
    jax.block_until_ready(est)
    seconds = time.perf_counter() - t0
    by, bx = grid.shape[0] // samples, grid.shape[1] // samples
    power = None
    if strength:
        blocks = grid.reshape(by, samples, bx, samples).transpose(0, 2, 1, 3)
        power = _strength(blocks.reshape(by * bx, samples, samples),
                          estimate_options).reshape(by, bx)
    out = BlockEstimate(est, power, block_px, samples, scene.width, scene.height, seconds,
                        by * bx * samples * samples)
    if gate:
        out = gate_estimate(scene, out, probe, integrand=integrand, options=options,
                            progress=progress)
    return out


def gate_estimate(
    scene: Scene,
    estimate: BlockEstimate,
    probe: int = 6,
    *,
    integrand=None,
    options: IntegratorOptions | None = None,
    progress: bool = False,
) -> BlockEstimate:
    """``estimate`` with the per-pixel gate filled in (``discontinuous``, ``probe``,
    ``probe_seconds``): :func:`probe_discontinuous` of each pixel's :func:`pixel_probes`, for
    the pixels of blocks with a direction (False elsewhere: they take the base sampler
    anyway). The integrand options must be the estimate's."""
    if not isinstance(estimate, BlockEstimate):
        raise TypeError(f"estimate must be a BlockEstimate, got {type(estimate).__name__}")
    probe = check_int("probe", probe, minimum=3)
    t0 = time.perf_counter()
    bp = estimate.block_px
    block_has = np.asarray(estimate.estimate.valid).any(-1)
    need = np.kron(block_has, np.ones((bp, bp), bool))[:scene.height, :scene.width]
    rows, cols = np.nonzero(need)
    disc = np.zeros((scene.height, scene.width), bool)
    if rows.size:
        disc[rows, cols] = probe_discontinuous(pixel_probes(
            scene, probe, pixels=np.stack([cols, rows], -1), integrand=integrand,
            options=options, progress=progress))
    return dataclasses.replace(estimate, discontinuous=disc, probe=probe,
                               probe_seconds=time.perf_counter() - t0)


def strongest_directions(estimate) -> tuple[np.ndarray, np.ndarray]:
    """``(directions_deg, valid)``, both ``(rows, cols)``: each block's strongest extra
    direction (slot 0 of the estimate) and whether it has one (``directions_deg`` is -1 where
    not). Takes a :class:`BlockEstimate` or an :class:`anisosample.directions.Estimate`."""
    est = getattr(estimate, "estimate", estimate)
    d = np.asarray(est.directions_deg, np.float64)[..., 0]
    v = np.asarray(est.valid)[..., 0]
    return np.where(v, d, -1.0), v

"""Shared plumbing of the W render figures (W Figs. 7-10, Sec. 5.3-5.4, 6.2): scenes, per-block
direction estimates, the per-block point sets, per-pixel estimates. No science of its own: it
only strings together ``anisosample.render``, ``anisosample.directions``, ``anisosample.tables``,
``anisosample.samplers`` and ``anisosample.variance``.

* Per-block estimation (W Sec. 5.3): one ``s x s`` grid of integrand samples per block of
  ``B x B`` pixels (W: s = 96, B = 16, i.e. 36 samples per pixel). Grid sample ``(i, j)`` at
  ``x = ((j + .5)/s, (i + .5)/s)`` is taken by pixel ``(row0 + i // t, col0 + j // t)`` of the
  block, ``t = s / B``: each pixel fills one ``t x t`` tile of the grid (its own part of the
  domain), neighbouring tiles come from neighbouring pixels, so the grid pieces together one
  integrand from the block's structurally similar ones (jumps between tiles are those between
  adjacent pixels, along the axes, whose histogram windows are zeroed anyway). W does not say
  how pixels share the grid; an interleaved layout (``i mod B``) was tried first and put
  15-pixel jumps every B samples. The pixel integrands are the papers' fixed-primary-hit ones
  (``pixel_center``; W Sec. 6.2).
* Per-pixel estimator (W Sec. 5.4): one point set per block (pmj02bn; pmj02bn sheared to the
  block's strongest direction, Singh & Jarosz 2017; the aligned 3-direction set of the table for
  the block's strongest direction, rounded), decorrelated across pixels and realizations by
  toroidal shifts: the variance engine's ``randomization="shift"`` with the fixed set, per pixel.
  Blocks without an extra direction use the unaligned pmj02bn set for every method (W Sec. 5.4
  falls back to an existing sampler).
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import anisosample as asp
from anisosample import directions, render, samplers, tables
from anisosample import variance as V

ROOT = Path(__file__).resolve().parent.parent
SCENE_DIR = ROOT / "experiments" / "scenes"
# W Sec. 6.2's four scenes; ours are the shipped look-alikes (attic only if someone ships it).
SCENES = {
    "cornell": dict(xml="cornell.xml", square_aperture=False),
    "blinds": dict(xml="blinds.xml", square_aperture=False),
    "attic": dict(xml="attic.xml", square_aperture=False),
    "dof": dict(xml="dof.xml", square_aperture=True),  # W: a square aperture
}
METHODS = ("pmj02bn", "sheared pmj02bn", "aligned 3-dir")
TABLES = ROOT / "results" / "w_render_tables"  # on-demand aligned sets, shared by Figs. 8-10


def available_scenes(names) -> tuple[list[str], list[str]]:
    """``(present, missing)`` scene names (missing: no XML under experiments/scenes/)."""
    present = [s for s in names if (SCENE_DIR / SCENES[s]["xml"]).exists()]
    return present, [s for s in names if s not in present]


def load_scene(name: str, width: int, height: int):
    return render.load_xml(SCENE_DIR / SCENES[name]["xml"], width=width, height=height)


def base_integrand(scene, name: str):
    """The luminance integrand of pixel (0, 0); other pixels by replacing its film position."""
    return render.pixel_integrand(scene, (0, 0), square_aperture=SCENES[name]["square_aperture"])


def pixel_f(base, scene, pixel):
    """``f_q`` of pixel ``(col, row)`` (pixel centre): ``base`` with its film moved."""
    col, row = pixel
    film = jnp.asarray([(col + 0.5) / scene.width, (row + 0.5) / scene.height], jnp.float32)
    return eqx.tree_at(lambda f: f.film, base, film)


def block_samples(scene, base, block_px: int, samples: int = 96) -> np.ndarray:
    """All blocks' estimation grids as one ``(rows*s, cols*s)`` array (module
    docstring; block ``(a, b)`` holds rows ``a s .. a s + s - 1``, ``estimate_blocks``' layout),
    computed one row of blocks at a time."""
    w, h = scene.width, scene.height
    if w % block_px or h % block_px:
        raise ValueError(f"image {w}x{h} is not a whole number of {block_px}-pixel blocks")
    if samples % block_px:
        raise ValueError(f"samples={samples} is not a multiple of block_px={block_px}")
    by, bx = h // block_px, w // block_px
    ii, jj = np.meshgrid(np.arange(samples), np.arange(samples), indexing="ij")
    ii, jj = ii // (samples // block_px), jj // (samples // block_px)  # the pixel of each sample
    c = (np.arange(samples) + 0.5) / samples
    x = np.stack(np.meshgrid(c, c, indexing="xy"), -1).reshape(-1, 2).astype(np.float32)
    xs = jnp.asarray(np.tile(x, (bx, 1)))
    out = np.empty((by * samples, bx * samples), np.float32)
    for a in range(by):
        row = a * block_px + ii
        films = np.concatenate([
            np.stack([(b * block_px + jj + 0.5) / w, (row + 0.5) / h], -1)
            .reshape(-1, 2) for b in range(bx)]).astype(np.float32)
        vals = np.asarray(_films_eval(base, jnp.asarray(films), xs))
        out[a * samples:(a + 1) * samples] = (
            vals.reshape(bx, samples, samples).transpose(1, 0, 2).reshape(samples, -1))
    return out


def estimate_blocks(scene, base, block_px: int, samples: int = 96, k: int = 2):
    """W Sec. 5.3 per-block estimate from the blocks' tiled pixel samples (module docstring).

    Returns (Estimate with leading axes (rows, cols), seconds including the integrand samples
    (not the strength), per-block edge strength: the orientation histogram's mass outside the
    zeroed axis windows, W Sec. 5.1).
    """
    t0 = time.perf_counter()
    grid = block_samples(scene, base, block_px, samples)
    est = directions.estimate_blocks(grid, k=k, samples_per_block=samples)
    jax.block_until_ready(est)
    seconds = time.perf_counter() - t0
    by, bx = grid.shape[0] // samples, grid.shape[1] // samples
    blocks = grid.reshape(by, samples, bx, samples).transpose(0, 2, 1, 3)
    # edge strength: gradient mass of the block's histogram outside the zeroed axis windows
    strength = np.array([[float(np.sum(directions.zero_axes(
        directions.orientation_histogram(blocks[a, b])))) for b in range(bx)]
        for a in range(by)])
    return est, seconds, strength


def block_grid_values(scene, base, block, block_px: int, samples: int = 96) -> np.ndarray:
    """The ``(s, s)`` sample grid of one block (what its histogram is built from)."""
    w, h = scene.width, scene.height
    ii, jj = np.meshgrid(np.arange(samples), np.arange(samples), indexing="ij")
    t = samples // block_px
    row = block[0] * block_px + ii // t
    col = block[1] * block_px + jj // t
    films = np.stack([(col + 0.5) / w, (row + 0.5) / h], -1).reshape(-1, 2).astype(np.float32)
    c = (np.arange(samples) + 0.5) / samples
    x = np.stack(np.meshgrid(c, c, indexing="xy"), -1).reshape(-1, 2).astype(np.float32)
    return np.asarray(_films_eval(base, jnp.asarray(films), jnp.asarray(x))).reshape(
        samples, samples)


@eqx.filter_jit
def _films_eval(base, films, x):
    """``f_q(x_i)`` with pixel ``q``'s film position ``films[i]`` (vmapped)."""
    return jax.vmap(lambda film, xy: eqx.tree_at(lambda g: g.film, base, film)(xy))(films, x)


def strongest(est, block) -> float | None:
    """The block's strongest extra direction (degrees) or None."""
    a, b = block
    valid = np.asarray(est.valid[a, b])
    if not valid[0]:
        return None
    return float(np.asarray(est.directions_deg[a, b])[0])


def aligned_usable(direction: float | None) -> int | None:
    """The integer direction the 3-direction table is asked for, or None (axis after rounding)."""
    if direction is None:
        return None
    r = int(round(direction)) % 180
    return None if r in tables.AXES_DEG else r


def aligned_set(direction: int, n: int, key) -> jax.Array:
    """The aligned 3-direction set (table lookup; sets missing from the installed tables are
    synthesized on demand into ``results/w_render_tables``), toroidally shifted by ``key``."""
    try:
        s = samplers.get("aligned", directions_deg=(direction,))
        return s(key, n)
    except (FileNotFoundError, ValueError):
        s = samplers.get("aligned", directions_deg=(direction,), table=TABLES, build_missing=True)
        return s(key, n)


def block_sets(direction: float | None, n: int, key) -> dict[str, jax.Array]:
    """The fixed point set of every method for a block with strongest direction ``direction``."""
    k_pmj, k_al = jax.random.split(key)
    pmj = jnp.asarray(samplers.get("pmj02bn")(k_pmj, n), jnp.float32)
    out = {"pmj02bn": pmj}
    out["sheared pmj02bn"] = pmj if direction is None else samplers.shear(pmj, direction)
    d = aligned_usable(direction)
    out["aligned 3-dir"] = pmj if d is None else jnp.asarray(aligned_set(d, n, k_al), jnp.float32)
    return out


def pixel_variance(f, points, n: int, key, realizations: int) -> tuple[float, float, float]:
    """(variance, std error, mean) of pixel ``f``'s estimator over toroidal shifts of ``points``."""
    est = V.realization_estimates(f, points, n, key, realizations, randomization="shift")
    r = V.variance_from_estimates(est, n=n, randomization="shift")
    return r.variance, r.std_error, r.mean


def region_pixels(block, block_px: int, region_px: int) -> list[tuple[int, int]]:
    """``(col, row)`` of the ``region_px^2`` pixels centred in ``block`` (W Fig. 9's regions)."""
    off = (block_px - region_px) // 2
    r0, c0 = block[0] * block_px + off, block[1] * block_px + off
    return [(c0 + j, r0 + i) for i in range(region_px) for j in range(region_px)]


def pick_block(est, *, strength=None, exclude=(), min_axis_deg: float = 10.0):
    """The block for W Fig. 9's region: among blocks whose first direction the aligned table can
    match, prefer directions at least ``min_axis_deg`` from both axes (where alignment matters),
    then the largest ``strength`` (e.g. the block's edge strength from :func:`estimate_blocks`;
    default: the direction's confidence). None if no block has a matchable direction."""
    d = np.asarray(est.directions_deg)[..., 0]
    v = np.asarray(est.valid)[..., 0]
    c = np.asarray(est.confidence)[..., 0] if strength is None else np.asarray(strength)
    off = np.minimum(np.abs(d % 90.0), 90.0 - np.abs(d % 90.0))
    for need in (min_axis_deg, 0.0):
        ok = [(float(c[a, b]), (a, b)) for a in range(d.shape[0]) for b in range(d.shape[1])
              if v[a, b] and off[a, b] >= need and (a, b) not in exclude
              and aligned_usable(float(d[a, b])) is not None]
        if ok:
            return max(ok)[1]
    return None


def direction_rgb(directions_deg, valid) -> np.ndarray:
    """Per-block colour maps ``(rows, cols, k, 3)``: hue = direction / 180, grey = none."""
    import matplotlib

    d, v = np.asarray(directions_deg), np.asarray(valid)
    rgb = matplotlib.colormaps["hsv"](np.clip(d, 0, 180) / 180.0)[..., :3]
    return np.where(v[..., None], rgb, 0.5)


def finite_json(x):
    """Floats for JSON (NaN/inf -> None)."""
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


__all__ = [
    "METHODS", "SCENES", "TABLES", "available_scenes", "load_scene", "base_integrand", "pixel_f",
    "estimate_blocks", "block_grid_values", "strongest", "aligned_usable", "aligned_set",
    "block_sets", "pixel_variance", "region_pixels", "pick_block", "block_samples",
    "direction_rgb", "asp",
]

"""Shared plumbing of the W render figures (W Figs. 7-10, Sec. 5.3-5.4, 6.2): scenes, per-block
direction estimates, the per-block point sets, per-pixel estimates. No science of its own: the
per-block estimation, the per-pixel gate and the set selection are the library's
(``anisosample.render.estimation``, ``anisosample.selection`` and ``anisosample.render.aligned``,
the code ``anisosample render --sampler aligned`` runs); this module only strings them together
with ``anisosample.render``, ``anisosample.tables`` and ``anisosample.variance``.

* Per-block estimation (W Sec. 5.3): ``anisosample.render.estimation.estimate_blocks`` -- one
  ``s x s`` grid of integrand samples per block of ``B x B`` pixels (W: s = 96, B = 16), each
  pixel filling one ``(s/B)^2`` tile; see that module's docstring for the layout. The pixel
  integrands are the papers' fixed-primary-hit ones (``pixel_center``; W Sec. 6.2).
* Per-pixel estimator (W Sec. 5.4): one point set per block (pmj02bn; pmj02bn sheared to the
  block's strongest direction, Singh & Jarosz 2017; the aligned 3-direction set of the table for
  the block's strongest direction, rounded: ``aligned.block_sets``), decorrelated across pixels
  and realizations by toroidal shifts: the variance engine's ``randomization="shift"`` with the
  fixed set, per pixel. Blocks without an extra direction use the unaligned pmj02bn set for
  every method (W Sec. 5.4 falls back to an existing sampler). Aligned sets missing from the
  installed tables are synthesized on demand into ``results/w_render_tables``.
* Per-pixel gate (beyond W): ``pixel_gate`` -- whether each pixel's own probe of its integrand
  shows a jump (``anisosample.render.estimation.probe_discontinuous``); the gated sampler gives
  the other pixels pmj02bn.
"""

from __future__ import annotations

import math
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import anisosample as asp
from anisosample import render
from anisosample import variance as V
from anisosample.plot import direction_rgb as _direction_rgb
from anisosample.progress import progress
from anisosample.render import aligned, estimation

ROOT = Path(__file__).resolve().parent.parent
SCENE_DIR = asp.scenes.FOLDER
# W Sec. 6.2's four scenes; ours are the shipped look-alikes (attic only if someone ships it).
SCENES = {
    "cornell": dict(xml="cornell.xml", square_aperture=False),
    "blinds": dict(xml="blinds.xml", square_aperture=False),
    "attic": dict(xml="attic.xml", square_aperture=False),
    "dof": dict(xml="dof.xml", square_aperture=True),  # W: a square aperture
    "pillars": dict(xml="pillars.xml", square_aperture=False),  # directions turn in a block
}
METHODS = ("pmj02bn", "sheared pmj02bn", "aligned 3-dir")
TABLES = ROOT / "results" / "w_render_tables"  # on-demand aligned sets, shared by Figs. 8-10


def available_scenes(names) -> tuple[list[str], list[str]]:
    """``(present, missing)`` scene names (missing: no XML under anisosample/scenes/)."""
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
    """All blocks' estimation grids as one ``(rows*s, cols*s)`` array
    (``estimation.estimation_grid`` with ``base``'s film moved to every pixel)."""
    return estimation.estimation_grid(scene, block_px, samples, integrand=base)


def estimate_blocks(scene, base, block_px: int, samples: int = 96, k: int = 2):
    """W Sec. 5.3 per-block estimate (``estimation.estimate_blocks``).

    Returns (Estimate with leading axes (rows, cols), seconds including the integrand samples
    (not the strength), per-block edge strength: the orientation histogram's mass outside the
    zeroed axis windows, W Sec. 5.1).
    """
    be = estimation.estimate_blocks(scene, block_px, samples, k, integrand=base, strength=True)
    return be.estimate, be.seconds, be.strength


def pixel_gate(scene, base, probe: int = 6) -> tuple[np.ndarray, float]:
    """``(discontinuous, seconds)``: each pixel's gate decision, ``(height, width)`` bool (its
    ``probe^2`` probe shows a jump: it keeps its block's set), and the probe's wall time."""
    import time

    t0 = time.perf_counter()
    disc = estimation.probe_discontinuous(estimation.pixel_probes(scene, probe, integrand=base))
    return disc, time.perf_counter() - t0


def block_grid_values(scene, base, block, block_px: int, samples: int = 96) -> np.ndarray:
    """The ``(s, s)`` sample grid of one block (what its histogram is built from)."""
    return estimation.block_grid_values(scene, block, block_px, samples, integrand=base)


def strongest(est, block) -> float | None:
    """The block's strongest extra direction (degrees) or None."""
    d, v = estimation.strongest_directions(est)
    a, b = block
    return float(d[a, b]) if v[a, b] else None


def aligned_usable(direction: float | None) -> int | None:
    """The integer direction the 3-direction table is asked for, or None (axis after rounding)."""
    return aligned.table_direction(direction)


def aligned_set(direction: int, n: int, key) -> jax.Array:
    """The aligned 3-direction set (table lookup; sets missing from the installed tables are
    synthesized on demand into ``results/w_render_tables``), toroidally shifted by ``key``."""
    try:
        return aligned.aligned_set(direction, n, key, build_missing=False)
    except (FileNotFoundError, ValueError):
        return aligned.aligned_set(direction, n, key, table=TABLES, build_missing=True)


def block_sets(direction: float | None, n: int, key) -> dict[str, jax.Array]:
    """The fixed point set of every method for a block with strongest direction ``direction``
    (``aligned.block_sets``; aligned sets from the installed tables, else ``TABLES``)."""
    try:
        sets = aligned.block_sets(direction, n, key, build_missing=False)
    except (FileNotFoundError, ValueError):
        sets = aligned.block_sets(direction, n, key, table=TABLES, build_missing=True)
    return {"pmj02bn": sets["pmj02bn"], "sheared pmj02bn": sets["sheared"],
            "aligned 3-dir": sets["aligned"]}


def pixel_variance(f, points, n: int, key, realizations: int, *, chunks: int | None = None,
                   devices=None) -> tuple[float, float, float]:
    """(variance, std error, mean) of pixel ``f``'s estimator over toroidal shifts of ``points``:
    the shifts in ``chunks`` chunks (default: the variance engine's chunk size; a ray-casting
    integrand's bits can follow it), dealt out to ``devices`` (the same bits on any number)."""
    size = V.DEFAULT_CHUNK_ELEMENTS if chunks is None else n * max(1, realizations // chunks)
    est = V.realization_estimates(f, points, n, key, realizations, randomization="shift",
                                  chunk_elements=size, devices=devices)
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


def block_estimate(full, base, pixel, cfg, cache):
    """W's estimate (Sec. 5.3) of the block holding ``pixel``: directions, strongest first.
    ``cfg``: ``block_px`` and ``samples``; ``cache``: a dict of the blocks estimated so far."""
    b = (int(pixel[1]) // cfg["block_px"], int(pixel[0]) // cfg["block_px"])
    if b not in cache:
        grid = aligned.block_grid_values(full, b, cfg["block_px"], cfg["samples"], integrand=base)
        cache[b] = asp.directions.estimate(grid, k=2)
    return b, cache[b]


def direction_rgb(directions_deg, valid) -> np.ndarray:
    """Per-block colour maps ``(rows, cols, k, 3)``: hue = direction / 180, grey = none."""
    return _direction_rgb(directions_deg, valid)


def finite_json(x):
    """Floats for JSON (NaN/inf -> None)."""
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


__all__ = [
    "METHODS", "SCENES", "TABLES", "available_scenes", "load_scene", "base_integrand", "pixel_f",
    "estimate_blocks", "block_grid_values", "strongest", "aligned_usable", "aligned_set",
    "block_sets", "pixel_variance", "region_pixels", "pick_block", "block_samples", "pixel_gate",
    "direction_rgb", "asp",
]


def scene_option(p, default=None):
    """``--scenes`` (W Figs. 7-9): comma-separated scene names, ``default`` (a sequence of
    names; all shipped when None)."""
    p.add_argument("--scenes", default=",".join(SCENES if default is None else default),
                   help="comma-separated scenes (default: all shipped)")


def scene_settings(scale: dict, args) -> dict:
    """The settings of a W Figs. 7-9 record: the scale's, ``scale``, ``seed`` and the scenes
    asked for (their order sets their keys)."""
    return {**scale, "scale": args.scale, "seed": args.seed, "scenes": args.scenes.split(",")}


def run_scenes(name: str, args, cfg: dict, run_scene, *, catalog_keys: bool = False):
    """``run_scene(scene, cfg, key, out, fresh)`` for every shipped scene named in
    ``args.scenes`` (key ``fold_in(key(seed), i)``, ``i`` its place in ``args.scenes``, or with
    ``catalog_keys`` its place in :data:`SCENES`, so that a scene gets the same key in any
    subset), with progress; missing scenes are reported and skipped. Returns
    ``(results, missing)``."""
    present, missing = available_scenes(args.scenes.split(","))
    for s in missing:
        print(f"{s}: anisosample/scenes/{SCENES[s]['xml']} is not shipped; skipped")
    (args.out / "scenes").mkdir(parents=True, exist_ok=True)
    key = jax.random.key(args.seed)
    index = list(SCENES) if catalog_keys else present
    results = {s: run_scene(s, cfg, jax.random.fold_in(key, index.index(s)), args.out,
                            args.fresh) for s in progress(present, desc=name)}
    return results, missing

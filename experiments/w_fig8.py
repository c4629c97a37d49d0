"""W Fig. 8: per-pixel variance images after many samples per pixel.

The regime is W's: a ``film``^2 image (W: 1280^2) in 16-pixel blocks. Rendering all of it at W's
4096 spp is a GPU's work, so the image mean is estimated on ``windows x windows`` windows of
``window``^2 pixels (:func:`anisosample.render.crop`), one centred in each stratum of the film
(:func:`window_offsets`, on the block grid; chosen by position, not by content, so the mean over
the windows is a stratified estimate of the whole image's).

Per window, the principal directions are estimated per block (W Sec. 5.3,
``render.estimation.estimate_blocks`` with the gate's per-pixel probes), and every pixel's
estimator (fixed primary hit, light or lens sample, luminance; W Sec. 6.2) is rendered with
``spp`` points by :func:`anisosample.render.render` -- the renderer's own samplers, split over
``--cpu-devices`` devices (default 1; the same bits on any number) -- once per
realization, and its variance is the sample variance of the pixel's luminance over the
``realizations`` renders. Every method's render of realization ``r`` uses the key
``fold_in(window key, r)``: the same base pmj02bn set (one per realization, shared by the
pixels) and the same per-pixel toroidal shifts (W Sec. 5.4):

* ``pmj02bn`` (unaligned: 0 and 90 degrees; ``sampler="pmj02bn"``),
* ``sheared pmj02bn`` (Singh & Jarosz 2017: the realization's pmj02bn set sheared to the block's
  strongest direction; ``block_sampler(scene, "sheared", k=1)``),
* ``aligned 3-dir`` (the table set for 0, 90 and the block's strongest direction;
  ``block_sampler(scene, "aligned", k=1, gate=False)``),
* ``aligned 3-dir gated`` (beyond W: the same, but pixels whose own probe of their integrand
  shows no jump -- fully lit, fully occluded -- keep pmj02bn; the renderer's default for
  ``sampler="aligned"``). A gated pixel's estimator *is* the pmj02bn pixel's (same set, same
  shift, same bits), so its variance is taken from that column.
* ``aligned (pixel)`` (beyond W: ``sampler="aligned-pixel"``,
  :mod:`anisosample.render.pixel_aligned`): the pixel's own edge search on its fixed prefix,
  its own prefix set (pmj02bn without an edge), the prefix reused; the search's samples beyond
  ``spp`` are recorded (``pixel_search_samples_mean``; ``pixel_estimation_samples_mean`` adds
  the prefix that pixels without an edge take beside pmj02bn's ``spp``). With one direction
  allowed and two edges found, an edge within ``pixel_aligned.NEAR_AXIS_DEG`` of an axis yields
  to the other (the record's ``near_axis_deg``). An edge whose direction rounds onto an axis
  takes the set one degree off it (the record's ``axis_snap``; records without the key predate
  it and dropped such edges, W's rule). Each pixel's directions are checked against its
  neighbours' (``pixel_aligned.neighbour_consensus``, the record's ``neighbours``: the window's
  radius; records without the key predate it).
* ``aligned (pixel own)`` (beyond W: the same with ``neighbours=0``: every pixel keeps its own
  search's directions, the default before the consensus).
* ``aligned (pixel apart)`` (beyond W: the same search and choice, with probes apart,
  ``sampler_options={"reuse": False}``): the prefix only drives the search, and every pixel's
  estimate is ``spp`` points of its set without a prefix (pmj02bn without an edge). Its
  estimation samples are not counted, as W's block probes are not; the difference to
  ``aligned (pixel)`` is the price of the fixed prefix at this ``spp``.

Blocks without an extra direction use pmj02bn for every block method. Every method takes one
extra direction (``k=1``: 3-direction sets), so the block and the per-pixel estimates are
compared on the same family of sets; W's 4-direction sets at corners are W Fig. 9's subject.
(With the per-pixel sampler's default ``k=2`` the windows of a 1280^2 image ask for hundreds
of distinct 4-direction prefix sets, each built on demand in about 2 s: runs on cornell,
blinds and attic built 644 before they were stopped, blinds and attic unfinished.) Sets missing
from the installed tables are built into ``results/w_render_tables``. The image number is the
mean pixel variance (W: "variance calculated over the entire image").

Writes per scene and method ``<scene>_<method>_variance.exr`` (one channel: the windows side by
side, row-major, row 0 on top) and a PNG panel ``w_fig8.png`` (log10 variance, one colour scale
per scene), and ``w_fig8.json`` (means over the windows' pixels, per-block means, ratios to
pmj02bn, the block directions, the windows' offsets). Resumable: each finished window is kept
in ``scenes/`` and reused on rerun, as is each finished scene.

Scale: small = 4 x 4 windows of 32^2 pixels of a 1280^2 image (16,384 pixels), 16-pixel blocks
(96^2 estimation samples per block), 256 spp, 16 realizations; paper = 8 x 8 windows of 64^2
(262,144 pixels), W's 4096 spp, 32 realizations (the guide's performance section projects the
time).

``--spp N`` replaces the scale's spp (e.g. ``--scale small --spp 4096``: W's spp on the small
image; needs a table for N points or builds one).

    python experiments/w_fig8.py --scale small|paper [--spp N] [--out DIR] [--scenes ...]
        [--cpu-devices N]
"""

from __future__ import annotations

import functools

import _w_render as W
import common
import jax
import numpy as np

import anisosample as asp
from anisosample import plot, render
from anisosample.progress import progress
from anisosample.render import aligned, estimation, pixel_aligned
from anisosample.render.scene import LUMINANCE

NAME = "w_fig8"
GATED = "aligned 3-dir gated"
PIXEL = "aligned (pixel)"
APART = "aligned (pixel apart)"
OWN = "aligned (pixel own)"
METHODS = (*W.METHODS, GATED, PIXEL, APART, OWN)
SCALES = {
    "small": dict(film=1280, windows=4, window=32, block_px=16, spp=256, realizations=16),
    "paper": dict(film=1280, windows=8, window=64, block_px=16, spp=4096, realizations=32),
}


def _slug(m: str) -> str:
    return m.replace(" ", "_").replace("-", "")


def window_offsets(cfg) -> list[tuple[int, int]]:
    """``(x, y)`` of each window: one centred in each of the ``windows x windows`` strata of the
    film, rounded down to the block grid (row-major)."""
    stratum, w, bp = cfg["film"] // cfg["windows"], cfg["window"], cfg["block_px"]
    off = [i * stratum + (stratum - w) // 2 // bp * bp for i in range(cfg["windows"])]
    return [(x, y) for y in off for x in off]


def window_variance(scene, name, cfg, key, devices, probe):
    """Every method's per-pixel variance on one window (a cropped scene), its block estimate's
    gate and directions, and the per-pixel search's samples: a dict of lists (JSON)."""
    bp, n, R = cfg["block_px"], cfg["spp"], cfg["realizations"]
    options = render.IntegratorOptions(pixel_center=True,
                                       square_aperture=W.SCENES[name]["square_aperture"])
    est = estimation.estimate_blocks(scene, bp, 96, 2, options=options, gate=True, probe=probe)
    # One key per realization for every method: the base pmj02bn set and each pixel's shift
    # are the same in every method's render, so a gated pixel's estimator is the pmj02bn
    # pixel's. One render per realization: the variance is the luminance estimate's (W's f_q).
    blocks = aligned.block_sampler(scene, "aligned", estimate=est, k=1, gate=False,
                                   options=options)
    samplers = {"pmj02bn": "pmj02bn",
                "sheared pmj02bn": aligned.block_sampler(scene, "sheared", estimate=est, k=1,
                                                         options=options),
                "aligned 3-dir": blocks, PIXEL: "aligned-pixel", APART: "aligned-pixel",
                OWN: "aligned-pixel"}
    lum = np.asarray(LUMINANCE, np.float64)
    var, extra, search = {}, [], []
    for m, sampler in samplers.items():
        opts = (dict(table=W.TABLES, build_missing=True, k=1,
                     near_axis_deg=pixel_aligned.NEAR_AXIS_DEG, reuse=m != APART,
                     axis_snap=pixel_aligned.AXIS_SNAP,
                     neighbours=0 if m == OWN else pixel_aligned.NEIGHBOURS)
                if m in (PIXEL, APART, OWN) else None)
        values = []
        for r in range(R):
            res = render.render(scene, jax.random.fold_in(key, r), spp=n, sampler=sampler,
                                options=options, devices=devices, progress=False,
                                sampler_options=opts)
            values.append(res.mean.astype(np.float64) @ lum)
            if m == PIXEL:  # the search's samples; the render's count adds the prefix that
                # pixels without an edge take beside pmj02bn's spp
                e = res.pixel_estimation_samples
                extra.append(e)
                search.append(e - np.where(res.pixel_sampler == 5,
                                           res.settings["blocks"]["prefix_points"], 0))
        var[m] = np.var(np.stack(values), axis=0, ddof=1)
    has_set = blocks.pixel_sampler == 2
    disc = np.asarray(est.discontinuous)
    var[GATED] = np.where(has_set & disc, var["aligned 3-dir"], var["pmj02bn"])
    dirs = [[float(d) if ok else None for d, ok in zip(dd, vv, strict=True)]
            for dd, vv in zip(blocks.directions_deg, blocks.valid, strict=True)]
    return {"variance": {m: v.tolist() for m, v in var.items()}, "has_set": has_set.tolist(),
            "discontinuous": disc.tolist(), "directions": dirs,
            "search": np.mean(search, axis=0).tolist(),
            "estimation": np.mean(extra, axis=0).tolist()}


def _mosaic(parts, k):
    """The windows' ``(w, w)`` arrays as one ``(k w, k w)`` image, row-major."""
    rows = [np.concatenate(parts[i * k:(i + 1) * k], axis=1) for i in range(k)]
    return np.concatenate(rows, axis=0)


def run_scene(name, cfg, key, out, fresh, devices=None):
    settings = {"scene": name, **cfg, "seed_key": str(jax.random.key_data(key).tolist()),
                "estimation_samples": 96, "gate_probe": 6, "methods": list(METHODS),
                "engine": "render, windows", "k": 1,
                "near_axis_deg": pixel_aligned.NEAR_AXIS_DEG,
                "axis_snap": pixel_aligned.AXIS_SNAP, "neighbours": pixel_aligned.NEIGHBOURS}
    path = out / "scenes" / f"{name}.json"
    cached = common.cached_json(path, fresh)
    exrs = [out / f"{name}_{_slug(m)}_variance.exr" for m in METHODS]
    if cached is not None and cached.get("settings") == settings and all(p.exists() for p in exrs):
        return cached
    k, n, R, bp = cfg["windows"], cfg["spp"], cfg["realizations"], cfg["block_px"]
    film = W.load_scene(name, cfg["film"], cfg["film"])
    offsets = window_offsets(cfg)
    parts = []
    for i, xy in enumerate(progress(offsets, desc=f"{name} windows", leave=False)):
        scene = render.crop(film, xy, (cfg["window"], cfg["window"]))
        parts.append(common.reuse_or_compute(
            out / "scenes" / f"{name}_window{i}.json", {**settings, "offset": list(xy)}, fresh,
            lambda s=scene, i=i: window_variance(s, name, cfg, jax.random.fold_in(key, i),
                                                 devices, settings["gate_probe"]),
            field="window"))
    var = {m: _mosaic([np.asarray(p["variance"][m]) for p in parts], k) for m in METHODS}
    has_set = _mosaic([np.asarray(p["has_set"]) for p in parts], k)
    disc = _mosaic([np.asarray(p["discontinuous"]) for p in parts], k)
    search = _mosaic([np.asarray(p["search"]) for p in parts], k)
    extra = _mosaic([np.asarray(p["estimation"]) for p in parts], k)
    dirs = _mosaic([np.asarray(p["directions"], np.float64) for p in parts], k)
    nb = dirs.shape[0]
    block_dirs = {f"{a},{b}": (None if np.isnan(dirs[a, b]) else float(dirs[a, b]))
                  for a in range(nb) for b in range(nb)}
    meta = {**asp.io.provenance(), "scene": name, "spp": str(n), "realizations": str(R),
            "windows": str(offsets)}
    for m, p in zip(METHODS, exrs, strict=True):
        asp.io.write_exr(p, var[m].astype(np.float32), {**meta, "method": m}, overwrite=True)
    means = {m: float(v.mean()) for m, v in var.items()}
    per_block = {m: v.reshape(nb, bp, nb, bp).mean(axis=(1, 3)).tolist() for m, v in var.items()}
    rec = {
        "settings": settings,
        "image_mean_variance": means,
        "ratio_to_pmj02bn": {m: means[m] / means["pmj02bn"] for m in METHODS},
        "gated_over_ungated": means[GATED] / means["aligned 3-dir"],
        "pixels_in_blocks_with_direction": int(has_set.sum()),
        "pixels_gated": int((has_set & ~disc).sum()),
        "window_offsets": [list(o) for o in offsets],
        "pixel_search_samples_mean": float(search.mean()),
        "pixel_estimation_samples_mean": float(extra.mean()),
        "block_mean_variance": per_block,
        "block_direction_deg": block_dirs,
        "blocks_with_direction": int(sum(d is not None for d in block_dirs.values())),
        "exr": [p.name for p in exrs],
    }
    asp.io.save_json(path, rec, overwrite=True)
    return rec


def figure(results, out):
    names = list(results)
    fig, axes = plot.new_figure(max(1, len(names)), len(METHODS), size=2.8)
    for row, s in enumerate(names):
        imgs = [asp.io.read_exr(out / f"{s}_{_slug(m)}_variance.exr") for m in METHODS]
        logs = [np.log10(np.maximum(im, 1e-30)) for im in imgs]
        # the colour scale from the pixels that vary: float32 rounding alone (e.g. attic's sky,
        # the same value in every realization up to its last bit) is not variance
        floor = 1e-12 * max(float(im.max()) for im in imgs)
        pos = np.concatenate([lg[im > floor] for lg, im in zip(logs, imgs, strict=True)])
        lo, hi = (np.percentile(pos, 2), np.percentile(pos, 99.5)) if pos.size else (-12, 0)
        for col, (m, lg) in enumerate(zip(METHODS, logs, strict=True)):
            ax = axes[row, col]
            im = ax.imshow(lg, vmin=lo, vmax=hi, cmap="inferno")
            mean = results[s]["image_mean_variance"][m]
            ax.set_title(f"{s} {m}\nmean Var {mean:.3e}", fontsize=7)
            ax.set_xticks([])
            ax.set_yticks([])
        fig.colorbar(im, ax=axes[row, :].tolist(), label="log10 Var", shrink=0.8)
    return plot.save_figure(fig, out / NAME, formats=("png",))


def arguments(p):
    W.scene_option(p)
    # One device by default: over two forced CPU devices a 4096-spp run stopped making
    # progress in one window (every thread waiting; docs/reproduction.md, W Fig. 8).
    common.devices_option(p, default=1)
    p.add_argument("--spp", type=int, default=None, help="replace the scale's spp")


def settings(scale, args):
    """The scale's settings (``--spp`` replacing its spp), the methods and the scenes."""
    cfg = dict(scale)
    if args.spp is not None:
        cfg["spp"] = args.spp
    return {**cfg, "scale": args.scale, "seed": args.seed, "methods": list(METHODS),
            "scenes": args.scenes.split(",")}


def compute(settings, args):
    """Every scene's record in ``scenes/`` (resumable: a finished scene, with its variance
    images, is reused), the figure (drawn from those images) and the images' numbers."""
    cfg = {k: settings[k] for k in SCALES[args.scale]}
    devices = common.render_devices(args)  # before anything runs on JAX
    results, missing = W.run_scenes(NAME, args, cfg, functools.partial(run_scene, devices=devices),
                                    catalog_keys=True)  # a scene's numbers, whatever --scenes
    figure(results, args.out)
    images = {s: {m: np.round(asp.io.read_exr(args.out / f"{s}_{_slug(m)}_variance.exr")
                              .astype(float), 15).tolist() for m in METHODS} for s in results}
    return {"scenes": results, "missing_scenes": missing, "pixel_variance": images}


def report(data, args):
    print(f"figure: {args.out / NAME}.png\nnumbers: {args.out / NAME}.json")
    for s, r in data["scenes"].items():
        print(f"  {s} ({r['blocks_with_direction']} blocks with an extra direction, "
              f"{r['pixels_gated']} of their {r['pixels_in_blocks_with_direction']} pixels "
              f"gated): " + ", ".join(f"{m} {v:.3e} (x{r['ratio_to_pmj02bn'][m]:.3f})"
                                      for m, v in r["image_mean_variance"].items())
              + f"; gated / ungated {r['gated_over_ungated']:.3f}")


def main(argv=None):
    return common.run(NAME, __doc__.splitlines()[0], SCALES, compute, report=report,
                      outputs=(f"{NAME}.png",), arguments=arguments, settings=settings,
                      argv=argv)


if __name__ == "__main__":
    main()

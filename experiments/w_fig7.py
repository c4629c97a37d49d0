"""W Fig. 7: per-block principal direction maps at W's resolution, and their error against the
classified true directions.

For each scene the extra principal directions (besides 0 and 90 degrees) are estimated in every
block of ``16 x 16`` pixels of the ``1280^2`` image (W's resolution and blocks) from one shared
grid of 96^2 samples of the pixels' light-sample (or lens-sample) integrands (W Sec. 5.3; each
pixel fills a 6x6 tile, ``experiments/_w_render.py``), with the library's
``render.estimation.estimate_blocks`` -- the same estimation as W Fig. 9 (``w_fig9``), whose
per-block call (``_w_render.block_estimate``) is rerun on every sampled block as a check: the two
must give the same first direction (``max_recheck_deg`` in the record).

The error of the estimate (``anisosample.render.direction_error``): in sampled blocks, sampled
pixels are classified from a dense ``grid^2`` sample of their own integrand
(``render.pixel_classes``); for every pixel classified ``one-edge`` the axial distance (mod 180)
between its true spectral direction and the block's first estimated direction (the one W's
aligned sampler uses). Per block the median over its one-edge pixels; per scene the median over
those blocks and the share within 3 degrees, also pixel-weighted (over all one-edge pixels), and
both again for pixels at least 10 degrees from both axes (``w_fig9``'s one-edge region, whose
block error is 1.1 / 3.3 degrees median on cornell / dof). Blocks with one-edge pixels but no
estimated direction are counted apart.

Which pixels are classified (classifying all 1.6 million pixels of a 1280^2 image on a 64^2 grid
takes hours on 2 cores):

* ``small``: a coarse classification (128^2 image, 48^2 grid, as ``w_fig9``) proposes the blocks
  holding coarse one-edge pixels; ``max_blocks`` (48) of them are chosen (seeded); in each, the
  4x4 lattice of pixels at offsets 2, 6, 10, 14 plus the full-size pixels at the centres of the
  coarse one-edge pixels are classified on a 64^2 grid. The direction map is the whole image's.
* ``paper``: every block, its 4x4 lattice classified on a 64^2 grid (no coarse proposal).

The picture shows per scene the render (``preview`` px, pmj02bn), the map of the first
direction (hue = angle / 180, cyclic; grey: none) and the error map (per block colour = median
error of its one-edge pixels; grey: no classified one-edge pixel, or the block not sampled; a
cross: one-edge pixels but no estimate).

Writes ``results/w_fig7/w_fig7.png``, the renders as ``<scene>.exr``/``.png`` and ``w_fig7.json``
(every block's directions, validity and confidence, the counts of blocks with 0/1/2 directions,
every sampled block's one-edge pixels as ``[column, row]`` with their true directions and the
block's, the summary). Reuses finished scenes on rerun (``--fresh`` recomputes).

Default scenes: cornell and dof (``w_fig9``'s); ``--scenes cornell,blinds,attic,dof`` runs all
four (blinds' shadow pattern classifies as ``other``, so it has no one-edge blocks to score).

    python experiments/w_fig7.py --scale small|paper [--out DIR] [--scenes cornell,dof]
"""

from __future__ import annotations

import time

import _w_render as W
import common
import jax
import numpy as np

import anisosample as asp
from anisosample import metrics, plot, render
from anisosample.render import direction_error
from anisosample.render import pixel_classes as pc

NAME = "w_fig7"
SCENES = ("cornell", "dof")  # W Fig. 9's scenes; ``--scenes`` adds blinds, attic
SCALES = {
    "small": dict(size=1280, block_px=16, samples=96, coarse=128, coarse_grid=48, grid=64,
                  lattice=4, max_blocks=48, preview=256, preview_spp=16, min_axis_deg=10.0),
    "paper": dict(size=1280, block_px=16, samples=96, coarse=None, coarse_grid=None, grid=64,
                  lattice=4, max_blocks=None, preview=1280, preview_spp=64, min_axis_deg=10.0),
}


def proposed_blocks(name, cfg, nb, rng):
    """The blocks to classify pixels in, and the coarse-proposed full-size pixels per block."""
    extra = {}
    if cfg["coarse"] is None:
        return [(a, b) for a in range(nb[0]) for b in range(nb[1])], extra
    coarse = W.load_scene(name, cfg["coarse"], cfg["coarse"])
    cl = pc.pixel_classes(coarse, grid=cfg["coarse_grid"], options=render.IntegratorOptions(
        square_aperture=W.SCENES[name]["square_aperture"]))
    f = cfg["size"] // cfg["coarse"]
    for c, r in cl.pixels("one-edge") * f + f // 2:
        extra.setdefault((int(r) // cfg["block_px"], int(c) // cfg["block_px"]), []).append(
            (int(c), int(r)))
    blocks = sorted(extra)
    blocks = [blocks[i] for i in sorted(rng.permutation(len(blocks))[: cfg["max_blocks"]])]
    return blocks, extra


def run_scene(name, cfg, key, out, fresh):
    settings = {"scene": name, **cfg, "seed_key": str(jax.random.key_data(key).tolist()),
                "estimation_layout": "tiles", "error": "first direction vs one-edge classes"}
    path = out / "scenes" / f"{name}.json"
    cached = common.cached_json(path, fresh)
    if cached is not None and cached.get("settings") == settings and (out / f"{name}.exr").exists():
        return cached
    started = time.time()
    scene = W.load_scene(name, cfg["size"], cfg["size"])
    base = W.base_integrand(scene, name)
    est, seconds, _ = W.estimate_blocks(scene, base, cfg["block_px"], cfg["samples"])
    est_d, est_v = np.asarray(est.directions_deg), np.asarray(est.valid)
    rng = np.random.default_rng(np.asarray(jax.random.key_data(key)).astype(np.uint32))
    blocks, extra = proposed_blocks(name, cfg, est_v.shape[:2], rng)
    pixels = [direction_error.block_pixels(b, cfg["block_px"], cfg["lattice"], extra.get(b, ()))
              for b in blocks]
    rows = []
    if blocks:  # none: no coarse one-edge pixel (e.g. blinds' pattern is "other")
        fc = pc.pixel_classes(scene, np.concatenate(pixels), grid=cfg["grid"],
                              options=render.IntegratorOptions(
                                  square_aperture=W.SCENES[name]["square_aperture"]),
                              progress=True)
        rows = direction_error.block_errors(blocks, est_d, est_v, fc, pixels)
    # The same estimation as W Fig. 9: its per-block call on every sampled block.
    cache, recheck = {}, []
    for a, b in blocks:
        _, d9 = W.block_estimate(scene, base, (b * cfg["block_px"], a * cfg["block_px"]),
                                      cfg, cache)
        if est_v[a, b, 0] and len(d9):
            recheck.append(float(metrics.axial_distance_deg(est_d[a, b, 0], d9[0])))
        elif bool(est_v[a, b, 0]) != bool(len(d9)):
            recheck.append(180.0)
    sq = W.SCENES[name]["square_aperture"]
    prev = W.load_scene(name, cfg["preview"], cfg["preview"])
    img = render.render(prev, key, spp=cfg["preview_spp"], sampler="pmj02bn", progress=False,
                        square_aperture=sq)
    meta = {**asp.io.provenance(), **img.settings}
    asp.io.write_exr(out / f"{name}.exr", img.mean, meta, overwrite=True)
    asp.io.save_png(out / f"{name}.png", render.tonemap(img.mean), overwrite=True)
    rec = {
        "settings": settings,
        "resolution": [cfg["size"], cfg["size"]],
        "blocks": list(est_v.shape[:2]),
        "directions_deg": np.round(est_d, 3).tolist(),
        "valid": est_v.tolist(),
        "confidence": np.round(np.asarray(est.confidence), 4).tolist(),
        "blocks_with_0_1_2_directions": np.bincount(est_v.sum(-1).reshape(-1),
                                                    minlength=3).tolist(),
        "estimation_seconds": seconds,
        "estimation_ms_per_block": 1e3 * seconds / max(1, est_v.shape[0] * est_v.shape[1]),
        "max_recheck_deg": max(recheck, default=0.0),
        "sampled_blocks": rows,
        "summary": direction_error.summarize_errors(rows, cfg["min_axis_deg"]),
        "seconds": time.time() - started,
    }
    asp.io.save_json(path, rec, overwrite=True)
    return rec


def error_map(r, nb, vmax):
    """Per block RGB: error colour, grey where no classified one-edge pixel (module doc)."""
    import matplotlib as mpl

    rgb = np.full((*nb, 3), 0.5)
    crosses = []
    cmap = mpl.colormaps["viridis"]
    for s in r["sampled_blocks"]:
        a, b = s["block"]
        if s["errors_deg"]:
            rgb[a, b] = cmap(min(1.0, np.median(s["errors_deg"]) / vmax))[:3]
        elif s["one_edge_pixels"]:
            crosses.append((a, b))
    return rgb, crosses


def figure(results, out, cfg, vmax=15.0):
    import matplotlib as mpl

    names = list(results)
    fig, axes = plot.new_figure(max(1, len(names)), 3, size=3.2)
    bp, size = cfg["block_px"], cfg["size"]
    for row, s in enumerate(names):
        r = results[s]
        img = render.tonemap(asp.io.read_exr(out / f"{s}.exr")[..., :3])
        nb = tuple(r["blocks"])
        rgb = W.direction_rgb(np.asarray(r["directions_deg"]), np.asarray(r["valid"]))[:, :, 0]
        err, crosses = error_map(r, nb, vmax)
        sm = r["summary"]
        titles = (f"{s} ({size}^2, render {img.shape[0]}^2)",
                  f"{s}: first direction (grey: none)",
                  f"error: median {sm['all']['blocks']['median'] or float('nan'):.1f} deg, "
                  f"{sm['blocks_with_one_edge_pixels_and_estimate']} blocks")
        for slot, over in enumerate((None, rgb, err)):
            ax = axes[row, slot]
            ax.imshow(img, extent=(0, size, size, 0))
            if over is not None:
                ax.imshow(np.kron(over, np.ones((bp, bp, 1))), extent=(0, size, size, 0),
                          alpha=0.6 if slot == 1 else 0.85)
            if slot == 2:
                for a, b in crosses:
                    ax.plot((b + 0.5) * bp, (a + 0.5) * bp, "rx", ms=3)
            ax.set_title(titles[slot], fontsize=7)
            ax.set_xticks([])
            ax.set_yticks([])
    hue = mpl.cm.ScalarMappable(norm=mpl.colors.Normalize(0, 180), cmap=plot.axial_colormap())
    fig.colorbar(hue, ax=axes[:, 1].ravel().tolist(), label="direction (deg)", shrink=0.6)
    vir = mpl.cm.ScalarMappable(norm=mpl.colors.Normalize(0, vmax), cmap="viridis")
    fig.colorbar(vir, ax=axes[:, 2].ravel().tolist(), label="block error (deg, clipped)",
                 shrink=0.6)
    return plot.save_figure(fig, out / NAME, formats=("png",))


def compute(settings, args):
    """Every scene's record in ``scenes/`` (resumable: a finished scene, with its preview
    render, is reused) and the figure (drawn over the preview renders, which the record does
    not keep)."""
    cfg = SCALES[args.scale]
    results, missing = W.run_scenes(NAME, args, cfg, run_scene)
    figure(results, args.out, cfg)
    return {"scenes": results, "missing_scenes": missing}


def report(data, args):
    print(f"figure: {args.out / NAME}.png\nnumbers: {args.out / NAME}.json")
    for s, r in data["scenes"].items():
        sm = r["summary"]
        a, o = sm["all"], sm["off_axis"]

        def fmt(x):
            return "n/a" if x["median"] is None else (
                f"median {x['median']:.1f} deg, {100 * x['within_3_deg']:.0f}% within 3 ({x['n']})")
        print(f"  {s}: {r['blocks'][0]}x{r['blocks'][1]} blocks, 0/1/2 extra directions "
              f"{r['blocks_with_0_1_2_directions']}, {r['estimation_ms_per_block']:.2f} ms/block; "
              f"sampled {sm['blocks_sampled']} blocks, {sm['blocks_with_one_edge_pixels']} with "
              f"one-edge pixels ({sm['blocks_with_one_edge_pixels_no_estimate']} without an "
              f"estimate); recheck vs w_fig9 {r['max_recheck_deg']:.3f} deg")
        print(f"    blocks {fmt(a['blocks'])}; pixels {fmt(a['pixels'])}")
        print(f"    off-axis blocks {fmt(o['blocks'])}; pixels {fmt(o['pixels'])}")


def main(argv=None):
    return common.run(NAME, __doc__.splitlines()[0], SCALES, compute, report=report,
                      outputs=(f"{NAME}.png",), arguments=lambda p: W.scene_option(p, SCENES),
                      settings=W.scene_settings, argv=argv)


if __name__ == "__main__":
    main()

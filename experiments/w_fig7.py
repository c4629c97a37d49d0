"""W Fig. 7: per-block principal direction maps over rendered images.

For each scene the extra principal directions (besides 0 and 90 degrees) are estimated in every
block of ``16 x 16`` pixels from one shared grid of 96^2 samples of the pixels' light-sample (or
lens-sample) integrands (W Sec. 5.3; samples tiled over the block's pixels, see
``experiments/_w_render.py``), with ``anisosample.directions.estimate_blocks``. The picture shows
the rendered image and, per block, the angle of the first and of the second direction as a colour
(hue = angle / 180 degrees, a cyclic map for axial angles); grey blocks have no such direction.
The block that W Fig. 9's region comes from (``w_fig9``'s rule, ``_w_render.pick_block``) is
outlined (at the same scale the two scripts see the same image size and blocks).

Writes ``results/w_fig7/w_fig7.png``, the renders as ``<scene>.exr``/``.png`` and ``w_fig7.json``
(every block's directions, validity and confidence, the counts of blocks with 0/1/2 directions,
the estimation time). Reuses finished scenes on rerun (``--fresh`` recomputes).

    python experiments/w_fig7.py --scale small|paper [--out DIR] [--scenes cornell,blinds]
"""

from __future__ import annotations

import json
import time

import _w_render as W
import common
import jax
import numpy as np

import anisosample as asp
from anisosample import plot, render

NAME = "w_fig7"
SCALES = {
    "small": dict(size=128, block_px=16, samples=96, preview_spp=16),
    "paper": dict(size=1280, block_px=16, samples=96, preview_spp=64),
}


def run_scene(name, cfg, key, out, fresh):
    settings = {"scene": name, **cfg, "seed_key": str(jax.random.key_data(key).tolist()),
                "estimation_layout": "tiles", "block_rule": "edge strength"}
    path = out / "scenes" / f"{name}.json"
    cached = common.cached_json(path, fresh)
    if cached is not None and cached.get("settings") == settings and (out / f"{name}.exr").exists():
        return cached
    scene = W.load_scene(name, cfg["size"], cfg["size"])
    base = W.base_integrand(scene, name)
    est, seconds, strength = W.estimate_blocks(scene, base, cfg["block_px"], cfg["samples"])
    img = render.render(scene, key, spp=cfg["preview_spp"], sampler="pmj02bn", progress=False,
                        square_aperture=W.SCENES[name]["square_aperture"])
    meta = {**asp.io.provenance(), **img.settings}
    asp.io.write_exr(out / f"{name}.exr", img.mean, meta, overwrite=True)
    asp.io.save_png(out / f"{name}.png", render.tonemap(img.mean), overwrite=True)
    v = np.asarray(est.valid)
    counts = np.bincount(v.sum(-1).reshape(-1), minlength=3).tolist()
    block = W.pick_block(est, strength=strength)
    rec = {
        "settings": settings,
        "blocks": list(v.shape[:2]),
        "directions_deg": np.round(np.asarray(est.directions_deg), 3).tolist(),
        "valid": v.tolist(),
        "confidence": np.round(np.asarray(est.confidence), 4).tolist(),
        "blocks_with_0_1_2_directions": counts,
        "fig9_block": list(block) if block is not None else None,
        "estimation_seconds": seconds,
        "estimation_ms_per_block": 1e3 * seconds / max(1, v.shape[0] * v.shape[1]),
        "image_mean_luminance": float(np.mean(img.mean @ np.array(render.integrator.LUMINANCE))),
    }
    asp.io.save_json(path, rec, overwrite=True)
    return rec


def figure(results, out, cfg):
    import matplotlib.patches as patches

    names = list(results)
    fig, axes = plot.new_figure(max(1, len(names)), 3, size=3.0)
    bp = cfg["block_px"]
    for row, s in enumerate(names):
        r = results[s]
        img = render.tonemap(asp.io.read_exr(out / f"{s}.exr")[..., :3])
        h, w = img.shape[:2]
        est_d = np.asarray(r["directions_deg"])
        est_v = np.asarray(r["valid"])
        rgb = W.direction_rgb(est_d, est_v)
        for slot in range(3):
            ax = axes[row, slot]
            ax.imshow(img, extent=(0, w, h, 0))
            if slot > 0:
                over = np.kron(rgb[:, :, slot - 1], np.ones((bp, bp, 1)))
                ax.imshow(over, extent=(0, w, h, 0), alpha=0.55)
                ax.set_title(f"{s}: direction {slot} (grey: none)", fontsize=8)
            else:
                c = r["blocks_with_0_1_2_directions"]
                ax.set_title(f"{s}: blocks with 0/1/2 dirs {c}", fontsize=8)
            if r["fig9_block"] is not None:
                a, b = r["fig9_block"]
                ax.add_patch(patches.Rectangle((b * bp, a * bp), bp, bp, fill=False, ec="w",
                                               lw=1.5))
            ax.set_xticks([])
            ax.set_yticks([])
    import matplotlib as mpl

    sm = mpl.cm.ScalarMappable(norm=mpl.colors.Normalize(0, 180), cmap="hsv")
    fig.colorbar(sm, ax=axes[:, 1:].ravel().tolist(), label="direction (deg)", shrink=0.6)
    return plot.save_figure(fig, out / NAME, formats=("png",))


def main(argv=None):
    args = W.scene_parser(NAME, __doc__.splitlines()[0]).parse_args(argv)
    started = time.time()
    cfg = SCALES[args.scale]
    results, missing = W.run_scenes(NAME, args, cfg, run_scene)
    pngs = figure(results, args.out, cfg)
    json_path = common.write_record(args.out, NAME, {"scenes": results, "missing_scenes": missing},
                                    {**cfg, "scale": args.scale, "seed": args.seed}, started)
    print(f"figure: {pngs[0]}\nnumbers: {json_path}")
    for s, r in results.items():
        print(f"  {s}: {r['blocks'][0]}x{r['blocks'][1]} blocks, with 0/1/2 extra directions "
              f"{r['blocks_with_0_1_2_directions']}, {r['estimation_ms_per_block']:.1f} ms/block "
              f"(incl. the 96^2 integrand samples), Fig. 9 block {r['fig9_block']}")
    return json.loads(json_path.read_text())


if __name__ == "__main__":
    main()

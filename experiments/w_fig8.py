"""W Fig. 8: per-pixel variance images after many samples per pixel.

Per scene, the principal directions are estimated per block (W Sec. 5.3, as in ``w_fig7``), and
every pixel's estimator (fixed primary hit, light or lens sample; W Sec. 6.2) is measured with
``spp`` points from one set per block and method, decorrelated by toroidal shifts per pixel and
realization (W Sec. 5.4; the variance engine's ``"shift"`` randomization):

* ``pmj02bn`` (unaligned: 0 and 90 degrees),
* ``sheared pmj02bn`` (Singh & Jarosz 2017, sheared to the block's strongest direction),
* ``aligned 3-dir`` (the table set for 0, 90 and the block's strongest direction),
* ``aligned 3-dir gated`` (beyond W: the same, but pixels whose own probe of their integrand
  shows no jump -- fully lit, fully occluded -- keep pmj02bn; ``_w_render.pixel_gate``, the
  renderer's default for ``sampler="aligned"``). A gated pixel's estimator *is* the pmj02bn
  pixel's (same set, same per-pixel shift), so its variance is taken from that column.
* ``aligned (pixel)`` (beyond W: the renderer's ``sampler="aligned-pixel"``,
  ``render.pixel_aligned.integrand_estimates``): per realization the pixel's own edge search on
  its fixed prefix, its own prefix set (pmj02bn without an edge), the prefix reused; the
  search's samples beyond ``spp`` are recorded (``pixel_search_samples``).

Blocks without an extra direction use pmj02bn for every method. W's 4-direction sets are not
measured here (no 4141-set table ships; the renderer builds them on demand, one n = 256 set in
11 s at load 3.8). The variance of a pixel is the sample variance over ``realizations`` shifts;
the image number is its mean over all pixels (W: "variance calculated over the entire image").

Writes per scene and method ``<scene>_<method>_variance.exr`` (one channel, row 0 on top) and a
PNG panel ``w_fig8.png`` (log10 variance, one colour scale per scene), and ``w_fig8.json`` (image
means, per-block means, ratios to pmj02bn, the block directions). Reuses finished scenes on rerun.

Scale: small = 32^2 pixels in 8-pixel blocks (96^2 estimation samples per block), 256 spp;
paper = 128^2 pixels in W's 16-pixel blocks, W's 4096 spp (W renders 1280^2: too many per-pixel
variance runs for this script's pixel loop).

``--spp N`` replaces the scale's spp (e.g. ``--scale small --spp 4096``: W's spp on the small
image; needs a table for N points or builds one).

    python experiments/w_fig8.py --scale small|paper [--spp N] [--out DIR] [--scenes ...]
"""

from __future__ import annotations

import _w_render as W
import common
import jax
import numpy as np

import anisosample as asp
from anisosample import plot
from anisosample.progress import progress

NAME = "w_fig8"
GATED = "aligned 3-dir gated"
PIXEL = "aligned (pixel)"
METHODS = (*W.METHODS, GATED, PIXEL)
SCALES = {
    "small": dict(size=32, block_px=8, spp=256, realizations=16),
    "paper": dict(size=128, block_px=16, spp=4096, realizations=32),
}


def _slug(m: str) -> str:
    return m.replace(" ", "_").replace("-", "")


def run_scene(name, cfg, key, out, fresh):
    settings = {"scene": name, **cfg, "seed_key": str(jax.random.key_data(key).tolist()),
                "estimation_layout": "tiles", "gate_probe": 6, "methods": list(METHODS)}
    path = out / "scenes" / f"{name}.json"
    cached = common.cached_json(path, fresh)
    exrs = [out / f"{name}_{_slug(m)}_variance.exr" for m in METHODS]
    if cached is not None and cached.get("settings") == settings and all(p.exists() for p in exrs):
        return cached
    size, bp, n, R = cfg["size"], cfg["block_px"], cfg["spp"], cfg["realizations"]
    scene = W.load_scene(name, size, size)
    base = W.base_integrand(scene, name)
    est, _, _ = W.estimate_blocks(scene, base, bp)
    disc, gate_seconds = W.pixel_gate(scene, base, settings["gate_probe"])
    nb = size // bp
    from anisosample.render import pixel_aligned as PA

    var = {m: np.zeros((size, size)) for m in (*W.METHODS, PIXEL)}
    search = np.zeros((size, size))
    k_sets, k_pix = jax.random.split(key)
    block_dirs = {}
    for a, b in progress([(a, b) for a in range(nb) for b in range(nb)], desc=f"{name} blocks",
                         leave=False):
        d = W.strongest(est, (a, b))
        block_dirs[f"{a},{b}"] = d
        sets = W.block_sets(d, n, jax.random.fold_in(k_sets, a * nb + b))
        for i in range(bp):
            for j in range(bp):
                row, col = a * bp + i, b * bp + j
                f = W.pixel_f(base, scene, (col, row))
                kq = jax.random.fold_in(k_pix, row * size + col)
                for m in W.METHODS:
                    if m != "pmj02bn" and d is None:
                        continue
                    var[m][row, col] = W.pixel_variance(f, sets[m], n, kq, R)[0]
                if d is None:  # no extra direction: every method falls back to pmj02bn
                    for m in W.METHODS[1:]:
                        var[m][row, col] = var["pmj02bn"][row, col]
                e = PA.integrand_estimates(f, n, kq, R, table=W.TABLES, build_missing=True)
                var[PIXEL][row, col] = float(np.var(e.estimates, ddof=1))
                search[row, col] = float(np.mean(e.search_samples))
    has_set = np.kron(np.asarray([[block_dirs[f"{a},{b}"] is not None for b in range(nb)]
                                  for a in range(nb)]), np.ones((bp, bp), bool))
    keep = has_set & disc  # gated: only these pixels keep the block's aligned set
    var[GATED] = np.where(keep, var["aligned 3-dir"], var["pmj02bn"])
    meta = {**asp.io.provenance(), "scene": name, "spp": str(n), "realizations": str(R)}
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
        "gate_seconds": gate_seconds,
        "pixel_search_samples_mean": float(search.mean()),
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
        pos = np.concatenate([lg[im > 0] for lg, im in zip(logs, imgs, strict=True)])
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
    results, missing = W.run_scenes(NAME, args, cfg, run_scene)
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

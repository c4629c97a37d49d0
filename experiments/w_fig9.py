"""W Fig. 9: per-region variance convergence in the rendered scenes over 2^8..2^12 spp.

For each scene (W Sec. 6.2: CORNELL-BOX, BREAKFAST-ROOM = our blinds, ATTIC, DEPTH-OF-FIELD;
the shipped look-alikes under experiments/scenes/, attic only if its XML exists) the principal
directions are estimated per block of pixels (W Sec. 5.3, 96^2 samples per block, tiled
over the block's pixels; see ``experiments/_w_render.py``), one block is picked
(``_w_render.pick_block``: a first direction that a 3-direction table can match, at least 10
degrees from both axes if any block has one, then the largest edge strength, i.e. orientation-
histogram mass off the axes; outlined in ``w_fig7``'s maps), and in a region of pixels at its
centre the variance of each pixel's estimator (fixed primary hit, W's setting) is measured
over toroidal shifts of one point set per method (fresh per n) and averaged over the region:

* ``pmj02bn`` (matches 0 and 90 degrees only),
* ``sheared pmj02bn`` (Singh & Jarosz 2017: one axis re-aimed at the block's direction),
* ``aligned 3-dir`` (the table set for 0, 90 and the block's direction, W Sec. 5.4).

W's 4-direction sets are not measured (no 4141-set table here). Slopes are weighted log-log fits
with 95 % intervals (``anisosample.variance.fit_slope``). W's claims: aligned about -1.75 vs about
-1.5 for pmj02bn/sheared on CORNELL and DEPTH-OF-FIELD; shearing helps only on BREAKFAST-ROOM.

Writes ``results/w_fig9/w_fig9.png`` (per scene: the block's sample grid, its power spectrum, its
orientation histogram with the estimate, and the convergence plot) and ``w_fig9.json`` (every
plotted number). Finished scenes are reused on rerun (``--fresh`` recomputes).

    python experiments/w_fig9.py --scale small|paper [--out DIR] [--scenes cornell,blinds]
"""

from __future__ import annotations

import json
import time

import _w_render as W
import common
import jax
import numpy as np

import anisosample as asp
from anisosample import directions, plot
from anisosample import variance as V
from anisosample.progress import progress

NAME = "w_fig9"
SCALES = {
    # small: a 128^2 image, 16-pixel blocks, the 4x4 pixels at the block centre, 2^8..2^12 spp
    "small": dict(size=128, block_px=16, region_px=4, log2_ns=[8, 9, 10, 11, 12], realizations=256),
    # paper: W's 1280^2 image, 16x16-pixel blocks, the whole block, 2^8..2^12 spp (GPU)
    "paper": dict(size=1280, block_px=16, region_px=16, log2_ns=[8, 9, 10, 11, 12],
                  realizations=128),
}


def run_scene(name, cfg, key, out, fresh):
    settings = {"scene": name, **cfg, "seed_key": str(jax.random.key_data(key).tolist()),
                "estimation_layout": "tiles",
                "block_rule": "off-axis >= 10 deg, then largest edge strength"}
    path = out / "scenes" / f"{name}.json"
    cached = common.cached_json(path, fresh)
    if cached is not None and cached.get("settings") == settings:
        return cached
    scene = W.load_scene(name, cfg["size"], cfg["size"])
    base = W.base_integrand(scene, name)
    est, est_seconds, strength = W.estimate_blocks(scene, base, cfg["block_px"])
    block = W.pick_block(est, strength=strength)
    if block is None:
        print(f"{name}: no block with a matchable extra direction; skipped")
        rec = {"settings": settings, "skipped": "no block with a matchable extra direction"}
        asp.io.save_json(path, rec, overwrite=True)
        return rec
    a, b = block
    d = W.strongest(est, block)
    dirs = np.asarray(est.directions_deg[a, b]).tolist()
    valid = np.asarray(est.valid[a, b]).tolist()
    print(f"{name}: block {block}, directions {[x for x, v in zip(dirs, valid, strict=True) if v]} "
          f"(table direction {W.aligned_usable(d)})")
    pixels = W.region_pixels(block, cfg["block_px"], cfg["region_px"])
    ns = [2**k for k in cfg["log2_ns"]]
    curves = {m: {"variance": [], "std_error": [], "mean": []} for m in W.METHODS}
    k_sets, k_pix = jax.random.split(key)
    for n in progress(ns, desc=f"{name} n", leave=False):
        sets = W.block_sets(d, n, jax.random.fold_in(k_sets, n))
        for m in W.METHODS:
            var, se, mean = [], [], []
            for q, pix in enumerate(pixels):
                f = W.pixel_f(base, scene, pix)
                kq = jax.random.fold_in(jax.random.fold_in(k_pix, n), q)
                v, s, mu = W.pixel_variance(f, sets[m], n, kq, cfg["realizations"])
                var.append(v)
                se.append(s)
                mean.append(mu)
            curves[m]["variance"].append(float(np.mean(var)))
            curves[m]["std_error"].append(float(np.sqrt(np.sum(np.square(se))) / len(se)))
            curves[m]["mean"].append(float(np.mean(mean)))
    for c in curves.values():
        c["fit"] = V.fit_slope(ns, c["variance"], c["std_error"]).as_dict()
    grid = W.block_grid_values(scene, base, block, cfg["block_px"])
    hist = np.asarray(directions.orientation_histogram(grid))
    rec = {
        "settings": settings, "block": list(block), "pixels": [list(p) for p in pixels],
        "directions_deg": dirs, "valid": valid,
        "confidence": np.asarray(est.confidence[a, b]).tolist(),
        "table_direction_deg": W.aligned_usable(d), "ns": ns, "curves": curves,
        "estimation_seconds_all_blocks": est_seconds,
        "block_grid": grid.tolist(), "histogram": hist.tolist(),
    }
    asp.io.save_json(path, rec, overwrite=True)
    return rec


def figure(results, out):
    names = [s for s, r in results.items() if "curves" in r]
    fig, axes = plot.new_figure(max(1, len(names)), 4, size=2.6)
    for row, s in enumerate(names):
        r = results[s]
        g = np.asarray(r["block_grid"])
        ax = axes[row, 0]
        ax.imshow(g, origin="lower", cmap="gray", extent=(0, 1, 0, 1))
        ax.set_title(f"{s}: block {tuple(r['block'])} f(x)", fontsize=8)
        spec = np.abs(np.fft.fftshift(np.fft.fft2(g - g.mean()))) ** 2
        ax = axes[row, 1]
        ax.imshow(np.log10(spec + 1e-12 * spec.max()), origin="lower", cmap="magma")
        ax.set_title("log10 P_f", fontsize=8)
        ax.set_xticks([])
        ax.set_yticks([])
        ax = axes[row, 2]
        h = np.asarray(r["histogram"])
        ax.plot(np.arange(h.size), h, lw=0.8)
        for d, v in zip(r["directions_deg"], r["valid"], strict=True):
            if v:
                ax.axvline(d, color="r", lw=0.8)
        ax.set_title("orientation histogram, estimate (red)", fontsize=8)
        ax.set_xlabel("deg", fontsize=7)
        ax = axes[row, 3]
        for m, c in r["curves"].items():
            f = c["fit"]
            plot.convergence_panel(ax, r["ns"], c["variance"], label=m, slope=f["slope"],
                                   slope_ci=(f["ci_low"], f["ci_high"]))
        ax.legend(fontsize=6, loc="lower left")
        ax.set_title(f"{s}: region variance", fontsize=8)
    return plot.save_figure(fig, out / NAME, formats=("png",))


def main(argv=None):
    args = W.scene_parser(NAME, __doc__.splitlines()[0]).parse_args(argv)
    started = time.time()
    cfg = SCALES[args.scale]
    results, missing = W.run_scenes(NAME, args, cfg, run_scene)
    pngs = figure(results, args.out)
    data = {"scenes": results, "missing_scenes": missing}
    json_path = common.write_record(args.out, NAME, data, {**cfg, "scale": args.scale,
                                    "seed": args.seed, "methods": list(W.METHODS)}, started)
    print(f"figure: {pngs[0]}\nnumbers: {json_path}")
    for s, r in results.items():
        if "curves" not in r:
            continue
        print(f"  {s}: block {tuple(r['block'])}, directions "
              f"{[round(d, 1) for d, v in zip(r['directions_deg'], r['valid'], strict=True) if v]}")
        for m, c in r["curves"].items():
            f = c["fit"]
            print(f"    {m:16s} slope {f['slope']:+.3f} [{f['ci_low']:+.3f}, {f['ci_high']:+.3f}]"
                  f"  Var@{r['ns'][-1]} {c['variance'][-1]:.3e}")
    return json.loads(json_path.read_text())


if __name__ == "__main__":
    main()

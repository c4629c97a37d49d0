"""Beyond W: the per-pixel sampler's prefix size at low spp, on W Fig. 9's one-edge pixels.

The per-pixel aligned sampler (``render.pixel_aligned``) renders a fixed isotropic prefix of
``m`` points first, finds the pixel's edge directions from it and completes the set with the
table set that starts with that prefix; :func:`anisosample.render.pixel_aligned.pixel_prefix`
gives ``m = 64`` from 256 spp on. At 256 spp that prefix is a quarter of the set, and W Fig. 10
(equal cost) finds the per-pixel sampler behind the block estimate there. This script asks
whether a smaller prefix helps at low spp: a smaller ``m`` leaves more of the set aligned, but
gives the edge search fewer samples.

On the one-edge pixels of ``w_fig9``'s record (run first in its own process, which reuses its
finished scenes; the same pixels, keys and shifts), per scene, ``n`` and prefix ``m``:

* ``search``: :func:`anisosample.render.pixel_aligned.integrand_estimates` with
  ``prefix="dihedral-<m>"`` (the search on the prefix's values, the prefix set for what it found,
  the prefix reused): per-pixel variance over ``realizations`` shifts relative to the record's
  pmj02bn variance at ``n``; the median and the geometric mean over the pixels; the median
  direction error (a realization without a direction counts 90 degrees); the share of
  realizations that fell back to pmj02bn; the search's samples beyond the prefix;
* ``true direction``: the prefix set for the pixel's classified direction, no search (what the
  prefix alone costs), and ``m = 0``, the set without a prefix, as the reference.

Writes ``results/beyond_pixel_prefix/beyond_pixel_prefix.json`` and ``.png``.

    python experiments/beyond_pixel_prefix.py --scale small|paper [--fig9-out DIR]
"""

from __future__ import annotations

import json
from pathlib import Path

import _w_render as W
import common
import jax
import numpy as np

from anisosample import metrics, plot, selection
from anisosample import variance as V
from anisosample.render import pixel_aligned as PA

NAME = "beyond_pixel_prefix"
SCALES = {"small": dict(ns=[256, 512], prefixes=[16, 32, 64]),
          "paper": dict(ns=[256, 512, 1024], prefixes=[16, 32, 48, 64])}
CLASS = "one-edge"
CLASS_INDEX = 0  # w_fig9's CLASS_NAMES.index("one-edge"): the class's key


def arguments(p):
    p.add_argument("--fig9-out", type=Path, default=common.ROOT / "results" / "w_fig9",
                   help="w_fig9's results folder (reused; computed there if missing)")


def settings(scale, args):
    """The scale's settings, ``scale``, ``seed`` and w_fig9's settings, from its record (w_fig9
    runs first, in its own process: ``args.fig9``)."""
    args.fig9 = common.run_script("w_fig9", args.fig9_out, "--scale", args.scale, "--seed",
                                  str(args.seed))
    cfg9 = {k: v for k, v in args.fig9["settings"].items() if k not in ("scale", "seed")}
    return {**scale, "scale": args.scale, "seed": args.seed, "fig9": cfg9}


def _summary(ratios, errors=None, fallback=None, search=None) -> dict:
    g, se = metrics.geometric_mean(ratios)
    out = {"ratio_median": float(np.median(ratios)), "ratio_geomean": g, "ratio_geomean_se": se}
    if errors is not None:
        out.update(direction_error_median_deg=float(np.median(errors)),
                   fallback_share=float(np.mean(fallback)),
                   search_samples_per_pixel=float(np.mean(search)))
    return out


def measure_scene(name, c, cfg9, settings, key):
    """One scene's pixels: ``{n: {"search": {m: summary}, "true direction": {m: summary}}}``."""
    full = W.load_scene(name, cfg9["size"], cfg9["size"])
    base = W.base_integrand(full, name)
    ckey = jax.random.fold_in(key, CLASS_INDEX)
    realizations = cfg9["realizations"]
    out = {}
    for n in settings["ns"]:
        i = c["ns"].index(n)
        searched = {m: ([], [], [], []) for m in settings["prefixes"]}
        true = {m: [] for m in [0, *settings["prefixes"]]}
        for q, r in enumerate(c["pixels"]):
            f = W.pixel_f(base, full, (int(r["pixel"][0]), int(r["pixel"][1])))
            kq = jax.random.fold_in(jax.random.fold_in(ckey, 10_000 + q), n)
            pmj = r["methods"]["pmj02bn"]["variance"][i]
            direction = r["true_directions_deg"][0]
            for m, (ratio, err, fell, extra) in searched.items():
                e = PA.integrand_estimates(f, n, kq, realizations, table=W.TABLES,
                                           build_missing=True, prefix=f"dihedral-{m}")
                res = V.variance_from_estimates(e.estimates, n=n, randomization="shift")
                ratio.append(res.variance / pmj)
                found = e.directions_deg[:, 0]
                ok = np.isfinite(found)
                err.extend(metrics.axial_distance_deg(found[ok], direction).tolist())
                err.extend([90.0] * int((~ok).sum()))
                fell.append(float(np.mean(e.code == 5)))
                extra.append(float(np.mean(e.search_samples)))
            request = [selection.table_directions([direction], 1)]
            for m, ratio in true.items():
                pts = selection.aligned_sets(request, n, table=W.TABLES, build_missing=True,
                                             prefix=f"dihedral-{m}" if m else None,
                                             progress=False)[0]
                ratio.append(W.pixel_variance(f, pts, n, kq, realizations)[0] / pmj)
        out[str(n)] = {"search": {str(m): _summary(*v) for m, v in searched.items()},
                       "true direction": {str(m): _summary(v) for m, v in true.items()}}
        print(f"{name} n={n}: " + ", ".join(
            f"m={m} {v['ratio_median']:.3f}" for m, v in out[str(n)]["search"].items()))
    return out


def compute(settings, args):
    rows = {}
    for s, rec in args.fig9["scenes"].items():
        c = rec["classes"][CLASS]
        if not c.get("pixels"):
            continue
        # the scene's own key, as w_fig9 drew it
        key = jax.random.wrap_key_data(np.asarray(json.loads(rec["settings"]["seed_key"]),
                                                  np.uint32))
        rows[s] = {"pixels": len(c["pixels"]),
                   "by_n": measure_scene(s, c, settings["fig9"], settings, key)}
    return {"scenes": rows}


def figure(data, args):
    scenes = list(data["scenes"])
    ns = list(next(iter(data["scenes"].values()))["by_n"])
    fig, axes = plot.new_figure(len(ns), max(1, len(scenes)), size=2.8)
    for row, n in enumerate(ns):
        for col, s in enumerate(scenes):
            ax = axes[row, col]
            d = data["scenes"][s]["by_n"][n]
            for label, part, marker in (("search (per-pixel sampler)", "search", "o"),
                                        ("true direction", "true direction", "s")):
                ms = [int(m) for m in d[part]]
                ax.plot(ms, [d[part][str(m)]["ratio_median"] for m in ms], marker=marker,
                        label=label)
            ax.set_xlabel("prefix points m (0: no prefix)")
            ax.set_ylabel("median Var / pmj02bn")
            ax.set_title(f"{s}, n = {n}", fontsize=8)
            ax.legend(fontsize=6)
    plot.save_figure(fig, args.out / NAME, formats=("png",))


def report(data, args):
    print(f"figure: {args.out / NAME}.png\nnumbers: {args.out / NAME}.json")
    for s, r in data["scenes"].items():
        for n, d in r["by_n"].items():
            print(f"  {s} n={n} ({r['pixels']} one-edge pixels): median Var / pmj02bn")
            for m, v in d["search"].items():
                print(f"    search, m={m:>2}: {v['ratio_median']:.3f} (geomean "
                      f"{v['ratio_geomean']:.3f} +- {v['ratio_geomean_se']:.3f}), error "
                      f"{v['direction_error_median_deg']:.2f} deg, fallback "
                      f"{100 * v['fallback_share']:.1f} %, search "
                      f"{v['search_samples_per_pixel']:.1f} samples")
            print("    true direction: " + ", ".join(
                f"m={m} {v['ratio_median']:.3f}" for m, v in d["true direction"].items()))


def main(argv=None):
    return common.run(NAME, __doc__.splitlines()[0], SCALES, compute, figure=figure,
                      report=report, arguments=arguments, settings=settings, argv=argv)


if __name__ == "__main__":
    main()

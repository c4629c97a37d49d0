"""W Fig. 10: equal-time comparison -- the aligned curves shifted by the direction-estimation cost.

W Sec. 6.2: estimating the block directions costs a constant time per pixel that the unaligned
samplers can spend on extra samples (W: at most 64 spp). Here that shift is *measured* on this
machine, per scene, with bench-like timing (warm-up, best of ``repeats``):

* ``t_est``: ``experiments/_w_render.estimate_blocks`` over the whole image (the 96^2 integrand
  samples per block plus histogram and vMF fit, ``anisosample.directions.estimate_blocks``),
  per pixel;
* ``t_spp``: one sample of one pixel in the renderer (``anisosample.render.render`` with the
  fixed primary hit, pmj02bn points, ``spp`` samples, whole image), per pixel and sample.

``shift = t_est / t_spp`` samples per pixel, timed on a ``timing_size``^2 image (both costs
are per pixel, so the image size only sets how long the timing takes); ``gate_shift_spp`` is
the per-pixel gate's probe (beyond W, an upper bound: every pixel probed) in the same units.
Beyond W, ``aligned (pixel)`` (the renderer's ``sampler="aligned-pixel"``) is shifted by its own
measured cost: ``(t_pixel - t_pmj) / t_spp`` per pixel, the two renders' times at
``pixel_spp`` on the same image (the search's samples and compute, the lit pixels' prefix beside
pmj02bn, the set lookups), and, as ``aligned (pixel) at equal samples``, by the integrand
samples its estimation takes beyond ``spp`` per pixel (``pixel_sample_shift_spp``: the render
record's ``estimation_samples_per_pixel``; the equal-time shift on a renderer whose samples
cost far more than the search's compute); ``aligned (window)`` by the block shift (the same
estimation samples; its per-pixel vMF fits are not timed, so its shift is a lower bound).
The curves are W Fig. 9's on its one-edge penumbra pixels (``w_fig9``, run first at the same
scale in its own process, which reuses its finished scenes): the median over those pixels of
each method's per-pixel variance; the aligned curves are drawn at ``N + shift``, the unaligned
ones at ``N``. The JSON also
gives, at the smallest N, each unaligned variance interpolated (log-log) at ``N + shift`` and
the aligned (block) variance over it, and at each N of the per-pixel curve the equal-cost
ratios to pmj02bn (``equal_cost_by_n``: :func:`equal_cost_by_n`). Timings depend on the
machine and its load.

    python experiments/w_fig10.py --scale small|paper [--out DIR] [--fig9-out DIR]
"""

from __future__ import annotations

import time
from pathlib import Path

import _w_render as W
import common
import jax
import numpy as np

from anisosample import plot, render

NAME = "w_fig10"
SCALES = {"small": dict(repeats=3, spp=64, timing_size=128, pixel_spp=256),
          "paper": dict(repeats=5, spp=256, timing_size=256, pixel_spp=256)}
CLASS = "one-edge"  # W Fig. 9's penumbra pixels: where the claim lives
ALIGNED = "aligned (block)"  # what the renderer's aligned sampler uses (W Sec. 5.4)
PIXEL = "aligned (pixel)"  # beyond W: the renderer's sampler="aligned-pixel"


def measure(name, cfg9, cfg, key):
    scene = W.load_scene(name, cfg["timing_size"], cfg["timing_size"])
    base = W.base_integrand(scene, name)
    bp = cfg9["block_px"]
    W.estimate_blocks(scene, base, bp)  # warm-up (compilation)
    t_est = min(W.estimate_blocks(scene, base, bp)[1] for _ in range(cfg["repeats"]))
    W.pixel_gate(scene, base)  # the per-pixel gate's probe (beyond W), warm-up
    t_gate = min(W.pixel_gate(scene, base)[1] for _ in range(cfg["repeats"]))
    opts = dict(spp=cfg["spp"], sampler="pmj02bn", pixel_center=True, progress=False,
                square_aperture=W.SCENES[name]["square_aperture"])
    render.render(scene, key, **opts)  # warm-up
    times = []
    for r in range(cfg["repeats"]):
        t0 = time.perf_counter()
        render.render(scene, jax.random.fold_in(key, r), **opts)
        times.append(time.perf_counter() - t0)
    px = scene.width * scene.height
    t_spp = min(times) / (px * cfg["spp"])
    # The per-pixel sampler against pmj02bn at pixel_spp, both timed alike.
    t_pair = {}
    for sampler in ("pmj02bn", "aligned-pixel"):
        o = dict(opts, spp=cfg["pixel_spp"], sampler=sampler)
        if sampler == "aligned-pixel":
            o["sampler_options"] = {"table": W.TABLES, "build_missing": True}
        render.render(scene, key, **o)  # warm-up (compilation, set builds)
        ts = []
        for _ in range(cfg["repeats"]):
            # The warm-up's key again: another key moves the per-pixel estimates, and sets the
            # table lacks for them would be synthesized inside the timed call (a one-time table
            # cost, not the render's: measured 52.5 s against 2.2 s on cornell, 2026-12-06).
            t0 = time.perf_counter()
            res = render.render(scene, key, **o)
            ts.append(time.perf_counter() - t0)
        t_pair[sampler] = min(ts)
    samples = res.settings["blocks"]["estimation_samples_per_pixel"]
    t_spp_p = t_pair["pmj02bn"] / (px * cfg["pixel_spp"])
    pixel_shift = (t_pair["aligned-pixel"] - t_pair["pmj02bn"]) / px / t_spp_p
    return {"t_est_s": t_est, "t_est_per_pixel_s": t_est / px, "t_render_s": min(times),
            "t_pixel_render_s": t_pair["aligned-pixel"], "t_pmj_render_s": t_pair["pmj02bn"],
            "pixel_shift_spp": pixel_shift, "pixel_sample_shift_spp": samples,
            "t_per_sample_s": t_spp, "shift_spp": t_est / px / t_spp,
            "t_gate_s": t_gate, "gate_shift_spp": t_gate / px / t_spp,
            "integrand_samples_per_pixel_for_estimation": 96**2 / bp**2}


def median_curves(c) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, np.ndarray]]:
    """``(ns, {method: median over the class's pixels of the per-pixel variance}, {method: its
    ns})`` (the beyond-W columns are measured on a subset of the sizes)."""
    methods = c["pixels"][0]["methods"]
    own = {m: np.asarray(c["pixels"][0]["methods"][m].get("ns", c["ns"]), float)
           for m in methods}
    return np.asarray(c["ns"], float), {
        m: np.median([r["methods"][m]["variance"] for r in c["pixels"]], axis=0)
        for m in methods}, own


def interp_loglog(ns, var, x):
    return float(np.exp(np.interp(np.log(x), np.log(ns), np.log(var))))


def equal_cost_by_n(ns, curves, own_ns, t) -> dict:
    """At each N of the per-pixel curve: the aligned curve at N over pmj02bn's interpolated
    at N + shift, for ``aligned (block)`` (its estimation's shift), ``aligned (pixel)`` (its
    render's time shift, measured at ``pixel_spp`` and taken as constant in N: the search, the
    prefix beside pmj02bn on smooth pixels and the set lookups do not grow with spp) and
    ``aligned (pixel) at equal samples``; NaN where N + shift lies past pmj02bn's largest N
    (no extrapolation)."""
    if PIXEL not in curves:
        return {}
    pmj = curves["pmj02bn"]

    def over(m, n, shift):
        x = n + shift
        if x > ns[-1]:
            return float("nan")
        return float(curves[m][list(own_ns[m]).index(n)] / interp_loglog(ns, pmj, x))

    return {str(int(n)): {ALIGNED: over(ALIGNED, n, t["shift_spp"]),
                          PIXEL: over(PIXEL, n, t["pixel_shift_spp"]),
                          PIXEL + " at equal samples": over(PIXEL, n, t["pixel_sample_shift_spp"])}
            for n in own_ns[PIXEL] if n in list(own_ns[ALIGNED])}


def arguments(p):
    p.add_argument("--fig9-out", type=Path, default=common.ROOT / "results" / "w_fig9",
                   help="w_fig9's results folder (reused; computed there if missing)")


def settings(scale, args):
    """The scale's settings, ``scale``, ``seed`` and w_fig9's settings (but its scale, seed and
    scenes), from w_fig9's record: w_fig9 runs first, in its own process (``args.fig9``)."""
    args.fig9 = common.run_script("w_fig9", args.fig9_out, "--scale", args.scale, "--seed",
                                  str(args.seed))
    cfg9 = {k: v for k, v in args.fig9["settings"].items()
            if k not in ("scale", "seed", "scenes")}
    return {**scale, "scale": args.scale, "seed": args.seed, "fig9": cfg9}


def fig9_curves(fig9):
    """``{scene: (ns, {method: median curve}, {method: its ns})}`` of w_fig9's record."""
    return {s: median_curves(r["classes"][CLASS]) for s, r in fig9["scenes"].items()
            if r["classes"].get(CLASS, {}).get("pixels")}


def complete(data, args):
    """A record is reused only while w_fig9's curves it drew are w_fig9's curves now."""
    now = {s: {m: v.tolist() for m, v in c[1].items()} for s, c in fig9_curves(args.fig9).items()}
    return now == {s: r["curves"] for s, r in data["scenes"].items()}


def compute(settings, args):
    """The timings (``timings.json``, reused under the same settings), the figure (an extra
    output: the curves at their own ns, from w_fig9's record) and the equal-time numbers."""
    fig9, cfg9 = args.fig9, settings["fig9"]
    cfg = SCALES[args.scale]
    key = jax.random.key(args.seed)
    curves9 = fig9_curves(fig9)
    ns_of = {s: c[2] for s, c in curves9.items()}
    curves9 = {s: c[:2] for s, c in curves9.items()}
    scenes = list(curves9)
    timings = common.reuse_or_compute(
        args.out / "timings.json", settings, args.fresh,
        lambda: {s: measure(s, cfg9, cfg, jax.random.fold_in(key, i))
                 for i, s in enumerate(scenes)}, field="timings")
    fig, axes = plot.new_figure(1, max(1, len(scenes)), size=3.4)
    rows = {}
    for col, s in enumerate(scenes):
        ns, curves = curves9[s]
        t = timings[s]
        shift = t["shift_spp"]
        ax = axes[0, col]
        cmp = {}
        shifts = {m: (t["pixel_shift_spp"] if m == PIXEL else shift)
                  for m in curves if m.startswith("aligned")}
        for m, v in curves.items():
            x = ns_of[s][m] + shifts.get(m, 0.0)
            plot.convergence_panel(ax, x, v, label=m + (" (+est.)" if m in shifts else ""))
        for m, v in curves.items():
            if m not in shifts:
                cmp[m] = {"variance_at_N0_plus_shift": interp_loglog(ns, v, ns[0] + shift),
                          "aligned_over_this": curves[ALIGNED][0]
                          / interp_loglog(ns, v, ns[0] + shift)}
                cmp[m]["by_method"] = {
                    a: {"shift_spp": sh, "aligned_over_this":
                        curves[a][0] / interp_loglog(ns, v, ns_of[s][a][0] + sh)}
                    for a, sh in shifts.items()}
                if PIXEL in curves:  # the per-pixel sampler's cost counted in samples alone
                    sh = t["pixel_sample_shift_spp"]
                    cmp[m]["by_method"][PIXEL + " at equal samples"] = {
                        "shift_spp": sh, "aligned_over_this":
                        curves[PIXEL][0] / interp_loglog(ns, v, ns_of[s][PIXEL][0] + sh)}
        rows[s] = {"equal_cost_by_n": equal_cost_by_n(ns, curves, ns_of[s], t),
                   "ns": ns.tolist(), "pixels": len(fig9["scenes"][s]["classes"][CLASS]["pixels"]),
                   "shift_spp": shift, "aligned_ns_shifted": (ns + shift).tolist(),
                   "curves": {m: v.tolist() for m, v in curves.items()},
                   "at_smallest_n": cmp, **t}
        ax.set_title(f"{s}: {CLASS} pixels, equal time, aligned +{shift:.1f} spp", fontsize=8)
        ax.set_xlabel("N (samples per pixel of equal time)")
        ax.legend(fontsize=6, loc="lower left")
    plot.save_figure(fig, args.out / NAME, formats=("png",))
    return {"scenes": rows}


def report(data, args):
    print(f"figure: {args.out / NAME}.png\nnumbers: {args.out / NAME}.json")
    for s, r in data["scenes"].items():
        print(f"  {s}: estimation {1e3 * r['t_est_s']:.1f} ms for the image "
              f"({1e6 * r['t_est_per_pixel_s']:.2f} us/pixel), {1e9 * r['t_per_sample_s']:.1f} "
              f"ns/sample -> shift {r['shift_spp']:.1f} spp")
        for n, row in r.get("equal_cost_by_n", {}).items():
            print(f"    N = {n}: " + ", ".join(f"{m} {v:.3f}" for m, v in row.items())
                  + " of pmj02bn's at N + shift")
        for m, c in r["at_smallest_n"].items():
            print(f"    aligned@{r['ns'][0]} / {m}@{r['ns'][0]}+shift = "
                  f"{c['aligned_over_this']:.3f}")
            for a, b in c["by_method"].items():
                print(f"      {a:18s} +{b['shift_spp']:.1f} spp: {b['aligned_over_this']:.3f}")


def main(argv=None):
    return common.run(NAME, __doc__.splitlines()[0], SCALES, compute, report=report,
                      outputs=(f"{NAME}.png",), arguments=arguments, settings=settings,
                      complete=complete, argv=argv)


if __name__ == "__main__":
    main()

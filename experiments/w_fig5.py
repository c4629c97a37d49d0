"""W Fig. 5 (our half): power spectra of our optimized sets for n = 2^12..2^16 (small: 2^10..2^12).

For a fixed set a toroidal shift does not change ``P_S``, so the expected spectrum of a shifted
set is its own spectrum; with several seeds we average them.  Shown as ``n P_S`` on the centred
grid ``|v_x|, |v_y| <= 512`` (the paper's "1024 frequencies"), white noise at 1, with the
directions drawn.  The JSON holds, per set and direction, the mean of ``n P_S`` in octave bins
of ``|v|`` along the direction's wedge (how deep and how far the dark lines go) and the same for
the rest of the grid.  ``w_fig5_diagnostic.png``: W Eq. 5 term by term (``anisosample.diagnostics``)
for a set made with the default (rate) recipe and one made with the paper's recipe, on a
30-degree edge: which line and which radii carry the variance.

    python experiments/w_fig5.py --scale small|paper [--out DIR]
"""

from __future__ import annotations

import math

import common
import jax
import numpy as np

from anisosample import diagnostics, integrands, plot, spectrum, synthesis
from anisosample.progress import progress

SCALES = {
    "small": dict(log2_ns=[10, 11, 12], seeds=1, direction_sets=[[0.0, 90.0, 30.0]],
                  diagnostic_n=1024),
    "paper": dict(log2_ns=[12, 13, 14, 15, 16], seeds=1,
                  direction_sets=[[0.0, 90.0, 30.0], [0.0, 90.0, 30.0, 120.0]],
                  diagnostic_n=4096),
}
RADIUS = 512


def line_profile(grid, n, dirs, half_width=2.0):
    r = grid.shape[0] // 2
    vy, vx = np.mgrid[-r:r + 1, -r:r + 1]
    rad = np.hypot(vx, vy)
    edges = 2.0 ** np.arange(0, int(math.log2(r)) + 2)
    near_any = np.zeros_like(rad, bool)
    out = {}
    for d in dirs:
        t = math.radians(d)
        s = np.abs(-vx * math.sin(t) + vy * math.cos(t))
        near = (s <= half_width) & (rad > 0)
        near_any |= near
        out[f"{d:g}"] = [float(np.mean(n * grid[near & (rad >= a) & (rad < b)]))
                         if np.any(near & (rad >= a) & (rad < b)) else None
                         for a, b in zip(edges[:-1], edges[1:], strict=True)]
    rest = ~near_any & (rad > 0)
    out["elsewhere"] = [float(np.mean(n * grid[rest & (rad >= a) & (rad < b)]))
                        if np.any(rest & (rad >= a) & (rad < b)) else None
                        for a, b in zip(edges[:-1], edges[1:], strict=True)]
    return edges.tolist(), out


def settings_of(cfg, args) -> dict:
    return {"scale": args.scale, **cfg, "radius": RADIUS,
            "defaults": synthesis.recipe_defaults("rate")}


def compute(settings, args):
    """The sets (fixed keys; each reused when made with the same settings, load_or_synthesize),
    their line profiles, the W Eq. 5 diagnostic and both figures."""
    out = args.out
    ns = [2**k for k in settings["log2_ns"]]
    res = {"sets": {}}
    import matplotlib

    matplotlib.use("Agg")
    fig, axes = plot.new_figure(len(settings["direction_sets"]), len(ns))
    jobs = [(i, dirs, j, n) for i, dirs in enumerate(settings["direction_sets"])
            for j, n in enumerate(ns)]
    for i, dirs, j, n in progress(jobs, desc="w_fig5"):
        grids = []
        for s in range(settings["seeds"]):
            name = "_".join(f"{d:g}" for d in dirs) + f"_n{n}_s{s}.npz"
            pts = synthesis.load_or_synthesize(out / "sets" / name, jax.random.key(500 + s),
                                               n, dirs, show_progress=True).points
            grids.append(np.asarray(spectrum.power_spectrum_grid(pts, RADIUS)))
        grid = np.mean(grids, axis=0)
        edges, prof = line_profile(grid, n, dirs)
        label = f"{'/'.join(f'{d:g}' for d in dirs)} n={n}"
        res["sets"][label] = {"n": n, "directions_deg": dirs, "radius_edges": edges,
                              "mean_nP_by_octave": prof}
        plot.spectrum_panel(axes[i][j], grid, n=n, title=label, directions_deg=())
    plot.save_figure(fig, out / "w_fig5")

    # W Eq. 5 decomposition: the rate design against the paper's recipe on a 30-degree edge
    nd = settings["diagnostic_n"]
    f = integrands.edges([30.0])
    fig2, axes2 = plot.new_figure(1, 2, size=4.0)
    res["diagnostic"] = {"n": nd, "integrand": "edges([30])"}
    for ax, recipe in zip(axes2[0], ("rate", "paper"), strict=True):
        pts = synthesis.load_or_synthesize(out / "sets" / f"diag_{recipe}_n{nd}.npz",
                                           jax.random.key(77), nd, [0.0, 90.0, 30.0],
                                           recipe=recipe, show_progress=True).points
        d = diagnostics.variance_decomposition(pts, f)
        res["diagnostic"][recipe] = diagnostics.summary(d)
        diagnostics.plot_decomposition(ax, d, title=f"{recipe} recipe, n={nd}: "
                                                    f"Var {d['predicted']:.3g}")
    plot.save_figure(fig2, out / "w_fig5_diagnostic")
    return res


def report(res, args):
    for label, r in res["sets"].items():
        print(label, {k: [None if v is None else round(v, 4) for v in vals[:8]]
                      for k, vals in r["mean_nP_by_octave"].items()}, flush=True)
    for recipe in ("rate", "paper"):
        d = res["diagnostic"][recipe]
        print(f"diagnostic {recipe}: predicted variance {d['predicted']:.4g} (tail "
              f"{d['tail']:.2g}); by region " + ", ".join(
                  f"{k} {v['variance']:.3g} (white {v['white']:.3g})"
                  for k, v in d["regions"].items()), flush=True)
    out = args.out
    print(f"wrote {out / 'w_fig5.png'}, {out / 'w_fig5_diagnostic.png'} and {out / 'w_fig5.json'}")


def main(argv=None):
    return common.run("w_fig5", __doc__.splitlines()[0], SCALES, compute, seed=None, argv=argv,
                      settings=settings_of, report=report,
                      outputs=("w_fig5.png", "w_fig5_diagnostic.png"))


if __name__ == "__main__":
    main()

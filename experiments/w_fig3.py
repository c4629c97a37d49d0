"""W Fig. 3: three sets made with the paper's recipe (W Eqs. 10-15) — spectrum loss only, sliced
Wasserstein only, both — with their power spectra and a clumping statistic.

The clumping statistic is the nearest-neighbour distance distribution in units of the mean
spacing ``1/sqrt(n)`` (toroidal distance): its minimum and 1st percentile fall when 2D clumps
form (the paper's observation for SW alone), and the 1D stratification along each direction is
``n L_SW1D`` (:func:`anisosample.losses.sliced_wasserstein_loss`, per direction).

Writes ``results/w_fig3/w_fig3.png`` and ``w_fig3.json``; reuses finished sets on rerun.

    python experiments/w_fig3.py --scale small|paper [--out DIR]
"""

from __future__ import annotations

import common
import jax
import numpy as np

from anisosample import losses, metrics, plot, spectrum, synthesis
from anisosample.progress import progress

SCALES = {"small": dict(n=512, steps=300), "paper": dict(n=4096, steps=1500)}
DIRS = [0.0, 90.0, 30.0]
VARIANTS = {
    "spectrum loss only": dict(c=0.0),
    "SW loss only": dict(c=1.0, spectrum_weight=0.0),
    "both": dict(c=100.0),
}


def nn_distances(points) -> np.ndarray:
    return metrics.nearest_neighbour_distance(points) * np.sqrt(np.shape(points)[0])


def settings_of(cfg, args) -> dict:
    return {"scale": args.scale, "n": cfg["n"], "directions_deg": DIRS, "recipe": "paper",
            "steps": cfg["steps"], "variants": VARIANTS,
            "defaults": synthesis.recipe_defaults("paper")}


def compute(settings, args):
    """The three sets (fixed keys; each reused when made with the same settings,
    load_or_synthesize), their statistics and the figure."""
    out = args.out
    n = settings["n"]
    res = {"sets": {}}
    import matplotlib

    matplotlib.use("Agg")
    fig, axes = plot.new_figure(2, len(VARIANTS))
    radius = int(3 * np.sqrt(n))
    for col, (label, kw) in enumerate(progress(list(VARIANTS.items()), desc="w_fig3")):
        slug = label.replace(" ", "_")
        result = synthesis.load_or_synthesize(
            out / f"{slug}.npz", jax.random.key(3), n, DIRS, recipe="paper",
            steps=settings["steps"], show_progress=True, **kw)
        pts = result.points
        nn = nn_distances(pts)
        sw = {f"{d:g}": float(losses.sliced_wasserstein_loss(pts, [d])) for d in DIRS}
        grid = np.asarray(spectrum.power_spectrum_grid(pts, radius))
        res["sets"][label] = {
            "nn_distance_min": float(nn.min()), "nn_distance_p01": float(np.percentile(nn, 1)),
            "nn_distance_mean": float(nn.mean()),
            "nn_histogram": np.histogram(nn, bins=20, range=(0, 1.2))[0].tolist(),
            "n_sw_per_direction": sw,
            "loss_first": float(result.history[0]),
            "loss_final": float(result.history[-1]),
        }
        ax = axes[0][col]
        p = np.asarray(pts)
        ax.scatter(p[:, 0], p[:, 1], s=0.6, c="k")
        ax.set_aspect("equal")
        ax.set_xlim(0, 0.5)
        ax.set_ylim(0, 0.5)
        ax.set_title(f"{label}\nNN min {nn.min():.2f}, p1 {np.percentile(nn, 1):.2f}",
                     fontsize=8)
        plot.spectrum_panel(axes[1][col], grid, n=n, title=f"n P_S, |v| <= {radius}")
    plot.save_figure(fig, out / "w_fig3")
    return res


def report(res, args):
    for label, r in res["sets"].items():
        print(f"{label}: nn min {r['nn_distance_min']:.3f} p1 {r['nn_distance_p01']:.3f} mean "
              f"{r['nn_distance_mean']:.3f}; n*L_SW1D {r['n_sw_per_direction']}", flush=True)
    print(f"wrote {args.out / 'w_fig3.png'} and {args.out / 'w_fig3.json'}")


def main(argv=None):
    return common.run("w_fig3", __doc__.splitlines()[0], SCALES, compute, seed=None, argv=argv,
                      settings=settings_of, report=report, outputs=("w_fig3.png",))


if __name__ == "__main__":
    main()

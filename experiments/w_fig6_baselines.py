"""W Fig. 6, existing-pattern half: variance vs n of the baseline samplers on integrands with one,
two, three and four edges in non-axis directions, with and without a smooth texture.

Samplers: random, jittered, cmj, sobol-owen (each a fresh randomization plus a toroidal shift per
realization: the homogenized pattern of W Eq. 5), pmj02bn and pmj02bn sheared to the integrand's
first edge direction (Singh & Jarosz 2017; a few fixed sets per n, each moved by toroidal shifts,
as W does with its precomputed sets). Integrands come from ``anisosample.integrands.edges`` (the
square's border adds 0 and 90 degrees on the torus); the texture is
``integrands.smooth_texture()``. Variances are mean squared errors about the exact integral.

Writes ``results/w_fig6_baselines/w_fig6_baselines.png`` (one log-log panel per integrand, the
fitted slope and its 95 % interval in the legend) and ``w_fig6_baselines.json`` (every plotted
number, the fits, settings, provenance). Finished curves are reused on rerun (``--fresh`` redoes).

    python experiments/w_fig6_baselines.py --scale small|paper [--out DIR]
"""

from __future__ import annotations

import _w_variance as WV
import common
import numpy as np
from _w_variance import Memo, measure

import anisosample as asp
from anisosample import integrands, plot
from anisosample.progress import progress

NAME = "w_fig6_baselines"
SCALES = WV.BASELINE_SCALES
EDGES = {1: [30.0], 2: [30.0, 110.0], 3: [30.0, 75.0, 140.0], 4: [30.0, 75.0, 115.0, 150.0]}
JITTABLE = WV.JITTABLE


def integrand_cases():
    cases = {}
    for k, dirs in EDGES.items():
        shape = integrands.edges(dirs)
        cases[f"{k} edge{'s' if k > 1 else ''}"] = (shape, dirs)
        cases[f"{k} edge{'s' if k > 1 else ''} + texture"] = (
            integrands.Textured(integrands.smooth_texture(), shape), dirs)
    return cases


def sampler_table(dirs, memo_pmj, memo_sheared):
    table = {name: (name, "fresh+shift") for name in JITTABLE}
    table["pmj02bn"] = (memo_pmj, "shift")
    theta = dirs[0]
    if theta not in memo_sheared:
        memo_sheared[theta] = Memo(asp.samplers.get("sheared", base="pmj02bn",
                                                    direction_deg=theta))
    table[f"sheared pmj02bn {theta:g}"] = (memo_sheared[theta], "shift")
    return table


def integrand_figure(cases, out, radius=48, m=256):
    """Each integrand on a grid and its exact power spectrum log10 P_f (closed form)."""
    import jax.numpy as jnp

    fig, axes = plot.new_figure(2, len(cases), size=2.2)
    xy = asp.metrics.midpoint_grid(m, xp=jnp)  # values[i, j] = f(x_j, y_i)
    r = np.arange(-radius, radius + 1)
    v = np.stack(np.meshgrid(r, r, indexing="xy"), axis=-1)  # rows = v_y
    for j, (label, (f, dirs)) in enumerate(cases.items()):
        axes[0, j].imshow(np.asarray(f(xy)), origin="lower", cmap="gray", extent=(0, 1, 0, 1))
        axes[0, j].set_title(label, fontsize=8)
        pf = f.power_spectrum(v)
        pf[radius, radius] = np.nan  # the mean, I^2
        axes[1, j].imshow(np.log10(pf + 1e-12), origin="lower", cmap="magma", vmin=-9, vmax=-2,
                          extent=(-radius - 0.5, radius + 0.5, -radius - 0.5, radius + 0.5))
        axes[1, j].set_title("log10 P_f, dirs " + ",".join(f"{d:g}" for d in dirs), fontsize=7)
        for ax in axes[:, j]:
            ax.set_xticks([])
            ax.set_yticks([])
    return plot.save_figure(fig, out / f"{NAME}_integrands", formats=("png",))


def compute(settings, args):
    """Every (integrand, sampler) curve, each kept in ``curves/`` (resumable)."""
    cfg, out = settings, args.out
    ns, key = WV.curves_setup(settings, args)
    memo_pmj = Memo(asp.samplers.get("pmj02bn"))
    memo_sheared: dict[float, Memo] = {}
    cases = integrand_cases()
    tasks = [(label, s) for label, (f, dirs) in cases.items()
             for s in sampler_table(dirs, memo_pmj, memo_sheared)]
    results: dict[str, dict] = {}
    for label, sname in progress(tasks, desc=NAME):
        f, dirs = cases[label]
        sampler, mode = sampler_table(dirs, memo_pmj, memo_sheared)[sname]
        slug = f"{label}__{sname}".replace(" ", "_").replace("+", "plus")
        path = out / "curves" / f"{slug}.json"
        curve = common.reuse_or_compute(
            path, {"scale": args.scale, "seed": args.seed, "ns": ns, **SCALES[args.scale]},
            args.fresh,
            lambda f=f, sampler=sampler, mode=mode: measure(f, sampler, mode, ns, key, cfg))
        entry = results.setdefault(label, {
            "integrand": type(f).__name__, "edge_directions_deg": dirs,
            "integral": f.integral, "samplers": {}})
        entry["samplers"][sname] = curve
    return {
        "ns": ns, "fit_min_n": cfg["fit_min_n"], "realizations": cfg["realizations"],
        "texture": {"freqs": integrands.smooth_texture().freqs,
                    "amplitudes": integrands.smooth_texture().amplitudes,
                    "phases": integrands.smooth_texture().phases},
        "cases": results,
    }


def figure(data, args):
    ns, results = data["ns"], data["cases"]
    fig, axes = plot.new_figure(2, 4, size=3.4)
    for j, k in enumerate(EDGES):
        for i, suffix in enumerate(["", " + texture"]):
            label = f"{k} edge{'s' if k > 1 else ''}{suffix}"
            ax = axes[i, j]
            WV.curves_panel(ax, ns, results[label]["samplers"])
            dirs = ", ".join(f"{d:g}" for d in EDGES[k])
            ax.set_title(f"{label} ({dirs} deg)", fontsize=9)
            ax.legend(fontsize=5.5, loc="lower left")
    plot.save_figure(fig, args.out / NAME, formats=("png",))
    integrand_figure(integrand_cases(), args.out)


def report(data, args):
    print(f"figure: {args.out / NAME}.png\nnumbers: {args.out / NAME}.json")
    for label, entry in data["cases"].items():
        print(f"  {label:20s} " + WV.slopes(entry["samplers"]))


def main(argv=None):
    return common.run(NAME, __doc__.splitlines()[0], SCALES, compute, figure=figure,
                      report=report, argv=argv)


if __name__ == "__main__":
    main()

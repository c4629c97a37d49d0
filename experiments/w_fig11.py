"""W Fig. 11: variance vs n on a discontinuity and on two smoothed versions of it.

The edge passes through the centre with spectral direction 30 degrees; the smoothed integrands
are that half-plane convolved with a Gaussian of sigma = 2.83 and 8.5 pixels of a 2048^2 grid
(``integrands.SmoothedEdge``, sigma = 2.83/2048 and 8.5/2048 of the unit square, exact
integrals). The blur cuts the 30-degree ray of the spectrum off at ``|v| ~ 1/(2 pi sigma)``, so
the asymptotic rate stops depending on that direction (W Sec. 6.3); the square's border stays a
discontinuity on the torus. Samplers and randomizations as in ``w_fig6_baselines.py``, plus our
aligned 3-direction sets ``{0, 90, 30}`` (two synthesized sets per ``n``, toroidal shifts, as in
``w_fig6.py``; cached in ``<out>/sets``).

Writes ``results/w_fig11/w_fig11.png`` (integrands on top, log-log curves with fitted slopes and
95 % intervals below) and ``w_fig11.json`` (every plotted number, settings, provenance). Finished
curves are reused on rerun (``--fresh`` redoes).

    python experiments/w_fig11.py --scale small|paper [--out DIR]
"""

from __future__ import annotations

import common
import jax
import jax.numpy as jnp
import numpy as np
from _w_variance import (
    BASELINE_SCALES,
    JITTABLE,
    Memo,
    curves_panel,
    curves_setup,
    measure,
    our_sets,
    slopes,
    summarize,
    variance_of_sets,
)

import anisosample as asp
from anisosample import integrands, plot
from anisosample.progress import progress

NAME = "w_fig11"
THETA = 30.0
SIGMAS_PX = [2.83, 8.5]
GRID = 2048
OURS = f"aligned (ours, 0/90/{THETA:g})"
SEEDS = 2  # our fixed sets per n


def integrand_cases():
    cases = {"discontinuity": integrands.HalfPlane.through((0.5, 0.5), THETA)}
    for s in SIGMAS_PX:
        cases[f"smoothed sigma={s:g}px"] = integrands.SmoothedEdge.through(
            (0.5, 0.5), THETA, s / GRID)
    return cases


def samplers_table():
    samplers = {name: (name, "fresh+shift") for name in JITTABLE}
    samplers["pmj02bn"] = (Memo(asp.samplers.get("pmj02bn")), "shift")
    samplers[f"sheared pmj02bn {THETA:g}"] = (
        Memo(asp.samplers.get("sheared", base="pmj02bn", direction_deg=THETA)), "shift")
    return samplers


def compute(settings, args):
    """Every (integrand, sampler) curve, each kept in ``curves/`` (resumable)."""
    cfg, out = settings, args.out
    ns, key = curves_setup(settings, args)
    samplers = samplers_table()
    cases = integrand_cases()
    results: dict[str, dict] = {}
    sets = {}

    def ours(f):
        if not sets:  # synthesized (or loaded) once, for every integrand
            with progress(total=len(ns) * SEEDS, desc=f"{NAME} sets") as bar:
                sets.update(our_sets(out, [0.0, 90.0, THETA], ns, SEEDS, bar))
        rows = variance_of_sets(f, sets, ns, SEEDS, cfg["realizations"],
                                jax.random.fold_in(key, 11))
        return summarize(rows, ns, cfg, "shift", SEEDS)

    tasks = [(label, s) for label in cases for s in [*samplers, OURS]]
    for label, sname in progress(tasks, desc=NAME):
        f = cases[label]
        slug = f"{label}__{sname}".replace(" ", "_").replace("=", "").replace("/", "-")
        path = out / "curves" / f"{slug}.json"
        part = {"scale": args.scale, "seed": args.seed, "ns": ns,
                **BASELINE_SCALES[args.scale]}
        if sname == OURS:
            measured = lambda f=f: ours(f)  # noqa: E731
        else:
            sampler, mode = samplers[sname]
            measured = lambda f=f, sampler=sampler, mode=mode: measure(  # noqa: E731
                f, sampler, mode, ns, key, cfg)
        curve = common.reuse_or_compute(path, part, args.fresh, measured)
        entry = results.setdefault(label, {
            "integrand": type(f).__name__, "normal_deg": THETA, "integral": f.integral,
            "sigma": getattr(f, "sigma", 0.0), "samplers": {}})
        entry["samplers"][sname] = curve
    return {"ns": ns, "fit_min_n": cfg["fit_min_n"], "realizations": cfg["realizations"],
            "sigmas_px": SIGMAS_PX, "grid": GRID, "cases": results}


def figure(data, args):
    ns, results, cases = data["ns"], data["cases"], integrand_cases()
    fig, axes = plot.new_figure(2, len(cases), size=3.6)
    m = 256
    xy = asp.metrics.midpoint_grid(m, xp=jnp)  # values[i, j] = f(x_j, y_i)
    for j, (label, f) in enumerate(cases.items()):
        axes[0, j].imshow(np.asarray(f(xy)), origin="lower", cmap="gray", extent=(0, 1, 0, 1))
        axes[0, j].set_title(label, fontsize=9)
        axes[0, j].set_xticks([])
        axes[0, j].set_yticks([])
        curves_panel(axes[1, j], ns, results[label]["samplers"])
        axes[1, j].legend(fontsize=5.5, loc="lower left")
    plot.save_figure(fig, args.out / NAME, formats=("png",))


def report(data, args):
    print(f"figure: {args.out / NAME}.png\nnumbers: {args.out / NAME}.json")
    for label, entry in data["cases"].items():
        print(f"  {label:22s} " + slopes(entry["samplers"]))


def main(argv=None):
    return common.run(NAME, __doc__.splitlines()[0], BASELINE_SCALES, compute, figure=figure,
                      report=report, argv=argv)


if __name__ == "__main__":
    main()

"""The headline experiment at small scale (`make demo`).

An integrand with one discontinuity at a non-axis angle (a half-plane whose edge is
perpendicular to the spectral direction 30 degrees; the unit square's border adds 0 and 90 on the
torus). We synthesize point sets whose spectra are dark along all three directions (W Sec. 4),
randomize each by toroidal shifts, and compare the variance convergence with pmj02bn and
Owen-scrambled Sobol' (W Fig. 6). Prints the fitted slopes and where the figure is.
"""

from __future__ import annotations

import common
import jax
import numpy as np

import anisosample as asp
from anisosample import plot

NAME = "demo"
EXTRA_DIRECTION = 30.0


SCALES = {"small": dict(log2_ns=list(range(6, 11)), realizations=256),
          "paper": dict(log2_ns=list(range(8, 15)), realizations=2048)}


def compute(settings, args):
    """Our sets (cached in ``sets/``), the convergence of every sampler, the figure."""
    out = args.out
    ns = [2**m for m in settings["log2_ns"]]
    realizations = settings["realizations"]
    key = jax.random.key(args.seed)
    f = asp.integrands.edges([EXTRA_DIRECTION])
    directions = (0.0, 90.0, EXTRA_DIRECTION)

    sets = {}
    for n in ns:
        print(f"synthesizing n = {n} for spectral directions {directions} ...", flush=True)
        pts = asp.synthesis.load_or_synthesize(
            out / "sets" / f"aligned_n{n}.npz", jax.random.fold_in(key, n), n, directions
        ).points
        sets[n] = np.asarray(pts)

    def aligned(_key, n):
        return sets[n]

    samplers = {
        "aligned (ours, 0/90/30)": aligned,
        "pmj02bn": "pmj02bn",
        "sobol-owen": "sobol-owen",
    }
    result = asp.variance.convergence(
        f,
        samplers,
        ns,
        jax.random.fold_in(key, 1),
        realizations,
        exact=f.integral,
        randomization={
            "aligned (ours, 0/90/30)": "shift",
            "pmj02bn": "fresh+shift",
            "sobol-owen": "fresh+shift",
        },
        progress=True,
    )

    fig, axes = plot.new_figure(1, 2, size=4.0)
    ax = axes[0, 0]
    record = {}
    for label in samplers:
        est = result.estimates[label]
        fit = result.fits[label]
        v = np.array([e.variance for e in est])
        lo = np.array([e.ci_low for e in est])
        hi = np.array([e.ci_high for e in est])
        plot.convergence_panel(
            ax,
            ns,
            v,
            label=label,
            slope=fit.slope,
            slope_ci=(fit.ci_low, fit.ci_high),
            lower=lo,
            upper=hi,
        )
        record[label] = {
            "variance": v.tolist(),
            "ci_low": lo.tolist(),
            "ci_high": hi.tolist(),
            "slope": fit.slope,
            "slope_ci": [fit.ci_low, fit.ci_high],
        }
    ax.set_title(f"edge at spectral direction {EXTRA_DIRECTION:g} deg", fontsize=9)
    ax.legend(fontsize=7)
    n_show = ns[-1]
    grid = asp.spectrum.power_spectrum_grid(sets[n_show], 2 * int(np.sqrt(n_show)))
    plot.spectrum_panel(
        axes[0, 1], grid, n=n_show, title=f"our set, n = {n_show}", directions_deg=directions
    )
    plot.save_figure(fig, out / NAME)
    return {"ns": ns, "realizations": realizations, "integrand": "edges([30])",
            "samplers": record}


def report(data, args):
    print("\nvariance slopes (log Var vs log N, 95% interval):")
    for label, r in data["samplers"].items():
        print(
            f"  {label:26s} {r['slope']:+.2f}  [{r['slope_ci'][0]:+.2f}, {r['slope_ci'][1]:+.2f}]"
        )
    print(f"\nfigure:  {args.out / NAME}.png\nnumbers: {args.out / NAME}.json")


def main(argv=None):
    return common.run(NAME, __doc__, SCALES, compute, report=report, argv=argv,
                      outputs=(f"{NAME}.png",))


if __name__ == "__main__":
    main()

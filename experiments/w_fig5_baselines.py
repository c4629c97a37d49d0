"""W Fig. 5, existing-pattern half: expected power spectra of the baseline samplers at n = 4096.

random, jittered, cmj, sobol-owen, pmj02bn, and pmj02bn sheared (Singh & Jarosz 2017) to put a
low-energy axis along 30 degrees. Writes one PNG with all spectra, radial and angular profiles,
an EXR per spectrum and a JSON of every plotted number.
"""

from __future__ import annotations

import common
import jax
import numpy as np

import anisosample as asp
from anisosample import plot

NAME = "w_fig5_baselines"
SHEAR_DEG = 30.0


SCALES = {"small": dict(n=4096, realizations=16), "paper": dict(n=4096, realizations=256)}
CASES = [
    ("random", {}),
    ("jittered", {}),
    ("cmj", {}),
    ("sobol-owen", {}),
    ("pmj02bn", {}),
    ("sheared", {"base": "pmj02bn", "direction_deg": SHEAR_DEG}),
]


def compute(settings, args):
    """The expected spectra (cached in ``spectra.npz``), their figure and EXRs, the numbers."""
    n, realizations = settings["n"], settings["realizations"]
    radius = 2 * int(np.sqrt(n))
    out = args.out
    cache = out / "spectra.npz"
    grids = {}
    if cache.exists() and not args.fresh:
        arrays, meta = asp.io.load_npz(cache)
        if meta.get("realizations") == realizations and meta.get("seed") == args.seed:
            grids = arrays
    key = jax.random.key(args.seed)
    for i, (name, opts) in enumerate(CASES):
        label = name if not opts else f"sheared pmj02bn {SHEAR_DEG:g}deg"
        if label in grids:
            continue
        sampler = asp.samplers.get(name, **opts)
        grids[label] = np.asarray(
            asp.diagnostics.sampler_power_spectrum_grid(
                sampler,
                n,
                jax.random.fold_in(key, i),
                radius,
                realizations=realizations,
                progress=True,
            )
        )
    asp.io.save_npz(
        cache, grids, {"realizations": realizations, "seed": args.seed, "n": n}, overwrite=True
    )

    fig, axes = plot.new_figure(3, len(grids), size=2.6)
    record = {}
    for j, (label, g) in enumerate(grids.items()):
        dirs = [0.0, 90.0] if "sheared" not in label else [SHEAR_DEG, 90.0]
        plot.spectrum_panel(axes[0, j], g, n=n, title=label, directions_deg=[])
        plot.save_spectrum_image(out / f"{label.replace(' ', '_')}.exr", g, n=n, overwrite=True)
        radii, rad = asp.metrics.radial_profile(g)
        centres, ang = asp.metrics.angular_profile(g, r_min=8, r_max=radius, bins=90)
        axes[1, j].plot(radii, n * rad, lw=1)
        axes[1, j].axhline(1.0, color="k", lw=0.5, ls=":")
        axes[1, j].set_xlabel("|v|")
        axes[1, j].set_ylim(0, 2)
        axes[2, j].plot(centres, n * ang, lw=1)
        axes[2, j].axhline(1.0, color="k", lw=0.5, ls=":")
        axes[2, j].set_xlabel("direction (deg)")
        axes[2, j].set_ylim(0, 2)
        low = (
            np.hypot(*np.meshgrid(np.arange(-radius, radius + 1), np.arange(-radius, radius + 1)))
            <= np.sqrt(n) / 2
        )
        low[radius, radius] = False
        record[label] = {
            "low_energy_directions_deg": dirs if label not in ("random", "jittered") else [],
            "radial_profile_nP": (n * rad).tolist(),
            "angular_profile_nP": (n * ang).tolist(),
            "mean_nP_within_sqrt_n_over_2": float(n * g[low].mean()),
            "mean_nP_overall": float(n * np.delete(g.reshape(-1), g.size // 2).mean()),
        }
    axes[1, 0].set_ylabel("radial N<P>")
    axes[2, 0].set_ylabel("angular N<P> (|v| 8..128)")
    plot.save_figure(fig, out / NAME, formats=("png", "pdf"))
    return {
        "n": n,
        "radius": radius,
        "realizations": realizations,
        "radial_radii": list(range(1, radius + 1)),
        "angular_centres_deg": centres.tolist(),
        "samplers": record,
    }


def report(data, args):
    print(f"figure: {args.out / NAME}.png\nnumbers: {args.out / NAME}.json")
    for label, r in data["samplers"].items():
        print(
            f"  {label:24s} mean N<P> for |v| <= sqrt(n)/2: {r['mean_nP_within_sqrt_n_over_2']:.3f}"
        )


def main(argv=None):
    return common.run(NAME, __doc__, SCALES, compute, report=report, argv=argv,
                      outputs=(f"{NAME}.png",))


if __name__ == "__main__":
    main()

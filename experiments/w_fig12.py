"""W Fig. 12 (Sec. 6.3): hemisphere sampling with the angular vs the octahedral mapping.

A spherical integrand with a straight spherical edge: the indicator of the half-space
``n . w > 0`` on the upper hemisphere (a great-circle edge, as cast by a planar occluder through
the shading point), integral ``2 (pi - beta)`` sr where ``beta`` is the angle between ``n`` and
``+z``. In primary sample space it is ``g(u) = f(w(u)) / pdf(w(u))`` with ``w`` the warp's
``sample``:

* ``angular``: ``anisosample.warps.AngularHemisphere`` (``z = u0``, ``phi = 2 pi u1``): great
  circles become curves, the edge's energy spreads over a range of spectral directions;
* ``octahedral``: ``anisosample.warps.HemiOctahedral`` (Engelhardt & Dachsbacher 2008): great
  circles become straight segments in each octant face, the energy sits in a few discrete
  directions.

Measured: (1) the spread of the edge directions of ``g`` on a grid (W Sec. 5.1's orientation
histogram, axes zeroed): the share of its mass within +-3 degrees of its maximum and the number
of 1-degree bins holding 90 % of it, next to a picture of ``P_g`` (FFT of the grid); (2) the
directions
``anisosample.directions.estimate`` finds on a 96^2 grid; (3) the variance convergence of
pmj02bn and of the aligned 3-direction set for the estimated strongest direction (sets missing
from the installed tables are synthesized into ``results/w_render_tables``), under both maps,
as the mean squared error about the exact integral over toroidal shifts, with slopes.

Writes ``results/w_fig12/w_fig12.png`` and ``w_fig12.json``; reuses finished curves on rerun.

    python experiments/w_fig12.py --scale small|paper [--out DIR] [--beta DEG] [--alpha DEG]
"""

from __future__ import annotations

import math

import _w_render as W
import common
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from _w_variance import curves_panel, curves_setup

from anisosample import directions, metrics, plot, warps
from anisosample import variance as V
from anisosample.progress import progress

NAME = "w_fig12"
SCALES = {
    "small": dict(log2_ns=[8, 9, 10], realizations=1024, patterns=8, grid=256),
    "paper": dict(log2_ns=[8, 9, 10, 11, 12], realizations=2048, patterns=16, grid=512),
}
MAPS = {"angular": warps.AngularHemisphere, "octahedral": warps.HemiOctahedral}


class HemisphereEdge(eqx.Module):
    """``g(u) = 1[n . w(u) > 0] / pdf(w(u))`` on ``[0,1)^2`` for a hemisphere warp."""

    warp: eqx.Module
    normal: jax.Array
    integral: float = eqx.field(static=True)

    def __call__(self, x):
        x = jnp.asarray(x, jnp.float32)

        def one(u):
            w = self.warp.sample(u)
            return jnp.where(jnp.dot(self.normal, w) > 0, 1.0 / self.warp.pdf(w), 0.0)

        return jax.vmap(one)(x.reshape(-1, 2)).reshape(x.shape[:-1])


def spread(values: np.ndarray, window_deg: float = 3.0) -> dict:
    """How concentrated the edge directions of ``g`` are: W Sec. 5.1's gradient-orientation
    histogram (``anisosample.directions.orientation_histogram``, the +-2 degree windows at the
    axes zeroed by ``zero_axes``), the share of its mass within ``window_deg`` of its maximum,
    and the number of bins holding 90 % of the mass."""
    hist = np.asarray(directions.zero_axes(directions.orientation_histogram(values)), float)
    total = float(hist.sum())
    centres = np.arange(hist.size, dtype=float)
    top = float(centres[int(np.argmax(hist))])
    dist = metrics.axial_distance_deg(centres, top, xp=np)
    share = float(hist[dist <= window_deg].sum() / total) if total > 0 else 0.0
    cum = np.cumsum(np.sort(hist)[::-1]) / max(total, 1e-30)
    return {"histogram": hist.tolist(), "top_deg": top, "share_within_deg": window_deg,
            "share": share, "bins_for_90_percent": int(np.searchsorted(cum, 0.9) + 1)}


def spectrum_image(values: np.ndarray) -> np.ndarray:
    """``log10 P_g`` of the grid (FFT, centred, zero frequency removed) for the picture."""
    P = np.abs(np.fft.fftshift(np.fft.fft2(values - values.mean()))) ** 2
    return np.log10(P + 1e-12 * P.max())


def arguments(p):
    p.add_argument("--beta", type=float, default=55.0, help="angle of n from +z (degrees)")
    p.add_argument("--alpha", type=float, default=20.0, help="azimuth of n (degrees)")


def settings_of(cfg, args) -> dict:
    return {**cfg, "scale": args.scale, "seed": args.seed, "alpha_deg": args.alpha,
            "beta_deg": args.beta}


def curves_of(f, d0, ns, cfg, exact, k, mname):
    """pmj02bn's and the aligned set's convergence under one map."""
    aligned = (lambda kk, n, d=d0: W.aligned_set(d, n, kk)) if d0 is not None else "pmj02bn"
    table = {"pmj02bn": ("pmj02bn", cfg["patterns"]), f"aligned 3-dir {d0}": (aligned, 1)}
    curves = {}
    for label, (smp, pats) in table.items():
        rows = [V.estimate_variance(f, smp, n, k, cfg["realizations"], exact,
                                    randomization="shift", patterns=pats)
                for n in progress(ns, desc=f"{mname} {label}", leave=False)]
        var = [r.variance for r in rows]
        se = [r.std_error for r in rows]
        curves[label] = {"variance": var, "std_error": se,
                         "ci_low": [r.ci_low for r in rows],
                         "ci_high": [r.ci_high for r in rows],
                         "fit": V.fit_slope(ns, var, se).as_dict()}
    return curves


def compute(settings, args):
    """Per map: the grid's edge spread, the estimated directions, the curves (each map's kept in
    ``curves/<map>.json``), and the figure (drawn from the grids, ``<map>_grid.npy``)."""
    cfg, out = settings, args.out
    ns, key = curves_setup(settings, args)
    a, b = math.radians(args.alpha), math.radians(args.beta)
    normal = jnp.asarray([math.cos(a) * math.sin(b), math.sin(a) * math.sin(b), math.cos(b)],
                         jnp.float32)
    exact = 2.0 * (math.pi - b)
    results = {}
    for mi, (mname, cls) in enumerate(progress(list(MAPS.items()), desc=NAME)):
        f = HemisphereEdge(cls(), normal, exact)
        values = metrics.grid_values(f, cfg["grid"])
        sp = spread(values)
        est = directions.estimate(metrics.grid_values(f, 96), k=2)
        rounded = [W.aligned_usable(d) for d in est]
        d0 = next((d for d in rounded if d is not None), None)
        curves = common.reuse_or_compute(
            out / "curves" / f"{mname}.json", settings, args.fresh,
            lambda f=f, d0=d0, mi=mi, mname=mname: curves_of(
                f, d0, ns, cfg, exact, jax.random.fold_in(key, mi), mname), field="curves")
        results[mname] = {"estimated_deg": list(est), "table_direction_deg": d0,
                          "edge_spread": sp, "curves": curves,
                          "grid_min": float(values.min()), "grid_max": float(values.max())}
        np.save(out / f"{mname}_grid.npy", values)

    fig, axes = plot.new_figure(2, 4, size=3.0)
    for row, (mname, r) in enumerate(results.items()):
        vals = np.load(out / f"{mname}_grid.npy")
        axes[row, 0].imshow(vals, origin="lower", extent=(0, 1, 0, 1), cmap="gray")
        axes[row, 0].set_title(f"{mname}: g(u)", fontsize=8)
        axes[row, 1].imshow(spectrum_image(vals), origin="lower", cmap="magma")
        axes[row, 1].set_title(f"{mname}: log10 P_g", fontsize=8)
        axes[row, 1].set_xticks([])
        axes[row, 1].set_yticks([])
        sp = r["edge_spread"]
        axes[row, 2].plot(np.arange(len(sp["histogram"])), sp["histogram"], lw=0.8)
        axes[row, 2].set_title(f"orientation histogram: {100 * sp['share']:.0f}% within "
                               f"+-{sp['share_within_deg']:g} deg of {sp['top_deg']:.0f}",
                               fontsize=7)
        for d in r["estimated_deg"]:
            axes[row, 2].axvline(d, color="r", lw=0.8)
        axes[row, 2].set_xlabel("deg (estimates in red)", fontsize=7)
        ax = axes[row, 3]
        curves_panel(ax, ns, r["curves"])
        ax.legend(fontsize=6, loc="lower left")
        ax.set_title(f"{mname} mapping", fontsize=8)
    plot.save_figure(fig, out / NAME, formats=("png",))
    return {"ns": ns, "exact": exact, "normal": np.asarray(normal).tolist(), "maps": results}


def report(data, args):
    print(f"figure: {args.out / NAME}.png\nnumbers: {args.out / NAME}.json")
    ns = data["ns"]
    for mname, r in data["maps"].items():
        sp = r["edge_spread"]
        print(f"  {mname}: estimated {[round(d, 1) for d in r['estimated_deg']]}; edge-direction "
              f"mass within +-{sp['share_within_deg']:g} deg of {sp['top_deg']:.0f}: "
              f"{sp['share']:.3f}, bins for 90 %: {sp['bins_for_90_percent']}")
        for label, c in r["curves"].items():
            fit = c["fit"]
            print(f"    {label:22s} slope {fit['slope']:+.3f} [{fit['ci_low']:+.3f}, "
                  f"{fit['ci_high']:+.3f}]  Var@{ns[-1]} {c['variance'][-1]:.3e}")


def main(argv=None):
    return common.run(NAME, __doc__.splitlines()[0], SCALES, compute, arguments=arguments,
                      settings=settings_of, report=report, argv=argv, outputs=(f"{NAME}.png",))


if __name__ == "__main__":
    main()

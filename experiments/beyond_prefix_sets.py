"""Aligned sets with a fixed isotropic prefix (W Sec. 7; issue 22 item 1): what the prefix costs.

W's Sec. 7 proposes sets whose first 16-64 points are fixed and isotropic, so that the samples a
renderer spends on estimating the directions are reused in the final estimate. We synthesize
3-direction sets (0, 90 and an extra direction drawn at random, not chosen in advance) with no
prefix, with the symmetric ``dihedral-<m>`` prefixes (m = 16, 32, 64; the kind tables can hold)
and, for comparison, the first 32 points of pmj02bn; for n = 256..4096 we measure

* the variance of the half-plane integrand whose edge is perpendicular to the extra direction
  (``integrands.edges([a])``), over toroidal shifts (16384 at ``--scale small``: the shift
  noise is then a few per cent), its slope over n, and the ratio at the largest n to the sets
  without a prefix (the mean of three keys' sets: one set's variance differs from another's of
  the same size by up to about 10 %, which a ratio to one set would count as cost);
* the mean ``n P_S`` within one unit of every requested line, ``0 < |v| <= 32``, for n >= 1024
  (white noise = 1);
* the prefixes alone as estimators (the estimation samples a renderer would reuse): variance of
  edges at several angles with m points, the dihedral prefix against the pmj02bn head.

Targets (issue 22): first m points equal to the prefix bit for bit, edge slope <= -1.70, variance
at 4096 within 1.2x of the set without a prefix, band energy <= 0.1 of white.
"""

from __future__ import annotations

import common
import jax
import numpy as np

import anisosample as asp
from anisosample import diagnostics, plot, prefix

NAME = "beyond_prefix_sets"
PREFIXES = ("none", "dihedral-16", "dihedral-32", "dihedral-64", "pmj02bn-32")
# n per set, toroidal shifts per variance, extra directions drawn
SCALES = {
    "small": dict(ns=[256, 512, 1024, 2048, 4096], realizations=16384, n_dirs=3),
    "paper": dict(ns=[256, 512, 1024, 2048, 4096], realizations=65536, n_dirs=8),
}


def shifted(points):
    def sampler(key, _n):
        return asp.samplers.toroidal_shift(key, points)

    return sampler


def compute(cfg, args):
    out, ns, realizations = args.out, cfg["ns"], cfg["realizations"]
    rng = np.random.default_rng(args.seed)
    extra = [int(a) for a in rng.choice([a for a in range(5, 176) if abs(a - 90) >= 5],
                                        cfg["n_dirs"], replace=False)]
    key = jax.random.key(args.seed)
    rows = {}
    for a in extra:
        dirs = (0.0, 90.0, float(a))
        f = asp.integrands.edges([float(a)])
        for spec in PREFIXES:
            label = f"{a}/{spec}"
            var, bands = [], {}
            for n in ns:
                kw = {} if spec == "none" else {"prefix": spec}
                r = asp.synthesis.load_or_synthesize(
                    out / "sets" / f"a{a}_{spec}_n{n}.npz", jax.random.fold_in(key, 1000 * a + n),
                    n, dirs, show_progress=False, **kw)
                pts = np.asarray(r.points)
                if spec != "none":
                    m = prefix.prefix_size(spec)
                    assert pts[:m].tobytes() == prefix.prefix_points(spec).tobytes(), label
                var.append(asp.variance.estimator_variance(
                    f, shifted(pts), n, jax.random.fold_in(key, n), realizations, f.integral))
                if n >= 1024:
                    bands[n] = [diagnostics.band_energy(pts, d) for d in dirs]
            fit = asp.variance.fit_slope(ns, var)
            rows[label] = {"extra_deg": a, "prefix": spec, "variance": var, "slope": fit.slope,
                           "slope_ci": [fit.ci_low, fit.ci_high],
                           "band_energy_max": {str(n): max(b) for n, b in bands.items()}}
            print(row_line(rows[label], ns), flush=True)  # as it goes: the report's first lines
        more = [asp.synthesis.load_or_synthesize(
            out / "sets" / f"a{a}_none_n{ns[-1]}_k{k}.npz", jax.random.key(k), ns[-1], dirs,
            show_progress=False).points for k in (1, 2)]
        nones = [rows[f"{a}/none"]["variance"][-1]] + [asp.variance.estimator_variance(
            f, shifted(np.asarray(p)), ns[-1], jax.random.fold_in(key, ns[-1]), realizations,
            f.integral) for p in more]
        base = float(np.mean(nones))
        rows[f"{a}/none"]["none_variance_at_n_max"] = nones
        for spec in PREFIXES:
            rows[f"{a}/{spec}"]["ratio_to_none"] = rows[f"{a}/{spec}"]["variance"][-1] / base

    # the prefixes as estimators on their own: m points, edges at several angles
    angles = [float(t) for t in np.linspace(3.0, 177.0, 12)]
    estimators = {}
    for m in (16, 32, 64):
        for spec in (f"dihedral-{m}", f"pmj02bn-{m}"):
            pts = prefix.prefix_points(spec)
            v = [asp.variance.estimator_variance(asp.integrands.edges([t]), shifted(pts), m,
                                                 jax.random.fold_in(key, 7), realizations,
                                                 asp.integrands.edges([t]).integral)
                 for t in angles]
            estimators[spec] = {"mean_variance": float(np.mean(v)), "variance": v}
        fresh = [asp.variance.estimator_variance(asp.integrands.edges([t]), "pmj02bn", m,
                                                 jax.random.fold_in(key, 7), realizations,
                                                 asp.integrands.edges([t]).integral)
                 for t in angles]
        estimators[f"pmj02bn fresh {m}"] = {"mean_variance": float(np.mean(fresh)),
                                            "variance": fresh}

    summary = {}
    for spec in PREFIXES:
        sel = [r for r in rows.values() if r["prefix"] == spec]
        summary[spec] = {
            "slope_median": float(np.median([r["slope"] for r in sel])),
            "slope_worst": float(max(r["slope"] for r in sel)),
            "ratio_to_none_median": float(np.median([r["ratio_to_none"] for r in sel])),
            "ratio_to_none_worst": float(max(r["ratio_to_none"] for r in sel)),
            "band_energy_worst": float(max(max(r["band_energy_max"].values()) for r in sel)),
        }
    args.printed_rows = True
    return {"ns": ns, "realizations": realizations, "extra_deg": extra, "rows": rows,
            "summary": summary, "prefix_estimators": estimators}


def row_line(row, ns):
    return (f"extra {row['extra_deg']:3d} deg, prefix {row['prefix']:12s}: slope "
            f"{row['slope']:+.2f}, variance at {ns[-1]} {row['variance'][-1]:.3e}, max band n P_S "
            f"{max(row['band_energy_max'].values()):.3f}")


def figure(data, args):
    ns, rows, summary = data["ns"], data["rows"], data["summary"]
    fig, axes = plot.new_figure(1, 1, size=4.0)
    ax = axes[0, 0]
    for spec in PREFIXES:
        v = np.exp(np.mean([np.log(r["variance"]) for r in rows.values() if r["prefix"] == spec],
                           axis=0))
        ax.loglog(ns, v, marker="o", ms=3, label=f"{spec} ({summary[spec]['slope_median']:+.2f})")
    ax.set_xlabel("n")
    ax.set_ylabel("edge variance (geometric mean over directions)")
    ax.legend(fontsize=7)
    plot.save_figure(fig, args.out / NAME)


def report(data, args):
    """What the script prints: each row's line (a computing run printed them as it went), the
    prefixes as estimators, the summary."""
    ns = data["ns"]
    if not getattr(args, "printed_rows", False):
        for row in data["rows"].values():
            print(row_line(row, ns))
    for label, e in data["prefix_estimators"].items():
        print(f"prefix as estimator, {label:18s}: mean edge variance {e['mean_variance']:.3e}")
    for spec, s in data["summary"].items():
        print(f"{spec:12s}: slope median {s['slope_median']:+.2f} (worst {s['slope_worst']:+.2f}),"
              f" variance / none at {ns[-1]} median {s['ratio_to_none_median']:.2f} (worst "
              f"{s['ratio_to_none_worst']:.2f}), worst band n P_S {s['band_energy_worst']:.3f}")
    print(f"\nfigure:  {args.out / NAME}.png\nnumbers: {args.out / NAME}.json")


def main(argv=None):
    return common.run(NAME, __doc__, SCALES, compute, figure=figure, report=report, argv=argv)


if __name__ == "__main__":
    main()

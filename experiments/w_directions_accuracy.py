"""Accuracy of principal-direction estimation on random analytic integrands (W Sec. 5.2-5.3).

Cases (anisosample.integrands; fresh random parameters per instance, seed fixed):

* ``one_edge``: one extra edge at a random direction at least 8 deg from the axes, alternately a
  half-plane (``edges([a])``) and a polygon with axis-aligned edges too (``edges([0, 90, a])``);
* ``one_edge_near_axis``: the same with the direction 3.5-8 deg from an axis (reported apart:
  the +-3 deg windows around the axes are zeroed, see anisosample.directions);
* ``two_edges``: two extra edges at random directions (>= 8 deg from the axes, >= 15 deg apart),
  alternately ``edges([a, b])`` and ``edges([0, a, b])``;
* ``disk`` (curved) and ``bump`` (smooth Gaussian): controls that must give no extra direction.

Each integrand is sampled on s x s cell centres (s = 64, 96, 128) and estimated with the
defaults of ``anisosample.directions.estimate`` (k = 2), all instances of one size at once via
``estimate_blocks``: ``table`` with the fixed-kappa search (the default, W Sec. 5.2), and
``table_gradient`` with ``estimator="gradient"`` (96^2 only). A true direction counts as found
when an estimate lies within ``tol_deg`` (3 deg) of it. Angular error = distance from the true
direction to the nearest estimate.

    python experiments/w_directions_accuracy.py --scale small|paper [--out DIR] [--fresh]
"""

from __future__ import annotations

import common
import numpy as np

from anisosample import directions, integrands, metrics
from anisosample.progress import progress

NAME = "w_directions_accuracy"
SIZES = [64, 96, 128]
CASES = ["one_edge", "one_edge_near_axis", "two_edges", "disk", "bump"]
SCALES = {"small": {"n": 60}, "paper": {"n": 400}}
TOL_DEG = 3.0
SEED = 2026


def axial(a, b):
    return metrics.axial_distance_deg(a, b, xp=np)


def axis_distance(a):
    return min(axial(a, 0.0), axial(a, 90.0))


def random_direction(rng, lo=8.0, hi=45.0):
    while True:
        a = float(rng.uniform(0.0, 180.0))
        if lo <= axis_distance(a) <= hi:
            return round(a, 3)


def random_center_radius(rng):
    c = rng.uniform(0.35, 0.65, 2)
    r = float(rng.uniform(0.1, min(0.25, 0.98 * min(*c, *(1 - c)))))
    return (float(c[0]), float(c[1])), r


def make_case(case, rng):
    """-> (integrand, true extra directions)."""
    i = int(rng.integers(2))
    center, radius = random_center_radius(rng)
    if case in ("one_edge", "one_edge_near_axis"):
        a = random_direction(rng, 8.0, 45.0) if case == "one_edge" else \
            random_direction(rng, 3.5, 8.0)
        dirs = [a] if i == 0 else [0.0, 90.0, a]
        return integrands.edges(dirs, center=center, radius=radius), [a]
    if case == "two_edges":
        while True:
            a, b = random_direction(rng), random_direction(rng)
            if axial(a, b) >= 15.0:
                break
        dirs = [a, b] if i == 0 else [0.0, a, b]
        return integrands.edges(dirs, center=center, radius=radius), [a, b]
    if case == "disk":
        return integrands.Disk(center, float(rng.uniform(0.1, 0.3))), []
    if case == "bump":
        c = tuple(float(t) for t in rng.uniform(0.3, 0.7, 2))
        return integrands.GaussianBump(c, float(rng.uniform(0.05, 0.15))), []
    raise ValueError(case)


def evaluate(case, size, n, rng, bar, estimator="fixed"):
    x = directions.block_grid(size)
    grids, truths = [], []
    for _ in range(n):
        f, truth = make_case(case, rng)
        grids.append(np.asarray(f(x), np.float32))
        truths.append(truth)
        bar.update()
    est = directions.estimate_blocks(np.concatenate(grids, axis=1), k=2, samples_per_block=size,
                                     estimator=estimator)
    d = np.asarray(est.directions_deg)[0]
    v = np.asarray(est.valid)[0]
    conf = np.asarray(est.confidence)[0]
    rows = []
    for j, truth in enumerate(truths):
        found = [float(t) for t in d[j][v[j]]]
        errs = [min((axial(g, t) for g in found), default=None) for t in truth]
        rows.append({"truth_deg": truth, "estimates_deg": found, "errors_deg": errs,
                     "confidence": conf[j].tolist()})
    return rows


def summarize(case, rows):
    out = {"instances": len(rows)}
    if case in ("disk", "bump"):
        none = [len(r["estimates_deg"]) == 0 for r in rows]
        out["no_direction_rate"] = float(np.mean(none))
        return out
    errs = [e for r in rows for e in r["errors_deg"] if e is not None]
    found = [all(e is not None and e <= TOL_DEG for e in r["errors_deg"]) for r in rows]
    out["all_found_rate"] = float(np.mean(found))
    out["found_any_estimate_rate"] = float(
        np.mean([all(e is not None for e in r["errors_deg"]) for r in rows]))
    if errs:
        out["error_median_deg"] = float(np.median(errs))
        out["error_p95_deg"] = float(np.quantile(errs, 0.95))
        out["error_max_deg"] = float(np.max(errs))
        out["error_mean_deg"] = float(np.mean(errs))
    extra = [len(r["estimates_deg"]) > len(r["truth_deg"]) for r in rows]
    out["spurious_extra_rate"] = float(np.mean(extra))
    return out


def plot(res, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(15, 4))
    for size in SIZES:
        errs = [e for case in ("one_edge", "two_edges")
                for r in res["rows"][str(size)][case] for e in r["errors_deg"] if e is not None]
        axes[0].hist(errs, bins=np.arange(0, 6.25, 0.25), histtype="step", label=f"{size}^2")
    axes[0].set_xlabel("angular error (deg), one- and two-edge cases")
    axes[0].set_ylabel("count")
    axes[0].legend()
    width = 0.25
    labels = ["one_edge", "one_edge_near_axis", "two_edges"]
    for i, size in enumerate(SIZES):
        vals = [res["table"][str(size)][c]["all_found_rate"] for c in labels]
        axes[1].bar(np.arange(len(labels)) + i * width, vals, width, label=f"{size}^2")
    axes[1].set_xticks(np.arange(len(labels)) + width, labels, fontsize=8)
    axes[1].set_ylabel(f"all true directions found (<= {TOL_DEG:g} deg)")
    axes[1].axhline(0.9, color="k", lw=0.5)
    axes[1].legend()
    for i, size in enumerate(SIZES):
        vals = [res["table"][str(size)][c]["no_direction_rate"] for c in ("disk", "bump")]
        axes[2].bar(np.arange(2) + i * width, vals, width, label=f"{size}^2")
    axes[2].set_xticks(np.arange(2) + width, ["disk", "bump"])
    axes[2].set_ylabel("'no extra direction' rate")
    axes[2].axhline(0.95, color="k", lw=0.5)
    axes[2].legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def settings_of(cfg, args) -> dict:
    return {"scale": args.scale, "instances_per_case": cfg["n"], "sizes": SIZES,
            "tol_deg": TOL_DEG, "seed": SEED, "k": 2,
            "estimator": "anisosample.directions defaults (fixed kappa)",
            "defaults": directions.default_options()}


def compute(settings, args):
    """Every (size, case) part, each kept in ``parts_<scale>/`` so an interrupted run resumes."""
    n = settings["instances_per_case"]
    part_dir = args.out / f"parts_{args.scale}"
    part_dir.mkdir(exist_ok=True)
    bar = progress(total=n * (len(SIZES) + 1) * len(CASES), desc="integrands")

    def part(name, size, case, ci, estimator):
        # the same integrands at every size: seed by case only
        return common.reuse_or_compute(
            part_dir / f"{name}.json",
            {**settings, "size": size, "case": case, "estimator": estimator}, args.fresh,
            lambda: evaluate(case, size, n, np.random.default_rng([SEED, ci]), bar,
                             estimator=estimator),
            field="rows", reused=lambda: bar.update(n))

    rows, table = {}, {}
    for size in SIZES:
        rows[str(size)], table[str(size)] = {}, {}
        for ci, case in enumerate(CASES):
            r = part(f"{size}_{case}", size, case, ci, "fixed")
            rows[str(size)][case] = r
            table[str(size)][case] = summarize(case, r)
    rows_g, table_g = {}, {}
    for ci, case in enumerate(CASES):
        r = part(f"96_{case}_gradient", 96, case, ci, "gradient")
        rows_g[case] = r
        table_g[case] = summarize(case, r)
    bar.close()
    return {
        "table": table,
        "table_gradient": {"96": table_g},
        "rows": rows,
        "rows_gradient": {"96": rows_g},
    }


def report(res, args):
    for size in SIZES:
        for case in CASES:
            t = res["table"][str(size)][case]
            cells = ", ".join(f"{k}={v:.3f}" if isinstance(v, float) else f"{k}={v}"
                              for k, v in t.items())
            print(f"{size:4d}^2 {case:20s} {cells}")
    for case in CASES:
        t = res["table_gradient"]["96"][case]
        cells = ", ".join(f"{k}={v:.3f}" if isinstance(v, float) else f"{k}={v}"
                          for k, v in t.items())
        print(f"  96^2 {case:20s} (gradient) {cells}")
    stem = args.out / f"{NAME}_{args.scale}"
    print(f"wrote {stem}.png and {stem}.json")


def main(argv=None):
    return common.run(
        NAME, __doc__.splitlines()[0], SCALES, compute, seed=None, argv=argv,
        arguments=lambda p: p.add_argument("--force", dest="fresh", action="store_true",
                                           help="the same as --fresh"),
        settings=settings_of, record=NAME + "_{scale}.json",
        figure=lambda res, args: plot(res, args.out / f"{NAME}_{args.scale}.png"),
        report=report)


if __name__ == "__main__":
    main()

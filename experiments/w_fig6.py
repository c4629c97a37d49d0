"""W Fig. 6: variance vs n of our aligned sets next to pmj02bn and sobol-owen.

Cases (integrands from ``anisosample.integrands.edges``; the square's border adds 0 and 90):

* ``one edge at theta``: our 3-direction set ``{0, 90, theta}`` — the rate claim (-1.70 or
  steeper over 2^8..2^12, 2^14 at paper scale);
* ``two edges at (a, b)``: our 4-direction set ``{0, 90, a, b}``;
* ``four edges``: a 3-direction set on an integrand with more edges than it covers (back near
  -1.5, the paper's observation);
* ``misaligned``: the set made for theta on edges at theta + delta (the robustness curve).

The robustness study of issue 4 (``frequencies.ROBUST_OFFSETS_DEG``; one set per n) ran

    python experiments/w_fig6.py --out results/w_fig6/robust_dense --log2-ns 8,9,10,11,12,13,14 \
        --seeds 1 --one-edge 30,67,12,145 --no-multi-edge --baselines none \
        --offsets-deg=-1,-0.75,-0.5,-0.25,0.25,0.5,0.75,1 --misaligned-deltas=-2,-1.5,-1,...,2

and the same with ``--offsets-deg none --out results/w_fig6/robust_old`` (the weights before)
and with offsets every 0.125 deg (``--out results/w_fig6/robust_dense125``, a measured alternative);
``w_fig6_seeds2.*`` hold the 30-deg curves with ``--seeds 2``;
``--compare DIR`` overlays another run's misalignment curve.

Our sets are fixed sets (several seeds per n) randomized by toroidal shifts; baselines use their
own randomization plus a shift.  Writes ``results/w_fig6/w_fig6.png`` and ``w_fig6.json`` (every
plotted number, slopes with 95 % intervals, settings, provenance).  Reuses finished sets and
variances on rerun.

    python experiments/w_fig6.py --scale small|paper [--out DIR]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import common
import jax
import numpy as np
from _w_variance import our_sets, variance_of_sets

from anisosample import integrands, synthesis
from anisosample import variance as V
from anisosample.progress import progress

SCALES = {
    "small": dict(
        log2_ns=[8, 9, 10, 11, 12], seeds=2, realizations=2048,
        one_edge=[30.0, 67.0], two_edges=[], four_edges=[(30.0, [30.0, 75.0, 115.0, 150.0])],
        misaligned=(30.0, [-2.0, -1.0, -0.5, 0.5, 1.0, 2.0]),
    ),
    "paper": dict(
        log2_ns=[8, 9, 10, 11, 12, 13, 14], seeds=3, realizations=4096,
        one_edge=[30.0, 67.0, 15.0, 50.0], two_edges=[(30.0, 120.0), (67.0, 150.0)],
        four_edges=[(30.0, [30.0, 75.0, 115.0, 150.0])],
        misaligned=(30.0, [-2.0, -1.0, -0.5, 0.5, 1.0, 2.0]),
    ),
}
BASELINES = {"pmj02bn": "shift", "sobol-owen": "fresh+shift"}


def variance_of_baseline(f, name, ns, realizations, key):
    mode = BASELINES[name]
    kw = {"patterns": 16} if mode == "shift" else {}
    return [V.estimate_variance(f, name, n, key, realizations, f.integral, randomization=mode,
                                **kw) for n in ns]


def curve(rows, ns):
    var = [r.variance for r in rows]
    se = [r.std_error for r in rows]
    fit = V.fit_slope(ns, var, se)
    return {"variance": var, "std_error": se, "fit": fit.as_dict()}


def baselines_option(text):
    """``--baselines``: a comma list of :data:`BASELINES`' names, or 'none'."""
    chosen = [] if text == "none" else text.split(",")
    for b in chosen:
        if b not in BASELINES:
            raise argparse.ArgumentTypeError(
                f"unknown {b!r}; choose from {list(BASELINES)} or 'none'")
    return chosen


def arguments(ap):
    ap.add_argument("--log2-ns", default=None, help="override, e.g. 8,9,10,11,12,13,14")
    ap.add_argument("--seeds", type=int, default=None, help="override sets per n")
    ap.add_argument("--one-edge", default=None, help="override one-edge angles, e.g. 30,67")
    ap.add_argument("--only-one-edge", action="store_true",
                    help="skip the two-/four-edge cases and the misalignment curve")
    ap.add_argument("--two-edges", default=None,
                    help="override two-edge pairs and run only them, e.g. 30:120,67:150")
    ap.add_argument("--weight-spread-deg", type=float, default=None,
                    help="frequency design option (robustness weights); use its own --out")
    ap.add_argument("--core-deg", type=float, default=None,
                    help="frequency design option: flat weight core of this angular half-width"
                         " (frequencies.edge_weights); 0 = none; use its own --out")
    ap.add_argument("--offsets-deg", default=None,
                    help="frequency design option: extra weight lines at theta + each offset,"
                         " e.g. -1,-0.5,0.5,1, or 'none' (frequencies.edge_weights);"
                         " use its own --out")
    ap.add_argument("--misaligned-deltas", default=None,
                    help="override the misalignment offsets (deg), e.g. -2,-1,-0.5,0.5,1,2")
    ap.add_argument("--no-multi-edge", action="store_true",
                    help="skip the two-/four-edge cases (keep one edge and the misalignment)")
    ap.add_argument("--compare", action="append", default=None,
                    help="another run's --out whose misalignment curve is overlaid (repeatable)")
    ap.add_argument("--label", default=None, help="legend label of this run's curve")
    ap.add_argument("--baselines", type=baselines_option, default=",".join(BASELINES),
                    help="comma list of baselines to compare with, or 'none'")


def settings(scale, args):
    """The scale's settings with the command line's overrides, the sets' recipe and its
    defaults: what the record, the sets and the variance curves are made with."""
    cfg = dict(scale)
    fopts = {}
    if args.weight_spread_deg:
        fopts["weight_spread_deg"] = args.weight_spread_deg
    if args.core_deg is not None:
        fopts["core_deg"] = args.core_deg
    if args.offsets_deg:  # "none": no offsets (the aligned-only weights)
        fopts["offsets_deg"] = ([] if args.offsets_deg == "none"
                                else [float(t) for t in args.offsets_deg.split(",")])
    cfg["frequency_options"] = fopts or None
    cfg["baselines"] = args.baselines
    if args.log2_ns:
        cfg["log2_ns"] = [int(t) for t in args.log2_ns.split(",")]
    if args.seeds:
        cfg["seeds"] = args.seeds
    if args.one_edge:
        cfg["one_edge"] = [float(t) for t in args.one_edge.split(",")]
    if args.two_edges:
        cfg["two_edges"] = [tuple(float(x) for x in p.split(":")) for p in
                            args.two_edges.split(",")]
        cfg["one_edge"], cfg["four_edges"], cfg["misaligned"] = [], [], (None, [])
    if args.misaligned_deltas:
        cfg["misaligned"] = (cfg["misaligned"][0],
                             [float(t) for t in args.misaligned_deltas.split(",")])
    if args.no_multi_edge:
        cfg["two_edges"], cfg["four_edges"] = [], []
    if args.only_one_edge:
        cfg["two_edges"], cfg["four_edges"] = [], []
        cfg["misaligned"] = (cfg["one_edge"][0], [])
    return {"scale": args.scale, **cfg, "ns": [2**k for k in cfg["log2_ns"]],
            "recipe": "rate", "defaults": synthesis.recipe_defaults("rate")}


def compute(cfg, args):
    """Our sets (``sets/``), every case's variance curves and the misalignment curve (``var/``,
    one settings-checked file a curve: resumable)."""
    out = args.out
    fopts, baselines = cfg["frequency_options"], cfg["baselines"]
    ns = cfg["ns"]
    seeds, R = cfg["seeds"], cfg["realizations"]
    key = jax.random.key(6)

    cases = []  # (label, integrand directions, our set directions)
    for t in cfg["one_edge"]:
        cases.append((f"one edge {t:g}", [t], [0.0, 90.0, t]))
    for a, b in cfg["two_edges"]:
        cases.append((f"two edges {a:g},{b:g}", [a, b], [0.0, 90.0, a, b]))
    for t, four in cfg["four_edges"]:
        cases.append((f"four edges {'/'.join(f'{x:g}' for x in four)} (set 0/90/{t:g})", four,
                      [0.0, 90.0, t]))
    t0, deltas = cfg["misaligned"]

    tag = f"_n{min(ns)}-{max(ns)}_s{seeds}_R{R}"  # variance caches are per sweep
    # ... and reused only when made with the same settings (the sets' too)
    ours_settings = {"ns": ns, "seeds": seeds, "realizations": R, "key": 6, "set_key": 1000,
                     "recipe": "rate", "defaults": synthesis.recipe_defaults("rate"),
                     "frequency_options": fopts}

    def cached(path, settings, fn):
        return common.reuse_or_compute(path, settings, args.fresh, fn)

    set_dirs = {tuple(c[2]) for c in cases}
    bar = progress(total=len(set_dirs) * len(ns) * seeds, desc="w_fig6 sets")
    sets = {d: our_sets(out, list(d), ns, seeds, bar, fopts) for d in sorted(set_dirs)}
    bar.close()

    results = {"cases": {}}
    for label, fdirs, sdirs in progress(cases, desc="w_fig6 variance"):
        f = integrands.edges(fdirs)
        slug = label.replace(" ", "_").replace("/", "-").replace(",", "-") + tag
        entry = {"integrand_directions_deg": fdirs, "set_directions_deg": sdirs}
        entry["ours"] = cached(
            out / "var" / f"{slug}_ours.json",
            {**ours_settings, "integrand_directions_deg": fdirs, "set_directions_deg": sdirs},
            lambda f=f, sdirs=sdirs: curve(
                variance_of_sets(f, sets[tuple(sdirs)], ns, seeds, R, key), ns))
        for b in baselines:
            entry[b] = cached(
                out / "var" / f"{slug}_{b}.json",
                {"ns": ns, "realizations": R, "key": 6, "integrand_directions_deg": fdirs,
                 "baseline": b, "randomization": BASELINES[b],
                 "patterns": 16 if BASELINES[b] == "shift" else None},
                lambda b=b, f=f: curve(variance_of_baseline(f, b, ns, R, key), ns))
        results["cases"][label] = entry

    # robustness: the set made for t0 on edges at t0 + delta
    if t0 is not None:
        rob = {}
        for dl in progress(deltas, desc="w_fig6 misalignment"):
            f = integrands.edges([t0 + dl])
            rob[f"{dl:+g}"] = cached(out / "var" / f"misaligned_{t0:g}_{dl:+g}{tag}.json",
                                     {**ours_settings, "integrand_directions_deg": [t0 + dl],
                                      "set_directions_deg": [0.0, 90.0, t0]},
                                     lambda f=f: curve(
                variance_of_sets(f, sets[(0.0, 90.0, t0)], ns, seeds, R, key), ns))
        rob["+0"] = results["cases"][f"one edge {t0:g}"]["ours"]
        results["misalignment"] = {"set_direction_deg": t0,
                                   "slope_by_delta": {k: v["fit"] for k, v in sorted(
                                       rob.items(), key=lambda kv: float(kv[0]))}}
    return results


def figure(results, args):
    """One panel per case (ours and the baselines), one for the misalignment slopes (with
    ``--compare``'s runs overlaid); drawn from the record."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ns, out = args.settings["ns"], args.out
    rob = results.get("misalignment")
    k = len(results["cases"]) + (1 if rob else 0)
    fig, axes = plt.subplots(1, k, figsize=(3.4 * k, 3.2), squeeze=False)
    for ax, (label, e) in zip(axes[0], results["cases"].items(), strict=False):
        for name, style in (("ours", "-o"), ("pmj02bn", "--s"), ("sobol-owen", ":^")):
            if name not in e:
                continue
            ax.loglog(ns, e[name]["variance"], style, ms=3,
                      label=f"{name} {e[name]['fit']['slope']:.2f}")
        ax.set_xscale("log", base=2)
        ax.set_title(label, fontsize=8)
        ax.set_xlabel("n")
        ax.legend(fontsize=7)
    axes[0][0].set_ylabel("variance")
    if rob:
        t0 = rob["set_direction_deg"]
        ax = axes[0][-1]
        d = sorted(float(x) for x in rob["slope_by_delta"])
        s = [rob["slope_by_delta"][f"{x:+g}"]["slope"] for x in d]
        lo = [rob["slope_by_delta"][f"{x:+g}"]["ci_low"] for x in d]
        hi = [rob["slope_by_delta"][f"{x:+g}"]["ci_high"] for x in d]
        ax.errorbar(d, s, yerr=[np.subtract(s, lo), np.subtract(hi, s)], fmt="-o", ms=3,
                    label=args.label or "this run")
        for other in args.compare or []:  # overlay another run's curve (e.g. the old design)
            om = json.loads((Path(other) / "w_fig6.json").read_text())["misalignment"]
            od = sorted(om["slope_by_delta"], key=float)
            ax.plot([float(x) for x in od], [om["slope_by_delta"][x]["slope"] for x in od],
                    "--s", ms=3, label=Path(other).name)
        if args.compare:
            ax.legend(fontsize=7)
        ax.axhline(-1.65, color="gray", lw=0.5, ls="--")
        ax.axhline(-1.70, color="gray", lw=0.5)
        ax.axhline(-1.5, color="gray", lw=0.5, ls=":")
        ax.set_xlabel("edge misalignment (deg)")
        ax.set_ylabel("slope")
        ax.set_title(f"set for {t0:g} deg on edges at {t0:g}+delta", fontsize=8)
    fig.tight_layout()
    out.mkdir(parents=True, exist_ok=True)
    fig.savefig(out / "w_fig6.png", dpi=130)
    plt.close(fig)


def report(results, args):
    baselines = args.settings["baselines"]
    for label, entry in results["cases"].items():
        fit = entry["ours"]["fit"]
        print(f"{label}: ours {fit['slope']:.3f} [{fit['ci_low']:.3f}, {fit['ci_high']:.3f}]  "
              + "  ".join(f"{b} {entry[b]['fit']['slope']:.3f}" for b in baselines))
    for k, v in results.get("misalignment", {}).get("slope_by_delta", {}).items():
        print(f"misaligned {k} deg: slope {v['slope']:.3f}")
    print(f"wrote {args.out / 'w_fig6.png'} and {args.out / 'w_fig6.json'}")


def main(argv=None):
    # fixed keys (sets: 1000 + s; variances: 6); --fresh recomputes the variance curves
    return common.run("w_fig6", __doc__.splitlines()[0], SCALES, compute, figure=figure,
                      report=report, arguments=arguments, settings=settings, seed=None,
                      argv=argv)


if __name__ == "__main__":
    main()

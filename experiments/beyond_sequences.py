"""Progressive aligned sequences (W Sec. 7; issue 22 item 2): what nesting costs each prefix.

One N = 4096 sequence per design and extra direction (0, 90 and a direction drawn at random:
four at ``--scale small``, six at full scale): every power-of-two prefix from 256 points up
should be an aligned set. Designs: ``equal`` (the defaults of ``synthesis.synthesize_sequence``:
every nested prefix's normalized loss counts once, ``SEQUENCE_LEARNING_RATE``,
``SEQUENCE_STEPS``, ``SEQUENCE_FREQUENCY_OPTIONS``) and ``equal, axes 1`` (the same with the
sets' frequency design, ``frequency_options={}``: the axes' weight 1 at every prefix, the default
before); at full scale also the same at 600 steps (the default before), at 600 steps
and the sets' learning rate 0.5, ``size`` (prefix n_k weighs n_k / N) and ``equal`` with the
default fixed prefix (``prefix.DEFAULT_PREFIX``), each at 600 steps. Per prefix size n we
measure the variance of the half-plane whose edge is perpendicular to the extra direction
(16384 toroidal shifts at small scale: the shift noise is then a few per cent, below the spread
between sets) against standalone aligned sets of the same n (three keys: their mean is the
reference, their max/min spread is reported) and against pmj02bn; the slope over the prefixes
(and the standalone sets' own slope at that direction); the mean ``n P_S`` within one unit of
every requested line, ``0 < |v| <= 32``, for n >= 1024 (white noise = 1).

Targets (issue 22): each prefix within 1.25x of a standalone set, slope <= -1.70, variance at
4096 <= 0.6x pmj02bn's, band energy <= 0.1.

``--direction-count 4`` (written to ``results/beyond_sequences_four``): the same for
4-direction sequences (0, 90 and two extra directions drawn at random, at least 20 degrees
apart and 5 from the axes: ``four_direction_pairs`` of them, two at small scale and four at
full scale), measured on
the corner integrand whose two edges are perpendicular to the two extra directions
(``integrands.edges``, the pixels W's 4-direction sets are for), against standalone
4-direction sets.
"""

from __future__ import annotations

import time

import common
import jax
import numpy as np

import anisosample as asp
from anisosample import diagnostics, plot, prefix, synthesis

NAME = "beyond_sequences"
DESIGNS = {"equal": {}, "equal, axes 1": {"frequency_options": {}},
           "equal, 600 steps": {"steps": 600},
           "equal, lr 0.5": {"steps": 600, "learning_rate": 0.5},
           "size": {"steps": 600, "sequence_weights": "size"},
           f"equal + {prefix.DEFAULT_PREFIX}": {"steps": 600, "prefix": prefix.DEFAULT_PREFIX}}
# the four comparisons add 4 x 600 optimizer steps per direction to the default's 3000
SMALL_DESIGNS = ("equal", "equal, axes 1")
FOUR_DIRECTION_PAIRS = {"small": 2, "paper": 4}  # --direction-count 4: sequences per run
KEYS = (1, 2, 3)
# the sequences' length and first prefix, toroidal shifts per variance, extra directions, designs
SCALES = {
    "small": dict(length=4096, start=256, realizations=16384, extra_directions=4,
                  designs=list(SMALL_DESIGNS)),
    "paper": dict(length=4096, start=256, realizations=65536, extra_directions=6,
                  designs=list(DESIGNS)),
}


def compute(cfg, args):
    out, length, start = args.out, cfg["length"], cfg["start"]
    ns = synthesis.sequence_levels(length, start)
    realizations = cfg["realizations"]
    rng = np.random.default_rng(args.seed + 1)
    designs = {k: DESIGNS[k] for k in cfg["designs"]}
    extra = [int(a) for a in rng.choice([a for a in range(5, 176) if abs(a - 90) >= 5], 6,
                                        replace=False)][:cfg["extra_directions"]]
    if cfg.get("direction_count", 3) == 4:
        pairs = np.random.default_rng(args.seed + 2)
        extra = []
        while len(extra) < cfg["four_direction_pairs"]:
            a, b = (int(x) for x in pairs.choice([a for a in range(5, 176) if abs(a - 90) >= 5],
                                                 2, replace=False))
            if min(abs(a - b), 180 - abs(a - b)) >= 20:
                extra.append((min(a, b), max(a, b)))
    key = jax.random.key(args.seed)
    vkey = jax.random.fold_in(key, 99)

    def edge_variance(f, pts, n):
        def sampler(k, _n):
            return asp.samplers.toroidal_shift(k, pts)
        return asp.variance.estimator_variance(f, sampler, n, vkey, realizations, f.integral)

    records = {}
    for a in extra:
        chosen = [float(x) for x in np.atleast_1d(a)]
        dirs = (0.0, 90.0, *chosen)
        f = asp.integrands.edges(chosen)
        name_a = "_".join(str(x) for x in np.atleast_1d(a))  # "134", or "40_121" for a pair
        a = a if np.isscalar(a) else list(a)
        sets = {(n, k): np.asarray(asp.synthesis.load_or_synthesize(
            out / "sets" / f"a{name_a}_set_n{n}_k{k}.npz", jax.random.key(k), n, dirs,
            show_progress=False).points) for n in ns for k in KEYS}
        standalone = {n: [edge_variance(f, sets[n, k], n) for k in KEYS] for n in ns}
        set_slope = asp.variance.fit_slope(ns, [float(np.mean(standalone[n]))
                                                for n in ns]).slope
        # the band energy of the first key's standalone set at each n >= 1024: what a set
        # of that size reaches, beside the sequence's prefix
        set_bands = {str(n): max(diagnostics.band_energy(sets[n, KEYS[0]], d) for d in dirs)
                     for n in ns if n >= 1024}
        pmj = {n: asp.variance.estimator_variance(f, "pmj02bn", n, vkey, realizations, f.integral)
               for n in ns}
        for label, opts in designs.items():
            t0 = time.time()
            name = label.replace(" ", "").replace("+", "_").replace(",", "_")
            seq = np.asarray(asp.synthesis.load_or_synthesize(
                out / "sets" / f"a{name_a}_seq_{name}.npz", jax.random.key(0), length, dirs,
                sequence_from=start, show_progress=False,
                **(synthesis.SEQUENCE_DEFAULTS | opts)).points)
            sec = time.time() - t0
            var = [edge_variance(f, seq[:n], n) for n in ns]
            ratio = [v / float(np.mean(standalone[n])) for v, n in zip(var, ns, strict=True)]
            bands = {str(n): max(diagnostics.band_energy(seq[:n], d) for d in dirs)
                     for n in ns if n >= 1024}
            fit = asp.variance.fit_slope(ns, var)
            records[f"{name_a}/{label}"] = {
                "extra_deg": a, "design": label, "variance": var, "ratio_to_set": ratio,
                "ratio_to_pmj02bn": [v / pmj[n] for v, n in zip(var, ns, strict=True)],
                "slope": fit.slope, "slope_ci": [fit.ci_low, fit.ci_high],
                "standalone_slope": set_slope,
                "band_energy_max": bands, "standalone_band_energy_max": set_bands,
                "seconds": sec,
                "standalone_variance": {str(n): standalone[n] for n in ns},
                "pmj02bn_variance": {str(n): pmj[n] for n in ns}}
            print(record_line(records[f"{name_a}/{label}"], length), flush=True)  # as it goes
        print(spread_line(a, records[f"{name_a}/{label}"]), flush=True)
    args.printed_records = True  # the report's first lines

    summary = {}
    for label in designs:
        sel = [r for r in records.values() if r["design"] == label]
        summary[label] = {
            "ratio_to_set_worst_per_prefix": [float(max(r["ratio_to_set"][i] for r in sel))
                                              for i in range(len(ns))],
            "ratio_to_set_median_per_prefix": [float(np.median([r["ratio_to_set"][i]
                                                                for r in sel]))
                                               for i in range(len(ns))],
            "slope_worst": float(max(r["slope"] for r in sel)),
            "slope_minus_standalone_worst": float(max(r["slope"] - r["standalone_slope"]
                                                      for r in sel)),
            "ratio_to_set_worst": float(max(max(r["ratio_to_set"]) for r in sel)),
            "ratio_to_pmj02bn_at_N_worst": float(max(r["ratio_to_pmj02bn"][-1] for r in sel)),
            "band_energy_worst": float(max(max(r["band_energy_max"].values()) for r in sel)),
            "standalone_band_energy_worst": float(max(
                max(r["standalone_band_energy_max"].values()) for r in sel)),
        }
    return {"ns": ns, "length": length, "realizations": realizations, "extra_deg": extra,
            "keys": list(KEYS), "records": records, "summary": summary}


def _deg(a) -> str:
    return f"{a:3d}" if np.isscalar(a) else "/".join(str(x) for x in a)


def record_line(r, length):
    return (f"extra {_deg(r['extra_deg'])} deg, {r['design']:18s}: ratio to set per prefix "
            f"{' '.join(f'{x:.2f}' for x in r['ratio_to_set'])}, slope {r['slope']:+.2f} (sets "
            f"{r['standalone_slope']:+.2f}), at {length}: "
            f"{r['ratio_to_pmj02bn'][-1]:.2f}x pmj02bn, worst band n P_S "
            f"{max(r['band_energy_max'].values()):.3f} ({r['seconds']:.0f} s)")


def spread_line(a, r):
    spread = [max(v) / min(v) for v in r["standalone_variance"].values()]
    return (f"extra {_deg(a)} deg: standalone sets over keys {KEYS}: max/min variance "
            f"{' '.join(f'{s:.2f}' for s in spread)}")


def figure(data, args):
    ns, records = data["ns"], data["records"]
    fig, axes = plot.new_figure(1, 1, size=4.0)
    ax = axes[0, 0]
    for label in data["summary"]:
        r = np.exp(np.mean([np.log(x["ratio_to_set"]) for x in records.values()
                            if x["design"] == label], axis=0))
        ax.semilogx(ns, r, marker="o", ms=3, label=label)
    ax.axhline(1.25, color="k", lw=0.6, ls="--")
    ax.set_xlabel("prefix size n")
    ax.set_ylabel("variance / standalone aligned set (geometric mean)")
    ax.legend(fontsize=7)
    plot.save_figure(fig, args.out / NAME)


def report(data, args):
    """What the script prints: each record's and each direction's spread line (a computing run
    printed them as it went), the summary per design."""
    length = data["length"]
    if not getattr(args, "printed_records", False):
        last = None
        for r in data["records"].values():
            if last is not None and r["extra_deg"] != last["extra_deg"]:
                print(spread_line(last["extra_deg"], last))
            print(record_line(r, length))
            last = r
        print(spread_line(last["extra_deg"], last))
    for label, s in data["summary"].items():
        print(f"{label:18s}: ratio to set, worst per prefix "
              f"{' '.join(f'{x:.2f}' for x in s['ratio_to_set_worst_per_prefix'])}; worst slope "
              f"{s['slope_worst']:+.2f} ({s['slope_minus_standalone_worst']:+.2f} from the sets'"
              f" own); worst at {length} {s['ratio_to_pmj02bn_at_N_worst']:.2f}x"
              f" pmj02bn; worst band {s['band_energy_worst']:.3f}"
              + (f" (standalone sets {s['standalone_band_energy_worst']:.3f})"
                 if "standalone_band_energy_worst" in s else ""))
    print(f"\nfigure:  {args.out / NAME}.png\nnumbers: {args.out / NAME}.json")


def arguments(p):
    p.add_argument("--direction-count", type=int, choices=(3, 4), default=3,
                   help="3: one extra direction per sequence; 4: two (the corner integrand)")


def adjust(args):
    """4-direction sequences write to their own folder by default."""
    if args.direction_count == 4 and args.out == common.ROOT / "results" / NAME:
        args.out = common.ROOT / "results" / f"{NAME}_four"


def settings_of(cfg, args) -> dict:
    """The scale's settings (3 directions: as they always were, so their record is reused);
    4 directions add the count and the number of direction pairs, and drop ``equal, axes 1``
    (with two extra directions the sets' design weighs the axes as the sequences' does)."""
    out = {**cfg, "scale": args.scale, "seed": args.seed}
    if args.direction_count == 4:
        out.update(direction_count=4, four_direction_pairs=FOUR_DIRECTION_PAIRS[args.scale],
                   designs=[d for d in cfg["designs"] if d != "equal, axes 1"])
    return out


def main(argv=None):
    return common.run(NAME, __doc__, SCALES, compute, figure=figure, report=report,
                      arguments=arguments, adjust=adjust, settings=settings_of, argv=argv)


if __name__ == "__main__":
    main()

"""W Fig. 4: MLE vs reverse-KL vMF fits on a synthetic two-mode direction histogram.

The histogram: samples of the mixture 3/4 vMF(mu = 90 deg, kappa = 10) + 1/4 vMF(180 deg, 30)
binned into 360 one-degree bins on [0, 360) (W Eq. 16's domain x in [0, 2 pi); these panels
work on that circle directly, without the axial doubling that anisosample.directions adds).

(a) one mode only (the 180-deg component disabled): MLE and reverse KL agree;
(b) both modes: MLE averages the modes, the reverse KL (gradient fit of mu and kappa from the
    highest histogram bin) seeks one;
(c) two reverse-KL fits started at the two histogram maxima (solid), and the fixed-kappa
    (kappa = 50) integer-degree search around each maximum (dashed);
(d) the objective D_KL(q || p) against mu for several kappa.

    python experiments/w_fig4.py --scale small|paper [--out results/w_fig4] [--fresh]
"""

from __future__ import annotations

import math

import common
import jax
import jax.numpy as jnp
import numpy as np

from anisosample import vmf
from anisosample.progress import progress

NBINS = 360
MODES = [(90.0, 10.0, 0.75), (180.0, 30.0, 0.25)]  # (mu deg, kappa, weight), W Fig. 4
KAPPAS_D = [2.0, 5.0, 10.0, 30.0, 50.0, 100.0]
SCALES = {"small": {"samples": 5000}, "paper": {"samples": 100000}}


def mixture_masses(modes):
    return sum(w * vmf.bin_masses(math.radians(m), k, NBINS) for m, k, w in modes)


def sampled_hist(key, masses, n):
    idx = jax.random.categorical(key, jnp.log(masses), shape=(n,))
    return jnp.zeros(NBINS, jnp.float32).at[idx].add(1.0)


def maxima(hist, count, min_sep_deg=30.0):
    """Highest bins at least ``min_sep_deg`` apart (circular distance on [0, 360))."""
    h = np.asarray(hist, np.float64).copy()
    deg = np.arange(NBINS) * 360.0 / NBINS
    out = []
    for _ in range(count):
        i = int(np.argmax(h))
        out.append(float(deg[i]))
        d = np.abs((deg - deg[i] + 180.0) % 360.0 - 180.0)
        h[d < min_sep_deg] = -1.0
    return out


def fit_panel(hist, starts_deg, kappa0):
    fits = [vmf.fit_reverse_kl(hist, math.radians(s), kappa0) for s in starts_deg]
    return [{"start_deg": s, "mu_deg": math.degrees(float(f.mu)), "kappa": float(f.kappa),
             "objective": float(f.value), "converged": bool(f.converged)}
            for s, f in zip(starts_deg, fits, strict=True)]


def fixed_kappa_search(hist, starts_deg, kappa, window_deg=10):
    obj = np.asarray(vmf.reverse_kl_all_mu(hist, kappa))
    out = []
    for s in starts_deg:
        c = int(round(s)) % NBINS
        win = [(c + d) % NBINS for d in range(-window_deg, window_deg + 1)]
        best = min(win, key=lambda i: obj[i])
        out.append({"start_deg": s, "mu_deg": float(best), "kappa": kappa,
                    "objective": float(obj[best])})
    return out


def mle(hist):
    f = vmf.fit_mle(hist)
    return {"mu_deg": math.degrees(float(f.mu)), "kappa": float(f.kappa), "rbar": float(f.rbar)}


def settings_of(scale) -> dict:
    return {"scale": scale, "samples": SCALES[scale]["samples"], "bins": NBINS, "modes": MODES,
            "kappa_fixed": 50.0, "kappas_objective": KAPPAS_D, "seed": 4,
            "floor": vmf.DEFAULT_FLOOR, "nodes": vmf.DEFAULT_NODES}


def compute(settings, args):
    n = settings["samples"]
    key_a, key_b = jax.random.split(jax.random.key(settings["seed"]))
    res = {}
    steps = progress(total=5, desc="w_fig4")
    one = sampled_hist(key_a, mixture_masses(MODES[:1]), n)
    two = sampled_hist(key_b, mixture_masses(MODES), n)
    exact = mixture_masses(MODES)
    res["hist_one"] = np.asarray(one / one.sum()).tolist()
    res["hist_two"] = np.asarray(two / two.sum()).tolist()
    steps.update()
    res["a"] = {"mle": mle(one), "reverse_kl": fit_panel(one, maxima(one, 1), 20.0)}
    steps.update()
    res["b"] = {"mle": mle(two), "reverse_kl": fit_panel(two, maxima(two, 1), 20.0)}
    steps.update()
    starts = maxima(two, 2)
    res["c"] = {"starts_deg": starts, "reverse_kl": fit_panel(two, starts, 20.0),
                "fixed_kappa": fixed_kappa_search(two, starts, 50.0)}
    steps.update()
    res["d"] = {"mu_deg": list(range(NBINS)),
                "objective": {str(k): np.asarray(vmf.reverse_kl_all_mu(two, k)).tolist()
                              for k in KAPPAS_D}}
    # the same fits on the exact mixture (no sampling noise), as in the fact sheet
    res["exact_mixture"] = {
        "mle": mle(exact),
        "reverse_kl": fit_panel(exact, [80.0, 172.0], 8.0),
        "fixed_kappa": fixed_kappa_search(exact, [90.0, 180.0], 50.0),
    }
    steps.update()
    steps.close()
    plot(res, args.out / f"w_fig4_{args.scale}.png")  # drawn once, with the record
    return res


def plot(res, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    deg = np.arange(NBINS)
    x = jnp.radians(jnp.asarray(deg, jnp.float32))

    def density(mu_deg, kappa):  # per degree, to overlay on the normalised 1-degree histogram
        return np.asarray(vmf.pdf(x, math.radians(mu_deg), kappa)) * math.pi / 180.0

    fig, axes = plt.subplots(1, 4, figsize=(18, 3.8))
    for ax, key, title in [(axes[0], "a", "(a) one mode"), (axes[1], "b", "(b) two modes")]:
        hist = res["hist_one" if key == "a" else "hist_two"]
        ax.bar(deg, hist, width=1.0, color="0.75", label="histogram")
        m = res[key]["mle"]
        ax.plot(deg, density(m["mu_deg"], m["kappa"]), color="goldenrod",
                label=f"MLE mu={m['mu_deg']:.1f}")
        r = res[key]["reverse_kl"][0]
        ax.plot(deg, density(r["mu_deg"], r["kappa"]), color="crimson",
                label=f"reverse KL mu={r['mu_deg']:.1f}")
        ax.set_title(title)
        ax.legend(fontsize=7)
    ax = axes[2]
    ax.bar(deg, res["hist_two"], width=1.0, color="0.75")
    for r in res["c"]["reverse_kl"]:
        ax.plot(deg, density(r["mu_deg"], r["kappa"]), color="crimson",
                label=f"rKL mu={r['mu_deg']:.1f} k={r['kappa']:.1f}")
    for r in res["c"]["fixed_kappa"]:
        ax.plot(deg, 0.25 * density(r["mu_deg"], r["kappa"]), "--", color="crimson",
                label=f"fixed k=50 mu={r['mu_deg']:.0f} (x1/4)")
    ax.set_title("(c) two reverse-KL fits")
    ax.legend(fontsize=7)
    ax = axes[3]
    for k, obj in res["d"]["objective"].items():
        ax.plot(res["d"]["mu_deg"], obj, label=f"kappa={float(k):g}")
    ax.set_title("(d) D_KL(q||p) against mu")
    ax.set_yscale("log")
    ax.legend(fontsize=7)
    for ax in axes:
        ax.set_xlabel("direction (deg)")
        ax.set_xlim(0, 360)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def report(res, args):
    json_path = args.out / f"w_fig4_{args.scale}.json"
    png = args.out / f"w_fig4_{args.scale}.png"
    print(f"(a) one mode:  MLE mu={res['a']['mle']['mu_deg']:.2f}, "
          f"reverse KL mu={res['a']['reverse_kl'][0]['mu_deg']:.2f}")
    print(f"(b) two modes: MLE mu={res['b']['mle']['mu_deg']:.2f}, "
          f"reverse KL mu={res['b']['reverse_kl'][0]['mu_deg']:.2f}")
    for r in res["c"]["reverse_kl"]:
        print(f"(c) reverse KL from {r['start_deg']:.0f}: mu={r['mu_deg']:.2f} "
              f"kappa={r['kappa']:.2f}")
    for r in res["c"]["fixed_kappa"]:
        print(f"(c) fixed kappa=50 from {r['start_deg']:.0f}: mu={r['mu_deg']:.0f}")
    e = res["exact_mixture"]
    print(f"exact mixture: MLE mu={e['mle']['mu_deg']:.2f} rbar={e['mle']['rbar']:.4f} "
          f"kappa={e['mle']['kappa']:.4f}; reverse KL "
          + ", ".join(f"{r['mu_deg']:.2f} (kappa {r['kappa']:.2f})" for r in e["reverse_kl"])
          + "; fixed kappa " + ", ".join(f"{r['mu_deg']:.0f}" for r in e["fixed_kappa"]))
    print(f"wrote {png} and {json_path}")


def main(argv=None):
    return common.run(
        "w_fig4", __doc__.splitlines()[0], SCALES, compute, seed=None, argv=argv,
        arguments=lambda p: p.add_argument("--force", dest="fresh", action="store_true",
                                           help="the same as --fresh"),
        settings=lambda cfg, args: settings_of(args.scale), record="w_fig4_{scale}.json",
        outputs=("w_fig4_{scale}.png",), report=report)


if __name__ == "__main__":
    main()

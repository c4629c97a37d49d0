"""What W Figs. 6 and 11 share: our fixed sets and their variance under random shifts, the
baseline samplers' variance curves (W Fig. 6's baselines, reused by W Fig. 11)."""

from __future__ import annotations

from pathlib import Path

import jax
import numpy as np

from anisosample import plot, synthesis
from anisosample import variance as V

BASELINE_SCALES = {
    "small": dict(log2_ns=list(range(4, 15, 2)), realizations=256, patterns=4, fit_min_n=64),
    "paper": dict(log2_ns=list(range(4, 17)), realizations=4096, patterns=16, fit_min_n=64),
}
JITTABLE = ["random", "jittered", "cmj", "sobol-owen"]


def curves_setup(settings, args):
    """What a curve-recording W script starts from: the sizes ``ns = 2^log2_ns`` and the run's
    key, with ``<out>/curves/`` (its resumable parts) made."""
    (args.out / "curves").mkdir(parents=True, exist_ok=True)
    return [2**k for k in settings["log2_ns"]], jax.random.key(args.seed)


def our_sets(out: Path, dirs, ns, seeds, bar, frequency_options=None):
    sets = {}
    for n in ns:
        for s in range(seeds):
            name = "_".join(f"{d:g}" for d in dirs) + f"_n{n}_s{s}.npz"
            pts = synthesis.load_or_synthesize(out / "sets" / name, jax.random.key(1000 + s),
                                               n, dirs, show_progress=False,
                                               frequency_options=frequency_options).points
            sets[(n, s)] = pts
            bar.update(1)
    return sets


def variance_of_sets(f, sets, ns, seeds, realizations, key):
    rows = []
    for n in ns:
        est = np.concatenate([
            V.realization_estimates(f, sets[(n, s)], n, jax.random.fold_in(key, s),
                                    realizations // seeds, randomization="shift",
                                    center=f.integral)
            for s in range(seeds)
        ])
        rows.append(V.variance_from_estimates(est, f.integral, n=n, randomization="shift"))
    return rows


class Memo:
    """Remember the fixed sets a slow (NumPy) sampler made, across integrands."""

    def __init__(self, sampler):
        self.sampler, self.sets = sampler, {}

    def __call__(self, key, n):
        k = (np.asarray(jax.random.key_data(key)).tobytes(), int(n))
        if k not in self.sets:
            self.sets[k] = self.sampler(key, n)
        return self.sets[k]


def measure(f, sampler, mode, ns, key, cfg):
    patterns = cfg["patterns"] if mode == "shift" else 1
    rows = [V.estimate_variance(f, sampler, n, key, cfg["realizations"], f.integral,
                                randomization=mode, patterns=patterns) for n in ns]
    return summarize(rows, ns, cfg, mode, patterns)


def summarize(rows, ns, cfg, mode, patterns):
    """The curve record of one sampler: variances with intervals, slope fitted from fit_min_n."""
    fit_ns = [n for n in ns if n >= cfg["fit_min_n"]]
    sel = [i for i, n in enumerate(ns) if n >= cfg["fit_min_n"]]
    fit = V.fit_slope(fit_ns, [rows[i].variance for i in sel], [rows[i].std_error for i in sel])
    return {
        "randomization": mode, "patterns": patterns,
        "variance": [r.variance for r in rows], "std_error": [r.std_error for r in rows],
        "ci_low": [r.ci_low for r in rows], "ci_high": [r.ci_high for r in rows],
        "fit": fit.as_dict(),
    }


def curves_panel(ax, ns, curves: dict) -> None:
    """Every curve record of ``curves`` (``{label: summarize(...)}``, or any record with
    ``variance``, ``ci_low``, ``ci_high`` and ``fit``) on one log-log panel, the fitted slope and
    its 95 % interval in the legend."""
    for label, c in curves.items():
        fit = c["fit"]
        plot.convergence_panel(ax, ns, c["variance"], label=label, slope=fit["slope"],
                               slope_ci=(fit["ci_low"], fit["ci_high"]),
                               lower=c["ci_low"], upper=c["ci_high"])


def slopes(curves: dict) -> str:
    """``"label: slope  label: slope ..."`` of curve records, for a script's report."""
    return "  ".join(f"{s}: {c['fit']['slope']:+.2f}" for s, c in curves.items())

"""Beyond the papers: PSS warps tuned by the gradient of the estimator variance.

H Sec. 3.3 fits a bilinear / biquadratic PSS warp point-wise (H Eq. 9: control values = the
factor at the control points' images). With the fitted warp first in ``compose(w_theta, base)``
the one-sample variance is ``int g^2 / J_theta dy - I^2`` with ``g = f / p_base``: only the
warp's closed-form density depends on ``theta``, so the variance is differentiable and can be
minimised directly (``warps.fit_min_variance``: Gauss-Legendre 32^2 quadrature in PSS,
Levenberg-Marquardt on residuals whose sum of squares is the variance, or BFGS on the scalar).

Setting as ``h_shading_points`` (H Secs. 4.1-4.2): irradiance at a grid of shading points on the
plane z = 0, no visibility or MIS, warps fitted anew at every shading point, under

* a unit-radiance triangle light: integrand = the cosine at the shading point (the whole
  integrand behind uniform solid-angle sampling, Arvo 1995); bilinear and biquadratic warps;
* the twisted bilinear-patch light: the whole integrand (1/r^2 and both cosines) behind the
  bilinear approximate-area warp (H Sec. 4.2), a biquadratic warp fitted to it in front
  (point-wise, least squares, minimum variance), next to H's three-warp chain.

Per method and shading point:

* ``variance``: the one-sample variance through sampling on a ``res x res`` midpoint grid of PSS
  inputs (H Algorithm 1, Newton solves included; moments about the exact irradiance: Lambert's
  closed form, 96^2 Gauss-Legendre over the patch) -- an
  independent check of the objective, not the objective itself;
* ``mse``: MSE of one-sample estimates over ``realizations`` random keys against the exact value;
* ``seconds_per_fit``: best-of-5 process CPU time of fitting all shading points (jit, vmap),
  divided by their number.

Summary: mean variance and its improvement over uniform; geometric means over shading points of
the variance ratio to the point-wise and least-squares fits of the same family; the fraction of
shading points where the minimum-variance fit is at least as good (within 1e-4), and where the
least-squares fit is worse than the point-wise one.

Part 2 (``--part synthesis``): a synthesis design scalar. The "rate" recipe (``synthesize``:
linear spectrum loss on ``frequencies.design``, Adam) for directions 0/90/30 at ``n = 256``,
with the 30-degree wedge's length ``L`` made continuous (a sigmoid of width ``tau`` on
``|v . d|`` over a wedge twice as long), ``steps`` Adam steps unrolled from a jittered set (the
rate recipe's Adam: lr ``0.5 / sqrt(n)`` decaying to 1%, ``b2 = 0.9``, eps ``1e-30``; direct
sums, float64), and W Eq. 5's variance prediction for a half-plane edge at 30 degrees (closed-form
``P_f``; disk of radius 64 plus bands of half-width 2 along 0/90/30 out to 1024, no tail).
``d Var / d L`` at ``L = n^0.8`` by reverse-mode through the unrolled loop, against central
differences of two syntheses from the same start at ``L +- delta``, per initial set.

    python experiments/beyond_differentiable_tuning.py --scale small|paper [--out DIR] [--fresh]
        [--part all|warps|synthesis]
"""

from __future__ import annotations

import re
import time

import common
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from _h_shading import (
    NORMAL,
    TRIANGLE,
    lambert_irradiance,
    patch_factors,
    patch_irradiance,
    patch_three_warp,
    triangle_methods,
)
from common import reuse_or_compute

import anisosample as asp
import anisosample.warps as W
from anisosample.progress import progress

NAME = "beyond_differentiable_tuning"
SCALES = {
    "small": dict(grid=16, realizations=128, res=128),
    "paper": dict(grid=64, realizations=1024, res=256),
}
# Part 2: n points, unrolled Adam steps, initial sets, central-difference half-steps (band-length
# units), the edge's spectral direction, the sigmoid width of the soft band end, how far the
# band may grow, and the W Eq. 5 evaluation set (disk radius, band length).
SYNTHESIS = {
    "small": dict(
        n=256,
        steps=40,
        seeds=4,
        deltas=[1e-4, 1e-2, 0.1, 1.0, 8.0],
        theta=30.0,
        tau=2.0,
        max_factor=2.0,
        eval_radius=64,
        eval_length=1024,
    ),
}
SYNTHESIS["paper"] = {**SYNTHESIS["small"], "steps": 100, "seeds": 16}
_N = jnp.asarray(NORMAL, jnp.float32)
_VERTS = jnp.asarray(TRIANGLE, jnp.float32)


def _cos(w):
    return jnp.maximum(jnp.dot(w, _N), 0.0)


def _base(p):
    return W.SphericalTriangle(_VERTS, p)


def methods():
    """name -> (shading point -> composed warp): h_shading_points' triangle-light methods (uniform,
    point-wise, least squares) plus the variance-minimising fits."""
    shared, _ = triangle_methods()
    keep = ("uniform solid angle", "+ bilinear (point-wise)", "+ biquadratic (point-wise)",
            "+ bilinear (least squares)", "+ biquadratic (least squares)")

    def mv(family, **options):
        def make(p):
            init = W.fit_pointwise(family, _cos, [_base(p)])
            fit = W.fit_min_variance(family, _cos, [_base(p)], init=init, **options)
            return W.compose(fit, _base(p))

        return make

    return {
        **{name: shared[name] for name in keep},
        "+ bilinear (min variance)": mv(W.Bilinear),
        "+ biquadratic (min variance)": mv(W.Biquadratic),
        # Ablations: the same objective on least squares' 8x8 midpoint probes; BFGS instead of LM.
        "+ biquadratic (min variance, 8x8 midpoint)": mv(W.Biquadratic, grid=8, rule="midpoint"),
        "+ biquadratic (min variance, BFGS)": mv(W.Biquadratic, solver="bfgs"),
    }


def patch_methods():
    """name -> (shading point -> composed warp) for the bilinear-patch light (H Sec. 4.2): the
    whole integrand (1/r^2, the light's cosine and the receiver's) behind the bilinear
    approximate-area warp; "+ biquadratic" warps fitted to it in front of that."""

    def area(p):
        patch = patch_factors(p)[0]
        return [W.Bilinear(patch.corner_area_elements()), patch]

    def pw(p):
        f = patch_factors(p)[3]
        return W.compose(W.fit_pointwise(W.Biquadratic, f, area(p)), *area(p))

    def ls(p):
        f = patch_factors(p)[3]
        init = W.fit_pointwise(W.Biquadratic, f, area(p))
        return W.compose(W.fit_least_squares(W.Biquadratic, f, area(p), init=init), *area(p))

    def mv(p):
        f = patch_factors(p)[3]
        init = W.fit_pointwise(W.Biquadratic, f, area(p))
        return W.compose(W.fit_min_variance(W.Biquadratic, f, area(p), init=init), *area(p))

    return {
        "uniform parametric": lambda p: patch_factors(p)[0],
        "bilinear approx. area": lambda p: W.compose(*area(p)),
        "three-warp approx. cosine": patch_three_warp,
        "+ biquadratic (point-wise)": pw,
        "+ biquadratic (least squares)": ls,
        "+ biquadratic (min variance)": mv,
    }


def measure(make, integrand, points, exact, keys, res):
    """Per shading point: brute-force variance, one-sample MSE; seconds per fit.
    ``integrand(p)`` is the integrand at shading point ``p`` (one output point -> scalar)."""
    fit = jax.jit(jax.vmap(make))
    warps = fit(points)
    u = jnp.asarray(asp.metrics.midpoint_grid(res, indexing="ij").reshape(-1, 2))
    exact32 = jnp.asarray(exact, jnp.float32)

    def ratio(warp, p, uu):
        x, pdf = jax.vmap(warp.sample_and_pdf)(uu)
        fx = jax.vmap(integrand(p))(x)
        return jnp.where(pdf > 0, fx / jnp.where(pdf > 0, pdf, 1.0), 0.0)

    @jax.jit
    def grid_moments(warps, points, exact32):
        def one(warp, p, i):
            d = ratio(warp, p, u) - i  # about the exact mean: no cancellation
            return jnp.mean(d), jnp.mean(d * d)

        return jax.lax.map(lambda a: one(*a), (warps, points, exact32))

    bias_grid, var = (np.asarray(a, np.float64) for a in grid_moments(warps, points, exact32))

    @jax.jit
    def estimates(warps, points, keys):
        def one(warp, p, ks):
            return ratio(warp, p, jax.vmap(lambda k: jax.random.uniform(k, (2,)))(ks))

        return jax.vmap(one)(warps, points, keys)

    est = np.asarray(estimates(warps, points, keys), np.float64)
    err = est - exact[:, None]
    seconds = common.best_time(fit, points, repeats=5, clock=time.process_time) / points.shape[0]
    return dict(
        variance=(var - bias_grid**2).tolist(),
        mse=np.mean(err**2, axis=1).tolist(),
        bias_mean=float(np.mean(err)),
        bias_stderr=float(np.std(err) / np.sqrt(err.size)),
        seconds_per_fit=seconds,
    )


def _slug(name):
    return re.sub(r"[^a-z0-9]+", "_", name.lower()).strip("_")


def summarize(rows, exact):
    first = next(iter(rows.values()))
    v0 = np.mean(first["variance"])
    summary = {}
    for name, r in rows.items():
        v = np.asarray(r["variance"])
        s = dict(
            mean_variance=float(np.mean(v)),
            variance_improvement=float(v0 / np.mean(v)),
            mean_mse=float(np.mean(r["mse"])),
            mse_improvement=float(np.mean(first["mse"]) / np.mean(r["mse"])),
            relative_std=float(np.sqrt(np.mean(v)) / np.mean(exact)),
            seconds_per_fit=r["seconds_per_fit"],
        )
        family = next((k for k in ("bilinear", "biquadratic") if k in name), None)
        if family and "least squares" in name:
            ratio = v / np.asarray(rows[f"+ {family} (point-wise)"]["variance"])
            s["geomean_ratio_to_point_wise"] = float(np.exp(np.mean(np.log(ratio))))
            s["max_ratio_to_point_wise"] = float(np.max(ratio))
            s["fraction_worse_than_point_wise"] = float(np.mean(ratio > 1 + 1e-4))
        if family and "min variance" in name:
            for ref in ("point-wise", "least squares"):
                vr = np.asarray(rows[f"+ {family} ({ref})"]["variance"])
                ratio = v / vr
                key = _slug(ref)
                s[f"geomean_ratio_to_{key}"] = float(np.exp(np.mean(np.log(ratio))))
                s[f"max_ratio_to_{key}"] = float(np.max(ratio))
                s[f"fraction_at_least_as_good_as_{key}"] = float(np.mean(ratio <= 1 + 1e-4))
        summary[name] = s
    return summary


def run(settings, out, fresh):
    g = settings["grid"]
    xs = (np.arange(g) + 0.5) / g * 2 - 1
    X, Y = np.meshgrid(xs, xs, indexing="xy")
    pts64 = np.stack([X.ravel(), Y.ravel(), np.zeros(g * g)], -1)
    points = jnp.asarray(pts64, jnp.float32)
    keys = jax.random.split(jax.random.key(settings["seed"]), (g * g, settings["realizations"]))
    cases = (
        ("triangle", methods(), lambda p: _cos, lambert_irradiance, ""),
        ("patch", patch_methods(), lambda p: patch_factors(p)[3], patch_irradiance, "patch_"),
    )
    data = {}
    for light, table, integrand, reference, prefix in cases:
        exact = reference(pts64)
        rows = {}
        for name, make in progress(table.items(), desc=light, total=len(table)):
            rows[name] = reuse_or_compute(
                out / "parts" / f"{prefix}{_slug(name)}.json",
                dict(settings, light=light, method=name),
                fresh,
                lambda make=make, f=integrand, e=exact: measure(
                    make, f, points, e, keys, settings["res"]
                ),
                field="row",
            )
        data[light] = dict(
            summary=summarize(rows, exact),
            per_point=rows,
            exact=exact.tolist(),
            mean_irradiance=float(exact.mean()),
        )
    # The triangle's numbers at the top level (the report quotes them there).
    return dict(data.pop("triangle"), patch=data["patch"])


# --- part 2: a synthesis design scalar (W Sec. 4) -----------------------------------------------


def _relaxed_design(n, theta, max_factor):
    """The "rate" design for directions 0/90/``theta`` (aligned-only weights) with the wedge
    along ``theta`` grown to ``max_factor`` times its length, from the library's
    ``frequencies.design``: the 0/90 wedges and the disk, and the long ``theta`` wedge alone;
    returns the union, its edge weights, ``t = |v . d_theta|`` and whether each frequency is
    only in the long wedge."""
    from anisosample import frequencies as F

    fixed = F.design(n, (0.0, 90.0), "rate", offsets_deg=()).freqs
    long = F.design(n, (theta,), "rate", length=max_factor * n**0.8, disk_radius=0.0,
                    offsets_deg=()).freqs
    v = F.canonical_half(np.concatenate([fixed, long]))
    in_fixed = {tuple(r) for r in fixed.tolist()}
    only_long = np.array([tuple(r) not in in_fixed for r in v.tolist()])
    w = F.edge_weights(v, (0.0, 90.0, theta))
    d = np.array([np.cos(np.radians(theta)), np.sin(np.radians(theta))])
    return v.astype(np.float64), w, np.abs(v @ d), only_long


def synthesis_gradient(settings):
    """d(predicted variance)/d(band length) by unrolled Adam vs central finite differences:
    the library's objective (``optimizer.objective`` on the relaxed design), the rate recipe's
    Adam (``optimizer.Adam.from_recipe``) and the ``lax.scan`` runtime (``optimizer.minimize``)."""
    from anisosample import optimizer as O

    n, steps, theta, tau = settings["n"], settings["steps"], settings["theta"], settings["tau"]
    v, w, t, only_long = _relaxed_design(n, theta, settings["max_factor"])
    edge = asp.integrands.HalfPlane.through((0.5, 0.5), theta)
    # W Eq. 5's frequencies (one of each +-v): diagnostics.variance_decomposition's disk plus
    # bands of half-width 2 along 0, 90 and theta (no tail)
    v_eval = asp.diagnostics.decomposition_frequencies(
        (0.0, 90.0, theta), settings["eval_radius"], settings["eval_length"], 2.0
    ).astype(np.float64)
    pf = 2.0 * edge.power_spectrum(v_eval.astype(np.int64))  # both +-v
    l0 = float(n**0.8)
    out = {
        "n": n,
        "steps": steps,
        "theta": theta,
        "tau": tau,
        "length0": l0,
        "frequencies": int(v.shape[0]),
        "eval_frequencies": int(v_eval.shape[0]),
    }
    with jax.enable_x64(True):
        wj, tj = (jnp.asarray(a, jnp.float64) for a in (w, t))
        lj = jnp.asarray(only_long)
        vej, pfj = jnp.asarray(v_eval), jnp.asarray(pf)
        rate = asp.synthesis.make_recipe("rate", steps=steps)
        base = O.objective(n, (0.0, 90.0, theta), rate, freqs=v.astype(np.int64), weights=w)
        adam = O.Adam.from_recipe(rate, n)

        def synth(length, x0):
            mask = jnp.where(lj, jax.nn.sigmoid((length - tj) / tau), 1.0)
            return O.minimize(eqx.tree_at(lambda o: o.weights, base, wj * mask), adam, x0)

        def predicted(length, x0):
            ps = asp.spectrum.power_spectrum_autodiff(synth(length, x0), vej)
            return asp.metrics.predicted_variance(ps, pfj, xp=jnp)

        value_and_grad = jax.jit(jax.value_and_grad(predicted))
        value = jax.jit(predicted)
        rows = []
        for seed in progress(range(settings["seeds"]), desc="synthesis seeds"):
            x0 = jnp.asarray(
                asp.samplers.get("jittered")(jax.random.key(1000 + seed), n), jnp.float64
            )
            val, grad = value_and_grad(jnp.float64(l0), x0)
            fd = {}
            for delta in settings["deltas"]:
                hi, lo = value(jnp.float64(l0 + delta), x0), value(jnp.float64(l0 - delta), x0)
                fd[str(delta)] = float((hi - lo) / (2 * delta))
            rows.append(dict(seed=seed, variance=float(val), gradient=float(grad), fd=fd))
        # Our truncated W Eq. 5 sum against the library's (diagnostics, float64 NUFFT) on the
        # first seed's set: the same frequencies, so they must agree to rounding.
        x_end = jax.jit(synth)(
            jnp.float64(l0),
            jnp.asarray(asp.samplers.get("jittered")(jax.random.key(1000), n), jnp.float64),
        )
        lib = asp.diagnostics.variance_decomposition(
            np.asarray(x_end),
            edge,
            directions_deg=[0.0, 90.0, theta],
            disk_radius=settings["eval_radius"],
            line_length=settings["eval_length"],
            band=2.0,
        )
        out["library_total_seed0"] = float(lib["total"])
        # The no-warp reference: the initial jittered sets' predicted variance.
        x_init = jnp.asarray(asp.samplers.get("jittered")(jax.random.key(1000), n), jnp.float64)
        out["jittered_variance"] = float(asp.metrics.predicted_variance(
            asp.spectrum.power_spectrum_autodiff(x_init, vej), pfj, xp=jnp))
    var = np.array([r["variance"] for r in rows])
    grads = np.array([r["gradient"] for r in rows])
    out["seeds"] = rows
    out["mean_variance"] = float(var.mean())
    out["std_variance_over_seeds"] = float(var.std(ddof=1)) if len(var) > 1 else 0.0
    out["mean_gradient"] = float(grads.mean())
    out["std_gradient_over_seeds"] = float(grads.std(ddof=1)) if len(grads) > 1 else 0.0
    out["fraction_gradient_sign_as_mean"] = float(np.mean(np.sign(grads) == np.sign(grads.mean())))
    for delta in settings["deltas"]:
        fd = np.array([r["fd"][str(delta)] for r in rows])
        rel = np.abs(grads - fd) / np.maximum(np.abs(fd), 1e-300)
        out[f"median_rel_error_vs_fd_{delta}"] = float(np.median(rel))
        out[f"fraction_sign_agrees_fd_{delta}"] = float(np.mean(np.sign(grads) == np.sign(fd)))
    # The widest difference: the slope a tuner stepping by that much would see, its seed-to-seed
    # spread, and the local gradient measured in its units.
    wide = np.array([r["fd"][str(settings["deltas"][-1])] for r in rows])
    out["wide_fd_mean"] = float(wide.mean())
    out["wide_fd_std"] = float(wide.std(ddof=1)) if len(wide) > 1 else 0.0
    out["gradient_over_wide_fd"] = float(grads.mean() / wide.mean()) if wide.mean() else 0.0
    return out


def plot(data, settings, out):
    from anisosample import plot as aplot

    fig, axes = aplot.new_figure(1, 4, size=4.0)
    panels = [("triangle light", data["summary"])]
    if "patch" in data:
        panels.append(("bilinear-patch light (whole integrand)", data["patch"]["summary"]))
    for ax, (title, summ) in zip(axes[0][:2], panels, strict=False):
        names = list(summ)
        y = np.arange(len(names))
        ax.barh(y, [summ[n]["variance_improvement"] for n in names], color="tab:blue")
        ax.set_yticks(y, names, fontsize=6)
        ax.set_xscale("log")
        ax.invert_yaxis()
        ax.set_xlabel("variance improvement over the first method", fontsize=8)
        ax.set_title(title, fontsize=8)
        ax.grid(True, axis="x", alpha=0.3)
    g = settings["grid"]
    rows = data["per_point"]
    logs = {
        family: np.log10(
            np.asarray(rows[f"+ {family} (min variance)"]["variance"])
            / np.asarray(rows[f"+ {family} (least squares)"]["variance"])
        )
        for family in ("bilinear", "biquadratic")
    }
    lim = max(1.0, float(np.ceil(max(np.max(np.abs(v)) for v in logs.values()))))
    for ax, (family, lg) in zip(axes[0][2:], logs.items(), strict=True):
        im = ax.imshow(
            lg.reshape(g, g),
            origin="lower",
            extent=(-1, 1, -1, 1),
            cmap="RdBu_r",
            vmin=-lim,
            vmax=lim,
        )
        ax.set_title(
            f"triangle, {family}, per shading point:\nlog10 Var(min variance) / Var(least squares)",
            fontsize=8,
        )
        ax.set_xlabel("shading point x")
        ax.set_ylabel("shading point y")
        fig.colorbar(im, ax=ax, shrink=0.8)
    return aplot.save_figure(fig, out / f"{NAME}.png")


def arguments(ap):
    ap.add_argument(
        "--part",
        choices=["all", "warps", "synthesis"],
        default="all",
        help="warps (part 1), synthesis (part 2) or both (default)",
    )


def settings(scale, args):
    """Part 1's settings, part 2's under ``synthesis``: what the record is made with, whichever
    parts a run computes."""
    return dict(scale, scale=args.scale, seed=args.seed, timing="cpu",
                synthesis=dict(SYNTHESIS[args.scale], scale=args.scale))


def complete(data, args):
    """A record holds part 1 always (a run computes it when it is missing); part 2 where it was
    asked for once."""
    return args.part == "warps" or "synthesis" in data


def compute(chosen, args):
    """The parts ``--part`` names; the others are kept from a record made with these settings
    (part 1 is computed when there is none)."""
    settings = {k: v for k, v in chosen.items() if k != "synthesis"}
    syn = chosen["synthesis"]
    record = common.reuse(args.out / f"{NAME}.json", chosen, False) or {}
    if args.part in ("all", "warps") or "summary" not in record:
        data = run(settings, args.out, args.fresh)
    else:
        keep = ("summary", "per_point", "exact", "mean_irradiance", "patch")
        data = {k: record[k] for k in keep if k in record}
    if args.part in ("all", "synthesis"):
        data["synthesis"] = reuse_or_compute(
            args.out / "parts" / "synthesis.json",
            syn,
            args.fresh,
            lambda: synthesis_gradient(syn),
            field="result",
        )
    elif "synthesis" in record:
        data["synthesis"] = record["synthesis"]
    return data


def figure(data, args):
    plot(data, args.settings, args.out)


def report(data, args):
    for light, part in (("triangle", data), ("patch", data.get("patch"))):
        if part is None:
            continue
        print(f"\n{light} light, mean irradiance {part['mean_irradiance']:.4f}")
        print(
            f"  {'method':44s} {'mean var':>9s} {'var impr.':>9s} {'MSE impr.':>9s} {'s/fit':>8s}"
            f" {'/pw (gm)':>8s} {'/ls (gm)':>8s} {'>=ls':>5s}"
        )
        for n, s in part["summary"].items():
            extra = ""
            if "geomean_ratio_to_point_wise" in s:
                extra = f" {s['geomean_ratio_to_point_wise']:8.3f}"
            if "geomean_ratio_to_least_squares" in s:
                extra += (
                    f" {s['geomean_ratio_to_least_squares']:8.3f}"
                    f" {s['fraction_at_least_as_good_as_least_squares']:5.2f}"
                )
            print(
                f"  {n:44s} {s['mean_variance']:9.3e} {s['variance_improvement']:9.3g}"
                f" {s['mse_improvement']:9.3g} {s['seconds_per_fit']:8.1e}{extra}"
            )
    if "synthesis" in data:
        r = data["synthesis"]
        print(
            f"\nsynthesis (n={r['n']}, {r['steps']} Adam steps, edge at {r['theta']:g} deg):"
            f" predicted variance {r['mean_variance']:.3e} +- {r['std_variance_over_seeds']:.1e}"
            f" over seeds (jittered start {r['jittered_variance']:.3e})"
        )
        print(
            f"  d Var / d length (unrolled): {r['mean_gradient']:.3e} +- "
            f"{r['std_gradient_over_seeds']:.1e}"
        )
        print(
            f"  widest central difference: {r['wide_fd_mean']:.3e} +- {r['wide_fd_std']:.1e}"
            f" (local gradient / it: {r['gradient_over_wide_fd']:.3g})"
        )
        for d in args.settings["synthesis"]["deltas"]:
            print(
                f"  central difference +-{d:g}: median rel. error"
                f" {r[f'median_rel_error_vs_fd_{d}']:.3g},"
                f" sign agrees {r[f'fraction_sign_agrees_fd_{d}']:.2f}"
            )


def main(argv=None):
    return common.run(NAME, __doc__.splitlines()[0], SCALES, compute, figure=figure,
                      report=report, arguments=arguments, settings=settings, complete=complete,
                      argv=argv)


if __name__ == "__main__":
    main()

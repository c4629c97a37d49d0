"""Hart et al. Secs. 4.1-4.2 at the level of shading points (no visibility, no MIS).

Irradiance at a grid of shading points on the plane z = 0 (normal +z) under (a) a triangle light
and (b) a twisted bilinear-patch light, both of unit radiance and two-sided. Each method draws one
light sample per estimate, fitting its PSS warps anew at every shading point (as H does per
shading point); MSE is over all points and realizations against an independent reference:
Lambert's closed form for the triangle, 96x96 Gauss-Legendre quadrature over the patch's
parameters for the patch (both float64 NumPy).

Triangle (H Sec. 4.1): uniform solid angle (Arvo 1995); + bilinear and + biquadratic PSS warps
fitted point-wise to the cosine (H Eq. 9); the same warps fitted by optimistix least squares
(ours); Arvo 2001 exact cosine-weighted sampling; a 32x32 tabulated product reference (H 4.3).
Patch (H Sec. 4.2): uniform parametric; bilinear / biquadratic approximate equal-area; the
three-warp approximate cosine chain (area bilinear -> biquadratic 1/r^2 cos_l -> biquadratic
cos_r); bilinear area + least-squares biquadratic on the whole integrand (ours); tabulated.

Reported: MSE improvement over the first method (H: 1.75x bilinear, 1.91x biquadratic, 3.8x
Arvo 2001 for the triangle; 2.70x bilinear area, 6.62x three-warp for the patch -- in pbrt
scenes with MIS and visibility, so not the same quantity), time per estimate including the fit,
relative efficiency, and the time per fit.

    python experiments/h_shading_points.py --scale small|paper [--out DIR] [--fresh]
"""

from __future__ import annotations

import time

import common
import jax
import jax.numpy as jnp
import numpy as np
from _h_shading import (
    PATCH,
    lambert_irradiance,
    patch_factors,
    patch_irradiance,
    patch_three_warp,
    triangle_methods,
)

import anisosample as asp
import anisosample.warps as W
from anisosample.progress import progress

NAME = "h_shading_points"
SCALES = {"small": dict(grid=16, realizations=128), "paper": dict(grid=64, realizations=1024)}
HART = {
    "triangle": {
        "+ bilinear (point-wise)": 1.75,
        "+ biquadratic (point-wise)": 1.91,
        "Arvo 2001 (exact)": 3.8,
    },
    "patch": {
        "bilinear approx. area": 1 / 0.373,
        "biquadratic approx. area": 1 / 0.370,
        "three-warp approx. cosine": 1 / 0.151,
    },
}


def patch_methods():
    def uniform(p):
        return patch_factors(p)[0]

    def area_bilinear(p):
        return W.patch_area_warp(jnp.asarray(PATCH, jnp.float32))

    def area_biquadratic(p):
        patch = patch_factors(p)[0]
        q = W.fit_pointwise(W.Biquadratic, lambda x: patch.area_element(patch.inverse(x)), [patch])
        return W.compose(q, patch)

    def area_lsq(p):
        patch, _, _, f = patch_factors(p)
        w_area = W.Bilinear(patch.corner_area_elements())
        q = W.fit_least_squares(W.Biquadratic, f, [w_area, patch])
        return W.compose(q, w_area, patch)

    def tabulated(p):
        patch, _, _, f = patch_factors(p)
        return W.compose(W.fit_tabulated(f, [patch]), patch)

    return {
        "uniform parametric": uniform,
        "bilinear approx. area": area_bilinear,
        "biquadratic approx. area": area_biquadratic,
        "three-warp approx. cosine": patch_three_warp,
        "area + biquadratic (least squares)": area_lsq,
        "tabulated 32x32": tabulated,
    }, (lambda p: patch_factors(p)[3])


# --- measurement --------------------------------------------------------------------------------


def _best_time(fn, *args, repeats=5):
    """Best process CPU time of ``repeats`` runs after a warm-up: on a shared, loaded machine the
    CPU time of this process is a steadier measure of cost than wall time."""
    return common.best_time(fn, *args, repeats=repeats, clock=time.process_time)


def measure(make, integrand, points, keys, sampler):
    """Estimates (P, R), one light sample each, with the warps fitted once per shading point.

    Timing, per shading point: ``seconds_per_fit`` (build and fit the warp chain) and
    ``seconds_per_sample`` (sample, pdf by H Alg. 1, integrand); one estimate as in a renderer
    that fits at every shading point costs their sum.
    """

    def estimate(warp, p, key):
        x, pdf = warp.sample_and_pdf(sampler(key, 1)[0])
        return jnp.where(pdf > 0, integrand(p)(x) / jnp.where(pdf > 0, pdf, 1.0), 0.0)

    fit = jax.jit(jax.vmap(make))
    warps = fit(points)
    sample = jax.jit(jax.vmap(lambda w, p, ks: jax.vmap(lambda k: estimate(w, p, k))(ks)))
    est = np.asarray(sample(warps, points, keys), np.float64)
    t_fit = _best_time(fit, points) / points.shape[0]
    t_sample = _best_time(sample, warps, points, keys) / est.size
    return est, t_fit, t_sample


def run(settings, seed):
    g = settings["grid"]
    xs = (np.arange(g) + 0.5) / g * 2 - 1
    X, Y = np.meshgrid(xs, xs, indexing="xy")
    pts64 = np.stack([X.ravel(), Y.ravel(), np.zeros(g * g)], -1)
    points = jnp.asarray(pts64, jnp.float32)
    sampler = asp.samplers.get("random")
    key = jax.random.key(seed)
    keys = jax.random.split(key, (g * g, settings["realizations"]))
    out = {}
    for light, (methods, integrand), reference in (
        ("triangle", triangle_methods(), lambda_ref_tri),
        ("patch", patch_methods(), lambda_ref_patch),
    ):
        exact = reference(pts64)
        rows = {}
        for name, make in progress(methods.items(), desc=light, total=len(methods)):
            est, sec_fit, sec_sample = measure(make, integrand, points, keys, sampler)
            err = est - exact[:, None]
            rows[name] = dict(
                mse=float(np.mean(err**2)),
                bias=float(np.mean(err)),
                bias_stderr=float(np.std(err) / np.sqrt(err.size)),
                seconds_per_fit=sec_fit,
                seconds_per_sample=sec_sample,
                seconds_per_estimate=sec_fit + sec_sample,
            )
        first = next(iter(rows.values()))
        for r in rows.values():
            r["mse_improvement"] = first["mse"] / r["mse"] if r["mse"] > 0 else float("inf")
            r["time_ratio"] = r["seconds_per_estimate"] / first["seconds_per_estimate"]
            r["efficiency"] = r["mse_improvement"] / r["time_ratio"]
        out[light] = dict(methods=rows, mean_irradiance=float(exact.mean()), hart=HART[light])
    return out


def lambda_ref_tri(p):
    return lambert_irradiance(p)


def lambda_ref_patch(p):
    return patch_irradiance(p)


def plot(data, out):
    from anisosample import plot as aplot

    fig, axes = aplot.new_figure(1, 2, size=4.6)
    for ax, light in zip(axes[0], ("triangle", "patch"), strict=True):
        rows = data[light]["methods"]
        names = list(rows)
        vals = [min(rows[n]["mse_improvement"], 1e4) for n in names]
        y = np.arange(len(names))
        ax.barh(y, vals, color="tab:blue", label="ours (shading points)")
        hart = data[light]["hart"]
        labelled = False
        for i, n in enumerate(names):
            if rows[n]["mse_improvement"] > 1e4:
                ax.text(
                    2,
                    i,
                    "exact: MSE at float32 round-off, bar clipped",
                    va="center",
                    fontsize=6,
                    color="w",
                )
            if n in hart:
                ax.plot(
                    hart[n], i, "k*", ms=9, label=None if labelled else "Hart et al. (pbrt scene)"
                )
                labelled = True
        ax.set_yticks(y, names, fontsize=7)
        ax.set_xscale("log")
        ax.invert_yaxis()
        ax.set_xlabel("MSE improvement over the first method")
        ax.set_title(f"{light} light")
        ax.grid(True, axis="x", alpha=0.3)
    axes[0][1].legend(fontsize=7, loc="upper right")
    return aplot.save_figure(fig, out / f"{NAME}.png")


def report(data, args):
    for light in ("triangle", "patch"):
        print(f"\n{light} light (mean irradiance {data[light]['mean_irradiance']:.4f}):")
        print(
            f"  {'method':36s} {'MSE':>9s} {'bias/se':>7s} {'MSE impr.':>9s} {'time':>6s}"
            f" {'effic.':>7s} {'s/fit':>8s} {'s/sample':>8s}"
        )
        for n, r in data[light]["methods"].items():
            z = r["bias"] / r["bias_stderr"] if r["bias_stderr"] > 0 else 0.0
            print(
                f"  {n:36s} {r['mse']:9.2e} {z:7.2f} {r['mse_improvement']:9.3g}"
                f" {r['time_ratio']:6.2f} {r['efficiency']:7.3g} {r['seconds_per_fit']:8.1e}"
                f" {r['seconds_per_sample']:8.1e}"
            )


def main(argv=None):
    return common.run(
        NAME, __doc__.splitlines()[0], SCALES,
        compute=lambda settings, args: run(settings, args.seed),
        settings=lambda cfg, args: dict(cfg, scale=args.scale, seed=args.seed,
                                        sampler="random", timing="cpu"),
        figure=lambda data, args: plot(data, args.out), report=report, argv=argv)


if __name__ == "__main__":
    main()

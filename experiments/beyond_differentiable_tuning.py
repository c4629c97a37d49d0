"""Beyond the papers: PSS warps tuned by the gradient of the estimator variance.

H Sec. 3.3 fits a bilinear / biquadratic PSS warp point-wise (H Eq. 9: control values = the
factor at the control points' images). With the fitted warp first in ``compose(w_theta, base)``
the one-sample variance is ``int g^2 / J_theta dy - I^2`` with ``g = f / p_base``: only the
warp's closed-form density depends on ``theta``, so the variance is differentiable and can be
minimised directly (``warps.fit_min_variance``: Gauss-Legendre 32^2 quadrature in PSS,
Levenberg-Marquardt on residuals whose sum of squares is the variance, or BFGS on the scalar).

Setting as ``h_shading_points`` (H Sec. 4.1): irradiance at a grid of shading points on the plane
z = 0 under a unit-radiance triangle light, no visibility or MIS, integrand = the cosine at the
shading point (the whole integrand behind uniform solid-angle sampling, Arvo 1995). Warps are
fitted anew at every shading point. Per method and shading point:

* ``variance``: the one-sample variance through sampling on a ``res x res`` midpoint grid of PSS
  inputs (H Algorithm 1, Newton solves included; moments about Lambert's closed form) -- an
  independent check of the objective, not the objective itself;
* ``mse``: MSE of one-sample estimates over ``realizations`` random keys against Lambert;
* ``seconds_per_fit``: best-of-5 process CPU time of fitting all shading points (jit, vmap),
  divided by their number.

Summary: mean variance and its improvement over uniform; geometric means over shading points of
the variance ratio to the point-wise and least-squares fits of the same kind; the fraction of
shading points where the minimum-variance fit is at least as good (within 1e-4).

    python experiments/beyond_differentiable_tuning.py --scale small|paper [--out DIR] [--fresh]
"""

from __future__ import annotations

import re
import time

import jax
import jax.numpy as jnp
import numpy as np
from common import parser, reuse_or_compute, write_record
from h_shading_points import NORMAL, TRIANGLE, _best_time, lambert_irradiance

import anisosample.warps as W
from anisosample.progress import progress

NAME = "beyond_differentiable_tuning"
SCALES = {
    "small": dict(grid=16, realizations=128, res=128),
    "paper": dict(grid=64, realizations=1024, res=256),
}
_N = jnp.asarray(NORMAL, jnp.float32)
_VERTS = jnp.asarray(TRIANGLE, jnp.float32)


def _cos(w):
    return jnp.maximum(jnp.dot(w, _N), 0.0)


def _base(p):
    return W.SphericalTriangle(_VERTS, p)


def methods():
    """name -> (shading point -> composed warp)."""

    def pw(kind):
        return lambda p: W.compose(W.fit_pointwise(kind, _cos, [_base(p)]), _base(p))

    def ls(kind):
        def make(p):
            init = W.fit_pointwise(kind, _cos, [_base(p)])
            return W.compose(W.fit_least_squares(kind, _cos, [_base(p)], init=init), _base(p))

        return make

    def mv(kind, **options):
        def make(p):
            init = W.fit_pointwise(kind, _cos, [_base(p)])
            fit = W.fit_min_variance(kind, _cos, [_base(p)], init=init, **options)
            return W.compose(fit, _base(p))

        return make

    return {
        "uniform solid angle": _base,
        "+ bilinear (point-wise)": pw(W.Bilinear),
        "+ biquadratic (point-wise)": pw(W.Biquadratic),
        "+ bilinear (least squares)": ls(W.Bilinear),
        "+ biquadratic (least squares)": ls(W.Biquadratic),
        "+ bilinear (min variance)": mv(W.Bilinear),
        "+ biquadratic (min variance)": mv(W.Biquadratic),
        # Ablations: the same objective on least squares' 8x8 midpoint probes; BFGS instead of LM.
        "+ biquadratic (min variance, 8x8 midpoint)": mv(W.Biquadratic, grid=8, rule="midpoint"),
        "+ biquadratic (min variance, BFGS)": mv(W.Biquadratic, solver="bfgs"),
    }


def _midpoints(res):
    g = (np.arange(res, dtype=np.float32) + 0.5) / res
    return jnp.asarray(np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2))


def measure(make, points, exact, keys, res):
    """Per shading point: brute-force variance, one-sample MSE; seconds per fit."""
    fit = jax.jit(jax.vmap(make))
    warps = fit(points)
    u = _midpoints(res)
    exact32 = jnp.asarray(exact, jnp.float32)

    @jax.jit
    def grid_moments(warps, exact32):
        def one(warp, i):
            x, pdf = jax.vmap(warp.sample_and_pdf)(u)
            e = jax.vmap(_cos)(x) / pdf
            d = e - i  # about the exact mean: no cancellation
            return jnp.mean(d), jnp.mean(d * d)

        return jax.lax.map(lambda a: one(*a), (warps, exact32))

    bias_grid, var = (np.asarray(a, np.float64) for a in grid_moments(warps, exact32))

    @jax.jit
    def estimates(warps, keys):
        def one(warp, ks):
            uu = jax.vmap(lambda k: jax.random.uniform(k, (2,)))(ks)
            x, pdf = jax.vmap(warp.sample_and_pdf)(uu)
            return jax.vmap(_cos)(x) / pdf

        return jax.vmap(one)(warps, keys)

    est = np.asarray(estimates(warps, keys), np.float64)
    err = est - exact[:, None]
    seconds = _best_time(fit, points) / points.shape[0]
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
    first = rows["uniform solid angle"]
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
        kind = (
            "bilinear" if "bilinear" in name else "biquadratic" if "biquadratic" in name else None
        )
        if kind and "min variance" in name:
            for ref in ("point-wise", "least squares"):
                vr = np.asarray(rows[f"+ {kind} ({ref})"]["variance"])
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
    exact = lambert_irradiance(pts64)
    keys = jax.random.split(jax.random.key(settings["seed"]), (g * g, settings["realizations"]))
    rows = {}
    table = methods()
    for name, make in progress(table.items(), desc="methods", total=len(table)):
        rows[name] = reuse_or_compute(
            out / "parts" / f"{_slug(name)}.json",
            dict(settings, method=name),
            fresh,
            lambda make=make: measure(make, points, exact, keys, settings["res"]),
            field="row",
        )
    return dict(
        summary=summarize(rows, exact),
        per_point=rows,
        exact=exact.tolist(),
        mean_irradiance=float(exact.mean()),
    )


def plot(data, settings, out):
    from anisosample import plot as aplot

    fig, axes = aplot.new_figure(1, 3, size=4.0)
    ax = axes[0][0]
    summ = data["summary"]
    names = list(summ)
    y = np.arange(len(names))
    ax.barh(y, [summ[n]["variance_improvement"] for n in names], color="tab:blue")
    ax.set_yticks(y, names, fontsize=6)
    ax.set_xscale("log")
    ax.invert_yaxis()
    ax.set_xlabel("variance improvement over uniform solid angle")
    ax.grid(True, axis="x", alpha=0.3)
    g = settings["grid"]
    rows = data["per_point"]
    logs = {
        kind: np.log10(
            np.asarray(rows[f"+ {kind} (min variance)"]["variance"])
            / np.asarray(rows[f"+ {kind} (least squares)"]["variance"])
        )
        for kind in ("bilinear", "biquadratic")
    }
    lim = max(1.0, float(np.ceil(max(np.max(np.abs(v)) for v in logs.values()))))
    for ax, (kind, lg) in zip(axes[0][1:], logs.items(), strict=True):
        im = ax.imshow(
            lg.reshape(g, g),
            origin="lower",
            extent=(-1, 1, -1, 1),
            cmap="RdBu_r",
            vmin=-lim,
            vmax=lim,
        )
        ax.set_title(
            f"{kind}, per shading point:\nlog10 Var(min variance) / Var(least squares)", fontsize=8
        )
        ax.set_xlabel("shading point x")
        ax.set_ylabel("shading point y")
        fig.colorbar(im, ax=ax, shrink=0.8)
    return aplot.save_figure(fig, out / f"{NAME}.png")


def main(argv=None):
    ap = parser(NAME, __doc__.splitlines()[0])
    args = ap.parse_args(argv)
    started = time.time()
    settings = dict(SCALES[args.scale], scale=args.scale, seed=args.seed, timing="cpu")
    data = run(settings, args.out, args.fresh)
    write_record(args.out, NAME, data, settings, started)
    plot(data, settings, args.out)
    print(f"triangle light, mean irradiance {data['mean_irradiance']:.4f}")
    print(
        f"  {'method':44s} {'mean var':>9s} {'var impr.':>9s} {'MSE impr.':>9s} {'s/fit':>8s}"
        f" {'/pw (gm)':>8s} {'/ls (gm)':>8s} {'>=ls':>5s}"
    )
    for n, s in data["summary"].items():
        extra = ""
        if "geomean_ratio_to_least_squares" in s:
            extra = (
                f" {s['geomean_ratio_to_point_wise']:8.3f}"
                f" {s['geomean_ratio_to_least_squares']:8.3f}"
                f" {s['fraction_at_least_as_good_as_least_squares']:5.2f}"
            )
        print(
            f"  {n:44s} {s['mean_variance']:9.3e} {s['variance_improvement']:9.3g}"
            f" {s['mse_improvement']:9.3g} {s['seconds_per_fit']:8.1e}{extra}"
        )


if __name__ == "__main__":
    main()

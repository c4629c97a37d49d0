"""Beyond the papers: aligned anisotropic points *through* composed warps (W meets H).

Cornell-box pixels whose light integrand has a straight shadow edge across the quad light
(``anisosample/scenes/cornell.xml``, fixed primary hit at the pixel centre, spherical-rectangle
light sampling: Urena et al. 2013). Per pixel, four ways to draw its ``n`` light samples:

* **base + pmj02bn**: spherical-rectangle sampling alone with an unaligned low-discrepancy set;
* **base + aligned**: W's aligned sampler with the principal directions estimated from the
  base integrand ``f(x)`` on a 96^2 grid (``selection.aligned_sampler(integrand=...)``);
* **warp + pmj02bn**: H's composed warp -- a bilinear or biquadratic PSS warp fitted point-wise
  (H Eq. 9) to BSDF x cosine at the ray origin (the offset shading point the light rays leave
  from), in front of the spherical rectangle -- with pmj02bn points; the pixel integrand becomes
  ``g(u) = f(w(u)) / J_w(w(u))`` (H Eqs. 2-6; the renderer's own light warp,
  ``render.pixel_integrand(light_warp="product-bilinear")`` / ``"product-biquadratic"``);
* **warp + aligned (after)**: the aligned sampler with the directions estimated on ``g`` *in
  primary sample space after the warp* (the warp bends straight edges slightly, and moves them);
* **warp + aligned (before)**: the same warp but the directions of ``f`` (before the warp), to
  show what estimating after the warp buys.

Where the estimator finds no extra direction (smooth, curved or near-axis edges) the aligned
sampler falls back to pmj02bn (W Sec. 5.4), so that row then measures the same method as the
pmj02bn row with other random sets: the gap between them is the noise of the comparison. Two
extra directions take W's 4-direction set (built on demand into the user cache if missing).

Variance of the ``n``-sample estimator over randomizations (``patterns`` base sets, each moved by
toroidal shifts, W Sec. 5.4) with ``anisosample.variance.estimator_variance``; factors
relative to base + pmj02bn per pixel and their geometric mean over pixels. ``n = 256`` (the
shipped aligned table's size).

    python experiments/beyond_warped_aligned.py --scale small|paper [--out DIR] [--fresh]
"""

from __future__ import annotations

import common
import jax
import jax.numpy as jnp
import numpy as np

import anisosample as asp
from anisosample import selection
from anisosample.progress import progress

NAME = "beyond_warped_aligned"
SCALES = {
    "small": dict(size=64, candidates=12, pixels=6, n=256, realizations=1024, patterns=16,
                  probe=24),
    "paper": dict(size=128, candidates=24, pixels=24, n=256, realizations=2048, patterns=32,
                  probe=32),
}


def _grid(f, s):
    return np.asarray(f(jnp.asarray(asp.metrics.midpoint_grid(s))), np.float64)


def pick_pixels(scene, settings):
    """Pixels on a ``candidates^2`` lattice whose light integrand is partly shadowed (between
    15% and 85% of a ``probe^2`` grid is zero, the rest positive): a shadow edge crosses the
    light. At most ``pixels`` of them, spread over the lattice."""
    c, s = settings["candidates"], settings["size"]
    coords = [(int((i + 0.5) * s / c), int((j + 0.5) * s / c)) for j in range(c) for i in range(c)]
    found = []
    for px in progress(coords, desc="probing pixels"):
        f = asp.render.pixel_integrand(scene, px, technique="solid_angle")
        v = _grid(f, settings["probe"])
        zero = np.mean(v <= 0)
        if 0.15 < zero < 0.85 and np.max(v) > 0:
            found.append(px)
    step = max(1, len(found) // settings["pixels"])
    return found[::step][: settings["pixels"]]


def run(settings, seed):
    scene = asp.render.load_xml(
        asp.scenes.path("cornell"), width=settings["size"], height=settings["size"]
    )
    if scene.lights.n_prims != 1:
        raise ValueError("this experiment needs a scene with exactly one quad light")
    pixels = pick_pixels(scene, settings)
    n, R = settings["n"], settings["realizations"]
    pmj = asp.samplers.get("pmj02bn")
    key = jax.random.key(seed)
    results = []
    for pi, px in enumerate(progress(pixels, desc="pixels")):
        f = asp.render.pixel_integrand(scene, px, technique="solid_angle")
        al_f = selection.aligned_sampler(integrand=f, k=2, build_missing=True)
        row = dict(pixel=list(px), directions_before_deg=list(al_f.estimated_deg),
                   aligned_before=list(al_f.directions_deg), warps={})
        kp = jax.random.fold_in(key, pi)
        var = lambda g, smp, j, kp=kp: float(asp.variance.estimator_variance(  # noqa: E731
            g, smp, n, jax.random.fold_in(kp, j), R, randomization="shift",
            patterns=settings["patterns"]))
        row["base + pmj02bn"] = var(f, pmj, 0)
        row["base + aligned"] = var(f, al_f, 1)
        for wname in ("bilinear", "biquadratic"):
            # H Sec. 4.3's product warp through the renderer: fitted at the ray origin
            g = asp.render.pixel_integrand(scene, px, technique="solid_angle",
                                           light_warp=f"product-{wname}")
            al_g = selection.aligned_sampler(integrand=g, k=2, build_missing=True)
            row["warps"][wname] = {
                "directions_after_deg": list(al_g.estimated_deg),
                "aligned_after": list(al_g.directions_deg),
                "warp + pmj02bn": var(g, pmj, 2),
                "warp + aligned (after)": var(g, al_g, 3),
                "warp + aligned (before)": var(g, al_f, 4),
            }
        results.append(row)
    return scene, results


def summarize(results):
    """Geometric means over pixels of each method's variance over base + pmj02bn."""
    def gm(vals):
        vals = np.asarray(vals, np.float64)
        vals = vals[np.isfinite(vals) & (vals > 0)]
        return float(np.exp(np.mean(np.log(vals)))) if vals.size else float("nan")

    out = {}
    base = [r["base + pmj02bn"] for r in results]
    out["base + aligned"] = gm([r["base + aligned"] / b for r, b in zip(results, base,
                                                                        strict=True)])
    for w in ("bilinear", "biquadratic"):
        for m in ("warp + pmj02bn", "warp + aligned (after)", "warp + aligned (before)"):
            out[f"{w}: {m}"] = gm([r["warps"][w][m] / b for r, b in zip(results, base,
                                                                         strict=True)])
    return out


def plot(results, summary, out):
    from anisosample import plot as aplot

    fig, axes = aplot.new_figure(1, 2, size=4.8)
    ax = axes[0][0]
    methods = ["base + pmj02bn", "base + aligned", "warp + pmj02bn", "warp + aligned (after)",
               "warp + aligned (before)"]
    x = np.arange(len(results))
    width = 0.16
    for k, m in enumerate(methods):
        vals = [r[m] if m in r else r["warps"]["bilinear"][m] for r in results]
        ax.bar(x + (k - 2) * width, vals, width, label=m.replace("warp", "bilinear warp"))
    ax.set_yscale("log")
    ax.set_xticks(x, [f"{r['pixel'][0]},{r['pixel'][1]}" for r in results], fontsize=7)
    ax.set_xlabel("pixel (column,row)")
    ax.set_ylabel("variance of the 256-sample estimate")
    ax.legend(fontsize=6)
    ax.set_title("per pixel (bilinear product warp)", fontsize=9)
    ax = axes[0][1]
    names = list(summary)
    ax.barh(np.arange(len(names)), [summary[n] for n in names], color="tab:blue")
    ax.axvline(1.0, color="k", lw=0.8)
    ax.set_yticks(np.arange(len(names)), names, fontsize=7)
    ax.invert_yaxis()
    ax.set_xscale("log")
    vals = [v for v in summary.values() if np.isfinite(v) and v > 0]
    ax.set_xlim(min([0.1, *vals]) * 0.8, max([1.0, *vals]) * 1.25)
    ax.set_xlabel("variance / (base + pmj02bn), geometric mean over pixels")
    ax.set_title("aligned points through composed warps", fontsize=9)
    return aplot.save_figure(fig, out / f"{NAME}.png")


def compute(settings, args):
    args.out.mkdir(parents=True, exist_ok=True)
    _, results = run(settings, args.seed)
    return dict(pixels=results, summary=summarize(results))


def figure(data, args):
    results, summary = data["pixels"], data["summary"]
    plot(results, summary, args.out)
    lines = ["| method | variance / (base + pmj02bn), geometric mean |", "|---|---|"]
    lines += [f"| {k} | {v:.3f} |" for k, v in summary.items()]
    n = SCALES[args.scale]["n"]
    (args.out / f"{NAME}.md").write_text(
        f"# Aligned points through composed warps (scale {args.scale}, n = {n},"
        f" {len(results)} pixels)\n\n" + "\n".join(lines) + "\n"
    )


def report(data, args):
    results, summary = data["pixels"], data["summary"]
    cfg = SCALES[args.scale]
    print(f"{len(results)} penumbra pixels, n = {cfg['n']}, "
          f"{cfg['realizations']} realizations")
    for r in results:
        print(f"  pixel {r['pixel']}: directions before {np.round(r['directions_before_deg'], 1)}"
              f" after (bilinear) {np.round(r['warps']['bilinear']['directions_after_deg'], 1)};"
              f" base+pmj02bn {r['base + pmj02bn']:.3e}")
    print("variance relative to base + pmj02bn (geometric mean over pixels):")
    for k, v in summary.items():
        print(f"  {k:40s} {v:.3f}")


def main(argv=None):
    return common.run(
        NAME, __doc__.splitlines()[0], SCALES, compute, figure=figure, report=report,
        settings=lambda cfg, args: dict(cfg, scale=args.scale, seed=args.seed,
                                        technique="solid_angle", pixel="centre",
                                        scene="cornell.xml",
                                        warp="render light_warp product-* (fitted at the ray "
                                             "origin)"),
        argv=argv)


if __name__ == "__main__":
    main()

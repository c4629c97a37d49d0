"""Measurement plumbing of the Hart et al. image experiments (H Sec. 4: Fig. 2, Tables 4-5).

The images come from the library's renderer, nothing here renders: a technique is a pair
``(technique, light_warp)`` of :func:`anisosample.render.render` (the base light-sampling
technique and the warp chain fitted at every shading point, :mod:`anisosample.render.light_warps`),
and one realization is ``render(scene, key, spp=..., sampler="random", pixel_center=True,
technique=..., light_warp=..., mis=True)``: pixel-centre primary hits, one light sample through
the chain and one BSDF sample combined with the power heuristic (H Sec. 4: "one light sample and
one BSDF sample"), the BSDF sample's light pdf being the chain's H Algorithm 2 pdf at the same
ray origin. This module holds what is specific to the experiments:

MSE (H: mean over pixels of the squared error against a converged reference; MRSE divides each
pixel's squared error by ``ref^2 + 0.01``), time (one whole-image realization through
``render``, after compilation; min over 9 round-robin rounds) and Monte Carlo efficiency
``1 / (MSE x time)`` (H Sec. 4) are measured by :func:`measure` (the measures themselves, with
their standard errors, are the library's ``anisosample.metrics.image_error``, ``mse_ratio`` and
``efficiency``); tables and plots.
"""

from __future__ import annotations

import common
import jax
import numpy as np

import anisosample as asp
from anisosample import metrics
from anisosample.progress import progress

_LUM = np.asarray(asp.render.integrator.LUMINANCE, np.float64)


def make_render(scene, tech: tuple, spp: int, *, mis: bool = True):
    """``render(key) -> (h*w,)`` luminance of one realization of technique ``tech =
    (technique, light_warp)`` with ``spp`` samples per pixel (the library renderer)."""
    technique, light_warp = tech

    def call(key):
        res = asp.render.render(scene, key, spp=spp, sampler="random", pixel_center=True,
                                technique=technique, light_warp=light_warp, mis=mis,
                                progress=False)
        return res.mean.reshape(-1, 3).astype(np.float64) @ _LUM

    return call


def best_time(fn, *args, repeats: int = 9, calls: int = 4) -> float:
    """Seconds per call: the best of ``repeats`` timings of ``calls`` back-to-back calls (the
    minimum is the least disturbed by the other processes on a shared machine); no warm-up."""
    return common.best_time(fn, *args, repeats=repeats, calls=calls, warmup=False)


def reference(scene, tech: tuple, spp_total: int, key, *, chunk_spp: int = 64):
    """Converged image (mean of ``spp_total`` MIS samples per pixel with technique ``tech``) and
    its per-pixel variance of the mean (from the spread of the ``chunk_spp``-sample chunks)."""
    render = make_render(scene, tech, chunk_spp)
    n = max(spp_total // chunk_spp, 2)
    chunks = np.stack(
        [np.asarray(render(k), np.float64) for k in progress(jax.random.split(key, n),
                                                               desc="reference", total=n)]
    )
    return chunks.mean(0), chunks.var(0, ddof=1) / n


def measure(scene, techniques: dict, ref, spp: int, realizations: int, key, *,
            mis: bool = True, relative: bool = False, timing_rounds: int = 9):
    """Per technique (name -> ``(technique, light_warp)``): MSE (or MRSE) image and value, bias
    check, time per image, efficiency.

    Every technique sees the same keys (common random numbers do not matter here: the
    warps change what the numbers mean).
    """
    keys = jax.random.split(key, realizations)
    rows, images, renders, errors = {}, {}, {}, {}
    for name, tech in progress(techniques.items(), desc="techniques", total=len(techniques)):
        render = make_render(scene, tech, spp, mis=mis)
        est = np.stack([np.asarray(render(k), np.float64) for k in keys])  # (R, P)
        renders[name] = render
        errors[name] = metrics.image_error(est, ref, relative=relative)
        rows[name] = errors[name].as_dict()
        images[name] = errors[name].image
    # Timing round-robin over the techniques (min over rounds), so that load from other
    # processes on a shared machine hits every technique alike.
    best = dict.fromkeys(renders, np.inf)
    for render in renders.values():
        jax.block_until_ready(render(keys[0]))  # compiled already; warm
    for _ in range(timing_rounds):
        for name, render in renders.items():
            best[name] = min(best[name], best_time(render, keys[0], repeats=1))
    for name in rows:
        rows[name]["seconds_per_image"] = best[name]
    base_name = next(iter(rows))
    base = rows[base_name]
    for name, r in rows.items():
        # paired (same keys) standard error of the ratio, delta method
        r["mse_factor"], r["mse_factor_stderr"] = metrics.mse_ratio(errors[name],
                                                                    errors[base_name])
        r["time_factor"] = r["seconds_per_image"] / base["seconds_per_image"]
        r["efficiency"] = metrics.efficiency(r["mse"], r["seconds_per_image"])
        r["efficiency_factor"] = r["efficiency"] / base["efficiency"]
    return rows, images


def markdown_table(rows: dict, measure_name: str = "MSE") -> str:
    lines = [
        f"| Sampling method | {measure_name} (+- std. error) |"
        f" {measure_name} factor (+- paired std. error) | Time (s/image) | Time factor |"
        " Efficiency factor |",
        "|---|---|---|---|---|---|",
    ]
    for n, r in rows.items():
        lines.append(
            f"| {n} | {r['mse']:.4g} +- {r.get('mse_stderr', float('nan')):.2g} |"
            f" {r['mse_factor']:.3f} +- {r.get('mse_factor_stderr', float('nan')):.3f} |"
            f" {r['seconds_per_image']:.3g} |"
            f" {r['time_factor']:.2f} | {r['efficiency_factor']:.2f} |"
        )
    return "\n".join(lines) + "\n"


def print_rows(rows: dict, measure_name: str = "MSE") -> None:
    print(f"  {'method':44s} {measure_name:>9s} {'+-':>8s} {'factor':>7s} {'+-':>7s} {'time s':>8s}"
          f" {'t-fac':>6s} {'eff-fac':>7s} {'bias/se':>7s}")
    for n, r in rows.items():
        z = r["mean_error"] / r["mean_error_stderr"] if r["mean_error_stderr"] > 0 else 0.0
        print(f"  {n:44s} {r['mse']:9.3e} {r.get('mse_stderr', float('nan')):8.1e}"
              f" {r['mse_factor']:7.3f} {r.get('mse_factor_stderr', float('nan')):7.3f}"
              f" {r['seconds_per_image']:8.3g}"
              f" {r['time_factor']:6.2f} {r['efficiency_factor']:7.2f} {z:7.2f}")


def plot_images(out, name, scene, ref, images: dict, title: str, label: str = "MSE"):
    """Reference (tonemapped luminance) and per-technique error images on one log scale."""
    from matplotlib.colors import LogNorm

    from anisosample import plot as aplot

    h, w = scene.height, scene.width
    k = len(images) + 1
    fig, axes = aplot.new_figure(1, k, size=2.6)
    ax = axes[0][0]
    ax.imshow(np.clip(ref.reshape(h, w) / max(np.percentile(ref, 99), 1e-12), 0, 1) ** (1 / 2.2),
              cmap="gray")
    ax.set_title("reference", fontsize=8)
    vals = np.concatenate([v.ravel() for v in images.values()])
    pos = vals[vals > 0]
    lo = max(np.percentile(pos, 2), 1e-12) if pos.size else 1e-12
    hi = max(np.percentile(pos, 99.5), lo * 10) if pos.size else 1.0
    for ax, (n, img) in zip(axes[0][1:], images.items(), strict=True):
        im = ax.imshow(np.maximum(img.reshape(h, w), lo), cmap="inferno", norm=LogNorm(lo, hi))
        ax.set_title(f"{n}\n{label} {np.mean(img):.3g}", fontsize=7)
    for ax in axes[0]:
        ax.set_xticks([])
        ax.set_yticks([])
    fig.colorbar(im, ax=axes[0][-1], shrink=0.8)
    fig.suptitle(title, fontsize=9)
    return aplot.save_figure(fig, out / f"{name}.png")


def save_exrs(out, scene, ref, images: dict):
    h, w = scene.height, scene.width
    asp.io.write_exr(out / "reference.exr", ref.reshape(h, w), overwrite=True)
    for n, img in images.items():
        slug = "".join(c if c.isalnum() else "_" for c in n).strip("_")
        asp.io.write_exr(out / f"mse_{slug}.exr", img.reshape(h, w), overwrite=True)


def image_settings(cfg: dict, args) -> dict:
    """The image experiments' settings (one light and one BSDF sample, MIS, pixel centres,
    ``jax.random.uniform``), the ``settings`` of their ``common.run`` (a finished record made
    with the same settings is reused on rerun; ``--fresh`` ignores it)."""
    return dict(cfg, scale=args.scale, seed=args.seed, mis=True, sampler="random",
                pixel="centre", renderer="anisosample.render.render")

"""H Fig. 2 on the JAX ray caster: a triangle light over a diffuse floor, four light samplers.

Scene ``anisosample/scenes/triangle_light.xml`` (floor, a small box, one triangle emitter),
pixel-centre primary hits (a fixed shading point per pixel, the papers' 2D-integrand setting),
one light sample + one BSDF sample per pixel sample combined with the power heuristic (H Sec. 4:
"all images were rendered ... using multiple importance sampling with one light sample and one
BSDF sample"). Light-sampling techniques, the library renderer's light warps fitted at every
shading point's ray origin (``render(technique="solid_angle", light_warp=...)``, H Sec. 4.1):

* uniform solid angle (Arvo 1995, ``light_warp="none"``);
* + bilinear PSS warp fitted point-wise to the incident cosine (H Eq. 9, Sec. 3.3;
  ``"cosine-bilinear"``);
* + biquadratic PSS warp fitted the same way (``"cosine-biquadratic"``);
* Arvo 2001 cosine-weighted spherical triangle (``"arvo2001"``). Where a vertex lies below the
  shading point's horizon (box sides) that warp is not defined (no clipping); there the library
  weights by the cosine about the light plane's normal instead, which keeps it exact and
  unbiased but no longer cosine-proportional;
* projected-solid-angle sampling (Peters 2021, ``"projected-solid-angle"``): exact
  cosine-weighted sampling of the triangle clipped to the shading point's horizon, so also exact
  where Arvo 2001 is not (issue 24; with MIS both leave only the BSDF sample's variance).

Three scenes: the shipped one (the light 2.2 above the floor: the cosine hardly varies across
it, and a box's shadow carries much of the error, which no light warp can remove), a "near"
variant (the triangle enlarged 1.4x, 0.8 above the floor), written next to the results, and
``h_regime``, H's regime (``anisosample/scenes/h_triangle_plane.xml``: one large triangle light
0.5 above a diffuse plane, no occluder), measured as H did at 1 spp, with MIS on and, as
``methods_without_mis``, off (light sample only); and H's regime with the light raised to 1.0 and
2.0 above the plane (``h_regime_raised1``, ``h_regime_raised2``; MIS on).

Where H's-regime error lives (``phi_analysis``, figure ``h_fig2_phi.png``): per pixel the light's
projected solid angle ``Phi`` at the shading point, the closed-form MIS variance of Arvo 2001 (all
of it the BSDF sample's, see :func:`arvo_mis_analysis`) against the measured MSE, and per bin of
``Phi / pi`` every technique's MSE factor and the bin's share of the uniform-solid-angle error.

MSE standard errors: the image MSE of each realization (mean over the pixels of the squared
error against the reference) is one sample; the standard error is their spread over the
realizations over sqrt(realizations) (the per-pixel errors are heavy-tailed, the per-image
means much less so); MSE factors carry a paired (same keys) delta-method standard error.

Per technique: MSE image against a converged reference (mean of many MIS samples with the
Arvo 2001 technique, its own variance reported), mean MSE, time of the jitted per-pixel fit +
sampling + evaluation of one image (after compilation, best of 3) and efficiency
``1 / (MSE x time)`` relative to uniform solid angle, as H defines them.

H's claims (their pbrt scene): MSE improvement 1.75x bilinear, 1.91x biquadratic, 3.8x Arvo
2001; time 1.01x, 1.06x, 1.24x.

    python experiments/h_fig2.py --scale small|paper [--out DIR] [--fresh]
"""

from __future__ import annotations

import _h_render as H
import common
import jax
import jax.numpy as jnp
import numpy as np

import anisosample as asp

NAME = "h_fig2"
VARIANTS = ("shipped", "near", "h_regime", "h_regime_raised1", "h_regime_raised2")
# H's regime with its triangle light raised from 0.5 to 1.0 and 2.0 above the plane (same
# triangle, camera and floor): the share of pixels whose light fills much of the cosine-weighted
# hemisphere, where MIS's BSDF sample keeps its variance, shrinks.
RAISED = {"h_regime_raised1": 1.0, "h_regime_raised2": 2.0}
PHI_BINS = (0.0, 0.03, 0.1, 0.3, 0.6, 1.0001)  # bins of Phi / pi, the light's projected solid angle
SCALES = {
    "small": dict(width=48, height=48, spp=4, realizations=16, reference_spp=1024,
                  h_regime=dict(width=64, height=64, spp=1, realizations=64,
                                reference_spp=2048), variants=list(VARIANTS)),
    "paper": dict(width=256, height=256, spp=1, realizations=64, reference_spp=8192,
                  h_regime=dict(width=256, height=256, spp=1, realizations=256,
                                reference_spp=8192), variants=list(VARIANTS)),
}
H_REGIME = asp.scenes.path("h_triangle_plane")
HART = {
    "+ bilinear cosine warp": dict(mse_improvement=1.75, time=1.01),
    "+ biquadratic cosine warp": dict(mse_improvement=1.91, time=1.06),
    "Arvo 2001 (cosine-weighted)": dict(mse_improvement=3.8, time=1.24),
}


TECHNIQUES = {  # name -> (technique, light_warp) of asp.render.render
    "uniform solid angle": ("solid_angle", "none"),
    "+ bilinear cosine warp": ("solid_angle", "cosine-bilinear"),
    "+ biquadratic cosine warp": ("solid_angle", "cosine-biquadratic"),
    "Arvo 2001 (cosine-weighted)": ("solid_angle", "arvo2001"),
    "projected solid angle (Peters 2021)": ("solid_angle", "projected-solid-angle"),
}


SHIPPED = asp.scenes.path("triangle_light")
# "near": the shipped scene with its triangle enlarged 1.4x and lowered from y = 1.2 to y = -0.2
# (0.8 above the floor), so that the incident cosine varies strongly across the light as in H's
# close-up scene; same vertex order (normal -y).
NEAR_OBJ = """# triangle light of h_fig2's "near" variant (written by experiments/h_fig2.py)
v -0.84 -0.2 -0.42
v 0.84 -0.2 -0.7
v 0.0 -0.2 0.84
f 1 2 3
"""


def scene_path(variant, out):
    if variant == "shipped":
        return SHIPPED
    if variant == "h_regime":
        return H_REGIME
    if variant in RAISED:
        folder = out / f"scene_{variant}"
        folder.mkdir(parents=True, exist_ok=True)
        y = -1.0 + RAISED[variant]
        obj = H_REGIME.with_suffix(".obj").read_text().replace(" -0.5 ", f" {y:g} ")
        (folder / "h_triangle_plane.obj").write_text(obj)
        (folder / "h_triangle_plane.xml").write_text(H_REGIME.read_text())
        return folder / "h_triangle_plane.xml"
    folder = out / "scene_near"
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "triangle_light.obj").write_text(NEAR_OBJ)
    (folder / "triangle_light.xml").write_text(SHIPPED.read_text())
    return folder / "triangle_light.xml"


def arvo_mis_analysis(scene, images):
    """Where the MIS error of H's regime lives, per pixel, against the light's projected solid
    angle ``Phi`` (Lambert) at the pixel's shading point (unoccluded diffuse plane, one triangle).

    With Arvo 2001 the light sample's pdf is ``cos / Phi`` and the cosine-weighted BSDF sample's
    ``cos / pi``: their ratio ``r = pi / Phi`` is constant over the light, so the power-heuristic
    light term is constant (zero variance) and all of the estimator's variance is the BSDF
    sample's: it hits the light with probability ``1 / r`` and then carries ``rho L / (1 + r^2)``,
    a Bernoulli variance ``(rho L)^2 (r - 1) / (r^2 (1 + r^2)^2)`` per pixel and sample, which no
    light warp changes. Returns that closed form's mean next to the measured MSE, and per bin of
    ``Phi / pi`` each technique's MSE factor and the bin's share of the uniform-solid-angle MSE.
    """
    sp = asp.render.camera.primary_hits(scene)
    lights = scene.lights
    a = lights.p0[0]
    b, c = a + lights.e1[0], a + lights.e2[0]

    def phi_at(p, n):
        unit = lambda q: (q - p) / jnp.linalg.norm(q - p)  # noqa: E731
        return asp.warps.projected_solid_angle(unit(a), unit(b), unit(c), n)

    phi = np.asarray(jax.vmap(phi_at)(sp.p, sp.n), np.float64)
    valid = np.asarray(sp.valid)
    lum = np.asarray(asp.render.integrator.LUMINANCE, np.float64)
    rho = np.asarray(scene.materials.reflectance, np.float64)[np.asarray(sp.material)]
    rho_l = (rho * np.asarray(lights.radiance[0], np.float64)) @ lum
    r = np.pi / np.maximum(phi, 1e-12)
    var = np.where(valid, rho_l**2 * (r - 1) / (r**2 * (1 + r**2) ** 2), 0.0)
    base = images["uniform solid angle"]
    frac = phi / np.pi
    bins = []
    for lo, hi in zip(PHI_BINS[:-1], PHI_BINS[1:], strict=True):
        m = valid & (frac >= lo) & (frac < hi)
        if not m.any():
            continue
        bins.append(dict(
            phi_over_pi=[lo, min(hi, 1.0)], pixels=int(m.sum()),
            share_of_uniform_mse=float(base[m].sum() / base[valid].sum()),
            mse_factor={n: float(img[m].mean() / base[m].mean()) for n, img in images.items()},
            arvo_closed_form_factor=float(var[m].mean() / base[m].mean()),
        ))
    return dict(
        arvo_closed_form_mse=float(var.mean()),
        phi_over_pi_median=float(np.median(frac[valid])),
        phi_over_pi_mean=float(frac[valid].mean()),
        bins=bins,
    )


def plot_phi_bins(out, variants: dict):
    """MSE factor per bin of the light's projected solid angle, one panel per H-regime scene."""
    import matplotlib.ticker

    from anisosample import plot as aplot

    names = [v for v in variants if "phi_analysis" in variants[v]]
    fig, axes = aplot.new_figure(1, len(names), size=3.0)
    for ax, v in zip(axes[0], names, strict=True):
        bins = variants[v]["phi_analysis"]["bins"]
        x = [np.sqrt(max(b["phi_over_pi"][0], 0.01) * b["phi_over_pi"][1]) for b in bins]
        for n in TECHNIQUES:
            ax.plot(x, [b["mse_factor"][n] for b in bins], "o-", ms=3, label=n)
        ax.plot(x, [b["arvo_closed_form_factor"] for b in bins], "k:",
                label="Arvo 2001, closed form")
        ax.bar(x, [b["share_of_uniform_mse"] for b in bins], width=np.asarray(x) * 0.5,
               color="0.85", zorder=0, label="share of uniform MSE")
        ax.set_xscale("log")
        ax.set_xlim(0.01, 1.0)
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_xlabel("Phi / pi at the pixel")
        ax.set_title(v, fontsize=8)
    axes[0][0].set_ylabel("MSE factor (MIS, 1 spp)")
    axes[0][0].legend(fontsize=6)
    return aplot.save_figure(fig, out / f"{NAME}_phi.png")


def run(settings, seed, variant, out):
    if variant.startswith("h_regime"):  # H's setting: 1 spp, MIS on and off (its own sizes)
        settings = {**settings, **settings["h_regime"]}
    scene = asp.render.load_xml(
        scene_path(variant, out), width=settings["width"], height=settings["height"]
    )
    techs = TECHNIQUES
    k_ref, k_run = jax.random.split(jax.random.key(seed))
    ref, ref_var = H.reference(
        scene, techs["Arvo 2001 (cosine-weighted)"], settings["reference_spp"], k_ref
    )
    rows, images = H.measure(scene, techs, ref, settings["spp"], settings["realizations"], k_run)
    extra = {}
    if variant.startswith("h_regime"):
        extra["phi_analysis"] = arvo_mis_analysis(scene, images)
    if variant == "h_regime":
        extra["methods_without_mis"] = H.measure(
            scene, techs, ref, settings["spp"], settings["realizations"], k_run, mis=False)[0]
    return scene, ref, images, dict(
        scene=variant,
        size=[settings["width"], settings["height"]], spp=settings["spp"],
        realizations=settings["realizations"],
        methods=rows, **extra,
        reference=dict(
            technique="Arvo 2001 (cosine-weighted), MIS",
            spp=settings["reference_spp"],
            mean=float(ref.mean()),
            mean_variance_of_mean=float(ref_var.mean()),
        ),
        hart=HART,
    )


def compute(settings, args):
    args.out.mkdir(parents=True, exist_ok=True)
    variants = {}
    md = [f"# H Fig. 2 (ours), scale {args.scale}\n"]
    for variant in VARIANTS:
        sub = args.out / variant
        sub.mkdir(parents=True, exist_ok=True)
        scene, ref, images, data = run(settings, args.seed, variant, args.out)
        H.save_exrs(sub, scene, ref, images)
        H.plot_images(args.out, f"{NAME}_{variant}", scene, ref, images,
                      f"H Fig. 2 (ours), {variant} triangle light:"
                      f" {data['spp']} spp MIS, per-pixel MSE")
        data["mse_images_exr"] = sorted(f"{variant}/{p.name}" for p in sub.glob("*.exr"))
        variants[variant] = data
        md += [f"\n## {variant} scene\n", H.markdown_table(data["methods"])]
        if "methods_without_mis" in data:
            md += [f"\n## {variant} scene, light sample only (no MIS)\n",
                   H.markdown_table(data["methods_without_mis"])]
    plot_phi_bins(args.out, variants)
    (args.out / f"{NAME}.md").write_text("\n".join(md))
    return dict(variants=variants, hart=HART)


def report(record, args):
    for variant, data in record["variants"].items():
        w, h = data["size"]
        print(f"\n{variant} triangle light, {w}x{h}, {data['spp']} spp,"
              f" {data['realizations']} realizations; reference"
              f" {data['reference']['spp']} spp (mean variance of its mean"
              f" {data['reference']['mean_variance_of_mean']:.2e})")
        for label, key in (("MIS", "methods"), ("no MIS", "methods_without_mis")):
            if key not in data:
                continue
            print(f"  {label}:")
            H.print_rows(data[key])
            order = sorted(data[key], key=lambda n: data[key][n]["mse"])
            print("  MSE ordering (best first): " + " < ".join(order))
        if "phi_analysis" in data:
            pa = data["phi_analysis"]
            print("  Arvo 2001 + MIS: closed-form BSDF-sample variance"
                  f" {pa['arvo_closed_form_mse']:.4e}"
                  f" (+ reference {data['reference']['mean_variance_of_mean']:.1e}) vs measured"
                  f" {data['methods']['Arvo 2001 (cosine-weighted)']['mse']:.4e}")
            for b in pa["bins"]:
                lo, hi = b["phi_over_pi"]
                print(f"    Phi/pi {lo:.2f}-{hi:.2f}: {b['pixels']:5d} px,"
                      f" {b['share_of_uniform_mse']:.3f} of uniform MSE; factors "
                      + " ".join(f"{f:.3f}" for f in b["mse_factor"].values()))


def main(argv=None):
    return common.run(NAME, __doc__.splitlines()[0], SCALES, compute, report=report,
                      settings=H.image_settings, argv=argv)


if __name__ == "__main__":
    main()

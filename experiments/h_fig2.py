"""H Fig. 2 on the JAX ray caster: a triangle light over a diffuse floor, four light samplers.

Scene ``experiments/scenes/triangle_light.xml`` (floor, a small box, one triangle emitter),
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
  unbiased but no longer cosine-proportional.

Three scenes: the shipped one (the light 2.2 above the floor: the cosine hardly varies across
it, and a box's shadow carries much of the error, which no light warp can remove), a "near"
variant (the triangle enlarged 1.4x, 0.8 above the floor), written next to the results, and
``h_regime``, H's regime (``experiments/scenes/h_triangle_plane.xml``: one large triangle light
0.5 above a diffuse plane, no occluder), measured as H did at 1 spp, with MIS on and, as
``methods_without_mis``, off (light sample only).

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

import time

import _h_render as H
import jax
from common import ROOT, parser, write_record

import anisosample as asp

NAME = "h_fig2"
VARIANTS = ("shipped", "near", "h_regime")
SCALES = {
    "small": dict(width=48, height=48, spp=4, realizations=16, reference_spp=1024,
                  h_regime=dict(width=64, height=64, spp=1, realizations=64,
                                reference_spp=2048)),
    "paper": dict(width=256, height=256, spp=1, realizations=64, reference_spp=8192,
                  h_regime=dict(width=256, height=256, spp=1, realizations=256,
                                reference_spp=8192)),
}
H_REGIME = ROOT / "experiments/scenes/h_triangle_plane.xml"
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
}


SHIPPED = ROOT / "experiments/scenes/triangle_light.xml"
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
    folder = out / "scene_near"
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "triangle_light.obj").write_text(NEAR_OBJ)
    (folder / "triangle_light.xml").write_text(SHIPPED.read_text())
    return folder / "triangle_light.xml"


def run(settings, seed, variant, out):
    if variant == "h_regime":  # H's setting: 1 spp, MIS on and off (its own sizes)
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


def main(argv=None):
    ap = parser(NAME, __doc__.splitlines()[0])
    args = ap.parse_args(argv)
    started = time.time()
    settings, record = H.image_settings(NAME, args, SCALES)
    if record is not None:
        variants = record["variants"]
    else:
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
        (args.out / f"{NAME}.md").write_text("\n".join(md))
        write_record(args.out, NAME, dict(variants=variants, hart=HART), settings, started)
    for variant, data in variants.items():
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


if __name__ == "__main__":
    main()

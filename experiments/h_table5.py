"""H Table 5 on the JAX ray caster: BSDF product warps over a quad light, two base warps.

Scene ``anisosample/scenes/glossy.xml`` (rough gold floor, alpha 0.25; smoother copper panel,
alpha 0.08; a diffuse sphere; one tilted quad light). Pixel-centre primary hits, one light
sample + one BSDF sample with the power heuristic (H Sec. 4.3: "Multiple importance sampling was
used for all cases"). Light-sampling techniques, the library renderer's ``(technique,
light_warp)`` fitted at every shading point's ray origin (H Sec. 4.3):

* uniform solid angle (Urena et al. 2013, ``technique="solid_angle"``) -- the baseline;
* cosine bilinear warp in front of it (H Sec. 3.3, ``"cosine-bilinear"``);
* BSDF product bilinear / biquadratic warps (control values = BSDF x cosine at the control
  points, H Eq. 9; ``"product-bilinear"`` / ``"product-biquadratic"``) in front of the
  solid-angle warp *and* in front of uniform area sampling (``technique="area"``);
* BSDF product reference: the 32x32 tabulated distribution of BSDF x cosine
  (``"product-tabulated"``, H Sec. 4.3's exhaustive reference), with both base warps;
* (ours, extra row) uniform area sampling alone;
* (ours, extra row, issue 24) projected-solid-angle sampling of the quad (Peters 2021, exact
  cosine-weighted, clipped to the horizon; ``"projected-solid-angle"``), which ignores the BSDF:
  the cosine half of the product, exactly. Arvo 2001 samples triangles only;
* (ours, extra row, issue 24 item 3) LTC sampling (Heitz et al. 2016, the GGX table fitted by
  ``anisosample.render.ltc``) restricted to the quad, sampled exactly (Peters 2021's pairing;
  ``"ltc"``): the product of the lobe's LTC fit and the light's extent.

MRSE (H Sec. 4.3: squared error divided by ``ref^2 + 0.01`` per pixel, mean over pixels) against
a converged reference (tabulated solid-angle technique, many spp), time of the jitted per-pixel
fit + sampling + evaluation of one image, efficiency ``1/(MRSE x time)``, all relative to
uniform solid angle. H's three pbrt scenes: MRSE factors 0.78-0.84 (cosine bilinear), 0.68-0.82
(product bilinear, solid angle), 0.60-0.77 (product bilinear, area), reference 0.63-0.80 (solid
angle) and 0.57-0.73 (area).

    python experiments/h_table5.py --scale small|paper [--out DIR] [--fresh]
"""

from __future__ import annotations

import _h_render as H
import common
import jax
import numpy as np

import anisosample as asp

NAME = "h_table5"
SCALES = {
    "small": dict(width=40, height=40, spp=4, realizations=16, reference_spp=512),
    "paper": dict(width=256, height=256, spp=1, realizations=64, reference_spp=8192),
}
HART = {  # H Table 5, three scenes (rows: MRSE, time, efficiency per base warp)
    "cosine bilinear warp": {"solid angle": [[0.780, 1.02, 1.26], [0.797, 1.03, 1.22],
                                             [0.838, 1.01, 1.18]]},
    "BSDF product bilinear warp": {
        "solid angle": [[0.796, 1.04, 1.21], [0.676, 1.06, 1.40], [0.816, 1.03, 1.19]],
        "area": [[0.600, 1.00, 1.67], [0.598, 1.03, 1.62], [0.770, 1.01, 1.29]],
    },
    "BSDF product biquadratic warp": {
        "solid angle": [[0.804, 1.11, 1.12], [0.704, 1.09, 1.30], [0.838, 1.10, 1.08]],
        "area": [[0.597, 1.07, 1.57], [0.591, 1.06, 1.60], [0.763, 1.06, 1.24]],
    },
    "BSDF product reference": {"solid angle": [[0.760], [0.628], [0.802]],
                               "area": [[0.565], [0.600], [0.732]]},
}


TECHNIQUES = {  # name -> (technique, light_warp) of asp.render.render
    "uniform solid angle": ("solid_angle", "none"),
    "cosine bilinear warp (solid angle)": ("solid_angle", "cosine-bilinear"),
    "BSDF product bilinear warp (solid angle)": ("solid_angle", "product-bilinear"),
    "BSDF product biquadratic warp (solid angle)": ("solid_angle", "product-biquadratic"),
    "BSDF product reference 32x32 (solid angle)": ("solid_angle", "product-tabulated"),
    "uniform area": ("area", "none"),
    "BSDF product bilinear warp (area)": ("area", "product-bilinear"),
    "BSDF product biquadratic warp (area)": ("area", "product-biquadratic"),
    "BSDF product reference 32x32 (area)": ("area", "product-tabulated"),
    "projected solid angle (Peters 2021)": ("solid_angle", "projected-solid-angle"),
    "LTC over the polygon (Heitz 2016 + Peters 2021)": ("solid_angle", "ltc"),
}


def run(settings, seed):
    scene = asp.render.load_xml(
        asp.scenes.path("glossy"), width=settings["width"], height=settings["height"]
    )
    techs = TECHNIQUES
    k_ref, k_run = jax.random.split(jax.random.key(seed))
    ref_name = "BSDF product reference 32x32 (solid angle)"
    ref, ref_var = H.reference(scene, techs[ref_name], settings["reference_spp"], k_ref)
    rows, images = H.measure(
        scene, techs, ref, settings["spp"], settings["realizations"], k_run, relative=True
    )
    data = dict(
        methods=rows,
        measure="MRSE: mean over pixels of (estimate - ref)^2 / (ref^2 + 0.01)",
        reference=dict(
            technique=ref_name + ", MIS",
            spp=settings["reference_spp"],
            mean=float(ref.mean()),
            mean_variance_of_mean=float(ref_var.mean()),
            mean_relative_variance_of_mean=float(np.mean(ref_var / (ref**2 + 0.01))),
        ),
        hart=HART,
    )
    return scene, ref, images, data


def compute(settings, args):
    args.out.mkdir(parents=True, exist_ok=True)
    scene, ref, images, data = run(settings, args.seed)
    H.save_exrs(args.out, scene, ref, images)
    H.plot_images(args.out, NAME, scene, ref, images,
                  f"H Table 5 (ours): glossy scene, quad light, {settings['spp']} spp MIS,"
                  " per-pixel relative squared error", label="MRSE")
    md = f"# H Table 5 (ours), scale {args.scale}\n\n"
    md += H.markdown_table(data["methods"], "MRSE")
    md += ("\nFactors are relative to uniform solid angle; H Table 5 gives, for three pbrt"
           " scenes, MRSE factors 0.78-0.84 (cosine bilinear), 0.68-0.82 / 0.60-0.77"
           " (product bilinear, solid angle / area), 0.63-0.80 / 0.57-0.73 (reference).\n")
    (args.out / f"{NAME}.md").write_text(md)
    data["mse_images_exr"] = sorted(p.name for p in args.out.glob("*.exr"))
    return data


def report(data, args):
    settings = H.image_settings(SCALES[args.scale], args)
    print(f"glossy scene, {settings['width']}x{settings['height']}, {settings['spp']} spp,"
          f" {settings['realizations']} realizations; reference {settings['reference_spp']} spp"
          f" (mean relative variance of its mean"
          f" {data['reference']['mean_relative_variance_of_mean']:.2e})")
    H.print_rows(data["methods"], "MRSE")


def main(argv=None):
    return common.run(NAME, __doc__.splitlines()[0], SCALES, compute, report=report,
                      settings=H.image_settings, argv=argv)


if __name__ == "__main__":
    main()

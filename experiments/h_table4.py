"""H Table 4 on the JAX ray caster: a bilinear-patch light, four patch samplers.

Scene: ``anisosample/scenes/patch_light.xml``, the floor and box of ``triangle_light.xml`` under
a twisted, non-planar bilinear-patch light with one short edge (H Fig. 3's situation), emitting
downwards. The ray caster traces the exact patch (``<shape type="bilinear">``,
:mod:`anisosample.render.patch`, Reshetov 2019), so the surface that rays hit (visibility,
BSDF-sampled emission) is the surface that light sampling draws points on
(``warps.BilinearPatch``, inverted by tracing from the ray origin); where the patch folds in
front of a sampled point, the shadow ray meets the patch and that point is hidden.

Pixel-centre primary hits, one light + one BSDF sample per pixel sample with the power
heuristic (H: "All images were rendered using MIS"). Techniques, the library renderer's
``(technique, light_warp)`` fitted at every shading point's ray origin:

* uniform parametric (area pdf ``1/|p_u x p_v|``, H Eq. 11; ``technique="parametric"``);
* bilinear approximate equal-area warp (H Sec. 4.2, ``technique="area"``);
* biquadratic approximate equal-area warp (point-wise fit of the area element, H Eq. 9; this
  script's :func:`biquadratic_area`, passed as ``light_warp``);
* three-warp approximate cosine: bilinear area -> biquadratic ``cos_l / r^2`` -> biquadratic
  ``cos_r`` (H Sec. 4.2, the list after Eq. 11; ``light_warp="patch-three-warp"``).

MSE image against a converged reference (three-warp technique, many spp), time of the jitted
per-pixel fit + sampling + evaluation of one image, efficiency ``1/(MSE x time)``; factors
relative to uniform parametric as in H Table 4 (MSE factor 0.373, 0.370, 0.151; time 1.01,
1.02, 1.23; efficiency 2.66, 2.64, 5.38).

    python experiments/h_table4.py --scale small|paper [--out DIR] [--fresh]
"""

from __future__ import annotations

import _h_render as H
import common
import jax
import jax.numpy as jnp
import numpy as np

import anisosample as asp
import anisosample.warps as W

NAME = "h_table4"
SCALES = {
    "small": dict(width=40, height=40, spp=4, realizations=16, reference_spp=512),
    "paper": dict(width=256, height=256, spp=1, realizations=64, reference_spp=8192),
}
# corners[i, j] = p_ij at (u, v) = (i, j): twisted, non-planar, one short edge (p00-p01).
PATCH = np.array(
    [[[-0.9, 0.2, -0.6], [-0.8, 0.35, -0.45]], [[0.9, 0.05, -0.8], [0.6, 0.55, 0.9]]]
)
HART = {
    "uniform parametric": dict(mse_factor=1.0, time=1.0, efficiency_factor=1.0),
    "bilinear approx. area": dict(mse_factor=0.373, time=1.01, efficiency_factor=2.66),
    "biquadratic approx. area": dict(mse_factor=0.370, time=1.02, efficiency_factor=2.64),
    "three-warp approx. cosine": dict(mse_factor=0.151, time=1.23, efficiency_factor=5.38),
}


SCENE = asp.scenes.path("patch_light")


def load_scene(settings):
    """The shipped patch-light scene at the run's resolution; its patch must be ``PATCH``."""
    scene = asp.render.load_xml(SCENE, width=settings["width"], height=settings["height"])
    corners = np.asarray(scene.patches.corners, np.float64)
    if corners.shape != (1, 2, 2, 3) or not np.allclose(corners[0], PATCH, atol=1e-6):
        raise ValueError(f"{SCENE} must hold exactly the patch h_table4.PATCH")
    return scene


def biquadratic_area(base, rec):
    """H Sec. 4.2's biquadratic approximate equal-area warp: a biquadratic fitted point-wise
    (H Eq. 9) to the patch's area element in front of uniform parametric sampling (``base``).
    The area element is a function of the patch parameters, which are the PSS control points
    themselves here, so H Eq. 9 needs no inversion: ``values[i, j] = |p_u x p_v|(i/2, j/2)``."""
    grid = jnp.asarray(W.Biquadratic.control_points())
    return W.compose(W.Biquadratic(jax.vmap(jax.vmap(base.area_element))(grid)), base)


TECHNIQUES = {  # name -> (technique, light_warp) of asp.render.render
    "uniform parametric": ("parametric", "none"),
    "bilinear approx. area": ("area", "none"),
    "biquadratic approx. area": ("parametric", biquadratic_area),
    "three-warp approx. cosine": ("area", "patch-three-warp"),
}


def run(settings, seed, out):
    scene = load_scene(settings)
    techs = TECHNIQUES
    k_ref, k_run = jax.random.split(jax.random.key(seed))
    ref, ref_var = H.reference(
        scene, techs["three-warp approx. cosine"], settings["reference_spp"], k_ref
    )
    rows, images = H.measure(scene, techs, ref, settings["spp"], settings["realizations"], k_run)
    data = dict(
        methods=rows,
        reference=dict(
            technique="three-warp approx. cosine, MIS",
            spp=settings["reference_spp"],
            mean=float(ref.mean()),
            mean_variance_of_mean=float(ref_var.mean()),
        ),
        patch_corners=PATCH.tolist(),
        scene="anisosample/scenes/patch_light.xml (exact bilinear patch)",
        hart=HART,
    )
    return scene, ref, images, data


def compute(settings, args):
    args.out.mkdir(parents=True, exist_ok=True)
    scene, ref, images, data = run(settings, args.seed, args.out)
    H.save_exrs(args.out, scene, ref, images)
    H.plot_images(args.out, NAME, scene, ref, images,
                  f"H Table 4 (ours): bilinear-patch light, {settings['spp']} spp MIS,"
                  " per-pixel MSE")
    md = f"# H Table 4 (ours), scale {args.scale}\n\n" + H.markdown_table(data["methods"])
    md += "\nH Table 4 (pbrt scene): MSE factor 1 / 0.373 / 0.370 / 0.151; time 1 / 1.01 /"
    md += " 1.02 / 1.23; efficiency factor 1 / 2.66 / 2.64 / 5.38.\n"
    (args.out / f"{NAME}.md").write_text(md)
    data["mse_images_exr"] = sorted(p.name for p in args.out.glob("*.exr"))
    return data


def report(data, args):
    settings = H.image_settings(SCALES[args.scale], args)
    print(f"bilinear-patch light, {settings['width']}x{settings['height']}, {settings['spp']} spp,"
          f" {settings['realizations']} realizations; reference {settings['reference_spp']} spp"
          f" (mean variance of its mean {data['reference']['mean_variance_of_mean']:.2e})")
    H.print_rows(data["methods"])
    order = sorted(data["methods"], key=lambda n: data["methods"][n]["mse"])
    print("MSE ordering (best first): " + " < ".join(order))


def main(argv=None):
    return common.run(NAME, __doc__.splitlines()[0], SCALES, compute, report=report,
                      settings=H.image_settings, argv=argv)


if __name__ == "__main__":
    main()

"""Benchmark: the cost of each light warp in the renderer, relative to its base technique.

``render(scene, key, spp=1, technique=..., light_warp=..., mis=True, pixel_center=True)`` on
the shipped triangle-light scene (H Fig. 2, every triangle warp) and the shipped patch-light
scene (H Table 4, ``patch-three-warp``), after compilation. Times are the best of
``--repeats`` rounds, the techniques taking turns within each round (so that load from other
processes hits all of them alike); the table prints ns per sample (one light sample and one
BSDF sample, the chain fitted anew for every sample) and the ratio to the base technique of the
same scene measured in the same run. Issue 14's targets: cosine-bilinear <= 1.15x,
cosine-biquadratic <= 1.6x, arvo2001 <= 2x (H reports 1.01x, 1.06x, 1.24x in pbrt); issue 24's:
projected-solid-angle (Peters 2021) <= 1.5x the solid-angle base, on the triangle light and on
the glossy scene's quad light (H Table 5's scene; Arvo 2001 is for triangles only).

    python experiments/bench_light_warps.py [--size 256] [--repeats 7]
"""

from __future__ import annotations

import os
import time

import common
import jax

from anisosample import render, scenes

SCENES = scenes.FOLDER
CASES = {  # scene -> (base technique, [light warps]); the first row of each is the base
    "triangle_light": ("solid_angle", ["none", "cosine-bilinear", "cosine-biquadratic",
                                       "arvo2001", "projected-solid-angle", "product-bilinear",
                                       "product-biquadratic", "product-tabulated"]),
    "glossy": ("solid_angle", ["none", "cosine-bilinear", "cosine-biquadratic",
                               "projected-solid-angle", "product-bilinear",
                               "product-biquadratic"]),
    "patch_light": ("area", ["none", "cosine-bilinear", "cosine-biquadratic",
                             "patch-three-warp"]),
}


def main(argv=None):
    p = common.parser("bench_light_warps", __doc__.splitlines()[0], scale=False, out=False,
        seed=None, fresh=False)
    p.add_argument("--size", type=int, default=256, help="image width and height (1 spp)")
    p.add_argument("--repeats", type=int, default=7)
    p.add_argument("--scenes", default=",".join(CASES), help="comma-separated scene names")
    p.add_argument("--scale", default="small", choices=["small", "paper"],
                   help="accepted for uniformity; the size is fixed by --size")
    args = p.parse_args(argv)
    n = args.size * args.size
    print(f"{args.size}x{args.size} pixels, 1 spp (one light + one BSDF sample, MIS) = {n}"
          f" samples per image; {os.cpu_count()} CPUs, jax {jax.__version__} on"
          f" {jax.default_backend()}; load average {os.getloadavg()[0]:.2f} at the start")
    key = jax.random.key(0)
    for name in args.scenes.split(","):
        technique, warps = CASES[name]
        scene = render.load_xml(SCENES / f"{name}.xml", width=args.size, height=args.size)

        def run(lw, scene=scene, technique=technique):
            return render.render(scene, key, spp=1, technique=technique, light_warp=lw, mis=True,
                                 pixel_center=True, sampler="random", progress=False)

        compile_s = {}
        for lw in warps:
            t = time.perf_counter()
            run(lw)
            compile_s[lw] = time.perf_counter() - t
        best = dict.fromkeys(warps, float("inf"))
        for _ in range(args.repeats):
            for lw in warps:
                t = time.perf_counter()
                run(lw)
                best[lw] = min(best[lw], time.perf_counter() - t)
        base = best[warps[0]]
        print(f"\n{name}.xml, base technique {technique!r}")
        print(f"  {'light_warp':22s} {'ns/sample':>10s} {'ratio':>7s} {'first call s':>13s}")
        for lw in warps:
            print(f"  {lw:22s} {1e9 * best[lw] / n:10.1f} {best[lw] / base:7.2f}"
                  f" {compile_s[lw]:13.1f}")
    print(f"\nload average {os.getloadavg()[0]:.2f} at the end")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

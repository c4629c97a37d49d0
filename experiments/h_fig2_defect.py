"""Issue 14's defect, measured: rare samples of H Fig. 2's shipped scene and the 1-spp variance
they carry, through the library renderer.

Shipped scene ``anisosample/scenes/triangle_light.xml``, 48x48 pixel centres, ``N`` independent
1-spp MIS samples per pixel (one light sample, one BSDF sample, power heuristic), for uniform
solid angle, the bilinear and biquadratic cosine warps and Arvo 2001. Per sample: its luminance;
(a) the light sample's direction misses the triangle (ray-triangle test from the ray origin,
occluders ignored); (b) the BSDF sample hits the emitter while the technique's light pdf there is
0 (so MIS gives it the full weight). "carry" is the share of ``sum (x - pixel mean)^2`` over all
samples that comes from the flagged ones. Writes ``results/h_fig2_defect/h_fig2_defect.json``
(per technique the numbers printed; reused on rerun with the same N, ``--fresh`` remeasures).

The same measurement through the experiment pipeline before issue 14 (``--before``, which
loaded an archived ``_h_render.py`` / ``h_fig2.py`` from 74f13ac) is this script at 84b9c3a;
its numbers at N = 4096 are in the message of commit 8fbdf30.

    python experiments/h_fig2_defect.py [N] [--scale small|paper] [--out DIR] [--fresh]
"""

import common

NAME = "h_fig2_defect"
SCALES = {"small": dict(n=256), "paper": dict(n=4096)}


def hits_triangle(verts, o, w):
    """Whether the ray ``o + t w`` (t > 0) meets the triangle ``verts`` (Moeller-Trumbore)."""
    import jax.numpy as jnp

    e1, e2 = verts[1] - verts[0], verts[2] - verts[0]
    pv = jnp.cross(w, e2)
    det = jnp.dot(e1, pv)
    tv = o - verts[0]
    a = jnp.dot(tv, pv) / det
    qv = jnp.cross(tv, e1)
    b = jnp.dot(w, qv) / det
    t = jnp.dot(e2, qv) / det
    return (a >= 0) & (b >= 0) & (a + b <= 1) & (t > 0)


def numbers(v, m, z, N):
    """One technique's numbers: the mean per-pixel 1-spp variance and the share of it carried by
    light samples that miss (``m``) and BSDF hits with light pdf 0 (``z``)."""
    import numpy as np

    v = v.astype(np.float64)
    dev2 = (v - v.mean(1, keepdims=True)) ** 2
    tot = dev2.sum()
    return {"variance_1spp": float(dev2.sum(1).mean() / (N - 1)),
            "light_miss_share": float(m.mean()), "light_miss_carry": float(dev2[m].sum() / tot),
            "bsdf_pdf0_share": float(z.mean()), "bsdf_pdf0_carry": float(dev2[z].sum() / tot),
            "both_carry": float(dev2[m | z].sum() / tot)}


def report(data, args):
    print(f"shipped H Fig. 2 scene, 48x48 pixel centres, {data['n']} 1-spp MIS samples per pixel"
          " (library)")
    for name, r in data["techniques"].items():
        print(f"{name:30s} 1-spp var (mean over px) {r['variance_1spp']:.4e}  "
              f"light misses {r['light_miss_share']:.2e} of samples "
              f"(carry {r['light_miss_carry']:.3f}),  "
              f"BSDF-hit pdf 0 {r['bsdf_pdf0_share']:.2e} (carry {r['bsdf_pdf0_carry']:.3f}),  "
              f"both {r['both_carry']:.3f}", flush=True)


def after(N):
    import jax
    import jax.numpy as jnp
    import numpy as np

    import anisosample as asp
    from anisosample.render import integrator as I
    from anisosample.render.bsdf import sample_bsdf
    from anisosample.render.camera import generate_ray
    from anisosample.render.geometry import intersect, offset_origin
    from anisosample.render.light_warps import Receiver, chain
    from anisosample.render.lights import light_pdf

    scene = asp.render.load_xml(asp.scenes.path("triangle_light"), width=48, height=48)
    L = scene.lights
    verts = jnp.stack([L.p0[0], L.p0[0] + L.e1[0], L.p0[0] + L.e2[0]])
    lum = jnp.asarray(I.LUMINANCE, jnp.float32)
    TECHS = {"uniform solid angle": "none", "+ bilinear cosine warp": "cosine-bilinear",
             "+ biquadratic cosine warp": "cosine-biquadratic",
             "Arvo 2001 (cosine-weighted)": "arvo2001"}

    def in_tri(o, w):
        return hits_triangle(verts, o, w)

    def flagged(lw):
        w, h = scene.width, scene.height
        half = jnp.full(2, 0.5, jnp.float32)
        def pixel(q, k):
            film = jnp.stack([((q % w) + 0.5) / w, ((q // w) + 0.5) / h]).astype(jnp.float32)
            o, d = generate_ray(scene.camera, film, half)
            hit = intersect(scene, o, d)
            wi = -d
            rec = Receiver(origin=offset_origin(scene, hit.p, hit.n, wi), n=hit.n, wi=wi,
                           material=hit.material)
            surf = hit.valid & (hit.light < 0)
            warp = chain(scene, 1, 0, rec, "solid_angle", lw)
            u = jax.random.uniform(k, (N, 4), jnp.float32, 0.0, 1.0 - 2.0**-24)
            def one(ul, ub):
                rgb = I.radiance(scene, film, half, ul, ub, I.IntegratorOptions(
                    technique="solid_angle", light_warp=lw, mis=True))
                val = jnp.dot(rgb, lum)
                wl = warp.sample(ul)
                miss = ~in_tri(rec.origin, wl)
                wb, pb = sample_bsdf(scene.materials, hit.material, hit.n, wi, ub)
                h2 = intersect(scene, rec.origin, wb)
                hits = h2.valid & (h2.light >= 0) & (jnp.dot(h2.n, -wb) > 0) & (pb > 0)
                zero = hits & ~(light_pdf(scene, 0, h2.p, rec, "solid_angle", lw) > 0)
                return val, miss & surf, zero & surf
            return jax.vmap(one)(u[:, :2], u[:, 2:])
        npx = w * h
        keys = jax.random.split(jax.random.key(1), npx)
        f = jax.jit(lambda q, k: jax.lax.map(lambda a: jax.vmap(pixel)(*a), (q, k)))
        v, m, z = f(jnp.arange(npx).reshape(48, 48), keys.reshape(48, 48))
        return [np.asarray(a).reshape(-1, N) for a in (v, m, z)]

    return {"n": N, "techniques": {name: numbers(*flagged(lw), N) for name, lw in TECHS.items()}}


def main(argv=None):
    def arguments(p):
        p.add_argument("n", nargs="?", type=int, default=None,
                       help="1-spp samples per pixel (default: 256 small, 4096 paper)")

    return common.run(
        NAME, __doc__.splitlines()[0], SCALES, lambda settings, args: after(settings["n"]),
        arguments=arguments, report=report, seed=None, argv=argv,
        settings=lambda cfg, args: {"n": args.n or cfg["n"], "scale": args.scale})


if __name__ == "__main__":
    main()

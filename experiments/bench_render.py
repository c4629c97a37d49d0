"""Benchmark: the Cornell scene at 128x128, 64 spp, light sampling (``direct`` with one
emitter sample, no BSDF sample), rendered by this package and by Mitsuba 3 from the same XML
in the same run. Prints samples per second for both and their ratio (issue 7 target: >= 1.0).

Then the primitive-count table (issue 25): ns per sample of a light-sampling render
(``--prims-size`` squared pixels, ``--prims-spp``) of a tessellated sphere
(:func:`render.builder.sphere_mesh`) on a floor under a square area light, at each of
``--prims`` triangle counts, through the BVH and by testing every primitive (up to
``--brute-max`` triangles: beyond, brute force takes minutes); and the seconds to read a
``--obj-triangles`` OBJ file (written to a temporary folder first) and build its scene with a
BVH. The crossover of the two columns is ``render.bvh.THRESHOLD``.

Our time excludes compilation (reported separately); Mitsuba's excludes scene loading. Both
report the best of ``--repeats`` runs, the two renderers alternating run by run. Mitsuba
runs ``scalar_rgb`` (its multi-threaded CPU variant that needs nothing but the wheel), and
also ``llvm_ad_rgb`` when ``DRJIT_LIBLLVM_PATH`` points at a usable LLVM, or when Debian's
libllvm19 is installed (``apt-get install libllvm19``; found automatically).
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import common
import jax
import numpy as np

from anisosample import render, scenes

SCENE = scenes.path("cornell")
DEBIAN_LLVM19 = "/usr/lib/x86_64-linux-gnu/libLLVM-19.so"  # apt-get install libllvm19


def main(argv=None):
    p = common.parser("bench_render", __doc__, scale=False, out=False, seed=None,
        fresh=False)
    p.add_argument("--size", type=int, default=128, help="image width and height")
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--scale", default="small", choices=["small", "paper"],
                   help="accepted for uniformity; the benchmark size is fixed by --size/--spp")
    p.add_argument("--prims", default="10,100,1000,10000,100000",
                   help="triangle counts of the primitive-count table (comma-separated; '' skips)")
    p.add_argument("--prims-size", type=int, default=64, help="table: image width and height")
    p.add_argument("--prims-spp", type=int, default=16, help="table: samples per pixel")
    p.add_argument("--brute-max", type=int, default=10000,
                   help="table: brute force (every primitive tested) up to this many triangles")
    p.add_argument("--obj-triangles", type=int, default=1_000_000,
                   help="triangles of the OBJ file read and built (0 skips)")
    p.add_argument("--no-mitsuba", action="store_true", help="skip the Cornell comparison")
    args = p.parse_args(argv)
    if not args.no_mitsuba:
        cornell(args)
    counts = [int(c) for c in args.prims.split(",") if c.strip()]
    if counts:
        prims_table(counts, args.prims_size, args.prims_spp, args.brute_max, args.repeats)
    if args.obj_triangles > 0:
        obj_load_build(args.obj_triangles)
    return 0


def cornell(args):
    size = dict(width=args.size, height=args.size)
    n = args.size * args.size * args.spp
    print(f"scene {SCENE.name}, {args.size}x{args.size}, {args.spp} spp = {n} samples; "
          f"{os.cpu_count()} CPUs, jax {jax.__version__} on {jax.default_backend()}")

    scene = render.load_xml(SCENE, **size)
    key = jax.random.key(0)
    t0 = time.perf_counter()
    render.render(scene, key, spp=args.spp, progress=False)
    first = time.perf_counter() - t0
    ours_fn = lambda: render.render(scene, key, spp=args.spp, progress=False)  # noqa: E731

    try:
        import mitsuba as mi
    except ImportError:
        mi = None
    variants = []
    if mi is not None:
        variants = ["scalar_rgb"]
        llvm = os.environ.get("DRJIT_LIBLLVM_PATH")
        if not llvm and Path(DEBIAN_LLVM19).exists():
            llvm = os.environ["DRJIT_LIBLLVM_PATH"] = DEBIAN_LLVM19
        if llvm and Path(llvm).exists():
            variants.append("llvm_ad_rgb")
        else:
            print("llvm_ad_rgb skipped (set DRJIT_LIBLLVM_PATH to Debian's libLLVM-19.so)")
    else:
        print("mitsuba not installed: no comparison")
    # Alternate ours and scalar_rgb run by run so that both see the same machine load (the
    # reference machine is shared); llvm_ad_rgb runs afterwards on its own (its thread pool,
    # once started, slows other processes down). Report the best time of each.
    ours_times, theirs = [], {v: [] for v in variants}
    scenes = {}

    def mitsuba_run(v):
        mi.set_variant(v)
        if v not in scenes:
            scenes[v] = mi.load_file(str(SCENE), **size)
            mi.render(scenes[v], spp=args.spp)  # warm-up (JIT for llvm)
        theirs[v].append(common.best_time(lambda: np.asarray(mi.render(scenes[v], spp=args.spp)),
                                          repeats=1, warmup=False))

    for _ in range(args.repeats):
        ours_times.append(common.best_time(ours_fn, repeats=1, warmup=False))
        if "scalar_rgb" in variants:
            mitsuba_run("scalar_rgb")
    for v in variants:
        if v != "scalar_rgb":
            for _ in range(args.repeats):
                mitsuba_run(v)
    ours = min(ours_times)
    print(f"anisosample: first call {first:.2f} s (with compilation), best {ours:.3f} s "
          f"-> {n / ours / 1e6:.3f} M samples/s")
    for v in variants:
        t = min(theirs[v])
        print(f"mitsuba {mi.__version__} {v}: best {t:.3f} s -> {n / t / 1e6:.3f} M "
              f"samples/s; ratio anisosample/mitsuba = {t / ours:.3f}")


def mesh_scene(triangles: int):
    """A ``sphere_mesh`` of about ``triangles`` faces (diffuse) on a floor under a square light,
    seen from above at an angle: ``(builder, camera to_world, mesh triangles)``."""
    from anisosample.render.builder import sphere_mesh
    from anisosample.render.xml import look_at

    b = render.SceneBuilder()
    b.rectangle(np.diag([3.0, 3.0, 1.0, 1.0]), b.diffuse(0.6))
    v, f = sphere_mesh((0, 0, 0.6), 0.5, triangles)
    b.triangles(v, f, b.diffuse(0.5))
    t = np.diag([0.4, 0.4, -1.0, 1.0])
    t[:3, 3] = (0.5, 0.4, 2.2)
    b.rectangle(t, b.diffuse(0.0), radiance=15.0)
    cam = look_at(np.array([2.0, -2.5, 1.8]), np.array([0, 0, 0.4]), np.array([0, 0, 1.0]))
    return b, cam, len(f)


def prims_table(counts, size, spp, brute_max, repeats):
    """Print ns per sample, BVH and brute force, at each triangle count (best of ``repeats``
    after a compiling call)."""
    n = size * size * spp
    print(f"\nprimitive count: sphere mesh on a floor, light sampling, {size}x{size} x {spp} spp "
          f"= {n} samples; ns per sample (best of {repeats}, after compilation)")
    print(f"{'triangles':>10} {'BVH':>10} {'brute force':>12} {'brute/BVH':>10}")
    key = jax.random.key(0)
    for c in counts:
        b, cam, tris = mesh_scene(c)
        b.camera(cam, width=size, height=size, fov=40)
        row = {}
        for bvh in (True, False):
            if not bvh and tris > brute_max:
                continue
            scene = b.build(bvh=bvh)
            fn = lambda s=scene: render.render(s, key, spp=spp, progress=False)  # noqa: E731
            fn()
            row[bvh] = common.best_time(fn, repeats=repeats, warmup=False) / n * 1e9
        brute = f"{row[False]:12.0f}" if False in row else f"{'-':>12}"
        ratio = f"{row[False] / row[True]:10.2f}" if False in row else f"{'-':>10}"
        print(f"{tris:>10} {row[True]:10.0f} {brute} {ratio}", flush=True)
    print(f"(render.bvh.THRESHOLD = {render.bvh.THRESHOLD}: SceneBuilder.build's default "
          "uses the BVH from that many planar primitives)")


def obj_load_build(triangles: int):
    """Write a ``sphere_mesh`` OBJ (positions, texture coordinates, ``v/vt`` faces), then time
    reading it (:func:`render.obj.read_obj`), adding it (``SceneBuilder.triangles``) and
    building the scene with its BVH."""
    from anisosample.render.builder import sphere_mesh
    from anisosample.render.obj import read_obj

    v, f = sphere_mesh((0, 0, 0), 1.0, triangles)
    uv = np.random.default_rng(0).random((len(v), 2))
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "sphere.obj"
        with open(path, "w") as fh:
            np.savetxt(fh, v, fmt="v %.7f %.7f %.7f")
            np.savetxt(fh, uv, fmt="vt %.6f %.6f")
            np.savetxt(fh, np.repeat(f + 1, 2, axis=1), fmt="f %d/%d %d/%d %d/%d")
        mb = path.stat().st_size / 1e6
        t0 = time.perf_counter()
        vv, uvs, faces, _ = read_obj(path)
        t1 = time.perf_counter()
    b = render.SceneBuilder()
    b.triangles(vv, faces, b.diffuse(0.5), uvs=uvs)
    b.point_light((0, 0, 5), 1.0)
    b.camera(np.eye(4), width=4, height=4)
    t2 = time.perf_counter()
    scene = b.build(bvh=True)
    jax.block_until_ready(scene)
    t3 = time.perf_counter()
    print(f"\nOBJ {len(faces)} triangles ({mb:.0f} MB): read_obj {t1 - t0:.2f} s, "
          f"SceneBuilder.triangles {t2 - t1:.2f} s, build with BVH {t3 - t2:.2f} s "
          f"({scene.bvh.num_nodes} nodes, depth {scene.bvh.depth}); total {t3 - t0:.2f} s")


if __name__ == "__main__":
    raise SystemExit(main())

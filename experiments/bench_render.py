"""Benchmark: the ray caster against Mitsuba 3 on the same XML files (issue 25), then the
primitive-count table and an OBJ load.

Per scene (``--scenes``: shipped scene names, and ``meshNk``: a tessellated sphere of about N
thousand triangles on a floor under a square light, written as OBJ + XML to a temporary folder
so that both renderers load the same file), at ``--size`` squared pixels and ``--spp``, light
sampling as the scene files say (``direct``, one emitter sample, no BSDF sample): our M samples
per second, Mitsuba's, and the ratio ours / Mitsuba. Mitsuba runs ``llvm_ad_rgb`` (the
reference of issue 25; it uses every core) when Dr.Jit finds an LLVM -- ``DRJIT_LIBLLVM_PATH``,
or Debian's libllvm19 (``apt-get install libllvm19``; found automatically) -- and ``scalar_rgb``
with ``--scalar`` (or when no LLVM is found). Scenes with our own XML extension (bilinear
patches) go to Mitsuba through :func:`anisosample.render.mitsuba_compat.mitsuba_compatible_copy`.

``--cpu-devices N`` (default 1, as ``render``'s own default) starts JAX's CPU backend with N
devices (``jax_num_cpu_devices``) and renders over all of them (``render(...,
devices=jax.devices())``, the same bits as one device). The ``cores`` column is the process's
CPU time over wall time. On the 2-core reference machine one device already keeps 1.8 cores busy
(XLA:CPU splits large loops over its threads), and two devices do not pay: 2026-12-06 (load 0.6)
cornell 7.3-9.3 M samples/s on two against 7.3-7.5 on one; 2026-12-07 (two runs of ``--repeats
5``, loads 1.8 and 2.7, not interleaved) two / one device: cornell 25.94 / 25.21, blinds 20.23 /
20.81, attic 14.02 / 15.27, dof 12.19 / 16.20 (dof's loss not traced). ``--costs``: also the
per-block aligned sampler and the light warps on the first scene, against its plain pmj02bn
render.

Then the primitive-count table (ns per sample of a light-sampling render, ``--prims-size``
squared pixels, ``--prims-spp``, of a tessellated sphere (:func:`render.builder.sphere_mesh`)
on a floor under a square area light, at each of ``--prims`` triangle counts, through the BVH
and by testing every primitive (up to ``--brute-max`` triangles)); and the seconds to read a
``--obj-triangles`` OBJ file and build its scene with a BVH. The crossover of the two columns
is ``render.bvh.THRESHOLD``.

Our time excludes compilation (reported separately); Mitsuba's excludes scene loading and its
JIT (a warm-up render first). Both report the best of ``--repeats`` runs.
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import common
import jax
import numpy as np

from anisosample import render

DEBIAN_LLVM19 = "/usr/lib/x86_64-linux-gnu/libLLVM-19.so"  # apt-get install libllvm19
DEFAULT_SCENES = "cornell,blinds,attic,dof,mesh100k"


def main(argv=None):
    p = common.parser("bench_render", __doc__, scale=False, out=False, seed=None,
        fresh=False)
    p.add_argument("--size", type=int, default=128, help="image width and height")
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--scale", default="small", choices=["small", "paper"],
                   help="accepted for uniformity; the benchmark size is fixed by --size/--spp")
    p.add_argument("--scenes", default=DEFAULT_SCENES,
                   help="comma-separated shipped scene names and meshNk ('' skips)")
    common.devices_option(p, default=1)
    p.add_argument("--scalar", action="store_true", help="also time Mitsuba's scalar_rgb")
    p.add_argument("--costs", action="store_true",
                   help="also the aligned sampler's and the light warps' cost on the first scene")
    p.add_argument("--prims", default="10,100,1000,10000,100000",
                   help="triangle counts of the primitive-count table (comma-separated; '' skips)")
    p.add_argument("--prims-size", type=int, default=64, help="table: image width and height")
    p.add_argument("--prims-spp", type=int, default=16, help="table: samples per pixel")
    p.add_argument("--brute-max", type=int, default=10000,
                   help="table: brute force (every primitive tested) up to this many triangles")
    p.add_argument("--obj-triangles", type=int, default=1_000_000,
                   help="triangles of the OBJ file read and built (0 skips)")
    p.add_argument("--no-mitsuba", action="store_true", help="skip the Mitsuba comparison")
    args = p.parse_args(argv)
    args.devices = common.render_devices(args)  # before anything starts the backend
    names = [s.strip() for s in args.scenes.split(",") if s.strip()]
    if names:
        scene_table(names, args)
    counts = [int(c) for c in args.prims.split(",") if c.strip()]
    if counts:
        prims_table(counts, args.prims_size, args.prims_spp, args.brute_max, args.repeats)
    if args.obj_triangles > 0:
        obj_load_build(args.obj_triangles)
    return 0


def mitsuba_variants(args):
    """``(mitsuba module or None, variants to time)``."""
    if args.no_mitsuba:
        return None, []
    try:
        import mitsuba as mi
    except ImportError:
        print("mitsuba not installed: no comparison")
        return None, []
    llvm = os.environ.get("DRJIT_LIBLLVM_PATH")
    if not llvm and Path(DEBIAN_LLVM19).exists():
        llvm = os.environ["DRJIT_LIBLLVM_PATH"] = DEBIAN_LLVM19
    variants = ["llvm_ad_rgb"] if llvm and Path(llvm).exists() else []
    if not variants:
        print("llvm_ad_rgb skipped (set DRJIT_LIBLLVM_PATH to Debian's libLLVM-19.so)")
    if args.scalar or not variants:
        variants.append("scalar_rgb")
    return mi, variants


def scene_file(name: str, folder: Path) -> Path:
    """The XML file of a shipped scene, or of ``meshNk`` written into ``folder``."""
    from anisosample import scenes

    if name.startswith("mesh") and name.endswith("k") and name[4:-1].isdigit():
        return write_mesh_scene(int(name[4:-1]) * 1000, folder / name)[0]
    return scenes.path(name)


def write_mesh_scene(triangles: int, folder: Path) -> tuple[Path, int]:
    """A ``sphere_mesh`` OBJ of about ``triangles`` faces on a floor under a square light,
    as a Mitsuba 3 XML file both renderers load (the primitive-count table's scenes too):
    ``(the XML file, the mesh's triangle count)``."""
    from anisosample.render.builder import sphere_mesh

    folder.mkdir(parents=True, exist_ok=True)
    v, f = sphere_mesh((0, 0, 0.6), 0.5, triangles)
    with open(folder / "sphere.obj", "w") as fh:
        np.savetxt(fh, v, fmt="v %.7f %.7f %.7f")
        np.savetxt(fh, f + 1, fmt="f %d %d %d")
    (folder / "scene.xml").write_text("""<scene version="3.0.0">
    <default name="spp" value="64"/>
    <default name="width" value="128"/>
    <default name="height" value="128"/>
    <integrator type="direct">
        <integer name="emitter_samples" value="1"/>
        <integer name="bsdf_samples" value="0"/>
    </integrator>
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world">
            <lookat origin="2, -2.5, 1.8" target="0, 0, 0.4" up="0, 0, 1"/>
        </transform>
        <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
        <film type="hdrfilm">
            <integer name="width" value="$width"/>
            <integer name="height" value="$height"/>
            <rfilter type="box"/>
        </film>
    </sensor>
    <shape type="rectangle">
        <transform name="to_world"><scale x="3" y="3"/></transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.6"/></bsdf>
    </shape>
    <shape type="obj">
        <string name="filename" value="sphere.obj"/>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.5"/></bsdf>
    </shape>
    <shape type="rectangle">
        <transform name="to_world">
            <scale x="0.4" y="0.4" z="-1"/><translate x="0.5" y="0.4" z="2.2"/>
        </transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0"/></bsdf>
        <emitter type="area"><rgb name="radiance" value="15"/></emitter>
    </shape>
</scene>
""")
    return folder / "scene.xml", len(f)


def timed(fn, repeats: int):
    """``(best seconds, cores, first call's seconds)``: :func:`common.best_time` of ``repeats``
    calls after a first (compiling) one, which is timed too."""
    t0 = time.perf_counter()
    fn()
    first = time.perf_counter() - t0
    return (*common.best_time(fn, repeats=repeats, warmup=False, cores=True), first)


def scene_table(names, args):
    mi, variants = mitsuba_variants(args)
    devices = args.devices
    n = args.size * args.size * args.spp
    print(f"{args.size}x{args.size}, {args.spp} spp = {n} samples per image; "
          f"{os.cpu_count()} CPUs, load {os.getloadavg()[0]:.2f}; jax {jax.__version__} on "
          f"{jax.default_backend()}, {len(jax.devices())} device(s)"
          + (f"; mitsuba {mi.__version__}" if mi else ""))
    head = f"{'scene':>10} {'prims':>7} {'ours M/s':>9} {'cores':>6} {'compile s':>9}"
    for v in variants:
        head += f" {v + ' M/s':>16} {'ratio':>6}"
    print(head)
    key = jax.random.key(0)
    size = dict(width=args.size, height=args.size)
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            path = scene_file(name, Path(tmp))
            scene = render.load_xml(path, **size)
            fn = lambda s=scene: render.render(  # noqa: E731
                s, key, spp=args.spp, sampler="pmj02bn", progress=False, devices=devices)
            ours, cores, first = timed(fn, args.repeats)
            prims = int(scene.tri_ids.shape[0])
            row = (f"{name:>10} {prims:>7} {n / ours / 1e6:9.2f} {cores:6.2f} "
                   f"{first - ours:9.1f}")
            for v in variants:
                mi.set_variant(v)
                mpath = render.mitsuba_compat.mitsuba_compatible_copy(
                    path, Path(tmp) / f"mitsuba_{name}", **size)
                ms = mi.load_file(str(mpath), **size)
                theirs, _, _ = timed(lambda ms=ms: np.asarray(mi.render(ms, spp=args.spp)),
                                     args.repeats)
                row += f" {n / theirs / 1e6:16.2f} {theirs / ours:6.3f}"
            print(row, flush=True)
            if args.costs and name == names[0]:
                costs(scene, key, args, devices, ours)


def costs(scene, key, args, devices, plain):
    """The per-block aligned sampler and two light warps on ``scene``, in seconds per image
    relative to its plain pmj02bn render (``plain`` seconds)."""
    n = args.size * args.size * args.spp
    cases = {"aligned (per block)": dict(sampler="aligned"),
             "cosine-bilinear warp": dict(sampler="pmj02bn", light_warp="cosine-bilinear"),
             "product-bilinear warp": dict(sampler="pmj02bn", light_warp="product-bilinear",
                                           technique="solid_angle")}
    for label, kw in cases.items():
        fn = lambda kw=kw: render.render(scene, key, spp=args.spp, progress=False,  # noqa: E731
                                         devices=devices, **kw)
        t, cores, _ = timed(fn, args.repeats)
        print(f"{'':>10}   {label}: {n / t / 1e6:.2f} M samples/s, {t / plain:.2f}x the plain "
              f"render's time ({cores:.2f} cores)", flush=True)


def prims_table(counts, size, spp, brute_max, repeats):
    """Print ns per sample, BVH and brute force, at each triangle count (best of ``repeats``
    after a compiling call)."""
    n = size * size * spp
    print(f"\nprimitive count: sphere mesh on a floor, light sampling, {size}x{size} x {spp} spp "
          f"= {n} samples; ns per sample (best of {repeats}, after compilation)")
    print(f"{'triangles':>10} {'BVH':>10} {'brute force':>12} {'brute/BVH':>10}")
    key = jax.random.key(0)
    for c in counts:
        with tempfile.TemporaryDirectory() as tmp:
            path, tris = write_mesh_scene(c, Path(tmp))
            scenes = {bvh: render.load_xml(path, width=size, height=size, bvh=bvh)
                      for bvh in (True, False) if bvh or tris <= brute_max}
        row = {}
        for bvh, scene in scenes.items():
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

"""Benchmark: the Cornell scene at 128x128, 64 spp, light sampling (``direct`` with one
emitter sample, no BSDF sample), rendered by this package and by Mitsuba 3 from the same XML
in the same run. Prints samples per second for both and their ratio (issue 7 target: >= 1.0).

Our time excludes compilation (reported separately); Mitsuba's excludes scene loading. Both
report the best of ``--repeats`` runs, the two renderers alternating run by run. Mitsuba
runs ``scalar_rgb`` (its multi-threaded CPU variant that needs nothing but the wheel), and
also ``llvm_ad_rgb`` when ``DRJIT_LIBLLVM_PATH`` points at a usable LLVM, or when Debian's
libllvm19 is installed (``apt-get install libllvm19``; found automatically).
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import jax
import numpy as np

from anisosample import render, scenes

SCENE = scenes.path("cornell")
DEBIAN_LLVM19 = "/usr/lib/x86_64-linux-gnu/libLLVM-19.so"  # apt-get install libllvm19


def _best(fn, repeats):
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--size", type=int, default=128, help="image width and height")
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--scale", default="small", choices=["small", "paper"],
                   help="accepted for uniformity; the benchmark size is fixed by --size/--spp")
    args = p.parse_args(argv)
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
        theirs[v].append(_best(lambda: np.asarray(mi.render(scenes[v], spp=args.spp)), 1))

    for _ in range(args.repeats):
        ours_times.append(_best(ours_fn, 1))
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
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

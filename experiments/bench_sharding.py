"""Benchmark: sharded rendering (``render(..., devices=...)``, ``anisosample render --devices
/--processes``) against one device, on the same scene, size and spp.

In this process: the scene rendered on one device and on every local device (on a CPU, force
several with ``XLA_FLAGS=--xla_force_host_platform_device_count=N``; they share the cores), best
of ``--repeats`` after a compiling run, M samples/s and the speed-up; the images are checked
equal bit for bit. ``--processes P``: also the command line end to end (start-up and compilation
included), one process against ``--processes P`` (each worker pinned to its share of the
cores), the images checked equal.

    python experiments/bench_sharding.py [--scene cornell] [--size 128] [--spp 64] [--processes 2]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import common
import jax
import numpy as np

from anisosample import io, render, scenes


def main(argv=None):
    p = common.parser("bench_sharding", __doc__, scale=False, out=False, seed=None,
        fresh=False,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scene", default="cornell", help="shipped scene name")
    p.add_argument("--size", type=int, default=128, help="image width and height")
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--sampler", default="pmj02bn")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--processes", type=int, default=0,
                   help="also time the command line with this many local processes (0: no)")
    args = p.parse_args(argv)
    if args.size < 1 or args.spp < 1 or args.repeats < 1 or args.processes < 0:
        p.error("--size, --spp and --repeats must be >= 1 and --processes >= 0")
    scene = render.load_xml(scenes.path(args.scene), width=args.size, height=args.size)
    samples = args.size**2 * args.spp
    opts = dict(spp=args.spp, sampler=args.sampler, progress=False)
    local = jax.local_devices()
    print(f"{args.scene} {args.size}^2 x {args.spp} spp, {args.sampler}; load average "
          f"{os.getloadavg()[0]:.2f}; {len(local)} local device(s): {local[0].platform}")
    t1, one = common.best_time(lambda: render.render(scene, jax.random.key(0), **opts),
                              repeats=args.repeats, with_output=True)
    print(f"  1 device : {t1:.3f} s  {samples / t1 / 1e6:.2f} M samples/s")
    if len(local) > 1:
        tn, many = common.best_time(
            lambda: render.render(scene, jax.random.key(0), devices=local, **opts),
            repeats=args.repeats, with_output=True)
        same = np.array_equal(one.mean, many.mean)
        print(f"  {len(local)} devices: {tn:.3f} s  {samples / tn / 1e6:.2f} M samples/s  "
              f"speed-up {t1 / tn:.2f}x  same bits: {same}")
        if not same:
            raise SystemExit("the sharded image differs from the one-device image")
    if args.processes:
        with tempfile.TemporaryDirectory() as tmp:
            base = [sys.executable, "-m", "anisosample", "render", args.scene, "--set",
                    f"width={args.size}", "--set", f"height={args.size}", "--spp", str(args.spp),
                    "--sampler", args.sampler]
            env = dict(os.environ, ANISOSAMPLE_PROGRESS="0")
            env.pop("XLA_FLAGS", None)
            times, images = [], []
            for k, extra in enumerate(([], ["--processes", str(args.processes)])):
                out = Path(tmp) / f"{k}.exr"
                t = time.perf_counter()
                subprocess.run([*base, *extra, "-o", str(out)], env=env, check=True,
                               stdout=subprocess.DEVNULL)
                times.append(time.perf_counter() - t)
                images.append(io.read_exr(out))
            same = np.array_equal(*images)
            print(f"  command line, start-up and compilation included: 1 process "
                  f"{times[0]:.1f} s, {args.processes} processes {times[1]:.1f} s "
                  f"({times[0] / times[1]:.2f}x); same bits: {same}")
            if not same:
                raise SystemExit("the multi-process image differs from the one-process image")


if __name__ == "__main__":
    main()

"""Benchmark: time to build aligned point-set tables (W Sec. 5.4) on this machine.

Builds ``--sets`` canonical sets of the 3-direction table at ``--n`` points (default 4096) with
the synthesis defaults (or ``--steps``), through ``anisosample.tables.build`` into a scratch
folder, and prints the seconds per set (each includes its compilation: synthesize compiles one
loop per direction set) and the projected totals for the 46-set and 4,141-set tables on the
devices used. Target (issue 8): the 46 sets at n = 4096 in <= 15 minutes on 2 CPU cores.
Run it under ``nice -n 10`` on a shared machine; it prints the load average so the figures can be
judged.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

import jax
import numpy as np

import anisosample as asp
from anisosample import tables


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--n", type=int, default=4096)
    p.add_argument("--sets", type=int, default=2, help="how many canonical sets to time")
    p.add_argument("--steps", type=int, default=None, help="synthesis steps (default: recipe's)")
    p.add_argument("--recipe", default="rate", choices=["rate", "paper"])
    args = p.parse_args(argv)
    canon = tables.canonical_sets(3)
    # spread over the range: 0 (axes only) is cheaper than a set with an extra wedge
    pick = [canon[i] for i in np.linspace(len(canon) // 3, len(canon) - 1, args.sets).astype(int)]
    steps = args.steps or asp.synthesis.recipe_defaults(args.recipe)["steps"]
    ndev = len(jax.local_devices())
    print(f"devices: {ndev} x {jax.devices()[0].platform}, cpu_count {os.cpu_count()}, "
          f"load average {os.getloadavg()[0]:.1f}")
    print(f"n = {args.n}, recipe {args.recipe}, steps {steps}, timing sets {pick}")
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        summary = tables.build(args.n, 3, out=tmp, sets=pick, steps=args.steps,
                               recipe=args.recipe, show_progress=True)
        wall = time.perf_counter() - t0
    per = np.array(list(summary["seconds"].values()))
    per_set = wall / len(pick)  # wall time per set with all devices busy
    print(f"seconds per set: {', '.join(f'{s:.1f}' for s in per)} (mean {per.mean():.1f}); "
          f"wall {wall:.1f} s for {len(pick)} sets")
    print(f"projected 46-set table (kind 3): {46 * per_set / 60:.1f} min")
    print(f"projected 4141-set table (kind 4): {4141 * per_set / 3600:.1f} h")
    print(f"load average after: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()

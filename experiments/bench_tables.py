"""Benchmark: time to build aligned point-set tables (W Sec. 5.4) on this machine.

Builds canonical sets of the 3-direction table at ``--n`` points (default 4096) through
``anisosample.tables.build`` into a scratch folder and prints the measured wall seconds per set,
then the projected totals for the 46-set and 4,141-set tables with the recipe's default number of
steps.

Two modes:

* ``--full``: time ``--sets`` complete sets (the recipe's steps); the projection is
  ``46 x`` (and ``4141 x``) the measured mean.
* default (quick): time one set at ``--short`` and one at ``--long`` steps (different directions,
  so each pays its own compilation, as every set of a table does), fit
  ``t = fixed + steps * per_step`` and project ``46 x (fixed + default_steps * per_step)``.

Each set includes its compilation (synthesize compiles one loop per direction set). 4-direction
sets carry one more wedge of frequencies, so the 4,141 projection from 3-direction sets is a lower
bound. Target (issue 8): the 46 sets at n = 4096 in <= 15 minutes on 2 CPU cores. On a shared
machine run it under ``nice -n 10``; it prints the load average so the figures can be judged.

    python experiments/bench_tables.py [--n 4096] [--full --sets 2] [--batch B]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

import jax

import anisosample as asp
from anisosample import tables


def _time_sets(n, sets, steps, recipe, batch):
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        tables.build(n, 3, out=tmp, sets=sets, steps=steps, recipe=recipe, batch=batch,
                     show_progress=False)
        return time.perf_counter() - t0


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--n", type=int, default=4096)
    p.add_argument("--recipe", default="rate", choices=["rate", "paper"])
    p.add_argument("--full", action="store_true", help="time complete sets")
    p.add_argument("--sets", type=int, default=1, help="complete sets to time with --full")
    p.add_argument("--short", type=int, default=10, help="steps of the short run (quick mode)")
    p.add_argument("--long", type=int, default=40, help="steps of the long run (quick mode)")
    p.add_argument("--batch", type=int, default=1,
                   help="sets per synthesize_batch loop (--full only; sets must be >= batch)")
    args = p.parse_args(argv)
    steps = asp.synthesis.recipe_defaults(args.recipe)["steps"]
    print(f"devices: {len(jax.local_devices())} x {jax.devices()[0].platform}, "
          f"cpu_count {os.cpu_count()}, load average {os.getloadavg()[0]:.1f}")
    print(f"n = {args.n}, recipe {args.recipe} (default steps {steps})")
    if args.full:
        canon = tables.canonical_sets(3)
        pick = canon[15:15 + args.sets]
        wall = _time_sets(args.n, pick, None, args.recipe, args.batch)
        per_set = wall / len(pick)
        print(f"measured: {wall:.1f} s for {len(pick)} complete set(s) {pick} "
              f"(batch {args.batch}): {per_set:.1f} s per set")
    else:
        t_short = _time_sets(args.n, [(20,)], args.short, args.recipe, 1)
        t_long = _time_sets(args.n, [(21,)], args.long, args.recipe, 1)
        per_step = max(t_long - t_short, 0.0) / (args.long - args.short)
        fixed = max(t_short - args.short * per_step, 0.0)
        per_set = fixed + steps * per_step
        print(f"measured: {t_short:.1f} s at {args.short} steps, {t_long:.1f} s at {args.long} "
              f"steps -> {per_step:.3f} s per step + {fixed:.1f} s per set (compile, setup)")
        print(f"projected per set at {steps} steps: {per_set:.1f} s")
    print(f"projected 46-set table (kind 3): {46 * per_set / 60:.1f} min")
    print(f"projected 4141-set table (kind 4): {4141 * per_set / 3600:.1f} h (lower bound)")
    print(f"load average after: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()

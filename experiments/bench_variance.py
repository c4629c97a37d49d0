"""Benchmark of the variance engine: integrand evaluations per second.

The issue's workload: a 4-edge polygon (``integrands.edges([25, 65, 115, 160])``), 4096
realizations of 2^14 points (6.7e7 evaluations), with each randomization: toroidal shifts of one
fixed set (the path of precomputed and slow sets), fresh jittered sets, and fresh random sets
plus shifts. Prints the best of ``--repeats`` timed runs after one warm-up (compilation) run.
Not a test: nothing is asserted.

    python experiments/bench_variance.py [--realizations 4096] [--log2-n 14] [--repeats 3]
"""

from __future__ import annotations

import os

import common
import jax

from anisosample import integrands
from anisosample import variance as V


def main(argv=None):
    ap = common.parser("bench_variance", __doc__.splitlines()[0], scale=False, out=False,
        seed=None, fresh=False)
    ap.add_argument("--realizations", type=int, default=4096)
    ap.add_argument("--log2-n", type=int, default=14)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--chunk-elements", type=int, default=V.DEFAULT_CHUNK_ELEMENTS)
    args = ap.parse_args(argv)
    n, r = 2**args.log2_n, args.realizations
    f = integrands.edges([25.0, 65.0, 115.0, 160.0])
    print(f"jax {jax.__version__} on {jax.devices()[0].platform}, {os.cpu_count()} CPUs; "
          f"4-edge polygon, {r} realizations x {n} points = {r * n:.3g} evaluations")
    cases = [("shift of one fixed jittered set", "jittered", "shift"),
             ("fresh jittered sets", "jittered", "fresh"),
             ("fresh random sets + shift", "random", "fresh+shift")]
    for label, sampler, mode in cases:
        key = jax.random.key(0)

        def run(sampler=sampler, mode=mode, key=key):
            return V.estimator_variance(f, sampler, n, key, r, f.integral, randomization=mode,
                                        chunk_elements=args.chunk_elements)

        dt = common.best_time(run, repeats=args.repeats)
        print(f"  {label:34s} {dt:7.3f} s   {r * n / dt:10.3g} evaluations/s")


if __name__ == "__main__":
    main()

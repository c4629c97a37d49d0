"""Wall time to a converged set at the design that reaches the rate (issue 4 targets on 2 CPU
cores: <= 17 s for n = 2^12 and <= 10 min for n = 2^16, 3 directions).

Prints, per n: frequency count, one gradient's time with the default evaluation (``auto``:
type-1 NUFFTs on lattice-aligned grids, FINUFFT on one thread: deterministic), the same with
FINUFFT on its own thread count, and with the rotated type-3 NUFFT, after compilation,
the compile time, and the wall and CPU time of ``synthesize`` with the default recipe
(compilation included), the load average (other work on the machine inflates wall time) and the
final loss.  Not a test: nothing is asserted.

The synthesis runs one step per chunk, so its callback times every step: the first (set-up and
compilation) and the mean of the rest give a projection at the recipe's step count even when
``--steps`` is small.

    python experiments/bench_synthesis.py [--log2-n 12 16] [--directions 0,90,30] [--steps 10]
        [--nufft-precision single] [--prefix dihedral-32] [--sequence-from 256] [--no-gradients]

``--prefix``: a fixed-prefix set (W Sec. 7); ``--sequence-from S``: a progressive sequence
(``synthesize_sequence``) whose nested prefixes from ``S`` up are aligned; ``--no-gradients``
skips the per-method gradient timings.
"""

from __future__ import annotations

import os
import time

import common
import jax
import jax.numpy as jnp
import numpy as np

import anisosample as asp
from anisosample import frequencies, losses, spectrum, synthesis


def _gradient_times(n, fset, opts):
    """One gradient's time per evaluation method (after compilation) and the first call's."""
    with jax.enable_x64(True):
        x = jnp.asarray(np.asarray(asp.samplers.get("jittered")(jax.random.key(0), n)),
                        jnp.float64)
        grad_s, compile_s = {}, None
        # "auto threads": FINUFFT on its own thread count (nondeterministic spreading),
        # the cost of the one-thread default (spectrum.NUFFT_THREADS) in the same run
        for method, reps, threads in (("auto", 5, 1), ("auto threads", 5, 0),
                                      ("nufft3", 2, 1)):
            spectrum.NUFFT_THREADS = threads
            path = method.split()[0]
            g = jax.jit(jax.grad(lambda y, fset=fset, m=path: (
                losses.linear_spectrum_loss(y, fset, method=m, eps=opts["nufft_eps"]))))
            t = time.perf_counter()
            g(x).block_until_ready()
            if compile_s is None:
                compile_s = time.perf_counter() - t
            t = time.perf_counter()
            for _ in range(reps):
                g(x).block_until_ready()
            grad_s[method] = (time.perf_counter() - t) / reps
        spectrum.NUFFT_THREADS = 1
    return grad_s, compile_s


def main(argv=None):
    ap = common.parser("bench_synthesis", __doc__.splitlines()[0], scale=False, out=False,
        seed=None, fresh=False)
    ap.add_argument("--log2-n", type=int, nargs="+", default=[12, 16])
    ap.add_argument("--directions", default="0,90,30")
    ap.add_argument("--steps", type=int, default=None, help="override the recipe's steps")
    ap.add_argument("--nufft-precision", default="double", choices=["double", "single"],
                    help="the synthesis run's nufft_precision (single: the 4-direction tables')")
    ap.add_argument("--prefix", default=None, help="a fixed prefix, e.g. dihedral-32")
    ap.add_argument("--sequence-from", type=int, default=None,
                    help="time a progressive sequence with nested prefixes from this size")
    ap.add_argument("--no-gradients", action="store_true", help="skip the gradient timings")
    args = ap.parse_args(argv)
    dirs = [float(x) for x in args.directions.split(",")]
    opts = synthesis.recipe_defaults("rate")
    print(f"backend {jax.default_backend()}, {os.cpu_count()} CPUs, directions {dirs}, "
          f"recipe 'rate' {opts}")
    for k in args.log2_n:
        n = 2**k
        fset = frequencies.design(n, dirs, "rate")
        grad_s, compile_s = (None, None) if args.no_gradients else _gradient_times(n, fset, opts)
        t = time.perf_counter()
        c0 = time.process_time()
        stamps = []  # one chunk per step: the time after each step
        extra = {k2: v for k2, v in (("prefix", args.prefix),
                                     ("sequence_from", args.sequence_from)) if v is not None}
        what = ("sequence" if args.sequence_from else "set") + (
            f" with prefix {args.prefix}" if args.prefix else "")
        result = synthesis.synthesize(jax.random.key(0), n, dirs, steps=args.steps,
                                      nufft_precision=args.nufft_precision,
                                      show_progress=True, checkpoint_every=1, **extra,
                                      callback=lambda k, loss, s=stamps: s.append(
                                          time.perf_counter()))
        wall = time.perf_counter() - t
        cpu = time.process_time() - c0
        load = os.getloadavg()[0]
        steps = len(result.history) - 1
        first = stamps[0] - t  # set-up, compilation and the first step
        per_step = (stamps[-1] - stamps[0]) / max(steps - 1, 1)
        default_steps = synthesis.SEQUENCE_STEPS if args.sequence_from else opts["steps"]
        projected = first + (default_steps - 1) * per_step
        print(f"n=2^{k} synthesize a {what} ({args.nufft_precision} precision): first step "
              "(set-up, "
              f"compilation) {first:.1f} s, then "
              f"{per_step:.3f} s per step (the terms on {os.cpu_count()} threads); projected "
              f"at the default {default_steps} steps: {projected:.0f} s", flush=True)
        grads = "" if grad_s is None else (
            f"gradient {grad_s['auto']:.3f} s (FINUFFT on its own threads, not deterministic: "
            f"{grad_s['auto threads']:.3f} s; type-3 NUFFT: {grad_s['nufft3']:.3f} s; first "
            f"call incl. compile {compile_s:.1f} s); ")
        print(f"n=2^{k}: {len(fset)} frequencies; {grads}synthesize {steps} steps: "
              f"{wall:.1f} s wall, {cpu:.1f} s CPU (load average {load:.1f}); "
              f"loss {result.history[0]:.3g} -> {result.final_loss:.3g}",
              flush=True)


if __name__ == "__main__":
    main()

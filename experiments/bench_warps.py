"""Benchmark: cost of a bilinear / biquadratic PSS warp on top of spherical-rectangle sampling.

Two workloads, each per million samples (H Sec. 4.1 reports +1% / +6% run time inside pbrt):

* ``sample``: one fixed light and shading point; ``sample_and_pdf`` (H Alg. 1) of the spherical
  rectangle alone, and composed after a bilinear / biquadratic warp with fixed values.
* ``fit+sample``: a different shading point per sample (as in a renderer): build the spherical
  rectangle, fit the PSS warp to the cosine at the point (H Eq. 9), sample, pdf.

Then the eager fits a user calls from Python, one shading point per call (``--fits`` points
after a first, compiling call): ``fit_least_squares`` and ``fit_min_variance`` (bilinear and
biquadratic), milliseconds per call; each compiles its solve once per family and shapes.

Prints, per technique, the best of ``--repeats`` runs after a warm-up (compilation) run, minimised
over ``--rounds`` round-robin rounds (so a burst of other load hits every technique alike). Not a
test: nothing is asserted.

    python experiments/bench_warps.py [--n 1000000] [--repeats 5] [--rounds 3]
"""

from __future__ import annotations

import os
import time

import common
import jax
import jax.numpy as jnp

import anisosample.warps as W

CORNER = jnp.asarray([-0.5, -0.4, 1.0], jnp.float32)
EU = jnp.asarray([1.2, 0.0, 0.1], jnp.float32)
EV = jnp.asarray([0.0, 0.9, 0.0], jnp.float32)
NORMAL = jnp.asarray([0.0, 0.0, 1.0], jnp.float32)


def best_time(fn, args, repeats):
    """Best wall time and best process CPU time (less sensitive to other load) of ``repeats``."""
    jax.block_until_ready(fn(*args))
    wall, cpu = [], []
    for _ in range(repeats):
        t, c = time.perf_counter(), time.process_time()
        jax.block_until_ready(fn(*args))
        wall.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)
    return min(wall), min(cpu)


def _cos(w):
    return jnp.maximum(jnp.dot(w, NORMAL), 0.0)


def chain(family, origin):
    rect = W.SphericalRectangle(CORNER, EU, EV, origin)
    if family is None:
        return rect
    return W.compose(W.fit_pointwise(family, _cos, [rect]), rect)


def main(argv=None):
    ap = common.parser("bench_warps", __doc__.splitlines()[0], scale=False, out=False,
        seed=None, fresh=False)
    ap.add_argument("--n", type=int, default=1_000_000)
    ap.add_argument("--repeats", type=int, default=5, help="timed runs per round")
    ap.add_argument("--fits", type=int, default=20, help="eager fits timed per technique")
    ap.add_argument("--rounds", type=int, default=3,
                    help="round-robin rounds over the techniques (min taken: robust to other load)")
    args = ap.parse_args(argv)
    key_u, key_p = jax.random.split(jax.random.key(0))
    u = jax.random.uniform(key_u, (args.n, 2), dtype=jnp.float32)
    origins = jax.random.uniform(key_p, (args.n, 3), minval=-1.0, maxval=1.0) * jnp.asarray(
        [1.0, 1.0, 0.0]
    )
    fixed_origin = jnp.asarray([0.1, -0.2, 0.0], jnp.float32)
    families = {"rectangle": None, "+ bilinear": W.Bilinear, "+ biquadratic": W.Biquadratic}
    print(f"device: {jax.devices()[0]}, {os.cpu_count()} CPUs; n = {args.n}; "
          f"load average {os.getloadavg()[0]:.1f}")
    cases = {}
    for workload in ("sample", "fit+sample"):
        for name, family in families.items():
            if workload == "sample":
                fn = jax.jit(lambda w, uu: jax.vmap(w.sample_and_pdf)(uu))
                cases[workload, name] = (fn, (chain(family, fixed_origin), u))
            else:
                fn = jax.jit(jax.vmap(lambda o, uu, k=family: chain(k, o).sample_and_pdf(uu)))
                cases[workload, name] = (fn, (origins, u))
    best = {}
    for _ in range(args.rounds):
        for case, (fn, fargs) in cases.items():
            t, c = best_time(fn, fargs, args.repeats)
            w0, c0 = best.get(case, (float("inf"), float("inf")))
            best[case] = (min(w0, t), min(c0, c))
    for (workload, name), (t, c) in best.items():
        per_m, cpu_m = t / args.n * 1e6, c / args.n * 1e6
        b_wall, b_cpu = best[workload, "rectangle"]
        extra = (
            ""
            if name == "rectangle"
            else f"  (wall {100 * (t / b_wall - 1):+.1f}%, cpu {100 * (c / b_cpu - 1):+.1f}%)"
        )
        print(
            f"{workload:11s} {name:14s} wall {per_m * 1e3:8.2f} ms, cpu {cpu_m * 1e3:8.2f} ms"
            f" per million samples{extra}"
        )
    eager_fits(origins[: args.fits + 1])
    print(f"load average after: {os.getloadavg()[0]:.1f}")


def eager_fits(origins):
    """Per call, after a first (compiling) call: eager fits at ``origins[1:]``, one each."""
    for fit in (W.fit_least_squares, W.fit_min_variance):
        for family in (W.Bilinear, W.Biquadratic):
            def one(o, fit=fit, family=family):
                rect = W.SphericalRectangle(CORNER, EU, EV, o)
                return jax.block_until_ready(fit(family, _cos, [rect]).values)

            t0 = time.perf_counter()
            one(origins[0])
            first = time.perf_counter() - t0
            t0 = time.perf_counter()
            for o in origins[1:]:
                one(o)
            per = (time.perf_counter() - t0) / max(len(origins) - 1, 1)
            print(f"eager fit   {fit.__name__:18s} {family.__name__:11s} first call "
                  f"{first:6.2f} s, then {1e3 * per:7.1f} ms per call ({len(origins) - 1} points)")


if __name__ == "__main__":
    main()

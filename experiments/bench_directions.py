"""Time principal-direction estimation for all blocks of a screen (W Sec. 5.3, W Sec. 7).

The paper's GPU figure: <= 20 ms for a 1280x1280 screen in 16x16-pixel blocks (6400 blocks,
96^2 integrand samples each, sampling included). Here the samples are given (an array of
7680 x 7680 values, one random straight edge per block) and only the estimation is timed:
histograms (Gaussian + Sobel + binning) and the fixed-kappa search, vmapped over all blocks.
Prints its figures; no assertions (STYLE: benchmarks live apart from tests).

    python experiments/bench_directions.py [--blocks 80] [--samples 96] [--repeats 3]
"""

from __future__ import annotations

import os
import time

import common
import jax
import jax.numpy as jnp

import anisosample as asp


def make_samples(key, blocks: int, s: int):
    """One straight edge at a random direction through a random point per block."""
    k1, k2 = jax.random.split(key)
    phi = jax.random.uniform(k1, (blocks, blocks), minval=0.0, maxval=jnp.pi)
    c = jax.random.uniform(k2, (blocks, blocks, 2), minval=0.3, maxval=0.7)
    x = asp.directions.block_grid(s)  # (s, s, 2)
    n = jnp.stack([jnp.cos(phi), jnp.sin(phi)], axis=-1)  # (b, b, 2)
    d = jnp.einsum("ijc,abc->abij", x, n) - jnp.sum(c * n, axis=-1)[:, :, None, None]
    v = (d > 0).astype(jnp.float32)  # (b, b, s, s)
    return v.transpose(0, 2, 1, 3).reshape(blocks * s, blocks * s)


def main(argv=None):
    ap = common.parser("bench_directions", __doc__.splitlines()[0], scale=False, out=False,
        seed=None, fresh=False)
    ap.add_argument("--blocks", type=int, default=80, help="blocks per side (80: 1280 px)")
    ap.add_argument("--samples", type=int, default=96, help="samples per block side")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--estimator", default="fixed", choices=["fixed", "gradient"])
    args = ap.parse_args(argv)
    samples = jax.block_until_ready(make_samples(jax.random.key(0), args.blocks, args.samples))
    nb = args.blocks * args.blocks
    print(f"device: {jax.devices()[0]}, cpu_count: {os.cpu_count()}")
    print(f"{nb} blocks x {args.samples}^2 samples = {samples.size / 1e6:.1f} M samples, "
          f"estimator={args.estimator}")

    def run():
        est = asp.directions.estimate_blocks(samples, k=2, samples_per_block=args.samples,
                                             estimator=args.estimator)
        return jax.block_until_ready(est)

    t0 = time.perf_counter()
    est = run()
    print(f"first call (compile + run): {time.perf_counter() - t0:.2f} s")
    times, cpu = [], []
    for _ in range(args.repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        est = run()
        times.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    print(f"estimate_blocks: wall best {min(times):.3f} s, median "
          f"{sorted(times)[len(times) // 2]:.3f} s over {args.repeats} runs "
          f"({min(times) / nb * 1e6:.1f} us per block); process CPU time best {min(cpu):.3f} s")
    print(f"load average (1 min) during the run: {os.getloadavg()[0]:.1f} "
          "(wall times on a shared machine are upper bounds)")
    print(f"blocks with >= 1 direction: {float(jnp.mean(jnp.any(est.valid, -1))):.3f}")


if __name__ == "__main__":
    main()

"""Benchmark: value + gradient of a spectrum loss at n = 2^16 over ~50,000 frequencies,
direct sum vs NUFFT paths, in one run; and sampler generation times at n = 2^16.

Prints seconds (best of a few runs after compilation). Target (issue 2): NUFFT >= 30x faster
than the direct sum on a 2-core CPU.
"""

from __future__ import annotations

import common
import jax
import jax.numpy as jnp
import numpy as np

import anisosample as asp
from anisosample import spectrum


def main(argv=None):
    p = common.parser("bench_spectrum", __doc__, scale=False, out=False, seed=None,
        fresh=False)
    p.add_argument("--log2n", type=int, default=16)
    p.add_argument(
        "--radius",
        type=int,
        default=158,
        help="frequency grid half-width (158: ~50,000 half-plane frequencies)",
    )
    p.add_argument(
        "--direct-fraction",
        type=float,
        default=0.125,
        help="time the direct sum on this fraction of the frequencies and scale up "
        "(its cost is linear in their number); 1 times all of them",
    )
    p.add_argument("--repeats", type=int, default=3)
    args = p.parse_args(argv)
    n = 1 << args.log2n
    key = jax.random.key(0)
    pts = asp.samplers.get("pmj02bn")(key, n)
    freqs = spectrum.frequency_grid(args.radius)
    freqs = freqs[(freqs[:, 1] > 0) | ((freqs[:, 1] == 0) & (freqs[:, 0] > 0))]  # half plane
    m = freqs.shape[0]
    print(
        f"device: {jax.devices()[0]}, n = {n}, frequencies = {m} (half plane of radius "
        f"{args.radius})"
    )
    # a thin strip along 30 degrees, where the type-3 path shines
    t = np.radians(30.0)
    along = np.arange(1, 4 * int(np.sqrt(n)))
    strip = np.unique(
        np.concatenate(
            [
                np.stack(
                    [
                        np.rint(along * np.cos(t) - w * np.sin(t)),
                        np.rint(along * np.sin(t) + w * np.cos(t)),
                    ],
                    1,
                )
                for w in (-1, 0, 1)
            ]
        ).astype(np.int32),
        axis=0,
    )

    results = {}
    for label, f, methods in [
        ("grid", freqs, ["direct", "nufft1", "nufft3"]),
        ("strip30", strip, ["direct", "nufft1", "nufft3"]),
    ]:
        for method in methods:
            scale = 1.0
            f_all = f
            if method == "direct" and args.direct_fraction < 1.0:
                k = max(1, int(round(args.direct_fraction * f_all.shape[0])))
                f = f_all[np.random.default_rng(0).permutation(f_all.shape[0])[:k]]
                scale = f_all.shape[0] / k
            vg = jax.jit(
                jax.value_and_grad(
                    lambda q, f=f, method=method: jnp.sum(
                        spectrum.power_spectrum(q, f, method=method)
                    )
                )
            )
            # jax-finufft's rules need standard promotion; the benchmark runs with defaults.
            sec = common.best_time(
                lambda vg=vg: jax.block_until_ready(vg(pts)),
                repeats=1 if method == "direct" else args.repeats,
            )
            note = ""
            if scale != 1.0:
                note = f"  (measured {sec:.3f} s on {f.shape[0]} freqs, scaled x{scale:.2f})"
                sec *= scale
            f = f_all
            results[(label, method)] = sec
            print(
                f"  {label:8s} ({f.shape[0]:6d} freqs) {method:7s} value+grad: {sec:9.4f} s{note}"
            )
        d = results[(label, "direct")]
        best = min(results[(label, "nufft1")], results[(label, "nufft3")])
        print(f"  {label}: best NUFFT path is {d / best:.0f}x faster than the direct sum")

    print(f"sampler generation at n = {n} (fresh key each run; pmj02/pmj02bn uncached):")
    for name in asp.samplers.BASELINES:
        s = asp.samplers.get(name)
        counter = iter(range(1, 10**6))

        def gen(s=s, counter=counter):
            jax.block_until_ready(s(jax.random.key(next(counter)), n))

        print(f"  {name:11s} {common.best_time(gen, repeats=args.repeats):8.4f} s")


if __name__ == "__main__":
    main()

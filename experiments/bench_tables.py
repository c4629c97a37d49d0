"""Benchmark: aligned point-set tables (W Sec. 5.4) on this machine.

Default (``--direction-count 4``): the 4-direction sets *on demand*, as a user meets them. For
``--sets``
canonical 4-direction sets spread over the 4,141 (every ``4141 // sets``-th; ``--block K``:
runs of ``K`` consecutive sets, as a whole table's build meets them), each is looked up
with default arguments (``tables.lookup``) in an empty user cache, so each is synthesized (warm-
started from the shipped 3-direction table where there is one, else cold), written and verified;
prints each set's wall time (compilation included) and the number of XLA compilations it caused
(a set whose box shapes an earlier set had compiles nothing new), their mean, median and max,
and the 4,141-set table projected from the mean. ``--batch B`` times the same sets
through ``tables.build(..., batch=B)`` instead (groups of ``B`` sets per loop);
``--processes P`` times the table's one command, ``anisosample tables build --n N --direction-count
4 --processes P``, on the same sets (P local workers, each pinned to its share of the cores).

``--compare-warm``: the warm start against a cold start (see :func:`_compare_warm`).

``--direction-count 3``: time one set at ``--short`` and one at ``--long`` steps, fit
``t = fixed + steps * per_step`` and project the 46-set table.

Targets (issue 16, 2 CPU cores): one 4-direction n = 4096 set on demand <= 10 s; the 4,141-set
table <= 2 h projected from >= 20 sets. The machine is shared: the load average is printed before
and after (other work inflates the wall times); run it under ``nice -n 10``.

    python experiments/bench_tables.py [--n 4096] [--direction-count 4 --sets 20]
        [--batch B | --processes P]
    python experiments/bench_tables.py --direction-count 3 [--short 10 --long 40]
    python experiments/bench_tables.py --compare-warm [--pairs 2]
"""

from __future__ import annotations

import math
import os
import statistics
import subprocess
import sys
import tempfile
import time

import common
import jax
import numpy as np

import anisosample as asp
from anisosample import _table_build, tables

_COMPILES = [0]


def _count_compiles():
    """Count XLA compilations (``jax_log_compiles`` messages) from here on."""
    import logging

    class _Counter(logging.Handler):
        def emit(self, record):
            if record.getMessage().startswith("Finished XLA compilation"):
                _COMPILES[0] += 1

    jax.config.update("jax_log_compiles", True)
    log = logging.getLogger("jax")
    log.addHandler(_Counter())
    log.propagate = False  # counted, not printed


def _four_direction(args):
    canon = tables.canonical_sets(4)
    runs = max(1, args.sets // args.block)  # runs of --block consecutive sets, spread evenly
    step = max(1, len(canon) // runs)
    pick = [canon[i + j] for i in range(step // 2, len(canon) - args.block + 1, step)
            for j in range(args.block)][: args.sets]
    src = _table_build.warm_source(args.n)
    print(f"{len(pick)} canonical 4-direction sets, {runs} run(s) of {args.block} consecutive "
          f"one(s), every {step}th; warm start from "
          f"{src.path if src is not None else 'nothing (cold)'}")
    with tempfile.TemporaryDirectory() as tmp:
        os.environ["XDG_CACHE_HOME"] = tmp  # an empty user cache: every lookup builds
        times, cpu = [], []
        c_all = time.process_time()
        if args.processes > 1:  # the table's one command, on P local pinned workers
            spec = ",".join(":".join(str(a) for a in e) for e in pick)
            cmd = [sys.executable, "-m", "anisosample", "tables", "build", "--n", str(args.n),
                   "--direction-count", "4", "--sets", spec, "--processes", str(args.processes),
                   "--out", os.path.join(tmp, "d4"), "--no-progress"]
            t0 = time.perf_counter()
            done = subprocess.run(cmd, capture_output=True, text=True)
            if done.returncode:
                raise SystemExit(done.stderr)
            c_all = None  # the workers' CPU time is theirs, not this process's
            wall = time.perf_counter() - t0
            times = [wall / len(pick)] * len(pick)
            print(f"{' '.join(cmd[1:6])} ... --processes {args.processes}: {wall:.1f} s for "
                  f"{len(pick)} sets (each worker's first set compiles)")
        elif args.batch > 1:
            t0 = time.perf_counter()
            tables.build(args.n, 4, out=tables.cache_dir() / tables.table_name(4, args.n),
                         sets=pick, batch=args.batch, warm_start=True, show_progress=True)
            times = [(time.perf_counter() - t0) / len(pick)] * len(pick)
            print(f"batch {args.batch}: {time.perf_counter() - t0:.1f} s for {len(pick)} sets")
        else:
            _count_compiles()
            for e in pick:
                t0, p0 = time.perf_counter(), time.process_time()
                c0 = _COMPILES[0]
                tables.ensure([[0, 90, *e]], args.n, show_progress=False)
                times.append(time.perf_counter() - t0)
                cpu.append(time.process_time() - p0)
                print(f"  set {tables.set_name(e)}: {times[-1]:.1f} s ({cpu[-1]:.1f} CPU s), "
                      f"{_COMPILES[0] - c0} compilations (load average "
                      f"{os.getloadavg()[0]:.1f})", flush=True)
        if c_all is not None:
            c_all = time.process_time() - c_all
    mean = statistics.fmean(times)
    print(f"per set on demand: mean {mean:.1f} s, median {statistics.median(times):.1f} s, "
          f"max {max(times):.1f} s")
    print(f"projected 4141-set table: {len(canon) * mean / 3600:.2f} h (from {len(pick)} sets)")
    if c_all is None:
        return
    # the wall time counts the other work on a shared machine; the CPU time does not: on the
    # machine's cores alone (the terms of a step run in parallel), a set takes CPU / cores
    cores = os.cpu_count() or 1
    per = c_all / len(pick)
    print(f"CPU per set {per:.1f} s; on {cores} otherwise idle cores: {per / cores:.1f} s per set, "
          f"4141-set table {len(canon) * per / cores / 3600:.2f} h")


def _compare_warm(args):
    """Warm (from the 3-direction table) vs cold (jittered) 4-direction sets at n = 256 and
    4096: the final loss, the band energy along every line and the variance of an edge at the
    first extra direction, with the two-point slope of that variance from 256 to 4096.
    ``--neighbour-steps S``: also sets started from the nearest 4-direction set, ``(a, b - 1)``
    (itself warm-started with :data:`~anisosample._table_build.WARM_STEPS` steps), run for ``S``
    steps at ``--neighbour-lr``: the warm start a table could chain, measured, not used."""
    pairs = [(16, 146), (33, 43), (61, 118)][: args.pairs]
    ns = (256, 4096)
    var = {}
    for a, b in pairs:
        dirs = (0, 90, a, b)
        f = asp.integrands.edges([float(a)])
        for n in ns:
            src = _table_build.warm_source(n)
            start = _table_build.warm_points(n, (a, b), src.settings["fingerprint"])
            runs = {("cold" if len(args.cold_keys) == 1 else f"cold key {k}"): {"key": k}
                    for k in args.cold_keys}
            for steps in args.warm_steps:
                for prec in args.precisions:
                    label = f"warm {steps}" + (f" {prec}" if len(args.precisions) > 1 else "")
                    runs[label] = dict(initial_points=start, steps=steps, nufft_precision=prec,
                                       learning_rate=_table_build.WARM_LEARNING_RATE)
            if args.neighbour_steps:
                start4 = _table_build.warm_points(n, (a, b - 1), src.settings["fingerprint"])
                near = asp.synthesize(jax.random.key(1), n, (0, 90, a, b - 1),
                                      show_progress=False, initial_points=start4,
                                      steps=_table_build.WARM_STEPS,
                                      learning_rate=_table_build.WARM_LEARNING_RATE)
                for steps in args.neighbour_steps:
                    runs[f"neighbour {steps}"] = dict(initial_points=np.asarray(near.points),
                                                      steps=steps,
                                                      learning_rate=args.neighbour_lr)
            for label, kw in runs.items():
                kw = dict(kw)
                t0 = time.perf_counter()
                r = asp.synthesize(jax.random.key(kw.pop("key", 1)), n, dirs,
                                   show_progress=False, **kw)
                sec = time.perf_counter() - t0
                pts = r.points

                def sampler(key, m, pts=pts):
                    return asp.samplers.toroidal_shift(key, pts)

                v = asp.variance.estimator_variance(f, sampler, n, jax.random.key(2), 512,
                                                    f.integral)
                var[(a, b, n, label)] = v
                bands = [round(asp.diagnostics.band_energy(pts, d, min(32.0, n**0.5)), 4)
                         for d in dirs]
                print(f"{dirs} n={n} {label}: {len(r.history) - 1} steps {sec:.1f} s, loss "
                      f"{r.final_loss:.5f}, band n P_S (|v| <= {min(32, int(n**0.5))}) {bands}, "
                      f"edge {a} deg variance {v:.3e} (load {os.getloadavg()[0]:.1f})",
                      flush=True)
        for label in runs:
            slope = math.log(var[(a, b, 4096, label)] / var[(a, b, 256, label)]) / math.log(16)
            print(f"{dirs} {label}: edge variance slope 256 -> 4096: {slope:.2f}")


def _three_direction(args):
    steps = asp.synthesis.recipe_defaults(args.recipe)["steps"]

    def time_sets(sets, steps):
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            tables.build(args.n, 3, out=tmp, sets=sets, steps=steps, recipe=args.recipe,
                         show_progress=False)
            return time.perf_counter() - t0

    t_short = time_sets([(20,)], args.short)
    t_long = time_sets([(21,)], args.long)
    per_step = max(t_long - t_short, 0.0) / (args.long - args.short)
    fixed = max(t_short - args.short * per_step, 0.0)
    per_set = fixed + steps * per_step
    print(f"measured: {t_short:.1f} s at {args.short} steps, {t_long:.1f} s at {args.long} "
          f"steps -> {per_step:.3f} s per step + {fixed:.1f} s per set (compile, setup)")
    print(f"projected per set at {steps} steps: {per_set:.1f} s; 46-set table "
          f"{46 * per_set / 60:.1f} min")


def main(argv=None):
    p = common.parser("bench_tables", __doc__.splitlines()[0], scale=False, out=False,
        seed=None, fresh=False)
    p.add_argument("--n", type=int, default=4096)
    p.add_argument("--direction-count", type=int, default=4, choices=[3, 4])
    p.add_argument("--sets", type=int, default=20, help="4-direction sets to time")
    p.add_argument("--block", type=int, default=1,
                   help="time runs of this many consecutive canonical sets (a whole table's "
                        "build meets the box shapes of its neighbours, compiled once; spread "
                        "single sets each compile their own)")
    p.add_argument("--batch", type=int, default=1, help="sets per loop (4 directions)")
    p.add_argument("--processes", type=int, default=1,
                   help="time `anisosample tables build --processes P` (4 directions) instead")
    p.add_argument("--recipe", default="rate", choices=["rate", "paper"])
    p.add_argument("--short", type=int, default=10, help="steps of the short run (3 directions)")
    p.add_argument("--long", type=int, default=40, help="steps of the long run (3 directions)")
    p.add_argument("--compare-warm", action="store_true",
                   help="warm vs cold 4-direction sets at n = 256 and 4096 (quality, edge slope)")
    p.add_argument("--pairs", type=int, default=2, help="direction pairs for --compare-warm")
    p.add_argument("--warm-steps", type=int, nargs="+", default=[_table_build.WARM_STEPS],
                   help="step counts of the warm starts --compare-warm measures")
    p.add_argument("--cold-keys", type=int, nargs="+", default=[1],
                   help="--compare-warm: keys of the cold sets (several: their spread is the "
                        "set-to-set noise the warm starts are judged against)")
    p.add_argument("--precisions", nargs="+", default=["double"],
                   choices=["double", "single"],
                   help="--compare-warm: the warm starts' nufft_precision (each one measured)")
    p.add_argument("--neighbour-steps", type=int, nargs="*", default=[],
                   help="--compare-warm: also start from the set (a, b - 1), for these steps")
    p.add_argument("--neighbour-lr", type=float, default=0.05,
                   help="learning rate of the --neighbour-steps runs")
    args = p.parse_args(argv)
    print(f"devices: {len(jax.local_devices())} x {jax.devices()[0].platform}, "
          f"cpu_count {os.cpu_count()}, load average {os.getloadavg()}, n = {args.n}")
    if args.compare_warm:
        _compare_warm(args)
    else:
        (_four_direction if args.direction_count == 4 else _three_direction)(args)
    print(f"load average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()

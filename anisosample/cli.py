"""The ``anisosample`` command, for people who never open Python.

Each subcommand is a pair of functions: ``_add_NAME(subparsers)`` declares its arguments and
``_run_NAME(args)`` does the work by calling the library. Errors from the library (bad input,
missing or damaged files, refusing to overwrite, too large a request) become a one-line message
and exit status 2; so do argparse's own errors.

Building the parser imports neither JAX nor NumPy, so ``anisosample --help`` and every
subcommand's ``--help`` answer at once: ``_add_NAME`` takes its lists of names from
``anisosample._names`` and imports the library only inside ``_run_NAME``
(``tests/test_cli.py::test_help_does_not_import_jax`` holds this).
"""

from __future__ import annotations

import argparse
import math
import os
import re
import sys
from pathlib import Path


def _int_list(text: str) -> list[int]:
    try:
        return [int(t) for t in text.split(",") if t.strip()]
    except ValueError as exc:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated integers, got {text!r}"
        ) from exc


def _float_list(text: str) -> list[float]:
    try:
        values = [float(t) for t in text.split(",") if t.strip()]
    except ValueError as exc:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated numbers, got {text!r}"
        ) from exc
    if not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"expected finite numbers, got {text!r}")
    return values


def _finite_float(text: str) -> float:
    """argparse's ``float`` without NaN and infinities (``float("nan")`` parses)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def _seed(text: str) -> int:
    """A seed for ``jax.random.key``: an integer in [0, 2^32) (larger ones wrap around to the
    keys of small seeds without x64: ``key(2**32)`` is ``key(0)``)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer seed, got {text!r}") from None
    if not 0 <= value < 2**32:
        raise argparse.ArgumentTypeError(f"seeds must lie in [0, 2^32), got {value}")
    return value


# --- points ------------------------------------------------------------------------------------

_POINT_OUTPUTS = (".npy", ".npz", ".txt", ".csv", ".dat", ".bin", ".png")
_POINT_FORMATS = ("npy", "npz", "txt", "csv", "utk", "utk-bin")  # io.POINT_FORMATS, JAX-free


def _add_format_option(p):
    """``--format``: the point file format, for outputs whose suffix leaves a choice."""
    p.add_argument("--format", default=None, choices=_POINT_FORMATS,
                   help="point file format (default: by the suffix: .npy, .npz, .txt, .csv, "
                        ".dat = UTK text, .bin = UTK binary); 'utk' writes UTK's text format "
                        "(one 'x y' a line, sets separated by a '#' line) under .txt or .dat, "
                        "'utk-bin' its binary format (.bin)")


def _add_no_build(p):
    """``--no-build``: the one rule for aligned sets no table holds (tables.lookup's
    ``build_missing``) -- built on demand into the user cache with progress by default."""
    p.add_argument("--no-build", action="store_true",
                   help="aligned: refuse (naming the `anisosample tables build` command) "
                        "instead of synthesizing sets no table holds into the user cache "
                        "(default: build them on demand, with progress)")


def _add_directional_options(p):
    """``--directions`` (aligned) and ``--direction``/``--base`` (sheared), shared by the
    subcommands that make samplers by name."""
    p.add_argument("--directions", type=_float_list, default=None,
                   help="aligned: the set's spectral directions in degrees, e.g. 0,90,30 (the "
                        "axes are always in a table's sets; others are rounded to integers)")
    p.add_argument("--direction", type=_finite_float, default=None,
                   help="sheared: the spectral direction in degrees [0, 180) to shear to")
    p.add_argument("--base", default="pmj02bn",
                   help="sheared: the baseline sampler that is sheared")
    _add_no_build(p)


def _add_points(sub):
    from ._names import BASELINES, DIRECTIONAL_SAMPLERS

    p = sub.add_parser("points", help="generate a point set with a baseline, aligned or sheared "
                                      "sampler")
    p.add_argument("sampler", help=f"one of: {', '.join(BASELINES + DIRECTIONAL_SAMPLERS)}")
    p.add_argument("-n", type=int, required=True, help="number of points")
    p.add_argument("--seed", type=_seed, default=0, help="integer seed of the JAX key")
    p.add_argument("--shift", action="store_true", help="apply a random toroidal shift")
    _add_directional_options(p)
    p.add_argument("-o", "--output", required=True,
                   help="output .npy, .npz (with metadata), .txt ('x y' a line), .csv ('x,y' a "
                        "line), .dat / .bin (UTK text / binary) or .png (a scatter plot of the "
                        "set)")
    _add_format_option(p)
    p.add_argument("--force", action="store_true", help="overwrite an existing output")


def _make_sampler(name, args, option="--sampler", *, only=True):
    """The sampler ``name`` with the directional options of ``args``: ``aligned`` needs
    ``--directions`` (a set no table holds is built on demand into the user cache, with
    progress; ``--no-build`` refuses, naming the command that builds it), ``sheared`` needs
    ``--direction``; a baseline takes neither (when it is the ``only`` sampler named, giving
    them is an error)."""
    from . import samplers

    given = [flag for flag, value in (("--directions", args.directions),
                                      ("--direction", args.direction)) if value is not None]
    if name == "aligned":
        if args.directions is None:
            raise ValueError(f"{option} aligned needs --directions, the set's spectral "
                             "directions in degrees, e.g. --directions 0,90,30")
        return samplers.get("aligned", directions_deg=args.directions,
                            build_missing=False if getattr(args, "no_build", False) else None)
    if name == "sheared":
        if args.direction is None:
            raise ValueError(f"{option} sheared needs --direction, the spectral direction in "
                             "degrees [0, 180) to shear to, e.g. --direction 30")
        return samplers.get("sheared", base=args.base, direction_deg=args.direction)
    sampler = samplers.get(name)  # an unknown name lists the known ones
    if given and only:
        raise ValueError(f"{' and '.join(given)} {'apply' if len(given) > 1 else 'applies'} to "
                         f"the aligned or sheared sampler, not to {name!r}")
    return sampler


def _run_points(args):
    from . import io

    out = Path(args.output)
    if out.suffix.lower() not in _POINT_OUTPUTS:
        raise ValueError(f"--output must end in {', '.join(_POINT_OUTPUTS)}, got {out.name}")
    if out.suffix.lower() == ".png" and args.format is not None:
        raise ValueError("--format applies to point files, not to the .png picture")
    if out.suffix.lower() != ".png":
        io.point_format(out, args.format)  # a --format the suffix does not take: refused now
    if out.exists() and not args.force:
        raise FileExistsError(f"{out} exists; pass --force to replace it")
    if args.base != "pmj02bn" and args.sampler != "sheared":
        raise ValueError(f"--base applies to the sheared sampler, not to {args.sampler!r}")

    import jax

    from . import samplers

    sampler = _make_sampler(args.sampler, args, option="points")
    key = jax.random.key(args.seed)
    k_pts, k_shift = jax.random.split(key)
    pts = sampler(k_pts, args.n)
    if args.shift:
        pts = samplers.toroidal_shift(k_shift, pts)
    meta = {"sampler": args.sampler, "name": sampler.name, "n": args.n, "seed": args.seed,
            "shift": args.shift}
    if args.sampler == "aligned":
        meta["directions_deg"] = [0, 90, *sampler.directions_deg]
    if args.sampler == "sheared":
        meta.update(base=args.base, direction_deg=args.direction)
    if out.suffix.lower() == ".png":
        from . import plot

        plot.save_points_figure(out, pts, title=f"{sampler.name}, n = {args.n}",
                                overwrite=args.force)
    else:
        io.save_points(out, pts, meta, format=args.format, overwrite=args.force)
    print(f"wrote {args.n} {sampler.name} points to {out}")


def _add_points_option(p, what: str):
    p.add_argument("--points", dest="points_file", default=None, metavar="FILE",
                   help=f"{what}: a point file, .npy, .npz, .txt, .csv, UTK text (.dat, or "
                        ".txt with sets separated by '#' lines) or UTK binary (.bin); points "
                        "finite, in [0, 1)^2")


def _load_user_points(args, *, one: bool):
    """The user's point sets from ``--points FILE`` (or the positional file of ``spectrum``):
    a list of checked ``(n_i, 2)`` float32 sets; ``one``: the file must hold exactly one."""
    from . import io

    positional = getattr(args, "points", None)
    if positional is not None and args.points_file is not None:
        raise ValueError("give the point file once: as --points FILE or as the positional file")
    path = args.points_file if args.points_file is not None else positional
    if path is None:
        raise ValueError("--points FILE is required: the point set to measure")
    sets = io.load_point_sets(path)
    if one and len(sets) != 1:
        raise ValueError(f"{path} holds {len(sets)} point sets (n = "
                         f"{', '.join(str(len(s)) for s in sets)}); this command takes one set")
    return sets


# --- spectrum ----------------------------------------------------------------------------------


def _add_spectrum(sub):
    p = sub.add_parser("spectrum", help="power spectrum of a point set: a PNG figure (frequency "
                                        "axes, colour bar) or the raw P_S grid as EXR")
    p.add_argument("points", nargs="?", default=None,
                   help="point file (as --points; kept for older command lines)")
    _add_points_option(p, "the point set (one set)")
    p.add_argument("-o", "--output", required=True,
                   help="output .png (a figure of N P_S, white noise = 1) or .exr (raw P_S, "
                        "rows v_y)")
    p.add_argument("--radius", type=int, default=None,
                   help="half-width of the frequency grid (default: 2 sqrt(n))")
    p.add_argument("--method", default="auto", choices=["auto", "direct", "nufft1", "nufft3"],
                   help="spectrum engine: direct sum, type-1 NUFFT on lattice grids, type-3 "
                        "NUFFT, or auto (by size)")
    p.add_argument("--scale", default=None, choices=["linear", "log"],
                   help="PNG colour scale of N P_S, white noise = 1 (default: linear)")
    p.add_argument("--clip", type=_clip_option, default=None, metavar="X",
                   help="PNG: top of the colour range as a multiple of white noise, larger "
                        "values shown at it (default: 2); 'none' clips nothing")
    p.add_argument("--mark-directions", type=_float_list, default=None, metavar="DEG,DEG,...",
                   help="PNG: spectral directions in [0, 180) degrees to mark as dashed lines "
                        "through the origin, e.g. 0,90,30")
    p.add_argument("--force", action="store_true", help="overwrite an existing output")


def _clip_option(text: str) -> float | str:
    """``--clip``: a finite number > 0, or ``none`` (no clipping)."""
    if text.strip().lower() == "none":
        return "none"
    value = _finite_float(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"expected a number > 0 or 'none', got {text!r}")
    return value


def _run_spectrum(args):
    import numpy as np

    from . import plot, spectrum
    from ._validate import check_directions_deg

    pts = _load_user_points(args, one=True)[0]
    out = Path(args.output)
    if out.suffix not in (".png", ".exr"):
        raise ValueError(f"--output must end in .png or .exr, got {out.name}")
    if out.exists() and not args.force:
        raise FileExistsError(f"{out} exists; pass --force to replace it")
    # the picture's options, checked before the spectrum is computed
    given = [flag for flag, value in (("--scale", args.scale), ("--clip", args.clip),
                                      ("--mark-directions", args.mark_directions))
             if value is not None]
    if out.suffix == ".exr" and given:  # the raw P_S grid: the picture's options do not apply
        raise ValueError(f"{', '.join(given)} shape the PNG picture; the .exr output holds the "
                         "raw P_S grid")
    marks = check_directions_deg("--mark-directions", args.mark_directions or (),
                                 allow_empty=True)
    clip = 2.0 if args.clip is None else None if args.clip == "none" else args.clip
    n = pts.shape[0]
    radius = args.radius if args.radius is not None else max(8, int(2 * np.sqrt(n)))
    grid = spectrum.power_spectrum_grid(pts, radius, method=args.method)
    if out.suffix == ".exr":
        plot.save_spectrum_image(out, grid, n=n, overwrite=args.force)
    else:  # a figure: frequency axes, colour bar, marked directions (plot.spectrum_panel)
        plot.save_spectrum_figure(out, grid, n=n, scale=args.scale or "linear", clip=clip,
                                  directions_deg=marks, title=f"power spectrum, {n} points",
                                  overwrite=args.force)
    print(f"wrote the {2 * radius + 1}^2 power spectrum of {n} points to {out}")


# --- synthesize --------------------------------------------------------------------------------


def _add_synthesize(sub):
    p = sub.add_parser("synthesize", help="optimize a point set with dark spectral directions")
    p.add_argument("-n", type=int, required=True, help="number of points")
    p.add_argument("--directions", type=_float_list, required=True,
                   help="spectral directions in degrees, e.g. 0,90,30 (axes are not implied)")
    p.add_argument("--seed", type=_seed, default=0, help="integer seed of the JAX key")
    p.add_argument("--recipe", default="rate", choices=["rate", "paper"],
                   help="rate (default, reaches the rate) or paper (W Eqs. 10-15)")
    p.add_argument("--steps", type=int, default=None, help="optimizer steps (recipe default)")
    p.add_argument("--c", type=_finite_float, default=None, help="weight of the SW term (W Eq. 10)")
    p.add_argument("--learning-rate", type=_finite_float, default=None,
                   help="Adam step in units of 1/sqrt(n) (recipe default)")
    p.add_argument("-o", "--output", required=True,
                   help="output .npz (points + metadata), or any point file: .npy, .txt, "
                        ".csv, .dat / .bin (UTK text / binary; metadata kept as io.save_points "
                        "keeps it)")
    _add_format_option(p)
    p.add_argument("--checkpoint", default=None,
                   help="checkpoint .npz (default: OUTPUT.ckpt.npz); an interrupted run resumes")
    p.add_argument("--force", action="store_true", help="overwrite an existing output")


def _run_synthesize(args):
    import jax

    from . import io, synthesis

    out = Path(args.output)
    fmt = io.point_format(out, args.format)  # a suffix or --format no point file takes: refused
    if out.exists() and not args.force:
        raise FileExistsError(f"{out} exists; pass --force to replace it")
    ckpt = args.checkpoint or str(out.with_suffix(".ckpt.npz"))
    result = synthesis.synthesize(
        jax.random.key(args.seed), args.n, args.directions, recipe=args.recipe,
        steps=args.steps, c=args.c, learning_rate=args.learning_rate, checkpoint=ckpt,
    )
    info = dict(result.info, seed=args.seed)
    if fmt == "npz":
        synthesis.save_result(out, result.points, info, overwrite=args.force)
    else:  # a point file for other tools (UTK): the points, and the record where it fits
        io.save_points(out, result.points, info, format=fmt, overwrite=args.force)
    print(f"wrote {args.n} points optimized for {args.directions} deg to {out}"
          f" (loss {info['history'][0]:.3g} -> {info['final_loss']:.3g})")


# --- directions --------------------------------------------------------------------------------


def _add_directions(sub):
    p = sub.add_parser(
        "directions",
        help="principal (spectral) directions of a sampled integrand (W Sec. 5), per grid or "
             "per block",
    )
    p.add_argument("grid", help=".exr or .npy (h, w) grid of integrand samples")
    p.add_argument("-k", type=int, default=2, help="most extra directions per grid/block")
    p.add_argument("--block", type=int, default=None,
                   help="samples per block side: estimate per block (W Sec. 5.3, e.g. 96)")
    p.add_argument("-o", "--output", default=None,
                   help="per-block maps as a PNG figure (needs --block): one panel per "
                        "slot at the grid's size, y up, hue = 2 x direction (0 and 180 alike: "
                        "axial) with a half-wheel key, grey hatched = no estimate")
    p.add_argument("--top-down", action="store_true",
                   help="the grid's first row is the largest y (renderer images)")
    p.add_argument("--estimator", default="fixed", choices=["fixed", "gradient"],
                   help="W Sec. 5.2: fixed-kappa search or gradient fit of (mu, kappa)")
    _renamed_option(p, "--method", "--estimator")
    p.add_argument("--kappa", type=_finite_float, default=None,
                   help="vMF concentration (doubled angle)")
    p.add_argument("--threshold", type=_finite_float, default=None, help="confidence threshold")
    p.add_argument("--sigma", type=_finite_float, default=None, help="Gaussian sigma in grid cells")
    p.add_argument("--force", action="store_true", help="overwrite an existing output")


def _run_directions(args):
    import numpy as np

    from . import directions, io

    values = io.load_grid(args.grid, top_down=args.top_down)
    opts = {"estimator": args.estimator}
    for name, value in (("kappa", args.kappa), ("threshold", args.threshold),
                        ("sigma_px", args.sigma)):
        if value is not None:
            opts[name] = value
    out = None if args.output is None else Path(args.output)
    if out is not None:  # before the estimate, which takes seconds
        if args.block is None:
            raise ValueError("--output (per-block maps) needs --block")
        if out.suffix != ".png":
            raise ValueError(f"--output must end in .png, got {out.name}")
        if out.exists() and not args.force:
            raise FileExistsError(f"{out} exists; pass --force to replace it")
        if args.k < 1:
            raise ValueError(f"--output (per-block maps) needs -k >= 1, got {args.k}")
    if args.block is None:
        est = directions.estimate(values, k=args.k, details=True, **opts)
        found = [(float(d), float(c)) for d, c, v in
                 zip(est.directions_deg, est.confidence, est.valid, strict=True) if v]
        h, w = values.shape
        if not found:
            print(f"{args.grid} ({h}x{w}): no extra direction (besides 0 and 90 degrees)")
        for d, c in found:
            print(f"{d:.1f} deg (confidence {c:.3f})")
        return
    est = directions.estimate_blocks(values, k=args.k, samples_per_block=args.block, **opts)
    v = np.asarray(est.valid)
    by, bx = v.shape[:2]
    counts = np.bincount(v.sum(axis=-1).reshape(-1), minlength=args.k + 1)
    print(f"{by}x{bx} blocks of {args.block}^2 samples; blocks with 0..{args.k} extra "
          f"directions: {counts.tolist()}")
    if args.output is not None:
        from . import plot

        # one panel per slot at the grid's size, row 0 (smallest y) at the bottom as in
        # DESIGN's grid convention, axial hue with its half-wheel key, no-estimate blocks hatched
        plot.save_direction_map(out, est, block=args.block, shape=values.shape, origin="lower",
                                overwrite=args.force)
        print(f"wrote per-block direction maps to {out}")


# --- tables ------------------------------------------------------------------------------------


def _add_tables(sub):
    p = sub.add_parser("tables", help="aligned point-set tables (W Sec. 5.4): build, info")
    tsub = p.add_subparsers(dest="tables_command", required=True, metavar="ACTION")
    b = tsub.add_parser("build", help="synthesize every canonical set (resumable)")
    b.add_argument("--n", type=int, required=True, help="points per set")
    b.add_argument("--direction-count", type=int, choices=[3, 4], default=3,
                   help="3 (axes + 1 direction, 46 sets) or 4 (axes + 2, 4141 sets)")
    _renamed_option(b, "--directions", "--direction-count")
    b.add_argument("--out", default=None,
                   help="table directory (default: the user cache, see tables.cache_dir())")
    b.add_argument("--seed", type=_seed, default=0, help="integer seed of the JAX key")
    b.add_argument("--sets", default=None,
                   help="only these canonical sets, e.g. 0,30,45 or 10:20;0:45 (default: all)")
    b.add_argument("--recipe", default=None, choices=["rate", "paper"])
    b.add_argument("--steps", type=int, default=None, help="optimizer steps (recipe default)")
    b.add_argument("--prefix", default=None,
                   help="fixed isotropic first points of every set (W Sec. 7): dihedral-<m>, "
                        "e.g. dihedral-64 (anisosample.prefix); default none")
    b.add_argument("--sequence-from", type=int, default=None,
                   help="build progressive sequences whose every power-of-two prefix from this "
                        "size up is aligned (synthesize_sequence), e.g. 256; default: sets")
    b.add_argument("--checkpoint-every", type=int, default=25,
                   help="synthesis checkpoint interval in steps")
    b.add_argument("--batch", type=int, default=1,
                   help="sets per optimizer loop (synthesize_batch; 1: synthesize per set)")
    b.add_argument("--warm-start", action=argparse.BooleanOptionalAction, default=None,
                   help="4-direction table: start each set from the 3-direction table's set "
                        "(default: the existing table's choice, else on for 4 directions, as "
                        "the on-demand lookups build)")
    _add_distributed(b, "build", "a whole table")
    b.add_argument("--no-progress", action="store_true", help="no progress bar")
    i = tsub.add_parser("info", help="describe and verify a table directory")
    i.add_argument("path", help="table directory (holds table.json)")
    e = tsub.add_parser("export", help="write a table's sets to one point file (UTK text or "
                                       "binary, .npz, ...) for other tools")
    e.add_argument("--n", type=int, required=True, help="points per set")
    e.add_argument("--direction-count", type=int, choices=[3, 4], default=3,
                   help="3 (axes + 1 direction) or 4 (axes + 2)")
    _renamed_option(e, "--directions", "--direction-count")
    e.add_argument("--sets", default=None,
                   help="the sets' extra directions, e.g. 30,45,120 or 10:20,0:45 (any integer "
                        "degrees, reduced by symmetry as lookups do; missing sets are built on "
                        "demand unless --no-build); default: every canonical set the table "
                        "holds")
    e.add_argument("--table", default=None,
                   help="table directory or folder of tables (default: the search path)")
    e.add_argument("--no-build", action="store_true",
                   help="with --sets: refuse sets no table holds instead of building them")
    e.add_argument("-o", "--output", required=True,
                   help="output point file: .dat or .txt with --format utk (UTK text, sets "
                        "separated by '#'), .bin (UTK binary), .npz, .npy or .txt")
    _add_format_option(e)
    e.add_argument("--force", action="store_true", help="overwrite an existing output")


def _parse_sets(text):
    """``"0,30,45"`` -> [(0,), (30,), (45,)]; pairs as ``"10:20,0:45"``."""
    if text is None:
        return None
    try:
        return [tuple(int(a) for a in part.split(":")) for part in text.split(",") if part.strip()]
    except ValueError:
        raise ValueError(f"--sets must look like 0,30,45 or 10:20,0:45, got {text!r}") from None


def _add_distributed(p, verb: str, what: str) -> None:
    """The flags that spread one command over processes: ``--processes`` (local workers joined
    by jax.distributed) and ``--distributed`` with its coordinator (several hosts)."""
    p.add_argument("--processes", type=int, default=1,
                   help="local worker processes, each pinned to its share of the cores and "
                        f"joined by jax.distributed on a localhost coordinator (one command to "
                        f"{verb} {what} on one machine; 2 on a 2-core machine)")
    p.add_argument("--distributed", action="store_true",
                   help="call jax.distributed.initialize() first (several hosts, each running "
                        "this command)")
    p.add_argument("--coordinator", default=None,
                   help="with --distributed: coordinator host:port (else auto-detected, e.g. "
                        "SLURM)")
    p.add_argument("--num-processes", type=int, default=None,
                   help="with --distributed: number of processes (hosts)")
    p.add_argument("--process-id", type=int, default=None,
                   help="with --distributed: this process's id in 0..num_processes-1")


def _init_distributed(args, *, collectives: bool = False) -> None:
    """In a ``--processes`` worker, pin it to its cores; with ``--distributed``, check the
    coordinator flags and join (``collectives``: CPU collectives across processes (gloo), which
    a sharded render's gather needs), before anything touches the XLA backend."""
    affinity = os.environ.pop(_AFFINITY_ENV, None)
    if affinity:  # a worker of --processes: its share of the cores, before any thread starts
        os.sched_setaffinity(0, {int(c) for c in affinity.split(",")})
    given = [a is not None for a in (args.coordinator, args.num_processes, args.process_id)]
    if any(given) and not args.distributed:
        raise ValueError("--coordinator, --num-processes and --process-id need --distributed")
    if not args.distributed:
        return
    import jax

    if any(given) and not all(given):
        raise ValueError("--coordinator, --num-processes and --process-id go together")
    if collectives:
        jax.config.update("jax_cpu_collectives_implementation", "gloo")
    if all(given):
        if args.num_processes < 1 or not 0 <= args.process_id < args.num_processes:
            raise ValueError(f"--process-id must lie in 0..{args.num_processes - 1} and "
                             f"--num-processes be >= 1, got {args.process_id} of "
                             f"{args.num_processes}")
        jax.distributed.initialize(args.coordinator, args.num_processes, args.process_id)
    else:
        jax.distributed.initialize()


def _run_tables(args):
    from . import tables

    if args.tables_command == "export":
        return _run_tables_export(args)
    if args.tables_command == "info":
        tab = tables.open_table(args.path)
        sets = tables.canonical_sets(tab.direction_count)
        have = [e for e in sets if tab.has(e)]
        for e in have:
            tab.load(e)
        missing = tab.missing()
        print(f"{tab.path}: {tab.direction_count}-direction table, n={tab.n}, "
              f"{len(have)}/{len(sets)} sets "
              f"(all verified), complete={tab.complete}, seed={tab.settings['seed']}, "
              f"synthesis={tab.settings['synthesis']}"
              + (f"; missing: {', '.join(tables.set_name(e) for e in missing[:8])}"
                 + (f" and {len(missing) - 8} more" if len(missing) > 8 else "")
                 if missing else ""))
        return
    if args.processes != 1:
        _check_processes(args)
        out = Path(args.out) if args.out else tables.cache_table_path(
            args.direction_count, args.n, args.prefix or "none", args.sequence_from or 0)
        if (out / "table.json").exists():  # a damaged or foreign table: one message, not P
            tables.open_table(out, n=args.n, direction_count=args.direction_count)
        _run_local_processes(args.processes, lambda pid, port: _worker_argv(args, pid, port),
                             after_failure="; the same command resumes what they finished")
        tab = tables.open_table(out)
        sets = tables.canonical_sets(tab.direction_count)
        print(f"table {tab.path}: {args.processes} local processes done; "
              f"{sum(tab.has(e) for e in sets)}/{len(sets)} sets, complete={tab.complete}")
        return
    _init_distributed(args)
    opts = {k: v for k, v in (("recipe", args.recipe), ("steps", args.steps),
                              ("prefix", args.prefix), ("sequence_from", args.sequence_from))
            if v is not None}
    summary = tables.build(args.n, args.direction_count, out=args.out, seed=args.seed,
                           sets=_parse_sets(args.sets), checkpoint_every=args.checkpoint_every,
                           batch=args.batch, warm_start=args.warm_start,
                           show_progress=not args.no_progress, **opts)
    print(f"table {summary['path']}: built {len(summary['built'])} set(s) on "
          f"{len(summary['devices'])} device(s), kept {len(summary['skipped'])} finished one(s);"
          f" complete={summary['complete']}")


def _run_tables_export(args):
    """``tables export``: the requested sets (``--sets``, looked up as ``tables.lookup`` does)
    or every canonical set a table holds, in table order, to one point file with a record of
    each set's directions."""
    import numpy as np

    from . import io, tables

    out = Path(args.output)
    fmt = io.point_format(out, args.format)
    if out.exists() and not args.force:
        raise FileExistsError(f"{out} exists; pass --force to replace it")
    if args.sets is not None:
        extras = _parse_sets(args.sets)
        if not extras or any(len(e) != args.direction_count - 2 for e in extras):
            raise ValueError(f"--sets must give {args.direction_count - 2} extra direction(s) per "
                             f"set for a {args.direction_count}-direction table, got {args.sets!r}")
        requests = [[*tables.AXES_DEG, *e] for e in extras]
        tables.ensure(requests, args.n, direction_count=args.direction_count, table=args.table,
                      build_missing=False if args.no_build else (
                          True if args.table is not None else None))
        sets = [tables.lookup(r, args.n, direction_count=args.direction_count, table=args.table)
                for r in requests]
        dirs = [[*tables.AXES_DEG, *e] for e in extras]
        where = args.table or "the table search path"
    else:
        if args.no_build:
            raise ValueError("--no-build applies to --sets (without it, only the sets a table "
                             "holds are written)")
        path = tables.find_table(args.direction_count, args.n, root=args.table)
        if path is None:
            raise FileNotFoundError(
                f"no {args.direction_count}-direction table for n={args.n} in "
                f"{args.table or 'the table search path'}; build it with "
                f"`{tables.build_command(args.direction_count, args.n)}` or name sets with --sets")
        tab = tables.open_table(path)
        held = [e for e in tables.canonical_sets(tab.direction_count) if tab.has(e)]
        if not held:
            raise ValueError(f"table {path} holds no sets yet")
        sets = [tab.load(e) for e in held]
        dirs = [list(tables.set_directions(e)) for e in held]
        where = str(path)
    meta = {"what": f"aligned sets of the {args.direction_count}-direction table for n={args.n}",
            "n": args.n, "direction_count": args.direction_count, "directions_deg": dirs}
    io.save_points(out, [np.asarray(s) for s in sets], meta, format=fmt, overwrite=args.force)
    print(f"wrote {len(sets)} set(s) of {args.n} points from {where} to {out} "
          f"({'; '.join(','.join(str(d) for d in ds) for ds in dirs[:4])}"
          f"{' ...' if len(dirs) > 4 else ''})")


_AFFINITY_ENV = "ANISOSAMPLE_WORKER_CPUS"


def _worker_argv(args, pid: int, port: int) -> list[str]:
    """The ``tables build`` command line of local worker ``pid`` of ``--processes``."""
    argv = ["tables", "build", "--n", str(args.n), "--direction-count", str(args.direction_count),
            "--seed", str(args.seed), "--checkpoint-every", str(args.checkpoint_every),
            "--batch", str(args.batch), "--distributed", "--coordinator", f"127.0.0.1:{port}",
            "--num-processes", str(args.processes), "--process-id", str(pid)]
    for flag, value in (("--out", args.out), ("--sets", args.sets), ("--recipe", args.recipe),
                        ("--steps", args.steps), ("--prefix", args.prefix),
                        ("--sequence-from", args.sequence_from)):
        if value is not None:
            argv += [flag, str(value)]
    if args.warm_start is not None:
        argv.append("--warm-start" if args.warm_start else "--no-warm-start")
    if args.no_progress or pid:  # one progress bar: worker 0's share
        argv.append("--no-progress")
    return argv


def _die_with_parent():
    """In a ``--processes`` worker, before it runs (Linux): the kernel sends it SIGKILL when the
    parent dies (``prctl(PR_SET_PDEATHSIG)``), so a killed ``tables build`` leaves no workers."""
    import ctypes
    import signal

    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL))  # 1: PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def _check_processes(args) -> None:
    """``--processes P`` starts its own workers: ``P >= 1``, without the ``--distributed`` flags,
    and at most the usable cores (one each)."""
    from . import synthesis

    if args.processes < 1:
        raise ValueError(f"--processes must be >= 1, got {args.processes}")
    if args.distributed or any(a is not None for a in (args.coordinator, args.num_processes,
                                                        args.process_id)):
        raise ValueError("--processes starts its own local jax.distributed workers; it does not "
                         "go with --distributed, --coordinator, --num-processes or --process-id")
    cores = synthesis.usable_cpus()
    if args.processes > len(cores):
        raise ValueError(f"--processes must be at most the {len(cores)} usable cores, got "
                         f"{args.processes}")


def _run_local_processes(processes: int, worker_argv, *, quiet_others: bool = False,
                         after_failure: str = "") -> None:
    """``--processes P``: P workers on this machine, worker ``p`` running the command line
    ``worker_argv(p, port)`` (which joins jax.distributed on the localhost coordinator
    ``127.0.0.1:port``), each pinned to its share of the cores so the workers do not compete for
    them. A failed worker stops the others; a stopped parent takes them down
    (:func:`_die_with_parent`). ``quiet_others``: only worker 0 writes to stdout."""
    import socket
    import subprocess
    import time

    from . import synthesis

    cores = synthesis.usable_cpus()
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    procs = []
    try:
        for pid in range(processes):
            env = dict(os.environ)
            env[_AFFINITY_ENV] = ",".join(str(c) for c in cores[pid::processes])
            procs.append(subprocess.Popen(
                [sys.executable, "-m", "anisosample", *worker_argv(pid, port)], env=env,
                stdout=subprocess.DEVNULL if quiet_others and pid else None,
                preexec_fn=_die_with_parent if sys.platform.startswith("linux") else None))
        codes = [None] * len(procs)
        while None in codes:  # a failed worker stops the others (they would wait for it)
            codes = [p.poll() for p in procs]
            if any(c for c in codes if c is not None):
                break
            time.sleep(0.2)
    finally:
        for p in procs:
            if p.poll() is None:
                p.terminate()
        for p in procs:  # jax.distributed's preemption notice catches SIGTERM: then SIGKILL
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()
        codes = [p.wait() for p in procs]
    bad = [(i, c) for i, c in enumerate(codes) if c and c > 0] or [
        (i, c) for i, c in enumerate(codes) if c]
    if bad:
        raise RuntimeError(f"worker(s) {', '.join(str(i) for i, _ in bad)} of "
                           f"{processes} failed (exit {bad[0][1]}; their messages are "
                           f"above){after_failure}")


# --- variance ----------------------------------------------------------------------------------


def _add_variance(sub):
    from ._names import BASELINES, DIRECTIONAL_SAMPLERS, INTEGRAND_SPEC_HELP

    p = sub.add_parser("variance", help="estimator variance vs n on an analytic integrand")
    p.add_argument("--integrand", required=True, help=INTEGRAND_SPEC_HELP)
    p.add_argument("--sampler", default=None,
                   help="comma-separated; any of: "
                        f"{', '.join(BASELINES + DIRECTIONAL_SAMPLERS)} (default: "
                        f"{','.join(_DEFAULT_VARIANCE_SAMPLERS)}, or none with --points)")
    p.add_argument("--points", dest="points_files", action="append", default=None,
                   metavar="FILE",
                   help="your own point sets: a point file (.npy, .npz, .txt, .csv, UTK .dat / "
                        ".bin) with one fixed set per size, each shifted toroidally per "
                        "realization; repeat to compare several files")
    p.add_argument("--n", type=_int_list, default=None,
                   help="comma-separated sizes (default: 64,256,1024, or the sizes of the "
                        "--points sets)")
    p.add_argument("--realizations", type=int, default=1024,
                   help="independent estimates per sampler and n")
    p.add_argument("--randomization", default="auto",
                   choices=["auto", "shift", "fresh", "fresh+shift"],
                   help="auto: fresh for traceable samplers, shifts of fixed sets otherwise")
    p.add_argument("--patterns", type=int, default=1,
                   help="fixed sets per n for randomization 'shift'")
    p.add_argument("--seed", type=_seed, default=0, help="integer seed of the JAX key")
    _add_directional_options(p)
    p.add_argument("-o", "--output", action="append", default=None, metavar="FILE",
                   help="also write FILE: .json (the record) or .png (a convergence plot with "
                        "the fitted slopes and their intervals); repeat for both (default: "
                        "print the table only)")
    p.add_argument("--force", action="store_true", help="overwrite existing outputs")


_DEFAULT_VARIANCE_SAMPLERS = ("random", "jittered", "sobol-owen", "pmj02bn")


def _variance_outputs(args) -> list[Path]:
    """The ``-o`` files: .json or .png, each once, none existing unless ``--force``."""
    outs = [Path(o) for o in args.output or []]
    for out in outs:
        if out.suffix.lower() not in (".json", ".png"):
            raise ValueError(f"--output must end in .json or .png, got {out.name}")
    if len({o.suffix.lower() for o in outs}) != len(outs):
        raise ValueError("--output names two files of one kind; give at most one .json and one "
                         ".png")
    for out in outs:
        if out.exists() and not args.force:
            raise FileExistsError(f"{out} exists; pass --force to replace it")
    return outs


def _user_point_sets(args) -> dict[str, list]:
    """``--points`` files -> ``{label: sets}``, labelled by file name (the path if two names
    agree)."""
    from . import io

    files = args.points_files or []
    names = [Path(f).name for f in files]
    labels = [n if names.count(n) == 1 else str(f) for n, f in zip(names, files, strict=True)]
    if len(set(labels)) != len(labels):
        raise ValueError("--points names a file twice")
    return {label: io.load_point_sets(f) for label, f in zip(labels, files, strict=True)}


def _run_variance(args):
    import jax

    from . import integrands, io
    from . import variance as V

    outs = _variance_outputs(args)
    f = integrands.from_spec(args.integrand)
    mine = _user_point_sets(args)
    spec = args.sampler if args.sampler is not None else (
        "" if mine else ",".join(_DEFAULT_VARIANCE_SAMPLERS))
    names = [s.strip() for s in spec.split(",") if s.strip()]
    if not names and not mine:
        raise ValueError("--sampler must name at least one sampler (or give --points FILE)")
    if len(set(names)) != len(names):
        raise ValueError(f"--sampler names a sampler twice: {args.sampler!r}")
    clash = [name for name in names if name in mine]
    if clash:
        raise ValueError(f"--points file {clash[0]!r} has a sampler's name; rename the file")
    if args.patterns != 1 and not names:
        raise ValueError("--patterns counts the sets a named sampler draws per n; the sets of a "
                         "--points file are fixed (one per size)")
    if args.base != "pmj02bn" and "sheared" not in names:
        raise ValueError("--base applies to the sheared sampler, which --sampler does not name")
    chosen = {name: _make_sampler(name, args, only=False) for name in names}
    unused = [flag for flag, value, owner in (("--directions", args.directions, "aligned"),
                                              ("--direction", args.direction, "sheared"))
              if value is not None and owner not in names]
    if unused:
        raise ValueError(f"{' and '.join(unused)} given but --sampler names neither aligned nor "
                         "sheared")
    ns = args.n
    if ns is None:
        if mine:  # the sizes every --points file holds
            common = set.intersection(*({len(s) for s in sets} for sets in mine.values()))
            if not common:
                raise ValueError("the --points files hold no size in common; choose sizes with "
                                 "--n")
            ns = sorted(common)
        else:
            ns = [64, 256, 1024]
    for label, sets in mine.items():
        held = sorted(len(s) for s in sets)
        missing = [m for m in ns if m not in held]
        if missing:
            raise ValueError(f"--points {label} holds sets of n = {held}, none of n = {missing}")
        if len(set(held)) != len(held):
            raise ValueError(f"--points {label} holds two sets of one size (n = {held}); a "
                             "convergence run takes one fixed set per size")
    table = {**chosen, **{label: {len(s): s for s in sets} for label, sets in mine.items()}}
    labels = list(table)
    randomization = {label: "shift" if label in mine else args.randomization for label in labels}
    key = jax.random.key(args.seed)
    if len(set(ns)) >= 2:
        result = V.convergence(f, table, ns, key, args.realizations, exact=f.integral,
                               randomization=randomization, patterns=args.patterns,
                               progress=True)
        record = result.as_dict()
        estimates, fits = result.estimates, result.fits
    else:  # one size: the variances, no slope
        estimates = {label: (V.estimate_variance(
            f, smp[ns[0]] if label in mine else smp, ns[0], key, args.realizations, f.integral,
            randomization=randomization[label],
            patterns=args.patterns if label not in mine else 1),) for label, smp in table.items()}
        fits = {}
        record = {"ns": list(ns), "samplers": {
            label: {"variance": [e.variance for e in ests],
                    "std_error": [e.std_error for e in ests],
                    "ci_low": [e.ci_low for e in ests], "ci_high": [e.ci_high for e in ests],
                    "randomization": ests[0].randomization,
                    "realizations": ests[0].realizations, "fit": None}
            for label, ests in estimates.items()}}
    width = max(16, *(len(s) + 2 for s in labels))
    print(f"integrand {args.integrand}: exact integral {f.integral:.12g}")
    print(f"{'n':>8}" + "".join(f"{s:>{width}}" for s in labels))
    for i, n in enumerate(ns):
        print(f"{n:>8}" + "".join(f"{estimates[s][i].variance:>{width}.4e}" for s in labels))
    if fits:
        print(f"{'slope':>8}" + "".join(f"{fits[s].slope:>{width}.3f}" for s in labels))
        print(f"{'95% CI':>8}" + "".join(
            f"{f' [{fits[s].ci_low:.2f},{fits[s].ci_high:.2f}]':>{width}}" for s in labels))
    else:
        print("(one size: no slope; give sets or --n of two sizes or more for one)")
    for out in outs:
        if out.suffix.lower() == ".json":
            full = {"integrand": args.integrand, "integral": f.integral, "seed": args.seed,
                    "realizations": args.realizations, "patterns": args.patterns,
                    "randomization": args.randomization,
                    "points_files": {label: str(p) for label, p in
                                     zip(mine, args.points_files or [], strict=True)},
                    "sampler_options": {name: {"directions_deg": args.directions}
                                        if name == "aligned"
                                        else {"direction_deg": args.direction, "base": args.base}
                                        for name in names if name in ("aligned", "sheared")},
                    **record,
                    "provenance": io.provenance()}
            io.save_json(out, full, overwrite=args.force)
        else:
            _save_variance_figure(out, ns, estimates, fits, title=f"{args.integrand}",
                                  overwrite=args.force)
        print(f"wrote {out}")


def _save_variance_figure(path, ns, estimates, fits, *, title: str, overwrite: bool):
    """Log-log variance against n per sampler (``plot.convergence_panel``): the measured
    variances with their intervals shaded, the fitted power law dashed, slope and its interval
    in the legend."""
    import numpy as np

    from . import plot

    fig, axes = plot.new_figure(size=4.2)
    ax = axes[0, 0]
    x = np.asarray(ns, dtype=float)
    for label, ests in estimates.items():
        fit = fits.get(label)
        line = plot.convergence_panel(
            ax, x, [e.variance for e in ests], label=label,
            slope=None if fit is None else fit.slope,
            slope_ci=None if fit is None else (fit.ci_low, fit.ci_high),
            lower=[e.ci_low for e in ests], upper=[e.ci_high for e in ests])
        if fit is not None:
            ax.loglog(x, np.exp(fit.intercept) * x ** fit.slope, ls="--", lw=0.8,
                      color=line.get_color())
    ax.set_xscale("log", base=2)
    ax.set_title(f"variance vs N: {title}\n(slope [95% CI] of the dashed fit; shaded: "
                 "95% CI per N)", fontsize=8)
    ax.legend(fontsize=7)
    plot.save_figure(fig, path, formats=(Path(path).suffix.lower().lstrip("."),),
                     overwrite=overwrite)


# --- render ------------------------------------------------------------------------------------


def _add_render(sub):
    p = sub.add_parser("render", help="render a Mitsuba-XML scene (direct light, depth of field)")
    p.add_argument("scene", help="Mitsuba 3 XML scene (the supported subset: anisosample.render) "
                                 "or the name of a shipped scene (anisosample.scenes: cornell, "
                                 "blinds, attic, dof, ...)")
    p.add_argument("--sampler", default="random",
                   help="point-set sampler per pixel; 'aligned' (or 'sheared'): per-block sets "
                        "from a direction estimate per block (W Sec. 5.3-5.4); 'aligned-pixel': "
                        "every pixel its own directions from a fixed isotropic prefix that its "
                        "estimate reuses (spp >= 64)")
    p.add_argument("--block", type=int, default=None,
                   help="aligned/sheared: block side in pixels of the direction estimate "
                        "(default 16; images that are no multiple are padded)")
    p.add_argument("--estimation-samples", type=int, default=None,
                   help="aligned/sheared: grid samples per block side, a multiple of --block "
                        "(default 96: 36 per pixel at --block 16)")
    p.add_argument("--k", type=int, default=None, choices=(1, 2),
                   help="aligned/sheared: directions estimated per block (default 2: a block "
                        "with two gets a 4-direction set, W Sec. 5.4; 1: 3-direction sets only)")
    p.add_argument("--no-gate", action="store_true",
                   help="aligned: give every pixel of a block with a direction its block's set "
                        "(W's rule); by default pixels whose own probe is smooth use pmj02bn")
    _add_no_build(p)
    p.add_argument("--direction-map", default=None, metavar="PNG",
                   help="aligned/sheared: also write the per-block directions as PNG (hue = "
                        "direction / 180, black = none; one panel per direction)")
    p.add_argument("--spp", type=int, default=None,
                   help="points per pixel (default: the XML sampler's sample_count)")
    p.add_argument("--realizations", type=int, default=1,
                   help="independent renders; >1 also writes a per-pixel variance image")
    p.add_argument("--seed", type=_seed, default=0, help="integer seed of the JAX key")
    p.add_argument("--pixel-center", action="store_true",
                   help="fixed primary hit per pixel (the papers' 2D integrand) instead of "
                        "averaging over the pixel area")
    p.add_argument("--technique", default="area", choices=["area", "solid_angle", "parametric"],
                   help="light sampling technique")
    p.add_argument("--light-warp", default="none", metavar="NAME",
                   help="warp chain fitted at every shading point in front of (or instead of) "
                        "--technique (H Sec. 4): none, cosine-bilinear, cosine-biquadratic, "
                        "arvo2001, product-bilinear, product-biquadratic, product-tabulated, "
                        "patch-three-warp")
    p.add_argument("--dimension", default="auto", choices=["auto", "light", "lens"],
                   help="which 2D sample the sampler drives")
    p.add_argument("--mis", default=None, action=argparse.BooleanOptionalAction,
                   help="add one BSDF sample with MIS (default: the XML's bsdf_samples > 0)")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="override a <default> parameter of the XML (repeatable); width, "
                        "height and spp also resize a scene without such parameters (the "
                        "film's size, the sampler's sample_count)")
    p.add_argument("--reference", default=None, help="reference EXR: also write *_mse.exr")
    p.add_argument("--exposure", type=_finite_float, default=0.0,
                   help="PNG preview exposure (stops)")
    p.add_argument("-o", "--output", required=True, help="output .exr (a .png preview beside)")
    p.add_argument("--force", action="store_true", help="overwrite existing outputs")
    p.add_argument("--devices", default="1", metavar="N|all",
                   help="deal the image's blocks of pixels out to the first N local devices "
                        "(the same image as one); 'all': every local device. With --processes or "
                        "--distributed: every device of every process")
    _add_distributed(p, "render", "an image")


def _scene_file(text: str) -> Path:
    """``render``'s scene argument: a file, or else the name of a shipped scene."""
    from . import scenes

    path = Path(text)
    if not path.exists() and text in scenes.names():
        return scenes.path(text)
    if not path.exists():
        raise FileNotFoundError(f"no such scene file: {text} (or give a shipped scene's name: "
                                f"{', '.join(scenes.names())})")
    return path


def _run_render(args):
    import jax

    from . import io, render

    out = Path(args.output)
    if out.suffix != ".exr":
        raise ValueError(f"--output must end in .exr, got {out.name}")
    if not args.force and out.exists():
        raise FileExistsError(f"{out} exists; pass --force to replace it")
    several = args.processes != 1 or args.distributed
    if args.devices != "all" and (not args.devices.isdigit() or int(args.devices) < 1):
        raise ValueError(f"--devices must be a positive integer or 'all', got {args.devices!r}")
    if several and args.devices not in ("1", "all"):
        raise ValueError("--devices N is for one process; with --processes or --distributed "
                         "every device of every process renders")
    if args.processes != 1:
        _check_processes(args)
        _run_local_processes(args.processes, lambda pid, port: render_worker_argv(
            args, pid, port), quiet_others=True)
        return
    _init_distributed(args, collectives=True)
    if several:
        devices = jax.devices()
    else:
        local = jax.local_devices()
        count = len(local) if args.devices == "all" else int(args.devices)
        if count > len(local):
            raise ValueError(f"--devices {count}: this process has {len(local)} local "
                             f"device(s)")
        devices = None if count == 1 else local[:count]
    params = {}
    for item in args.set:
        if "=" not in item:
            raise ValueError(f"--set expects NAME=VALUE, got {item!r}")
        k, v = item.split("=", 1)
        params[k.strip()] = v.strip()
    scene, settings = render.load_xml_with_settings(_scene_file(args.scene), **params)
    spp = settings.spp if args.spp is None else args.spp
    mis = settings.mis if args.mis is None else args.mis
    options = render.IntegratorOptions(  # checked once, before any estimation
        dimension=args.dimension, technique=args.technique, light_warp=args.light_warp, mis=mis,
        pixel_center=args.pixel_center).for_scene(scene)
    reference = io.read_exr(args.reference) if args.reference else None
    sampler = _block_sampler(args, scene, spp, options)
    result = render.render(
        scene, jax.random.key(args.seed), spp=spp, sampler=sampler,
        realizations=args.realizations, options=options, devices=devices,
    )
    if jax.process_index() != 0:  # every process has the whole image; the first writes it
        return
    written = render.save_result(
        out, result, overwrite=args.force, exposure=args.exposure,
        reference=None if reference is None else reference[..., :3],
        metadata={"scene": str(args.scene), "seed": args.seed, "params": params},
    )
    if result.pixel_sampler is not None:
        print(_pixel_summary(result))
    print(f"wrote {', '.join(str(w) for w in written)}")


def render_worker_argv(args, pid: int, port: int) -> list[str]:
    """Worker ``pid``'s ``render`` command line under ``--processes``: the caller's own, without
    ``--processes``, joined to the localhost coordinator."""
    argv, skip = [], False
    for a in args.argv:
        flag = a.split("=", 1)[0]
        if skip:
            skip = False
        elif len(flag) >= len("--processe") and "--processes".startswith(flag):  # argparse
            skip = "=" not in a  # takes unambiguous abbreviations, --processe too
        else:
            argv.append(a)
    return [*argv, "--distributed", "--coordinator", f"127.0.0.1:{port}", "--num-processes",
            str(args.processes), "--process-id", str(pid)]


def _pixel_summary(result) -> str:
    """The per-block sampler's line, counted from the render's own record
    (``RenderResult.pixel_sampler`` and ``settings["blocks"]``), so the two cannot disagree."""
    import numpy as np

    rec = result.settings["blocks"]
    code = np.asarray(result.pixel_sampler)
    if rec["point_set"] == "aligned-pixel":
        return (f"pixels: {int((code == 3).sum())} of {code.size} with their own direction "
                f"(3-direction set), {int((code == 4).sum())} with two (corner, 4-direction "
                f"set), {int((code == 5).sum())} without an edge ({rec['fallback']}, the prefix "
                f"weighted in); estimation: {rec['estimation_samples_per_pixel']:g} samples per "
                f"pixel beyond --spp; the {rec['prefix_points']}-point prefix ({rec['prefix']}) "
                f"is part of every pixel's estimate")
    own, none, gated = (int((code == c).sum()) for c in (2, 0, 1))
    line = (f"pixels: {own} of {code.size} use their block's set ({rec['blocks_with_set']} of "
            f"{rec['blocks']} blocks have one), {none + gated} use {rec['base']} ({none} in "
            f"blocks without a set")
    return line + (f", {gated} gated: their probe is smooth)" if rec["gate"] else ")")


def _block_sampler(args, scene, spp, options):
    """``--sampler aligned|sheared``: estimate the blocks' directions (printing the cost, W
    Fig. 10 counts it) and write the direction map; other samplers pass through by name."""
    from . import tables
    from .render import aligned

    opts = {k: v for k, v in (("block_px", args.block), ("samples", args.estimation_samples),
                              ("k", args.k)) if v is not None}
    if args.no_gate:
        opts["gate"] = False
    if args.sampler not in aligned.BLOCK_SAMPLERS:
        if opts or args.direction_map is not None:
            raise ValueError("--block, --estimation-samples, --k, --no-gate and --direction-map "
                             f"need --sampler {' or '.join(aligned.BLOCK_SAMPLERS)}")
        return args.sampler
    if args.sampler == "aligned":
        if spp < 2:  # before the estimation, which costs seconds
            raise ValueError(f"--sampler aligned needs --spp >= 2 (a table set), got {spp}")
        # Sets build on demand (tables.lookup): the ones the blocks need and no table holds are
        # synthesized into the user cache after the estimation, with progress. Say so up front.
        # --no-build: refused after the estimation, naming the commands that build them.
        kinds = (3,) if opts.get("k", 2) == 1 else (3, 4)
        absent = [kd for kd in kinds if tables.find_table(kd, spp) is None]
        if args.no_build:
            opts["build_missing"] = False
        elif absent:
            print(f"note: no {' or '.join(f'{kd}-direction' for kd in absent)} table for n = "
                  f"{spp} is installed; the sets the blocks need are synthesized into "
                  f"{tables.cache_dir()} before rendering (`anisosample tables build --n {spp} "
                  f"--direction-count {absent[0]}` builds a whole table)")
    map_path = None if args.direction_map is None else Path(args.direction_map)
    if map_path is not None:
        if map_path.suffix != ".png":
            raise ValueError(f"--direction-map must end in .png, got {map_path.name}")
        if map_path.exists() and not args.force:
            raise FileExistsError(f"{map_path} exists; pass --force to replace it")
    sampler = aligned.block_sampler(scene, args.sampler, options=options, progress=True, **opts)
    sampler.check_tables(spp)
    est = sampler.estimate
    by, bx = est.blocks
    rec = sampler.settings()  # the record the render keeps (settings["blocks"])
    print(f"direction estimate: {by}x{bx} blocks of {est.block_px}x{est.block_px} px, "
          f"{est.samples}^2 integrand samples each = {est.integrand_samples} samples "
          f"({est.samples_per_pixel:g} per pixel, {100 * est.samples_per_pixel / spp:.0f}% of "
          f"--spp {spp}) in {est.seconds:.2f} s; {rec['blocks_with_direction']} of "
          f"{rec['blocks']} blocks have an extra direction, {rec['blocks_with_set']} a set "
          f"(k = {sampler.k}); per-pixel gate "
          + (f"on: {rec['pixels_gated']} pixels of blocks with a set gated to {sampler.base}"
             if sampler.gate else "off"))
    if map_path is not None:
        aligned.save_direction_map(map_path, sampler, overwrite=args.force)
        print(f"wrote the direction map to {map_path}")
    return sampler


# --- registry ----------------------------------------------------------------------------------

_COMMANDS = {
    "tables": (_add_tables, _run_tables),
    "directions": (_add_directions, _run_directions),
    "points": (_add_points, _run_points),
    "spectrum": (_add_spectrum, _run_spectrum),
    "synthesize": (_add_synthesize, _run_synthesize),
    "variance": (_add_variance, _run_variance),
    "render": (_add_render, _run_render),
}


class _HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """argparse's help with every option's default, e.g. ``(default: random)``, lists written
    as they are typed (``64,256,1024``) -- except where the help already states it, for flags
    (off unless given) and for ``None`` (the help says what happens without the option)."""

    def _get_help_string(self, action):
        text = action.help or ""
        d = action.default
        if (not action.option_strings or d is None or isinstance(d, bool)
                or d is argparse.SUPPRESS or "%(default)" in text or "default" in text.lower()):
            return text
        shown = ",".join(map(str, d)) if isinstance(d, list | tuple) else str(d)
        return f"{text} (default: {shown.replace('%', '%%')})"


class _Parser(argparse.ArgumentParser):
    """argparse's parser with one-line errors: ``PROG: error: MESSAGE (see PROG --help)`` and
    exit status 2, without the usage block argparse prints above it; ``--help`` shows every
    option's default (:class:`_HelpFormatter`), in subcommands too (they are ``_Parser`` s)."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", _HelpFormatter)
        super().__init__(*args, **kwargs)

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


class _RenamedOption(argparse.Action):
    """An old option spelling, hidden from ``--help`` and refused with the new one's name
    (docs/design.md, Vocabulary), e.g. ``directions --method`` -> ``--estimator``."""

    def __init__(self, option_strings, dest, new: str, nargs="?", **kwargs):
        self.new = new
        super().__init__(option_strings, argparse.SUPPRESS, nargs=nargs,
                         default=argparse.SUPPRESS, help=argparse.SUPPRESS)

    def __call__(self, parser, namespace, values, option_string=None):
        parser.error(f"{option_string} is now {self.new} (docs/design.md, Vocabulary)")


def _renamed_option(parser, old: str, new: str) -> None:
    parser.add_argument(old, action=_RenamedOption, new=new)


class _VersionAction(argparse.Action):
    """``--version``, reading the package metadata only when asked."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS,
                 help="show the version and exit"):
        super().__init__(option_strings, dest, nargs=0, default=default, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        from . import __version__

        print(f"anisosample {__version__}")
        parser.exit(0)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="anisosample",
        description="Anisotropic sampling patterns and product-sampling warps (JAX).",
    )
    parser.add_argument("--version", action=_VersionAction)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for add, _ in _COMMANDS.values():
        add(sub)
    return parser


_USER_ERRORS = (ValueError, TypeError, KeyError, OSError, MemoryError, RuntimeError, EOFError,
                OverflowError)
"""What bad input raises in the library: wrong values, missing/damaged/unwritable files, requests
too large to allocate, checks inside jit (``eqx.error_if`` raises a RuntimeError). ``OSError``
covers FileExistsError and FileNotFoundError; a damaged ``.npz`` (``zipfile.BadZipFile``) is
turned into a ValueError naming the file by :mod:`anisosample.io`, and caught here as well."""


def _one_line(exc: BaseException) -> str:
    """The first line of an exception's message (equinox's runtime errors add a paragraph of
    advice below it), or the exception's type if it has no message."""
    text = str(exc.args[0]) if isinstance(exc, KeyError) and exc.args else str(exc)
    inner = re.search(r"EquinoxRuntimeError: (.+)", text)  # a check inside jit, wrapped by XLA
    if inner:
        return inner.group(1).strip()
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    if not lines:
        return type(exc).__name__
    first = lines[0]
    if isinstance(exc, MemoryError | RuntimeError) and type(exc).__name__ not in first:
        first = f"{type(exc).__name__}: {first}"
    return first


def main(argv: list[str] | None = None) -> int:
    """Run the command line with ``argv`` (default ``sys.argv[1:]``); return the exit status:
    0 on success, 2 for bad input (one line on stderr), 130 when interrupted."""
    import zipfile

    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, --version and argparse's errors end here
        return exc.code if isinstance(exc.code, int) else 2
    args.argv = list(sys.argv[1:] if argv is None else argv)  # --processes workers rerun it
    _, run = _COMMANDS[args.command]
    name = args.command + (f" {args.tables_command}" if args.command == "tables" else "")
    try:
        run(args)
    except (*_USER_ERRORS, zipfile.BadZipFile) as exc:
        print(f"anisosample {name}: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"anisosample {name}: interrupted", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())

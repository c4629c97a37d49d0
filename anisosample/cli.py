"""The ``anisosample`` command, for people who never open Python.

Each subcommand is a pair of functions: ``_add_NAME(subparsers)`` declares its arguments and
``_run_NAME(args)`` does the work by calling the library. Errors from the library (bad input,
missing files, refusing to overwrite) become a one-line message and a non-zero exit status.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def _int_list(text: str) -> list[int]:
    try:
        return [int(t) for t in text.split(",") if t.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated integers, got {text!r}")


def _float_list(text: str) -> list[float]:
    try:
        return [float(t) for t in text.split(",") if t.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers, got {text!r}")


# --- points ------------------------------------------------------------------------------------


def _add_points(sub):
    from . import samplers

    p = sub.add_parser("points", help="generate a point set with a baseline sampler")
    p.add_argument("sampler", help=f"one of: {', '.join(samplers.names())}")
    p.add_argument("-n", type=int, required=True, help="number of points")
    p.add_argument("--seed", type=int, default=0, help="integer seed of the JAX key")
    p.add_argument("--shift", action="store_true", help="apply a random toroidal shift")
    p.add_argument("-o", "--output", required=True, help="output .npy or .npz")
    p.add_argument("--force", action="store_true", help="overwrite an existing output")


def _run_points(args):
    import jax

    from . import io, samplers

    out = Path(args.output)
    if out.suffix not in (".npy", ".npz"):
        raise ValueError(f"--output must end in .npy or .npz, got {out.name}")
    key = jax.random.key(args.seed)
    sampler = samplers.get(args.sampler)
    k_pts, k_shift = jax.random.split(key)
    pts = sampler(k_pts, args.n)
    if args.shift:
        pts = samplers.toroidal_shift(k_shift, pts)
    if out.suffix == ".npy":
        io.save_npy(out, pts, overwrite=args.force)
    else:
        meta = {"sampler": args.sampler, "n": args.n, "seed": args.seed, "shift": args.shift}
        io.save_npz(out, {"points": pts}, meta, overwrite=args.force)
    print(f"wrote {args.n} {args.sampler} points to {out}")


# --- spectrum ----------------------------------------------------------------------------------


def _add_spectrum(sub):
    p = sub.add_parser("spectrum", help="power spectrum image of a point set (PNG or EXR)")
    p.add_argument("points", help=".npy or .npz point set")
    p.add_argument("-o", "--output", required=True, help="output .png or .exr")
    p.add_argument("--radius", type=int, default=None,
                   help="half-width of the frequency grid (default: 2 sqrt(n))")
    p.add_argument("--method", default="auto", choices=["auto", "direct", "nufft"])
    p.add_argument("--force", action="store_true", help="overwrite an existing output")


def _run_spectrum(args):
    import numpy as np

    from . import io, spectrum

    pts = io.load_points(args.points)
    out = Path(args.output)
    if out.suffix not in (".png", ".exr"):
        raise ValueError(f"--output must end in .png or .exr, got {out.name}")
    n = pts.shape[0]
    radius = args.radius if args.radius is not None else max(8, int(2 * np.sqrt(n)))
    grid = spectrum.power_spectrum_grid(pts, radius, method=args.method)
    spectrum.save_spectrum_image(out, grid, n=n, overwrite=args.force)
    print(f"wrote the {2 * radius + 1}^2 power spectrum of {n} points to {out}")


# --- synthesize --------------------------------------------------------------------------------


def _add_synthesize(sub):
    p = sub.add_parser("synthesize", help="optimize a point set with dark spectral directions")
    p.add_argument("-n", type=int, required=True, help="number of points")
    p.add_argument("--directions", type=_float_list, required=True,
                   help="spectral directions in degrees, e.g. 0,90,30 (axes are not implied)")
    p.add_argument("--seed", type=int, default=0, help="integer seed of the JAX key")
    p.add_argument("--recipe", default="rate", choices=["rate", "paper"],
                   help="rate (default, reaches the rate) or paper (W Eqs. 10-15)")
    p.add_argument("--steps", type=int, default=None, help="optimizer steps (recipe default)")
    p.add_argument("--c", type=float, default=None, help="weight of the SW term (W Eq. 10)")
    p.add_argument("--learning-rate", type=float, default=None,
                   help="Adam step in units of 1/sqrt(n) (recipe default)")
    p.add_argument("-o", "--output", required=True, help="output .npz (points + metadata)")
    p.add_argument("--checkpoint", default=None,
                   help="checkpoint .npz (default: OUTPUT.ckpt.npz); an interrupted run resumes")
    p.add_argument("--force", action="store_true", help="overwrite an existing output")


def _run_synthesize(args):
    import jax

    from . import synthesis

    out = Path(args.output)
    if out.suffix != ".npz":
        raise ValueError(f"--output must end in .npz, got {out.name}")
    if out.exists() and not args.force:
        raise FileExistsError(f"{out} exists; pass --force to replace it")
    ckpt = args.checkpoint or str(out.with_suffix(".ckpt.npz"))
    pts, info = synthesis.synthesize(
        jax.random.key(args.seed), args.n, args.directions, recipe=args.recipe,
        steps=args.steps, c=args.c, learning_rate=args.learning_rate, checkpoint=ckpt,
        return_info=True,
    )
    info["seed"] = args.seed
    synthesis.save_result(out, pts, info, overwrite=args.force)
    print(f"wrote {args.n} points optimized for {args.directions} deg to {out}"
          f" (loss {info['history'][0]:.3g} -> {info['final_loss']:.3g})")


# --- registry ----------------------------------------------------------------------------------

_COMMANDS = {
    "points": (_add_points, _run_points),
    "spectrum": (_add_spectrum, _run_spectrum),
    "synthesize": (_add_synthesize, _run_synthesize),
}


def build_parser() -> argparse.ArgumentParser:
    from . import __version__

    parser = argparse.ArgumentParser(
        prog="anisosample",
        description="Anisotropic sampling patterns and product-sampling warps (JAX).",
    )
    parser.add_argument("--version", action="version", version=f"anisosample {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for add, _ in _COMMANDS.values():
        add(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    _, run = _COMMANDS[args.command]
    try:
        run(args)
    except (ValueError, TypeError, FileExistsError, FileNotFoundError, KeyError) as exc:
        msg = str(exc).strip("'\"") or type(exc).__name__
        print(f"anisosample {args.command}: error: {msg}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"anisosample {args.command}: interrupted", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())

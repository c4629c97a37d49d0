"""Render every shipped scene (``anisosample.scenes``) with this package and, when Mitsuba 3 is
installed, with Mitsuba from the same XML; record the relative RMSE between the two.
Mitsuba renders a copy in which our ``bilinear`` patches are fine tessellations
(``render.mitsuba_compat``), written to ``<out>/mitsuba_scenes/``.

small: 96x96, 256 spp (minutes on 2 cores); paper: 512x512, 4096 spp. Outputs per scene:
``<scene>.exr`` / ``.png`` (ours), ``<scene>_mitsuba.exr`` / ``.png``, and one JSON record
``render_scenes.json`` with every number. Finished scenes are reused on rerun when made with the
same size, spp and key (their EXR metadata says so).
"""

from __future__ import annotations

import time
from pathlib import Path

import jax
import numpy as np

from anisosample import io, render, scenes

try:
    import common
except ImportError:  # run as a module
    from experiments import common

SCENES = scenes.FOLDER
SIZES = {"small": (96, 256), "paper": (512, 4096)}


def reused_exr(path: Path, made: dict, fresh: bool):
    """The RGB image at ``path`` if it exists, ``fresh`` is false and its metadata says it was
    ``made`` with these settings; else None."""
    if path.exists() and not fresh:
        img, meta = io.read_exr(path, metadata=True)
        if meta.get("made_with") == made:
            return img[..., :3]
    return None


def arguments(p):
    p.add_argument("--scenes", default=None, help="comma-separated scene names (default: all)")


def settings(scale, args):
    """Size, spp, sampler, seed, Mitsuba's variant and the scenes (all shipped ones unless
    ``--scenes``; their order sets their keys)."""
    size, spp = scale
    names = sorted(x.stem for x in SCENES.glob("*.xml"))
    if args.scenes:
        names = [n for n in args.scenes.split(",") if n]
    return {"scale": args.scale, "size": size, "spp": spp, "sampler": "random",
            "seed": args.seed, "mitsuba_variant": "scalar_rgb", "scenes": names}


def compute(cfg, args):
    """Every scene, ours and Mitsuba's; each image is a resumable part (its EXR says what it was
    made with)."""
    size, spp = cfg["size"], cfg["spp"]
    out: Path = args.out
    rows = {}
    for i, name in enumerate(cfg["scenes"]):
        path = SCENES / f"{name}.xml"
        ours_path = out / f"{name}.exr"
        params = dict(width=size, height=size)
        t = time.time()
        # an image is reused only when made with these settings (kept in its EXR metadata)
        made = {"scene": name, "size": size, "spp": spp, "seed": args.seed, "key_index": i}
        ours = reused_exr(ours_path, made, args.fresh)
        t_ours = None
        if ours is None:
            scene, settings = render.load_xml_with_settings(path, **params)
            res = render.render(scene, jax.random.fold_in(jax.random.key(args.seed), i), spp=spp,
                                mis=settings.mis)  # the file's integrator, as Mitsuba renders it
            render.save_result(ours_path, res, overwrite=True,
                               metadata={"scene": name, "made_with": made})
            ours = res.mean
            t_ours = time.time() - t
        row = {"width": size, "height": size, "spp": spp, "seconds_ours": t_ours}
        try:
            import mitsuba as mi
        except ImportError:
            mi = None
        if mi is not None:
            mpath = out / f"{name}_mitsuba.exr"
            ref = reused_exr(mpath, made, args.fresh)
            if ref is None:
                mi.set_variant("scalar_rgb")
                mi_path = render.mitsuba_compat.mitsuba_compatible_copy(
                    path, out / "mitsuba_scenes", **params)
                t = time.time()
                ref = np.array(mi.render(mi.load_file(str(mi_path), **params), spp=spp,
                                         seed=args.seed))[..., :3]
                row["seconds_mitsuba"] = time.time() - t
                io.write_exr(mpath, ref, {"scene": name, "renderer": f"mitsuba {mi.__version__}",
                                          "made_with": made}, overwrite=True)
                io.save_png(mpath.with_suffix(".png"), render.tonemap(ref), overwrite=True)
            row["relative_rmse_vs_mitsuba"] = float(
                np.sqrt(np.mean((ours - ref) ** 2)) / np.sqrt(np.mean(ref**2)))
            row["mean_ours"] = float(ours.mean())
            row["mean_mitsuba"] = float(ref.mean())
        rows[name] = row
        print(f"{name}: {row}", flush=True)  # as it goes: the report's lines
    args.printed_rows = True
    return {"scenes": rows}


def report(data, args):
    if not getattr(args, "printed_rows", False):
        for name, row in data["scenes"].items():
            print(f"{name}: {row}")


def main(argv=None):
    return common.run("render_scenes", __doc__, SIZES, compute, report=report,
                      arguments=arguments, settings=settings, argv=argv)


if __name__ == "__main__":
    main()

"""W Fig. 9, measured where the claim lives: per-pixel convergence on classified pixels.

W's rendered claim (Sec. 6.2, Fig. 9) is about pixels whose 2D integrand has a straight edge:
there the aligned sets converge at about n^-1.75 while pmj02bn and sheared pmj02bn stay near
n^-1.5. A region of fully lit pixels shows every sampler's smooth-integrand rate instead, so
the regions here are chosen from the pixel classes (:mod:`anisosample.render.pixel_classes`):

* ``one-edge``: one straight edge whose spectral direction is at least 10 degrees from both axes
  (a penumbra of one occluder edge);
* ``corner``: two straight edges (W's 4-direction sets apply);
* ``lit``: no edge (the control: alignment has nothing to act on);
* ``lit-aligned-block``: lit pixels whose block has an estimated direction, the lit pixels W's
  sampler gives an aligned set (where the per-pixel gate matters).

Pixels are picked at W's resolution (``size``, 1280^2 at both scales): a coarse classification
(``coarse``^2) proposes candidates, each candidate's pixel of the full-size image is classified
again from its own dense grid and kept if its class agrees, up to ``per_class`` pixels per
class (seeded choice). Only those pixels and their blocks are evaluated, which is what makes
1280^2 affordable on a CPU: the block direction is W's estimate (Sec. 5.3: 16x16-pixel blocks,
96^2 samples per block, each pixel filling a 6x6 tile; ``render.aligned.block_grid_values`` and
``directions.estimate``) of the block that holds the pixel.

Per pixel (fixed primary hit, W's setting), the estimator variance over ``realizations``
toroidal shifts of one set per method and n (``variance.realization_estimates``), for

* ``pmj02bn``; ``sheared pmj02bn`` (Singh & Jarosz 2017, to the block's direction);
* ``aligned (block)``: the 3-direction table set for the block's estimated direction;
* ``aligned (true)``: the 3-direction set for the pixel's own (classified) direction, the upper
  bound of what estimation can reach;
* corners also: ``aligned 4-dir (true)``, W's 4-direction set for the pixel's two directions,
  and ``aligned 4-dir (block)`` for the block's two estimated directions when it has two;
* ``aligned (gated)``: ``aligned (block)`` where the renderer's per-pixel gate sees a
  discontinuity in the pixel's probe, pmj02bn elsewhere (beyond W; :func:`add_gate`).

A block whose direction rounds onto an axis (or has none) uses pmj02bn for its aligned methods
(W Sec. 5.4's fallback). Per-pixel slopes are weighted log-log fits over ``log2_ns``
(``variance.fit_slope``); the summary gives their median and quartiles, and the per-pixel
variance at the largest n relative to pmj02bn's (median and quartiles, and the geometric
mean with its standard error across the pixels, :func:`geomean_ratio`). Sets missing from the
installed tables are synthesized on demand into ``results/w_render_tables``.

Writes ``results/w_fig9/w_fig9.json`` (per scene and class: the image resolution, every pixel
as ``[column, row]`` as ``render.pixel_integrand`` takes it, row 0 at the top, its class
direction(s), its block's estimate, and per method its per-pixel variances and slopes) and
``w_fig9.png``. Finished scenes are reused on rerun (``--fresh`` recomputes). Each pixel
variance's shifts run in :data:`CHUNKS` chunks, dealt out to ``--cpu-devices`` devices (default
1; ``variance.realization_estimates(..., devices=...)``): the same numbers on any number.

    python experiments/w_fig9.py --scale small|paper [--scenes cornell,dof,pillars]
        [--cpu-devices N]
"""

from __future__ import annotations

import functools
import time

import _w_render as W
import common
import jax
import numpy as np

import anisosample as asp
from anisosample import directions, metrics, plot, samplers, tables
from anisosample import variance as V
from anisosample.progress import progress
from anisosample.render import pixel_classes as pc

NAME = "w_fig9"
SCALES = {
    "small": dict(coarse=128, coarse_grid=48, size=1280, grid=64, block_px=16, samples=96,
                  log2_ns=[8, 9, 10, 11, 12], corner_log2_ns=[8, 10, 12], realizations=64,
                  per_class=30, min_axis_deg=10.0),
    "paper": dict(coarse=256, coarse_grid=64, size=1280, grid=96, block_px=16, samples=96,
                  log2_ns=[8, 9, 10, 11, 12], corner_log2_ns=[8, 9, 10, 11, 12],
                  realizations=256, per_class=60, min_axis_deg=10.0),
}
CLASS_NAMES = ("one-edge", "corner", "lit", "lit-aligned-block")
# "lit-aligned-block": lit pixels whose block's estimate has a usable direction, i.e. the lit
# pixels W's sampler hands an aligned set (where the per-pixel gate matters).
SCENES = ("cornell", "dof", "pillars")  # pillars: penumbra directions turn within a block


def pick_pixels(name, cfg, rng):
    """Pixels of each class at the full resolution (module docstring), with their classes."""
    sq = W.SCENES[name]["square_aperture"]
    coarse = W.load_scene(name, cfg["coarse"], cfg["coarse"])
    cl = pc.pixel_classes(coarse, grid=cfg["coarse_grid"],
                          options=asp.render.IntegratorOptions(square_aperture=sq), progress=True)
    full = W.load_scene(name, cfg["size"], cfg["size"])
    f = cfg["size"] // cfg["coarse"]
    picked = {}
    for cname in CLASS_NAMES[:3]:
        cand = cl.pixels(cname)
        if cname == "one-edge":
            cand = cand[metrics.off_axis_deg(cl.directions_deg[cand[:, 1], cand[:, 0], 0])
                        >= cfg["min_axis_deg"]]
        cand = cand[rng.permutation(len(cand))][: 4 * cfg["per_class"]]
        if len(cand) == 0:
            picked[cname] = (np.zeros((0, 2), int), np.zeros((0, 2)), np.zeros(0, int))
            continue
        fine = cand * f + f // 2
        fc = pc.pixel_classes(full, fine, grid=cfg["grid"],
                              options=asp.render.IntegratorOptions(square_aperture=sq))
        keep = fc.classes[fine[:, 1], fine[:, 0]] == pc.CLASSES.index(cname)
        d = fc.directions_deg[fine[:, 1], fine[:, 0]]
        if cname == "one-edge":
            keep &= metrics.off_axis_deg(d[:, 0]) >= cfg["min_axis_deg"]
        sel = np.nonzero(keep)[0][: cfg["per_class"]]
        picked[cname] = (fine[sel], d[sel], fc.num_directions[fine[sel, 1], fine[sel, 0]])
    return full, cl.counts(), picked


def lit_in_aligned_blocks(name, cfg, key, full, base, cache):
    """Lit pixels (confirmed at the full size) whose block's estimate has a direction the
    aligned table can take (``selection.table_directions``), up to ``per_class`` of them."""
    from anisosample import selection

    sq = W.SCENES[name]["square_aperture"]
    rng = np.random.default_rng(np.asarray(jax.random.key_data(key)).astype(np.uint32))
    coarse = W.load_scene(name, cfg["coarse"], cfg["coarse"])
    cl = pc.pixel_classes(coarse, grid=cfg["coarse_grid"],
                          options=asp.render.IntegratorOptions(square_aperture=sq))
    f = cfg["size"] // cfg["coarse"]
    cand = cl.pixels("lit")
    cand = cand[rng.permutation(len(cand))] * f + f // 2
    chosen = []
    for s in range(0, len(cand), 4 * cfg["per_class"]):
        part = cand[s:s + 4 * cfg["per_class"]]
        part = [p for p in part if selection.table_directions(
            W.block_estimate(full, base, p, cfg, cache)[1], k=1)]
        if part:
            fc = pc.pixel_classes(full, np.array(part), grid=cfg["grid"],
                                  options=asp.render.IntegratorOptions(square_aperture=sq))
            chosen += [p for p in part if fc.classes[p[1], p[0]] == pc.CLASSES.index("lit")]
        if len(chosen) >= cfg["per_class"]:
            break
    px = np.array(chosen[: cfg["per_class"]], int).reshape(-1, 2)
    return px, np.zeros((len(px), 2)), np.zeros(len(px), int)


def _lookup(extra, n):
    """The aligned set for integer extra directions (3 or 4 directions in all), or None."""
    extra = tuple(sorted({int(round(e)) % 180 for e in extra} - set(tables.AXES_DEG)))
    if not extra:
        return None
    try:  # the installed tables (shipped, user cache), then this experiment's own
        return tables.lookup(extra, n, direction_count=2 + len(extra))
    except FileNotFoundError:
        tables.ensure([extra], n, direction_count=2 + len(extra), table=W.TABLES,
                      build_missing=True)
        return tables.lookup(extra, n, direction_count=2 + len(extra), table=W.TABLES)


def method_sets(cname, true_dirs, block_dirs, n, pmj):
    """The point set of every method for one pixel (module docstring)."""
    d_block = block_dirs[0] if block_dirs else None
    sets = {"pmj02bn": pmj,
            "sheared pmj02bn": pmj if d_block is None else samplers.shear(pmj, d_block)}
    sets["aligned (block)"] = (_lookup((d_block,), n) if d_block is not None else None)
    sets["aligned (true)"] = _lookup(true_dirs[:1], n) if len(true_dirs) else None
    if cname == "corner":
        sets["aligned 4-dir (true)"] = _lookup(true_dirs[:2], n)
        sets["aligned 4-dir (block)"] = (_lookup(block_dirs[:2], n) if len(block_dirs) == 2
                                         else None)
    return {m: pmj if s is None else s for m, s in sets.items()}


def measure_class(full, base, cname, pixels, dirs, num, cfg, key, cache, devices=None):
    ns = [2**k for k in (cfg["corner_log2_ns"] if cname == "corner" else cfg["log2_ns"])]
    rows = []
    for q, pix in enumerate(progress(pixels, desc=cname, leave=False)):
        true_dirs = [float(x) for x in dirs[q][: int(num[q])]]
        block, block_dirs = W.block_estimate(full, base, pix, cfg, cache)
        f = W.pixel_f(base, full, (int(pix[0]), int(pix[1])))
        per = {}
        for n in ns:
            pmj = samplers.get("pmj02bn")(jax.random.fold_in(key, n), n)
            sets = method_sets(cname, true_dirs, list(block_dirs), n, pmj)
            kq = jax.random.fold_in(jax.random.fold_in(key, 10_000 + q), n)
            for m, pts in sets.items():
                v, se, _ = _variance(f, pts, n, kq, cfg, devices)
                per.setdefault(m, {"variance": [], "std_error": []})
                per[m]["variance"].append(v)
                per[m]["std_error"].append(se)
        for c in per.values():
            c["slope"] = V.fit_slope(ns, c["variance"], c["std_error"]).slope
        rows.append({"pixel": [int(pix[0]), int(pix[1])], "true_directions_deg": true_dirs,
                     "block": list(block), "block_directions_deg": [float(x) for x in block_dirs],
                     "methods": per})
    add_gate(full, base, rows)
    add_beyond(full, base, cname, rows, ns, cfg, key, devices)
    return {"ns": ns, "pixels": rows, "summary": summarize(rows, ns)}


CHUNKS = 4
"""Chunks of shifts per pixel variance, dealt out to ``--cpu-devices`` devices: fixed, so that
the numbers are the same bits on any number of devices."""


def _variance(f, pts, n, key, cfg, devices):
    return W.pixel_variance(f, pts, n, key, cfg["realizations"], chunks=CHUNKS, devices=devices)


def add_gate(full, base, rows):
    """The renderer's per-pixel gate (``render.estimation.probe_discontinuous`` on the pixel's
    ``estimation.pixel_probes``) and the gated aligned method: the block's aligned set where the
    probe shows a discontinuity, pmj02bn elsewhere -- the same sets and keys as those two
    columns, so its variances are theirs, pixel by pixel."""
    if not rows:
        return
    from anisosample.render import estimation

    px = np.array([r["pixel"] for r in rows])
    probes = estimation.pixel_probes(full, pixels=px, integrand=base)
    for r, flag in zip(rows, estimation.probe_discontinuous(probes), strict=True):
        r["gate_discontinuous"] = bool(flag)
        r["methods"]["aligned (gated)"] = dict(
            r["methods"]["aligned (block)" if flag else "pmj02bn"])


BEYOND_LOG2_NS = (8, 10, 12)
"""The sizes of the beyond-W columns (``add_beyond``): every method's slope over these is in the
summary (``slope3_median``) so the columns compare on the same sizes."""


def add_beyond(full, base, cname, rows, ns, cfg, key, devices=None):
    """Beyond W (issue: per-pixel directions), on the same pixels and shifts' keys:

    * ``aligned (window)``: W's estimator (Sobel histogram + vMF, ``directions.estimate``) on a
      *sliding* window of ``block_px^2`` pixels centred on the pixel (``estimation.
      window_grid_values``: a crop of the same estimation grid, no extra samples), its
      3-direction set (corners: ``aligned 4-dir (window)`` with its two directions);
    * ``aligned (pixel)``: the renderer's per-pixel sampler (``render.pixel_aligned``): per
      shift, the fixed prefix's samples, the pixel's own edge search, the prefix set for what it
      found, the prefix reused in the estimate (``integrand_estimates``).
    """
    from anisosample.render import estimation
    from anisosample.render import pixel_aligned as PA

    todo = [n for n in ns if int(np.log2(n)) in BEYOND_LOG2_NS]
    for q, r in enumerate(progress(rows, desc=f"{cname} beyond", leave=False)):
        pix = (int(r["pixel"][0]), int(r["pixel"][1]))
        true_dirs = r["true_directions_deg"]
        grid = estimation.window_grid_values(full, pix, cfg["block_px"], cfg["samples"],
                                             integrand=base)
        wd = [float(d) for d in directions.estimate(grid, k=2)]
        r["window_directions_deg"] = wd
        f = W.pixel_f(base, full, pix)
        errs, extra = [], []
        for n in todo:
            kq = jax.random.fold_in(jax.random.fold_in(key, 10_000 + q), n)
            sets = {"aligned (window)": _lookup(wd[:1], n) if wd else None}
            if cname == "corner":
                sets["aligned 4-dir (window)"] = _lookup(wd[:2], n) if len(wd) == 2 else None
            pmj = samplers.get("pmj02bn")(jax.random.fold_in(key, n), n)
            for m, pts in sets.items():
                v, se, _ = _variance(f, pmj if pts is None else pts, n, kq, cfg, devices)
                c = r["methods"].setdefault(m, {"variance": [], "std_error": [], "ns": todo})
                c["variance"].append(v)
                c["std_error"].append(se)
            e = PA.integrand_estimates(f, n, kq, cfg["realizations"], table=W.TABLES,
                                       build_missing=True)
            res = V.variance_from_estimates(e.estimates, n=n, randomization="shift")
            c = r["methods"].setdefault("aligned (pixel)",
                                        {"variance": [], "std_error": [], "ns": todo})
            c["variance"].append(res.variance)
            c["std_error"].append(res.std_error)
            extra.append(float(np.mean(e.search_samples)))
            if true_dirs:
                found = e.directions_deg[:, 0]
                ok = np.isfinite(found)
                errs.extend(metrics.axial_distance_deg(found[ok], true_dirs[0]).tolist()
                            if cname != "corner" else
                            np.minimum(metrics.axial_distance_deg(found[ok], true_dirs[0]),
                                       metrics.axial_distance_deg(found[ok], true_dirs[-1]))
                            .tolist())
                errs.extend([90.0] * int((~ok).sum()))  # no edge found: counted as missed
        for m in ("aligned (window)", "aligned 4-dir (window)", "aligned (pixel)"):
            if m in r["methods"]:
                c = r["methods"][m]
                c["slope"] = V.fit_slope(todo, c["variance"], c["std_error"]).slope
        r["pixel_search_samples"] = extra
        if errs:
            r["pixel_direction_error_deg"] = float(np.median(errs))


def _slope3(c, ns):
    idx = [i for i, n in enumerate(c.get("ns", ns)) if int(np.log2(n)) in BEYOND_LOG2_NS]
    sub = [c.get("ns", ns)[i] for i in idx]
    return V.fit_slope(sub, [c["variance"][i] for i in idx],
                       [c["std_error"][i] for i in idx]).slope


def geomean_ratio(ratio) -> dict:
    """The class's per-pixel variance ratios at the largest N as one number: their geometric
    mean, with its standard error across the pixels (``g sd(log r) / sqrt(n)``: the pixels'
    spread and each ratio's noise together). Every pixel weighs the same, as in the median;
    the ratio of the summed variances, also tried, follows the few pixels with the most
    variance (cornell's lit-aligned-block: one pixel of 30 at 1.44 moved it to 1.20)."""
    try:
        g, se = metrics.geometric_mean(ratio)
    except ValueError:  # fewer than two pixels, or a ratio that is not finite and positive
        return {}
    return {"ratio_geomean": g, "ratio_geomean_se": se}


def summarize(rows, ns=None) -> dict:
    if not rows:
        return {}
    out = {}
    for m in rows[0]["methods"]:
        if ns is not None:
            s3 = np.array([_slope3(r["methods"][m], ns) for r in rows])
        slopes = np.array([r["methods"][m]["slope"] for r in rows])
        ratio = np.array([r["methods"][m]["variance"][-1] / r["methods"]["pmj02bn"]["variance"][-1]
                          for r in rows])
        out[m] = {"slope_median": float(np.median(slopes)),
                  "slope_quartiles": [float(x) for x in np.percentile(slopes, [25, 75])],
                  "ratio_median": float(np.median(ratio)),
                  "ratio_quartiles": [float(x) for x in np.percentile(ratio, [25, 75])],
                  **geomean_ratio(ratio)}
        if ns is not None:
            out[m]["slope3_median"] = float(np.median(s3))
    gate = [r["gate_discontinuous"] for r in rows if "gate_discontinuous" in r]
    if gate:
        out["gate_discontinuous_share"] = float(np.mean(gate))
    err = [metrics.axial_distance_deg(r["block_directions_deg"][0], r["true_directions_deg"][0])
           for r in rows if r["block_directions_deg"] and r["true_directions_deg"]]
    if err:
        err = np.asarray(err, float)
        out["block_direction_error_deg"] = {
            "median": float(np.median(err)), "within_3_deg": float(np.mean(err <= 3.0)),
            "pixels_with_estimate": int(len(err)), "pixels": len(rows)}
        out["by_block_error"] = by_block_error(rows)
    for key, name in (("window_directions_deg", "window_direction_error_deg"),):
        e = [metrics.axial_distance_deg(r[key][0], r["true_directions_deg"][0])
             for r in rows if r.get(key) and r["true_directions_deg"]]
        if e:
            out[name] = {"median": float(np.median(e)), "pixels_with_estimate": len(e),
                         "pixels": len(rows)}
    pe = [r["pixel_direction_error_deg"] for r in rows if "pixel_direction_error_deg" in r]
    if pe:
        out["pixel_direction_error_deg"] = {"median": float(np.median(pe)), "pixels": len(pe)}
    ss = [np.mean(r["pixel_search_samples"]) for r in rows if r.get("pixel_search_samples")]
    if ss:
        out["pixel_search_samples"] = float(np.mean(ss))
    return out


ERROR_BINS_DEG = (1.0, 3.0, 10.0, 90.0)


def by_block_error(rows) -> list[dict]:
    """The aligned methods' gain as a function of the block estimate's error: per bin of the
    error (block's strongest direction against the pixel's first edge; upper bounds
    ``ERROR_BINS_DEG``), the pixel count and the median slope and variance ratio at the largest
    n (to pmj02bn) of ``aligned (block)``, with ``aligned (true)`` on the same pixels."""
    err, idx = [], []
    for i, r in enumerate(rows):
        if r["block_directions_deg"] and r["true_directions_deg"]:
            err.append(metrics.axial_distance_deg(r["block_directions_deg"][0],
                                                     r["true_directions_deg"][0]))
            idx.append(i)
    err = np.asarray(err, float)
    out, lo = [], 0.0
    for hi in ERROR_BINS_DEG:
        sel = [idx[k] for k in np.flatnonzero((err > lo) & (err <= hi) | ((lo == 0) & (err == 0)))]
        entry = {"error_deg": [lo, hi], "pixels": len(sel)}
        for m in ("aligned (block)", "aligned (true)"):
            if sel:
                r_m = [rows[i]["methods"][m] for i in sel]
                ratio = [c["variance"][-1] / rows[i]["methods"]["pmj02bn"]["variance"][-1]
                         for c, i in zip(r_m, sel, strict=True)]
                entry[m] = {"slope_median": float(np.median([c["slope"] for c in r_m])),
                            "ratio_median": float(np.median(ratio))}
        out.append(entry)
        lo = hi
    return out


def run_scene(name, cfg, key, out, fresh, devices=None):
    settings = {"scene": name, **cfg, "seed_key": str(jax.random.key_data(key).tolist()),
                "variance_chunks": CHUNKS}
    path = out / "scenes" / f"{name}.json"
    cached = common.cached_json(path, fresh)
    if cached is not None and cached.get("settings") == settings:
        stale = [c for c in cached["classes"].values()
                 if c["pixels"] and "gate_discontinuous" not in c["pixels"][0]]
        absent = [c for c in CLASS_NAMES if c not in cached["classes"]]
        beyond = [n for n, c in cached["classes"].items()
                  if c["pixels"] and "aligned (pixel)" not in c["pixels"][0]["methods"]]
        if stale or absent or beyond:  # a record from before a column or class was added
            full = W.load_scene(name, cfg["size"], cfg["size"])
            base = W.base_integrand(full, name)
            for c in stale:
                add_gate(full, base, c["pixels"])
            for cname in absent:
                cached["classes"][cname] = measure_extra_class(name, cname, cfg, key, full, base,
                                                               devices=devices)
            for cname in beyond:
                c = cached["classes"][cname]
                add_beyond(full, base, cname, c["pixels"], c["ns"], cfg,
                           jax.random.fold_in(key, CLASS_NAMES.index(cname)), devices)
                asp.io.save_json(path, cached, overwrite=True)  # resumable class by class
            asp.io.save_json(path, cached, overwrite=True)
        for c in cached["classes"].values():  # derived: follows this script's summary
            c["summary"] = summarize(c["pixels"], c["ns"])
        return cached
    started = time.time()
    rng = np.random.default_rng(np.asarray(jax.random.key_data(key)).astype(np.uint32))
    full, coarse_counts, picked = pick_pixels(name, cfg, rng)
    base = W.base_integrand(full, name)
    cache = {}
    rec = {"settings": settings, "resolution": [cfg["size"], cfg["size"]],
           "coarse_class_counts": coarse_counts, "classes": {}}
    for i, cname in enumerate(CLASS_NAMES[:3]):
        pixels, dirs, num = picked[cname]
        print(f"{name}: {cname}: {len(pixels)} pixels")
        rec["classes"][cname] = measure_class(full, base, cname, pixels, dirs, num, cfg,
                                              jax.random.fold_in(key, i), cache, devices)
    for cname in CLASS_NAMES[3:]:
        rec["classes"][cname] = measure_extra_class(name, cname, cfg, key, full, base, cache,
                                                    devices)
    rec["seconds"] = time.time() - started
    asp.io.save_json(path, rec, overwrite=True)
    return rec


def measure_extra_class(name, cname, cfg, key, full, base, cache=None, devices=None):
    """The classes after the first three (their own keys, so adding one leaves the others)."""
    cache = {} if cache is None else cache
    i = CLASS_NAMES.index(cname)
    pixels, dirs, num = lit_in_aligned_blocks(name, cfg, jax.random.fold_in(key, 100 + i),
                                              full, base, cache)
    print(f"{name}: {cname}: {len(pixels)} pixels")
    return measure_class(full, base, cname, pixels, dirs, num, cfg, jax.random.fold_in(key, i),
                         cache, devices)


def figure(results, out):
    names = list(results)
    fig, axes = plot.new_figure(max(1, len(names)), len(CLASS_NAMES), size=2.8)
    for row, s in enumerate(names):
        for col, cname in enumerate(CLASS_NAMES):
            ax = axes[row, col]
            c = results[s]["classes"].get(cname, {})
            if not c.get("pixels"):
                ax.set_title(f"{s}: {cname}: no pixels", fontsize=8)
                continue
            ns = c["ns"]
            for m in c["pixels"][0]["methods"]:
                v = np.median([r["methods"][m]["variance"] for r in c["pixels"]], axis=0)
                sm = c["summary"][m]
                plot.convergence_panel(ax, c["pixels"][0]["methods"][m].get("ns", ns), v,
                                       label=m, slope=sm["slope_median"])
            ax.legend(fontsize=5, loc="lower left")
            ax.set_title(f"{s}: {cname} ({len(c['pixels'])} px), median variance", fontsize=8)
    return plot.save_figure(fig, out / NAME, formats=("png",))


def compute(settings, args):
    """Every scene's record in ``scenes/`` (resumable: a finished scene is reused)."""
    devices = common.render_devices(args)  # before anything runs on JAX
    results, missing = W.run_scenes(NAME, args, SCALES[args.scale],
                                    functools.partial(run_scene, devices=devices))
    return {"scenes": results, "missing_scenes": missing}


def report(data, args):
    print(f"figure: {args.out / NAME}.png\nnumbers: {args.out / NAME}.json")
    for s, r in data["scenes"].items():
        for cname, c in r["classes"].items():
            print(f"  {s} {cname}: {len(c['pixels'])} pixels at {r['resolution']}")
            for m, sm in c["summary"].items():
                if m == "gate_discontinuous_share":
                    print(f"    gate: {100 * sm:.0f}% of the pixels see a discontinuity")
                    continue
                if m == "block_direction_error_deg":
                    print(f"    block direction error: median {sm['median']:.1f} deg, "
                          f"{100 * sm['within_3_deg']:.0f}% within 3 deg")
                    continue
                if m in ("window_direction_error_deg", "pixel_direction_error_deg"):
                    print(f"    {m.split('_')[0]} direction error: median {sm['median']:.2f} deg")
                    continue
                if m == "pixel_search_samples":
                    print(f"    pixel search: {sm:.1f} samples per pixel beyond the prefix")
                    continue
                if m == "by_block_error":
                    for b in sm:
                        if b["pixels"]:
                            print(f"    block error {b['error_deg'][0]:g}-{b['error_deg'][1]:g}"
                                  f" deg: {b['pixels']} px, aligned (block) Var / pmj02bn "
                                  f"{b['aligned (block)']['ratio_median']:.2f}, slope "
                                  f"{b['aligned (block)']['slope_median']:+.2f}; aligned (true)"
                                  f" {b['aligned (true)']['ratio_median']:.2f}")
                    continue
                q = sm["slope_quartiles"]
                print(f"    {m:22s} slope {sm['slope_median']:+.2f} [{q[0]:+.2f}, {q[1]:+.2f}]"
                      f" (256/1k/4k: {sm.get('slope3_median', float('nan')):+.2f})"
                      f"  Var@{c['ns'][-1]} / pmj02bn {sm['ratio_median']:.2f}"
                      f" (geometric mean {sm.get('ratio_geomean', float('nan')):.2f}"
                      f" +- {sm.get('ratio_geomean_se', float('nan')):.2f})")


def arguments(p):
    W.scene_option(p, SCENES)
    common.devices_option(p, default=1)  # the pixel variances' shifts (the same bits on any)


def main(argv=None):
    return common.run(NAME, __doc__.splitlines()[0], SCALES, compute,
                      figure=lambda data, args: figure(data["scenes"], args.out), report=report,
                      arguments=arguments, settings=W.scene_settings,
                      argv=argv)


if __name__ == "__main__":
    main()

"""The error of per-block direction estimates against the pixels' own classified directions
(W Fig. 7's score).

A block's estimate (:func:`anisosample.render.estimation.estimate_blocks`) is one direction for
all its pixels; the truth of a pixel is its own integrand's class
(:func:`anisosample.render.pixel_classes.pixel_classes`). For every pixel classified
``"one-edge"`` the error is the axial distance (mod 180) between its true spectral direction and
its block's *first* estimated direction (the one W's aligned sampler uses):

* :func:`block_pixels`: which pixels of a block are classified: the ``lattice x lattice`` pixels
  at offsets ``lattice/2, 3 lattice/2, ...`` plus any proposed ones;
* :func:`block_errors`: per block its one-edge pixels, their true directions and errors;
* :func:`summarize_errors`: per image the median error over blocks (each block's median) and
  over pixels, the share within 3 degrees, both again for pixels at least ``min_axis_deg`` from
  both axes; blocks with one-edge pixels but no estimate are counted apart.
"""

from __future__ import annotations

import numpy as np

from .._validate import check_int
from ..metrics import axial_distance_deg, off_axis_deg
from .pixel_classes import CLASSES, PixelClasses

__all__ = ["block_errors", "block_pixels", "summarize_errors"]

WITHIN_DEG = 3.0
"""The error counted as a hit by :func:`summarize_errors` (``within_3_deg``)."""


def block_pixels(block, block_px: int, lattice: int, extra=()) -> np.ndarray:
    """``(m, 2)`` ``[column, row]`` (sorted, no repeats) of the pixels classified in ``block =
    (block_row, block_col)`` of ``block_px x block_px`` pixels: every ``lattice``-th pixel in
    both axes starting at ``lattice // 2``, plus the ``(column, row)`` pixels of ``extra``."""
    block_px = check_int("block_px", block_px, minimum=1)
    lattice = check_int("lattice", lattice, minimum=1)
    a, b = block
    offs = range(lattice // 2, block_px, lattice)
    px = {(b * block_px + j, a * block_px + i) for i in offs for j in offs} | set(extra)
    return np.array(sorted(px), int)


def block_errors(blocks, directions_deg, valid, classes: PixelClasses, pixels) -> list[dict]:
    """Per block of ``blocks`` (``(block_row, block_col)``, with its classified ``pixels``, an
    ``(m, 2)`` ``[column, row]`` array each): its pixels classified one-edge in ``classes``,
    their true directions, the block's first direction (``directions_deg[a, b, 0]`` if
    ``valid[a, b, 0]``, else None) and each pixel's axial distance to it (none without an
    estimate). Directions and errors rounded to 3 decimals, as W Fig. 7's record keeps them."""
    rows = []
    one = CLASSES.index("one-edge")
    for blk, px in zip(blocks, pixels, strict=True):
        a, b = blk
        sel = px[classes.classes[px[:, 1], px[:, 0]] == one]
        true = classes.directions_deg[sel[:, 1], sel[:, 0], 0].astype(float)
        est = float(directions_deg[a, b, 0]) if valid[a, b, 0] else None
        err = ([float(axial_distance_deg(est, t)) for t in true]
               if est is not None else [])
        rows.append({"block": [a, b], "pixels_classified": len(px),
                     "one_edge_pixels": sel.tolist(), "true_directions_deg": true.round(3).tolist(),
                     "block_direction_deg": est, "errors_deg": np.round(err, 3).tolist()})
    return rows


def _stats(per_block, per_pixel):
    def one(x):
        x = np.asarray(x, float)
        if len(x) == 0:
            return {"median": None, "within_3_deg": None, "n": 0}
        return {"median": float(np.median(x)), "within_3_deg": float(np.mean(x <= WITHIN_DEG)),
                "n": int(len(x))}
    return {"blocks": one(per_block), "pixels": one(per_pixel)}


def summarize_errors(rows, min_axis_deg: float) -> dict:
    """The summary of :func:`block_errors`' ``rows``: counts of blocks (sampled, with one-edge
    pixels, with and without an estimate) and of one-edge pixels; under ``"all"`` and
    ``"off_axis"`` (pixels whose true direction is at least ``min_axis_deg`` from both axes),
    ``{"blocks": ..., "pixels": ...}`` each ``{"median", "within_3_deg", "n"}`` (None, None, 0
    when empty) over the blocks' medians and over all their pixels' errors."""
    edge = [r for r in rows if r["one_edge_pixels"]]
    with_est = [r for r in edge if r["block_direction_deg"] is not None]
    out = {"blocks_sampled": len(rows), "blocks_with_one_edge_pixels": len(edge),
           "blocks_with_one_edge_pixels_and_estimate": len(with_est),
           "blocks_with_one_edge_pixels_no_estimate": len(edge) - len(with_est),
           "one_edge_pixels": sum(len(r["one_edge_pixels"]) for r in edge)}
    out["all"] = _stats([np.median(r["errors_deg"]) for r in with_est],
                        [e for r in with_est for e in r["errors_deg"]])
    off_block, off_px = [], []
    for r in with_est:
        e = [e for e, t in zip(r["errors_deg"], r["true_directions_deg"], strict=True)
             if off_axis_deg(t) >= min_axis_deg]
        if e:
            off_block.append(np.median(e))
            off_px += e
    out["off_axis"] = _stats(off_block, off_px)
    return out

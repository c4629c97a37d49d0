"""anisosample.render.direction_error (W Fig. 7's score) against hand-made truth: classes and
estimates whose axial distances (mod 180) are known by construction, so the per-block errors, the
medians and the 3-degree shares can be written down; and a block's pixel sample, which must be
its lattice plus the proposals and lie inside the block."""

import numpy as np
import pytest

from anisosample.render import direction_error as de
from anisosample.render import pixel_classes as pc


def _classes(size, one_edge):
    """A ``size^2`` PixelClasses: lit everywhere but ``one_edge`` {(col, row): direction}."""
    cl = np.full((size, size), pc.CLASSES.index("lit"), np.int8)
    d = np.zeros((size, size, 2), np.float32)
    n = np.zeros((size, size), np.int8)
    for (c, r), t in one_edge.items():
        cl[r, c], d[r, c, 0], n[r, c] = pc.CLASSES.index("one-edge"), t, 1
    return pc.PixelClasses(cl, d, n, np.ones((size, size), bool), 64, "light", "area")


def test_block_pixels_lattice_and_proposals_inside_the_block():
    block = (2, 3)
    px = de.block_pixels(block, 16, 4, [(3 * 16 + 7, 2 * 16 + 1), (3 * 16 + 2, 2 * 16 + 2)])
    assert len(px) == 16 + 1  # the 4x4 lattice plus one new proposal (the other is on it)
    assert np.all(px[:, 0] // 16 == 3) and np.all(px[:, 1] // 16 == 2)
    lattice = {(3 * 16 + j, 2 * 16 + i) for i in (2, 6, 10, 14) for j in (2, 6, 10, 14)}
    assert {tuple(p) for p in px} == lattice | {(3 * 16 + 7, 2 * 16 + 1)}
    assert [tuple(p) for p in px] == sorted(tuple(p) for p in px)
    with pytest.raises(ValueError, match="lattice"):
        de.block_pixels(block, 16, 0)


def test_block_errors_are_axial_distances_and_summary_counts():
    # block (0, 0): estimate 178, pixels at 1 and 10 (axial errors 3 and 12);
    # block (0, 1): estimate 45, pixel at 47 (error 2, and at least 10 deg off both axes);
    # block (1, 0): one-edge pixel but no estimate; block (1, 1): no one-edge pixel.
    cls = _classes(32, {(2, 2): 1.0, (6, 2): 10.0, (18, 6): 47.0, (2, 18): 30.0})
    est_d = np.zeros((2, 2, 2))
    est_v = np.zeros((2, 2, 2), bool)
    est_d[0, 0, 0], est_v[0, 0, 0] = 178.0, True
    est_d[0, 1, 0], est_v[0, 1, 0] = 45.0, True
    est_d[1, 1, 0], est_v[1, 1, 0] = 60.0, True
    blocks = [(0, 0), (0, 1), (1, 0), (1, 1)]
    pixels = [de.block_pixels(b, 16, 4) for b in blocks]
    rows = de.block_errors(blocks, est_d, est_v, cls, pixels)
    assert rows[0]["errors_deg"] == pytest.approx([3.0, 12.0], abs=1e-3)
    assert rows[0]["block_direction_deg"] == 178.0 and rows[0]["pixels_classified"] == 16
    assert rows[1]["errors_deg"] == pytest.approx([2.0], abs=1e-3)
    assert rows[2]["one_edge_pixels"] == [[2, 18]] and rows[2]["errors_deg"] == []
    assert rows[2]["block_direction_deg"] is None
    assert rows[3]["one_edge_pixels"] == []
    s = de.summarize_errors(rows, 10.0)
    assert s["blocks_sampled"] == 4 and s["one_edge_pixels"] == 4
    assert s["blocks_with_one_edge_pixels"] == 3
    assert s["blocks_with_one_edge_pixels_and_estimate"] == 2
    assert s["blocks_with_one_edge_pixels_no_estimate"] == 1
    assert s["all"]["blocks"]["median"] == pytest.approx(np.median([7.5, 2.0]), abs=1e-3)
    assert s["all"]["blocks"]["within_3_deg"] == pytest.approx(0.5)
    assert s["all"]["pixels"]["median"] == pytest.approx(3.0, abs=1e-3)
    assert s["all"]["pixels"]["within_3_deg"] == pytest.approx(2 / 3)
    # off-axis (>= 10 deg from both axes): the pixels at 10 and 47 only
    assert s["off_axis"]["pixels"]["n"] == 2
    assert s["off_axis"]["pixels"]["median"] == pytest.approx(7.0, abs=1e-3)
    assert s["off_axis"]["blocks"]["n"] == 2


def test_an_image_without_one_edge_pixels_has_no_medians():
    rows = de.block_errors([(0, 0)], np.zeros((1, 1, 2)), np.ones((1, 1, 2), bool),
                           _classes(16, {}), [de.block_pixels((0, 0), 16, 4)])
    s = de.summarize_errors(rows, 10.0)
    assert s["all"] == {"blocks": {"median": None, "within_3_deg": None, "n": 0},
                        "pixels": {"median": None, "within_3_deg": None, "n": 0}}
    assert s["blocks_with_one_edge_pixels"] == 0

"""The per-pixel aligned sampler (render.pixel_aligned): unbiased with the prefix reused, each
pixel's directions against its dense-grid class, the record, same bits."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import assert_pytree_round_trips

import anisosample.render as R
from anisosample import edges, samplers
from anisosample import variance as V
from anisosample.integrands import GaussianBump, HalfPlane
from anisosample.metrics import axial_distance_deg
from anisosample.prefix import prefix_points, prefix_size
from anisosample.render import pixel_aligned as PA
from anisosample.render.integrator import render_chunk

from .helpers import SCENES


def test_prefix_rule():
    spps = (64, 96, 128, 255, 256, 511, 512, 4096)
    assert [prefix_size(PA.pixel_prefix(n)) for n in spps] == [
        16, 24, 32, 32, 32, 56, 64, 64]
    with pytest.raises(ValueError, match="spp must be >= 64"):
        PA.pixel_prefix(32)


def _boundary_estimates(normal_deg: float, reuse: bool):
    """The worst case for a set chosen from the shifted prefix: the true direction halfway
    between two table directions, so the choice flips with the shift (measured: 41/42 about
    half each). Checks that it flips, that the mean over 2000 shifts matches the half-plane's
    closed-form area within 4 standard errors and that the variance beats pmj02bn's at n = 64;
    returns the estimates."""
    h = HalfPlane.through((0.47, 0.52), normal_deg)
    r = PA.integrand_estimates(h, 64, jax.random.key(7), 2000, reuse=reuse)
    picked = np.floor(r.directions_deg[:, 0] + 0.5)
    assert min(np.sum(picked == np.floor(normal_deg)), np.sum(picked == np.ceil(normal_deg))) > 500
    e = r.estimates
    se = e.std(ddof=1) / np.sqrt(len(e))
    assert abs(e.mean() - h.integral) < 4 * se
    pmj = V.realization_estimates(h, samplers.get("pmj02bn")(jax.random.key(1), 64), 64,
                                  jax.random.key(2), 2000, randomization="shift")
    assert np.var(e, ddof=1) < 0.6 * np.var(pmj, ddof=1)
    return h, r


@pytest.mark.parametrize("normal_deg", [41.5, pytest.param(131.5, marks=pytest.mark.slow)])
def test_reuse_is_unbiased_on_a_rounding_boundary(normal_deg):
    """The prefix reused in the estimate (:func:`_boundary_estimates`; measured 0.33x
    pmj02bn's variance)."""
    _, r = _boundary_estimates(normal_deg, reuse=True)
    assert_pytree_round_trips(r)  # PixelEstimates


def test_probes_apart_are_unbiased_on_a_rounding_boundary():
    """``reuse=False``: the shifted prefix only chooses the set; the estimate is the plain
    set's (no prefix) under an independent shift (:func:`_boundary_estimates`)."""
    h, r = _boundary_estimates(41.5, reuse=False)
    # the same search, so the same directions as with the prefix reused (to float32 rounding:
    # the vmapped width differs)
    again = PA.integrand_estimates(h, 64, jax.random.key(7), 8, reuse=True)
    np.testing.assert_allclose(r.directions_deg[:8], again.directions_deg, rtol=1e-6)
    with pytest.raises(TypeError, match="reuse"):
        PA.integrand_estimates(h, 64, jax.random.key(7), 8, reuse=1)


def test_a_prefix_other_than_the_rule_is_taken_and_checked():
    """``prefix=``: the rule's own prefix given explicitly gives the same bits; another size
    gives sets that start with it bit for bit; sizes outside 16..n/4, other kinds and
    non-multiples of 8 are refused naming ``prefix``."""
    h = HalfPlane.through((0.47, 0.52), 30.0)
    a = PA.integrand_estimates(h, 64, jax.random.key(7), 8)
    b = PA.integrand_estimates(h, 64, jax.random.key(7), 8, prefix="dihedral-16")
    np.testing.assert_array_equal(a.estimates, b.estimates)
    sets = PA.prefix_sets([(30,)], 128, prefix="dihedral-16", progress=False)
    np.testing.assert_array_equal(np.asarray(sets[0, :16]),
                                  prefix_points("dihedral-16").astype(np.float32))
    for bad in ("dihedral-8", "dihedral-40", "pmj02bn-16", "dihedral-20", "none"):
        with pytest.raises(ValueError, match="prefix"):
            PA.integrand_estimates(h, 128, jax.random.key(7), 4, prefix=bad)
    with pytest.raises(TypeError, match="prefix"):
        PA.check_pixel_prefix(16, 128)


def test_smooth_fallback_is_unbiased_and_keeps_pmj02bn():
    """No edge: pmj02bn with its own shift and the prefix at weight m^2/(m^2+n^2); the mean
    matches the bump's closed form, the variance is pmj02bn's or lower (theory: 0.94x at
    n = 256 for an N^-2 integrand)."""
    g = GaussianBump((0.45, 0.55), 0.12)
    r = PA.integrand_estimates(g, 256, jax.random.key(9), 1000)
    assert np.all(r.code == 5) and np.all(r.search_samples <= 4)
    e = r.estimates
    se = e.std(ddof=1) / np.sqrt(len(e))
    assert abs(e.mean() - g.integral) < 4 * se
    pmj = V.realization_estimates(g, samplers.get("pmj02bn")(jax.random.key(1), 256), 256,
                                  jax.random.key(2), 1000, randomization="shift")
    assert np.var(e, ddof=1) < 1.15 * np.var(pmj, ddof=1)
    assert PA.prefix_weight(64, 256) == pytest.approx(4096 / (4096 + 65536))


@pytest.fixture(scope="module")
def cornell():
    scene = R.load_xml(SCENES / "cornell.xml", width=24, height=24)
    res = R.render(scene, jax.random.key(3), spp=64, sampler="aligned-pixel", pixel_center=True,
                   progress=False)
    return scene, res


@pytest.fixture(scope="module")
def own(cornell):
    """The same render with every pixel's own search's directions (``neighbours=0``)."""
    return R.render(cornell[0], jax.random.key(3), spp=64, sampler="aligned-pixel",
                    pixel_center=True, progress=False, sampler_options={"neighbours": 0})


def test_record(cornell):
    scene, res = cornell
    code, dirs, extra = res.pixel_sampler, res.pixel_directions, res.pixel_estimation_samples
    assert code.shape == (24, 24) and dirs.shape == (24, 24, 2) and extra.shape == (24, 24)
    assert set(np.unique(code)) <= {3, 4, 5} and (code == 3).sum() > 10
    assert np.all(np.isfinite(dirs[code == 3][:, 0])) and np.all(np.isfinite(dirs[code == 4]))
    assert np.all((dirs[np.isfinite(dirs)] >= 0) & (dirs[np.isfinite(dirs)] < 180))
    # smooth: the re-evaluated prefix (pixel_center: none), the prefix beside pmj02bn, at most
    # one bisection
    assert np.all(extra[code == 5] <= 16 + 4) and np.all(extra[code == 5] >= 16)
    b = res.settings["blocks"]
    assert b["point_set"] == "aligned-pixel" and b["prefix"] == "dihedral-16"
    assert b["reused_samples_per_pixel"] == 16
    assert b["pixels_with_3_direction_set"] == int((code == 3).sum())
    # every set the render used is listed once (the pixels' own requests, recomputed)
    requests, _, _ = PA.choose_sets(dirs.reshape(-1, 2), np.isfinite(dirs).sum(-1).reshape(-1),
                                    2, PA.NEAR_AXIS_DEG, axis_snap=True)
    assert sorted(b["sets_3_directions_deg"]) == sorted(e[0] for e in requests if len(e) == 1)
    assert sorted(b["sets_4_directions_deg"]) == sorted(list(e) for e in requests if len(e) == 2)
    assert b["estimation_samples_per_pixel"] == pytest.approx(float(extra.mean()), abs=1e-3)
    # RenderResult: the images are leaves, spp, realizations and the settings record static
    assert_pytree_round_trips(res)
    assert [leaf.shape for leaf in jax.tree.leaves(res)] == [(24, 24, 3), (24, 24), (24, 24, 2),
                                                             (24, 24)]


def test_directions_match_the_dense_grid_classes(cornell):
    """Each one-edge pixel's direction against its own 128^2-grid class (pixel_classes, a
    different estimator on 16k samples): the grid's fit is itself good to a few tenths of a
    degree, so the median stays below 0.5. Only the render's one-edge pixels are classified
    (``pixels=``: each pixel's class is its own grid's, the same as in the whole image's)."""
    scene, res = cornell
    rows, cols = np.nonzero(res.pixel_sampler == 3)
    cls = R.pixel_classes.pixel_classes(scene, np.stack([cols, rows], -1), grid=128)
    one = cls.mask("one-edge") & (res.pixel_sampler == 3)
    assert one.sum() >= 10
    err = axial_distance_deg(res.pixel_directions[one][:, 0], cls.directions_deg[one][:, 0])
    assert np.median(err) < 0.5


def test_prefix_and_rest_are_the_whole_set(cornell):
    """The two passes give the estimate of the pixel's whole set under its shift: the prefix's
    samples are in the estimate (reused), not thrown away."""
    scene, res = cornell
    requests, index, code = PA.choose_sets(res.pixel_directions.reshape(-1, 2),
                                          np.isfinite(res.pixel_directions).sum(-1)
                                          .reshape(-1), 2, axis_snap=True)
    sets = PA.prefix_sets(requests, 64, progress=False)
    k_pix = jax.random.split(jax.random.fold_in(jax.random.key(3), 0))[1]
    for q in np.flatnonzero(code == 3)[:6]:
        whole = render_chunk(scene, sets[index[q]], k_pix, jnp.asarray([q], jnp.int32),
                             options=R.IntegratorOptions(dimension="light",
                                                         pixel_center=True))[0]
        np.testing.assert_allclose(res.mean.reshape(-1, 3)[q], np.asarray(whole), rtol=2e-6,
                                   atol=1e-9)


def test_search_on_candidates_equals_search_everywhere(cornell, own):
    """The render runs the edge search only on pixels with a candidate (pass 1 compacted); the
    search vmapped over every pixel gives the same counts and samples, and the directions to
    float32 rounding (on W Fig. 9's scenes at 128^2 x 256 spp the images were bit for bit the
    same as before the compaction)."""
    scene, res = cornell
    o = R.IntegratorOptions(pixel_center=True).for_scene(scene)
    res = own  # every pixel's own search, before the neighbour consensus
    s = res.settings["blocks"]
    prefix = jnp.asarray(prefix_points(s["prefix"]), jnp.float32)
    k_pix = jax.random.split(jax.random.fold_in(jax.random.key(3), 0))[1]
    q = jnp.arange(scene.width * scene.height, dtype=jnp.int32)
    search = edges.search_options(**s["search"])
    _, rough = PA.prefix_chunk(scene, prefix, k_pix, q, spp=64, options=o, search=search)
    dirs, count, samples = PA.search_chunk(scene, prefix, k_pix, q, spp=64, options=o,
                                           search=search)
    assert 0 < int(rough.sum()) < q.size
    # the same counts and samples; directions to float32 rounding (the vmapped width differs,
    # and with it the last bit of an eigenvector now and then)
    np.testing.assert_array_equal(np.asarray(count).reshape(24, 24),
                                  np.isfinite(res.pixel_directions).sum(-1))
    np.testing.assert_allclose(np.asarray(dirs).reshape(24, 24, 2), res.pixel_directions,
                               rtol=1e-6, atol=0)
    assert np.all(np.asarray(count)[~np.asarray(rough)] == 0)
    extra = np.asarray(samples) + np.where(res.pixel_sampler.reshape(-1) == 5, 16, 0)
    np.testing.assert_array_equal(extra.reshape(24, 24), res.pixel_estimation_samples)


def test_probes_apart_record_and_directions(cornell):
    """``reuse=False`` in a render: the same search (the same directions and sets per pixel),
    no sample reused, the prefix counted as estimation on every pixel, pmj02bn alone on pixels
    without an edge, and the image the same integral (mean over the pixels within 2 %)."""
    scene, res = cornell
    apart = R.render(scene, jax.random.key(3), spp=64, sampler="aligned-pixel",
                     pixel_center=True, progress=False, sampler_options={"reuse": False})
    np.testing.assert_array_equal(apart.pixel_directions, res.pixel_directions)
    np.testing.assert_array_equal(apart.pixel_sampler, res.pixel_sampler)
    b = apart.settings["blocks"]
    assert b["reuse"] is False and b["reused_samples_per_pixel"] == 0
    assert b["fallback_prefix_weight"] == 0.0
    extra = apart.pixel_estimation_samples
    np.testing.assert_array_equal(extra, res.pixel_estimation_samples
                                  + np.where(res.pixel_sampler == 5, 0, 16))
    edge = apart.pixel_sampler != 5
    assert not np.array_equal(apart.mean[edge], res.mean[edge])
    assert abs(apart.mean.mean() / res.mean.mean() - 1) < 0.02


def test_render_takes_the_neighbour_consensus(cornell, own):
    """The render's directions are :func:`neighbour_consensus` of the pixels' own searches
    (``neighbours=0``), and its record counts what the consensus changed; on cornell's 24^2
    penumbrae it changes a few pixels (not a vacuous check)."""
    res = cornell[1]
    dirs, count = PA.neighbour_consensus(own.pixel_directions,
                                         np.isfinite(own.pixel_directions).sum(-1))
    np.testing.assert_array_equal(res.pixel_directions, dirs)
    b = res.settings["blocks"]
    assert b["neighbours"] == PA.NEIGHBOURS == 2 and own.settings["blocks"]["neighbours"] == 0
    first = np.isfinite(own.pixel_directions[..., 0])
    changed = first & (own.pixel_directions[..., 0] != dirs[..., 0])
    dropped = np.isfinite(own.pixel_directions[..., 1]) & np.isnan(dirs[..., 1])
    assert b["pixels_first_direction_from_neighbours"] == int(changed.sum()) > 0
    assert b["pixels_second_direction_dropped"] == int(dropped.sum()) > 0
    # no edge is added where the pixel's own search found none
    np.testing.assert_array_equal(np.isfinite(dirs[..., 0]), first)
    np.testing.assert_array_equal(res.pixel_sampler == 5, own.pixel_sampler == 5)


def _field(h, w):
    """A direction field turning across the image (0.4 and 0.2 degrees per pixel), as the
    penumbra edges of an occluder whose shadow turns: no pixel's true direction is more than
    2.4 degrees from another's within a 5^2 window."""
    y, x = np.mgrid[0:h, 0:w]
    return (30.0 + 0.4 * x + 0.2 * y) % 180.0


def test_neighbour_consensus_replaces_the_searchs_misses():
    """A known field on a band of edge pixels, a fifth of them given a uniformly random first
    direction (the search's misses) and a third a random second one: every true direction is
    kept bit for bit, every miss goes back to within the tolerance of the field, every random
    second direction is dropped, and pixels without an edge stay without."""
    h, w = 40, 48
    rng = np.random.default_rng(7)
    true = _field(h, w)
    band = (np.arange(h)[:, None] >= 8) & (np.arange(h)[:, None] < 30) & np.ones((1, w), bool)
    miss = band & (rng.random((h, w)) < 0.2)
    second = band & (rng.random((h, w)) < 0.33)
    dirs = np.full((h, w, 2), np.nan, np.float32)
    dirs[..., 0] = np.where(band, np.where(miss, rng.uniform(0, 180, (h, w)), true), np.nan)
    dirs[..., 1] = np.where(second, rng.uniform(0, 180, (h, w)), np.nan)
    count = np.isfinite(dirs).sum(-1)
    out, n = PA.neighbour_consensus(dirs, count)
    err = axial_distance_deg(out[..., 0], true, xp=np)
    kept = band & ~miss
    np.testing.assert_array_equal(out[..., 0][kept], dirs[..., 0][kept])
    assert np.all(err[miss] <= PA.CONSENSUS_TOLERANCE_DEG)
    assert np.median(err[miss]) < 0.5
    assert axial_distance_deg(dirs[..., 0][miss], true[miss], xp=np).mean() > 30  # misses
    assert np.all(np.isnan(out[..., 1])) and np.array_equal(n, band.astype(np.int32))
    assert np.all(np.isnan(out[~band]))
    # radius 0: the search's own directions
    same, c0 = PA.neighbour_consensus(dirs, count, radius=0)
    np.testing.assert_array_equal(same, dirs)
    np.testing.assert_array_equal(c0, count)


def _consensus_by_pixel(d, r=PA.NEIGHBOURS, tol=PA.CONSENSUS_TOLERANCE_DEG, min_support=2,
                        rel=0.5):
    """The consensus of :func:`neighbour_consensus`'s docstring, pixel by pixel in loops:
    directions as float32 doubled-angle unit vectors, ties to the first in the window's
    row-major order after the pixel's own."""
    h, w, _ = d.shape
    found = np.isfinite(d)
    phi = np.radians(2.0 * np.nan_to_num(d.astype(np.float64)))
    vec = np.where(found[..., None], np.stack([np.cos(phi), np.sin(phi)], -1), 0.0
                   ).astype(np.float32)
    cos2 = np.float32(np.cos(np.radians(2.0 * tol)))

    def agree(a, b):
        return a[0] * b[0] + a[1] * b[1] >= cos2

    def window(y, x):
        return [(y + dy, x + dx) for dy in range(-r, r + 1) for dx in range(-r, r + 1)
                if (dy or dx) and 0 <= y + dy < h and 0 <= x + dx < w]

    support = np.full((h, w, 2), -1)
    for y, x, j in np.argwhere(found):
        support[y, x, j] = sum(agree(vec[y, x, j], vec[q][k]) for q in window(y, x)
                               for k in range(2))
    out = d.copy()
    for y, x in np.argwhere(found[..., 0]):
        best, best_vec = support[y, x, 0], vec[y, x, 0]
        for q in window(y, x):
            for k in range(2):
                if support[q][k] > best:
                    best, best_vec = support[q][k], vec[q][k]
        total, backing = np.zeros(2, np.float32), 0
        for q in [(y, x), *window(y, x)]:
            for k in range(2):
                if agree(vec[q][k], best_vec):
                    total += vec[q][k]
                    backing += q != (y, x)
        ok = [support[y, x, j] >= min_support and support[y, x, j] >= rel * backing
              for j in range(2)]
        first = vec[y, x, 0]
        if not ok[0] and backing > min_support:
            out[y, x, 0] = np.degrees(np.arctan2(total[1], total[0])) / 2.0 % 180.0
            first = best_vec
        if not ok[1] or agree(vec[y, x, 1], first):
            out[y, x, 1] = np.nan
    return out


def test_neighbour_consensus_is_its_definition():
    """:func:`neighbour_consensus` equals its docstring's definition computed pixel by pixel
    on random directions around a few edge directions, in an image whose strips of rows have
    few and many pixels with directions (the two ways it computes a strip)."""
    rng = np.random.default_rng(3)
    h, w = 80, 30
    density = np.repeat([0.05, 0.9, 0.2], [32, 32, 16])[:, None] * np.ones((1, w))
    has = rng.random((h, w)) < density
    dirs = np.full((h, w, 2), np.nan, np.float32)
    base = rng.choice([20.0, 95.0, 179.0], (h, w))
    dirs[..., 0] = np.where(has, (base + rng.normal(0, 1.5, (h, w))) % 180.0, np.nan)
    dirs[..., 1] = np.where(has & (rng.random((h, w)) < 0.3), rng.uniform(0, 180, (h, w)),
                            np.nan)
    out, n = PA.neighbour_consensus(dirs, np.isfinite(dirs).sum(-1))
    expect = _consensus_by_pixel(dirs.astype(np.float64))
    np.testing.assert_allclose(out, expect, rtol=0, atol=1e-4)
    np.testing.assert_array_equal(n, np.isfinite(expect).sum(-1))
    assert (out[..., 0] != dirs[..., 0]).sum() > 10  # some swapped
    assert np.isnan(out[..., 1]).sum() > np.isnan(dirs[..., 1]).sum()  # some dropped


def test_neighbour_consensus_keeps_a_corner():
    """Two one-pixel-wide edges across the image, at 10 (row 20) and 100 degrees (column 24),
    meet at a corner pixel that has both: every pixel keeps its directions, the corner both;
    a miss on the row edge takes the row's direction."""
    h, w = 40, 48
    dirs = np.full((h, w, 2), np.nan, np.float32)
    dirs[20, :, 0] = 10.0
    dirs[:, 24, 0] = 100.0
    dirs[20, 24] = (10.0, 100.0)
    dirs[20, 30, 0] = 61.0  # the search's miss on the row edge
    out, n = PA.neighbour_consensus(dirs, np.isfinite(dirs).sum(-1))
    expect = dirs.copy()
    expect[20, 30, 0] = 10.0
    np.testing.assert_allclose(out, expect, atol=1e-4)
    assert n[20, 24] == 2 and n.sum() == w + h


def test_render_takes_the_prefix_option(cornell):
    """``sampler_options={"prefix": ...}``: the rule's prefix named explicitly renders the same
    bits and records it; a prefix larger than spp / 4 is refused when the render starts, one
    of another kind when the sampler is made, each naming ``prefix``."""
    scene, res = cornell
    same = R.render(scene, jax.random.key(3), spp=64, sampler="aligned-pixel",
                    pixel_center=True, progress=False, sampler_options={"prefix": "dihedral-16"})
    np.testing.assert_array_equal(same.mean, res.mean)
    np.testing.assert_array_equal(same.pixel_directions, res.pixel_directions)
    assert same.settings["blocks"]["prefix"] == "dihedral-16"
    assert same.settings["blocks"]["prefix_points"] == 16
    with pytest.raises(ValueError, match="prefix must be None or 'dihedral-<m>' with m"):
        R.render(scene, jax.random.key(3), spp=64, sampler="aligned-pixel", progress=False,
                 sampler_options={"prefix": "dihedral-32"})
    with pytest.raises(ValueError, match="prefix must be None or 'dihedral-<m>'"):
        PA.pixel_sampler(scene, prefix="pmj02bn-16")
    assert PA.pixel_sampler(scene, prefix="dihedral-32").prefix_for(128) == "dihedral-32"
    assert PA.pixel_sampler(scene).prefix_for(256) == PA.pixel_prefix(256) == "dihedral-32"
    assert PA.pixel_sampler(scene).prefix_for(512) == "dihedral-64"


def test_same_key_same_bits(cornell):
    scene, res = cornell
    again = R.render(scene, jax.random.key(3), spp=64, sampler="aligned-pixel",
                     pixel_center=True, progress=False)
    np.testing.assert_array_equal(res.mean, again.mean)
    np.testing.assert_array_equal(res.pixel_directions, again.pixel_directions)


def test_bad_input():
    scene = R.load_xml(SCENES / "cornell.xml", width=8, height=8)
    with pytest.raises(ValueError, match="needs spp >= 64"):
        R.render(scene, jax.random.key(0), spp=32, sampler="aligned-pixel", progress=False)
    with pytest.raises(TypeError, match="unknown edge-search option"):
        R.render(scene, jax.random.key(0), spp=64, sampler="aligned-pixel", progress=False,
                 sampler_options={"stepz": 2})
    with pytest.raises(ValueError, match="k must be"):
        PA.pixel_sampler(scene, k=3)
    other = R.load_xml(SCENES / "cornell.xml", width=4, height=4)
    with pytest.raises(ValueError, match="sampler was made for a 4x4 image"):
        R.render(scene, jax.random.key(0), spp=64, sampler=PA.pixel_sampler(other),
                 progress=False)

"""anisosample.render.aligned / estimation and anisosample.selection: per-block direction
estimates and per-block point sets in the renderer (W Sec. 5.3-5.4), ``render(sampler="aligned")``
and ``anisosample render --sampler aligned``. W's own method (3-direction sets, no gate) is
``k=1, gate=False``; the defaults (4-direction sets for two directions, the per-pixel gate) are
checked here on the selection and in tests/render/test_gate.py on the variance.

Truth: the box-edge shadow directions predicted from the Cornell geometry (central projection
onto the light plane, ``tests/render/test_shadow_directions.py``), the pixel integrands
evaluated one by one, the table sets looked up directly, converged pixel values (512^2-point
quadrature of the pixel integrand), and the ordinary pmj02bn render of the same scene and key
(an unbiased estimator of the same pixel values, with the same per-pixel shifts). Where only the
choice of set is tested, 4-direction tables are stand-ins of random points (the selection does
not look at the points).
"""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import anisosample.render as R
from anisosample import _table_build, cli, io, samplers, scenes, selection, tables
from anisosample.metrics import midpoint_grid
from anisosample.render import aligned
from anisosample.render.camera import generate_ray
from anisosample.render.geometry import intersect

from .helpers import LIGHT_HALF, LIGHT_Y, box_edges

CORNELL = scenes.path("cornell")
SIZE, BLOCK, S, SPP, R_ = 32, 8, 96, 256, 8  # 4x4 blocks of 8x8 px, 12x12 samples per pixel


@pytest.fixture(scope="module")
def scene():
    return R.load_xml(CORNELL, width=SIZE, height=SIZE)


@pytest.fixture(scope="module")
def est(scene):
    return aligned.estimate_blocks(scene, BLOCK, S, strength=True)


@pytest.fixture(scope="module")
def renders(scene, est):
    """The aligned and the pmj02bn render (fixed primary hit, the papers' 2D integrands) with
    the same key: per pixel, the mean and variance over R_ realizations."""
    key = jax.random.key(7)
    sampler = aligned.block_sampler(scene, "aligned", estimate=est, k=1, gate=False)  # W's
    opts = dict(spp=SPP, realizations=R_, pixel_center=True, progress=False)
    return (sampler, R.render(scene, key, sampler=sampler, **opts),
            R.render(scene, key, sampler="pmj02bn", **opts))


BOXES = ([0.3, 0.6, 0.3], 20, [-0.35, -0.4, -0.3]), ([0.3] * 3, -15, [0.4, -0.7, 0.3])  # xml


def _segment_crosses_light(a, b):
    """Whether the 2D segment ``a -> b`` (light-plane X, Z) meets the open light square
    (Liang-Barsky clipping)."""
    t0, t1 = 0.0, 1.0
    d = b - a
    for k in range(2):
        for sign in (-1.0, 1.0):  # sign * (a_k + t d_k) < LIGHT_HALF
            q, r = sign * d[k], LIGHT_HALF - sign * a[k]
            if abs(q) < 1e-15:
                if r <= 0:
                    return False
            elif q > 0:
                t1 = min(t1, r / q)
            else:
                t0 = max(t0, r / q)
    return t1 - t0 > 1e-9


def _predicted_directions(p):
    """Spectral directions (degrees) of the shadow edges inside the light seen from ``p``.

    Each box is convex, so its shadow on the light plane (``y = LIGHT_Y``) is the convex hull
    of the central projections from ``p`` of its edges' parts above ``p`` (clipped 1e-3 above);
    the light sample maps the plane isotropically to ``[0, 1)^2``, so a hull side crossing the
    light is an edge of ``f_q`` at the side's angle + 90 degrees (spectral direction).
    """
    from scipy.spatial import ConvexHull

    out = set()
    for box in BOXES:
        pts = []
        for a, b in box_edges(*box):
            lo = p[1] + 1e-3
            if max(a[1], b[1]) <= lo:
                continue
            if min(a[1], b[1]) < lo:  # clip to the part above p
                t = (lo - a[1]) / (b[1] - a[1])
                c = a + t * (b - a)
                a, b = (c, b) if a[1] < lo else (a, c)
            for e in (a, b):
                q = p + (e - p) * (LIGHT_Y - p[1]) / (e[1] - p[1])
                pts.append([q[0], q[2]])
        if len(pts) < 3:
            continue
        pts = np.asarray(pts)
        hull = ConvexHull(pts)
        for i, j in hull.simplices:
            if _segment_crosses_light(pts[i], pts[j]):
                d = pts[j] - pts[i]
                out.add(round(float((np.degrees(np.arctan2(d[1], d[0])) + 90) % 180), 1))
    return sorted(out)


@jax.jit
def _hits(scene, pixels):
    """Primary hit points of the pixel centres ``pixels`` (k, 2) = (column, row)."""
    size = jnp.array([scene.width, scene.height], jnp.float32)

    def one(q):
        o, d = generate_ray(scene.camera, (q + 0.5) / size, jnp.array([0.5, 0.5], jnp.float32))
        return intersect(scene, o, d).p

    return jax.vmap(one)(pixels.astype(jnp.float32))


def test_grid_is_the_pixels_integrands(scene, est):
    grid = aligned.estimation_grid(scene, BLOCK, S)
    assert grid.shape == (SIZE // BLOCK * S,) * 2 and grid.dtype == np.float32
    t = S // BLOCK
    for a, b in [(3, 1), (2, 2)]:
        block = grid[a * S:(a + 1) * S, b * S:(b + 1) * S]
        np.testing.assert_array_equal(block, aligned.block_grid_values(scene, (a, b), BLOCK, S))
        # sample (i, j) of the block is pixel (row0 + i // t, col0 + j // t)'s f at the cell
        for i, j in [(0, 0), (37, 90), (95, 12)]:
            f = R.pixel_integrand(scene, (b * BLOCK + j // t, a * BLOCK + i // t))
            x = jnp.array([(j + 0.5) / S, (i + 0.5) / S], jnp.float32)
            np.testing.assert_allclose(block[i, j], float(f(x)), rtol=1e-5, atol=1e-7)
    assert est.blocks == (4, 4) and est.integrand_samples == 16 * S * S
    assert est.samples_per_pixel == (S // BLOCK) ** 2
    assert est.strength.shape == (4, 4) and np.all(est.strength >= 0)


# Blocks of a 1280^2 Cornell render (W's resolution and 16-pixel blocks) on the floor or the
# back wall with one box shadow edge across the light (found by scanning every third block).
EDGE_BLOCKS = [(72, 12), (72, 15), (72, 18), (72, 69), (75, 48), (75, 69), (75, 72), (48, 18),
               (54, 18), (60, 18)]


def test_blocks_with_a_known_shadow_edge_get_its_direction():
    """W Sec. 5.3 / Fig. 7 at W's scale: each block's strongest direction from its tiled 96^2
    grid is the shadow edge's direction predicted from the geometry for all its pixels, within
    3 degrees (1-degree bins; the edge's angle varies by < 0.5 degrees over a block)."""
    from anisosample import directions

    big = R.load_xml(CORNELL, width=1280, height=1280)
    grids, expected = [], []
    for a, b in EDGE_BLOCKS:
        pix = jnp.array([(b * 16 + j, a * 16 + i) for i in range(0, 16, 5)
                         for j in range(0, 16, 5)])
        pred = {tuple(_predicted_directions(q)) for q in np.asarray(_hits(big, pix), np.float64)}
        assert len(pred) == 1 and len(next(iter(pred))) == 1, ((a, b), pred)
        expected.append(next(iter(pred))[0])
        grids.append(aligned.block_grid_values(big, (a, b), 16, 96))
    # the blocks side by side, through the same per-block estimator estimate_blocks uses
    est = directions.estimate_blocks(np.concatenate(grids, axis=1), k=2, samples_per_block=96)
    d, v = aligned.strongest_directions(est)
    err = np.abs((d[0] - np.asarray(expected) + 90) % 180 - 90)
    assert np.all(v[0]) and np.all(err <= 3.0), list(zip(EDGE_BLOCKS, d[0], expected, strict=True))


def test_point_sets_follow_the_blocks(scene, est):
    key = jax.random.key(3)
    # each block's strongest valid direction: the first slot that passed the confidence test
    # (issue 27: a block whose slot 0 failed and slot 1 passed has a direction)
    slots, ok = np.asarray(est.estimate.directions_deg), np.asarray(est.estimate.valid)
    v = ok.any(-1)
    d = np.array([[next((x for x, y in zip(slots[a, b], ok[a, b], strict=True) if y), -1.0)
                   for b in range(ok.shape[1])] for a in range(ok.shape[0])])
    al = aligned.block_sampler(scene, "aligned", estimate=est, k=1, gate=False)
    sets, pix = al.point_sets(key, SPP)
    pmj = samplers.get("pmj02bn")(key, SPP)
    np.testing.assert_array_equal(np.asarray(sets[0]), np.asarray(pmj))  # the render's pmj02bn
    pix = pix.reshape(SIZE, SIZE)
    distinct = len(al.table_directions) + 1
    rows = 1 << (distinct - 1).bit_length()  # padded with pmj02bn copies no pixel indexes
    assert sets.shape == (rows, SPP, 2) and pix.max() < distinct
    np.testing.assert_array_equal(np.asarray(sets[distinct:]),
                                  np.broadcast_to(np.asarray(pmj), (rows - distinct, SPP, 2)))
    sh = aligned.block_sampler(scene, "sheared", estimate=est)
    assert not sh.gate  # the gate is on by default for "aligned" only
    sh_sets, sh_pix = sh.point_sets(key, SPP)
    sh_pix = sh_pix.reshape(SIZE, SIZE)
    for a in range(SIZE // BLOCK):
        for b in range(SIZE // BLOCK):
            ids = pix[a * BLOCK:(a + 1) * BLOCK, b * BLOCK:(b + 1) * BLOCK]
            assert np.all(ids == ids[0, 0])  # one set per block
            got = np.asarray(sets[ids[0, 0]])
            t = _extra(est, a, b, 1)  # the valid slots, strongest first
            want = pmj if not t else tables.lookup(t, SPP)
            np.testing.assert_array_equal(got, np.asarray(want))
            want_sh = pmj if not v[a, b] else samplers.shear(pmj, float(d[a, b]))
            got_sh = sh_sets[sh_pix[a * BLOCK, b * BLOCK]]
            np.testing.assert_array_equal(np.asarray(got_sh), np.asarray(want_sh))
    assert len(al.table_directions) >= 1


def test_aligned_render_is_unbiased(renders):
    """Per pixel the aligned and the pmj02bn mean estimate the same value: their difference,
    summed over the pixels whose block uses an aligned set, is within 4 standard errors (from
    both renders' per-pixel variances; pixels are uncorrelated, each has its own shift)."""
    sampler, al, pm = renders
    use = _aligned_pixels(sampler)
    assert use.sum() >= 64
    for c in range(3):  # per RGB channel
        ma, mp = al.mean[..., c], pm.mean[..., c]
        va, vp = al.variance[..., c], pm.variance[..., c]
        diff = float(np.sum((ma - mp)[use], dtype=np.float64))
        se = float(np.sqrt(np.sum((va + vp)[use], dtype=np.float64) / R_))
        assert abs(diff) < 4 * se, (c, diff, se)
        assert np.sum(va[use]) > 0  # the shifts randomize the aligned pixels
        ok = use & (va + vp > 0)
        z2 = (ma - mp)[ok] ** 2 / ((va + vp)[ok] / R_)
        # per pixel a t-statistic with ~nu = 2(R-1) = 14 degrees of freedom: E t^2 = nu/(nu-2)
        # = 1.17 (measured: 1.18); a biased pixel estimator would push the mean up
        assert np.mean(z2) < 1.6, (c, np.mean(z2))


def test_aligned_render_matches_converged_pixel_values(scene, renders):
    """Pixels with an aligned set against a converged reference: the pixel integrand's mean
    over a 512^2 midpoint grid (quadrature error ~1e-4 relative, far below the render's
    standard error), green channel; within 4.5 standard errors of the R_-realization mean."""
    sampler, al, _ = renders
    use = _aligned_pixels(sampler)
    rows, cols = np.nonzero(use & (al.variance[..., 1] > 0))
    pick = np.linspace(0, rows.size - 1, 8).astype(int)
    x = jnp.asarray(midpoint_grid(512))
    diffs, vars_ = [], []
    for r, c in zip(rows[pick], cols[pick], strict=True):
        f = R.pixel_integrand(scene, (int(c), int(r)), channel="g")
        ref = float(np.mean(np.asarray(f(x), np.float64)))
        m, v = float(al.mean[r, c, 1]), float(al.variance[r, c, 1]) / R_
        assert abs(m - ref) < 4.5 * np.sqrt(v) + 1e-4 * abs(ref), ((r, c), m, ref, np.sqrt(v))
        diffs.append(m - ref)
        vars_.append(v)
    assert abs(sum(diffs)) < 4 * np.sqrt(sum(vars_)), (diffs, vars_)


def test_aligned_variance_not_above_pmj02bn_on_edge_pixels(renders):
    """W Figs. 8-9: on the pixels of blocks with an aligned set, the aligned sets' variance is
    at most pmj02bn's (here clearly below); elsewhere both renders are the same estimator."""
    sampler, al, pm = renders
    use = _aligned_pixels(sampler)
    va, vp = al.variance.sum(-1), pm.variance.sum(-1)  # trace of the RGB covariance
    ratio = va[use].sum() / vp[use].sum()
    assert ratio <= 1.0, ratio  # measured 0.87 (W Fig. 8's Cornell: 0.89 over the whole image)
    # fallback blocks: the same pmj02bn set and the same per-pixel shifts as the pmj02bn render
    np.testing.assert_allclose(al.mean[~use], pm.mean[~use], rtol=1e-6, atol=1e-7)


def _extra(est, a, b, k):
    """Block ``(a, b)``'s table directions by the selection rule, from its valid slots."""
    d, v = np.asarray(est.estimate.directions_deg), np.asarray(est.estimate.valid)
    return selection.table_directions([x for x, ok in zip(d[a, b], v[a, b], strict=True)
                                       if ok], k)


def _aligned_pixels(sampler):
    by, bx = sampler.valid.shape
    blocks = np.array([[bool(_extra(sampler.estimate, a, b, sampler.k)) for b in range(bx)]
                       for a in range(by)])
    use = np.kron(blocks, np.ones((BLOCK, BLOCK), bool))[:SIZE, :SIZE]
    np.testing.assert_array_equal(use, sampler.pixel_sampler == 2)  # the record says the same
    return use


def test_render_records_the_sampler_and_rejects_bad_options(scene, est):
    s = aligned.block_sampler(scene, "aligned", estimate=est, k=1, build_missing=False)
    rec = s.settings()
    assert rec["block_px"] == BLOCK and rec["estimation_integrand_samples"] == 16 * S * S
    with pytest.raises(ValueError, match="sampler_options"):
        R.render(scene, jax.random.key(0), spp=4, sampler="random",
                 sampler_options={"block_px": 8}, progress=False)
    with pytest.raises(FileNotFoundError, match="tables build --n 64"):
        R.render(scene, jax.random.key(0), spp=64, sampler=s, progress=False)
    with pytest.raises(ValueError, match="not a finished BlockSampler"):
        R.render(scene, jax.random.key(0), spp=SPP, sampler=s, sampler_options={"k": 1},
                 progress=False)
    small = R.load_xml(CORNELL, width=16, height=16)
    with pytest.raises(ValueError, match="32x32 image"):
        R.render(small, jax.random.key(0), spp=SPP, sampler=s, progress=False)


@pytest.mark.parametrize("kwargs, match", [
    (dict(block_px=0), "block_px must be >= 1"),
    (dict(block_px=-4), "block_px must be >= 1"),
    (dict(samples=0), "samples must be >= 1"),
    (dict(samples=100), "multiple of block_px=16"),
    (dict(block_px=4, samples=12), "samples must be >= 15"),
    (dict(k=3), "k must be <= 2"),
    (dict(k=0), "k must be >= 1"),
])
def test_bad_block_options(scene, kwargs, match):
    with pytest.raises(ValueError, match=match):
        aligned.estimate_blocks(scene, **kwargs)


@pytest.mark.library_errors
def test_bad_choices(scene, est):
    with pytest.raises(ValueError, match="point_set must be one of"):
        aligned.block_sampler(scene, "aligned3", estimate=est)
    with pytest.raises(TypeError, match=r"block_sampler\(\) takes point_set= where it took "
                                        r"method="):
        aligned.block_sampler(scene, method="sheared", estimate=est)
    with pytest.raises(TypeError, match="block_px must be an integer"):
        aligned.estimate_blocks(scene, block_px=8.0)
    with pytest.raises(TypeError, match="estimate must be a BlockEstimate"):
        aligned.block_sampler(scene, estimate=object())
    with pytest.raises(ValueError, match="finite"):
        aligned.table_direction(float("nan"))
    assert aligned.table_direction(None) is None
    assert aligned.table_direction(179.6) is None and aligned.table_direction(90.4) is None
    assert aligned.table_direction(30.49) == 30


def test_padding_replicates_the_edge_pixels():
    """A 20x12 image in 8-pixel blocks is padded to 3x2 blocks; the missing pixels repeat the
    last column / row."""
    sc = R.load_xml(CORNELL, width=20, height=12)
    s = 16
    grid = aligned.estimation_grid(sc, 8, s)
    assert grid.shape == (2 * s, 3 * s)
    t = s // 8
    # block (1, 2) covers rows 8..15 (12.. padded) and columns 16..23 (20.. padded)
    blk = grid[s:, 2 * s:]
    f = R.pixel_integrand(sc, (19, 11))
    x = jnp.array([(s - 0.5) / s, (s - 0.5) / s], jnp.float32)
    np.testing.assert_allclose(blk[-1, -1], float(f(x)), rtol=1e-5, atol=1e-7)
    # grid rows 8..15 of the block belong to pixel rows 12..15, outside the image: row 11's
    for i in (4 * t, 7 * t + 1):
        xi = jnp.array([0.5 / s, (i + 0.5) / s], jnp.float32)
        np.testing.assert_allclose(blk[i, 0], float(R.pixel_integrand(sc, (16, 11))(xi)),
                                   rtol=1e-5, atol=1e-7)


@pytest.fixture(scope="module")
def four_tables(tmp_path_factory, scene, est):
    """A table root with a stand-in 4-direction n = SPP table holding every set the k = 2
    sampler of ``est`` needs (random points: only the choice of set is under test)."""
    root = tmp_path_factory.mktemp("tables")
    need = aligned.block_sampler(scene, "aligned", estimate=est, build_missing=False)
    pairs = [e for e in need.table_directions if len(e) == 2]
    assert pairs  # the 32^2 Cornell box has blocks with two directions
    tab = _table_build.create_table(root / tables.table_name(4, SPP), SPP, 4,
                                    synthesis={"steps": 1})
    rng = np.random.default_rng(0)
    for e in {tables.canonicalize(e, direction_count=4).extra for e in pairs}:
        _table_build.write_set(tab, e, rng.random((SPP, 2), dtype=np.float32))
    return root


def test_two_directions_take_the_four_direction_set(scene, est, four_tables, tmp_path,
                                                    monkeypatch):
    """k = 2 (the default): a block with two extra directions gets the 4-direction set of both
    (W Sec. 5.4), one with one direction the 3-direction set, one with none pmj02bn; a missing
    4-direction set is an error naming the 4-direction build, never a 3-direction stand-in."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))  # no user-built sets
    monkeypatch.setenv("ANISOSAMPLE_TABLES", str(four_tables))
    s = aligned.block_sampler(scene, "aligned", estimate=est, gate=False, build_missing=False)
    assert s.k == 2
    s.check_tables(SPP)
    sets, pix = s.point_sets(jax.random.key(3), SPP)
    pix = pix.reshape(SIZE, SIZE)
    kinds = []
    for a in range(SIZE // BLOCK):
        for b in range(SIZE // BLOCK):
            extra = _extra(est, a, b, 2)
            got = np.asarray(sets[pix[a * BLOCK, b * BLOCK]])
            want = (sets[0] if not extra else
                    tables.lookup(extra, SPP, direction_count=len(extra) + 2))
            np.testing.assert_array_equal(got, np.asarray(want))
            kinds.append(len(extra) + 2 if extra else 0)
    rec = s.settings()
    assert rec["blocks_with_4_direction_set"] == kinds.count(4) >= 1
    assert rec["blocks_with_3_direction_set"] == kinds.count(3) >= 1
    assert all(len(e) == 2 for e in rec["sets_4_directions_deg"])
    monkeypatch.delenv("ANISOSAMPLE_TABLES")
    with pytest.raises(FileNotFoundError, match="--direction-count 4"):
        s.check_tables(SPP)


def test_missing_sets_are_built_on_demand(scene, est, tmp_path, monkeypatch):
    """build_missing (the default): a missing 4-direction set is synthesized into the user
    cache before rendering (2 optimizer steps here, to stay fast) and then used."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    s = aligned.block_sampler(scene, "aligned", estimate=est, gate=False,
                              build_options={"steps": 2})
    one = dataclasses.replace(s, block_extra=((30, 100),) + ((),) * 15)
    assert one.table_directions == ((30, 100),)
    with pytest.raises(FileNotFoundError):
        tables.lookup((30, 100), 16, direction_count=4)
    one.check_tables(16, progress=False)
    assert (tables.cache_dir() / "d4_n16").is_dir()
    pts = tables.lookup((30, 100), 16, direction_count=4)
    sets, _ = one.point_sets(jax.random.key(0), 16)
    np.testing.assert_array_equal(np.asarray(sets[1]), np.asarray(pts))
    assert one.settings()["sets_4_directions_deg"] == [[30, 100]]


def test_a_block_marked_without_direction_gets_no_set(scene, est):
    """Issue 27: blocks whose first slot failed the confidence test but whose second passed
    got a set while marked without a direction. The marking is the strongest *valid* slot:
    a block has a direction exactly when a slot is valid, and only such blocks get sets."""
    e = est.estimate
    d = np.asarray(e.directions_deg).copy()
    v = np.asarray(e.valid).copy()
    d[0, 0], v[0, 0] = (-1.0, 40.0), (False, True)  # the case of the issue
    d[0, 1], v[0, 1] = (-1.0, -1.0), (False, False)  # none
    d[0, 2], v[0, 2] = (0.3, -1.0), (True, False)  # valid, but rounds onto an axis: no set
    fake = dataclasses.replace(est, estimate=dataclasses.replace(
        e, directions_deg=jnp.asarray(d), valid=jnp.asarray(v)))
    for point_set in aligned.BLOCK_SAMPLERS:
        s = aligned.block_sampler(scene, point_set, estimate=fake, gate=False, build_missing=False)
        assert s.valid[0, 0] and s.directions_deg[0, 0] == 40.0
        assert not s.valid[0, 1] and s.directions_deg[0, 1] == -1.0
        np.testing.assert_array_equal(s.valid, v.any(-1))
        has = np.array([i is not None for i in s._set_ids()]).reshape(s.valid.shape)
        assert not (has & ~s.valid).any()  # no block without a direction gets a set
        code = s.pixel_sampler
        assert (code[:BLOCK, :BLOCK] == 2).all() and (code[:BLOCK, BLOCK:2 * BLOCK] == 0).all()
        rec = s.settings()
        assert rec["blocks_with_set"] == int(has.sum()) <= rec["blocks_with_direction"]
        assert rec["pixels"] == (code == 2).sum() + rec["pixels_in_blocks_without_set"]
    assert s.point_set == "sheared" and s.valid[0, 2] and has[0, 2]  # sheared: any direction
    al = aligned.block_sampler(scene, "aligned", estimate=fake, gate=False, build_missing=False)
    assert al.block_extra[0] == (40,) and al.block_extra[2] == ()  # 0.3 rounds onto 0


def test_progress_false_silences_the_on_demand_builds(scene, est, tmp_path, monkeypatch, capfd):
    """``render(..., sampler=<aligned>, progress=False)`` prints nothing, not even the
    progress bar of a set it builds on demand; with progress the build's bar shows (so the
    check would see one). A real build, kept small: one 4-direction set, 2 steps."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    s = aligned.block_sampler(scene, "aligned", estimate=est, gate=False,
                              build_options={"steps": 2})
    opts = dict(spp=16, pixel_center=True)
    capfd.readouterr()
    for extra, progress in (((31, 101), False), ((32, 102), True)):
        one = dataclasses.replace(s, block_extra=(extra,) + ((),) * 15)
        R.render(scene, jax.random.key(0), sampler=one, progress=progress, **opts)
        out, err = capfd.readouterr()
        assert tables.lookup(extra, 16, direction_count=4).shape == (16, 2)
        if progress:
            assert "synthesize n=16" in err and "render" in err
        else:
            assert out == "" and err == "", (out, err)


def test_selection_rounding_rule():
    """The one rule (selection.aligned_sampler and the renderer use it): nearest integer degree,
    halves up, mod 180; axes and repeats dropped; strongest first, at most k."""
    ts = selection.table_directions
    assert ts([149.6, 30.2, 0.4], 2) == (150, 30)
    assert ts([30.5, 30.4], 2) == (31, 30) and ts([29.5], 1) == (30,)
    assert ts([179.6, 90.4, 44.0], 2) == (44,) and ts([None, 12.0]) == (12,) and ts([]) == ()
    assert ts([10.2, 9.8, 100.0], 2) == (10, 100)  # 9.8 repeats 10
    assert samplers.get("aligned", directions_deg=[30.5, 100.2]).directions_deg == (31, 100)
    for d in (30.49, 30.5, 179.6):
        assert aligned.table_direction(d) == (ts([d], 1) or (None,))[0]
    with pytest.raises(ValueError, match="finite"):
        ts([float("inf")])
    with pytest.raises(ValueError, match="k must be <= 2"):
        ts([10.0], 3)
    with pytest.raises(ValueError, match="one or two integer directions"):
        selection.aligned_set((), 16)


def test_cli_render_aligned(scene, four_tables, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.setenv("ANISOSAMPLE_TABLES", str(four_tables))  # the k = 2 default's sets
    out, png = tmp_path / "a.exr", tmp_path / "dirs.png"
    # the fixtures' sizes (32^2 pixels, 8-pixel blocks, 96^2 samples): their compilations serve
    args = ["render", str(CORNELL), "--sampler", "aligned", "--spp", str(SPP), "--realizations",
            "2", "--pixel-center", "--block", "8", "--estimation-samples", "96",
            "--set", "width=32", "--set", "height=32", "--direction-map", str(png), "-o",
            str(out)]
    assert cli.main(args) == 0
    text = capsys.readouterr().out
    assert "4x4 blocks of 8x8 px" in text and "147456 samples" in text
    assert "144 per pixel, 56% of --spp 256" in text
    assert "(k = 2); per-pixel gate on: " in text  # the CLI's defaults: W's k, our gate
    img = io.read_exr(out)
    assert img.shape == (SIZE, SIZE, 3)
    ref = R.render(scene, jax.random.key(0), spp=SPP, realizations=2, pixel_center=True,
                   sampler="aligned", sampler_options=dict(block_px=8, samples=96),
                   progress=False)
    np.testing.assert_array_equal(img[..., :3], ref.mean)
    # the summary's numbers are the record's (issue 27: it said the gated count "use pmj02bn")
    code, rec = ref.pixel_sampler, ref.settings["blocks"]
    line = next(ln for ln in text.splitlines() if ln.startswith("pixels: "))
    want = (f"pixels: {(code == 2).sum()} of {SIZE * SIZE} use their block's set "
            f"({rec['blocks_with_set']} of 16 blocks have one), {(code != 2).sum()} use pmj02bn "
            f"({(code == 0).sum()} in blocks without a set, {(code == 1).sum()} gated")
    assert line.startswith(want), (line, want)
    assert rec["blocks_with_set"] == len({p // SIZE // BLOCK * 4 + p % SIZE // BLOCK
                                          for p in np.flatnonzero(code.reshape(-1) != 0)}) >= 1
    assert (f"{rec['blocks_with_direction']} of 16 blocks have an extra direction, "
            f"{rec['blocks_with_set']} a set (k = 2); per-pixel gate on: "
            f"{rec['pixels_gated']} pixels") in text
    assert (tmp_path / "a_variance.exr").exists()
    from matplotlib.image import imread

    h, w = imread(png).shape[:2]  # a figure: two panels (k = 2) at the image's size and a key
    assert 300 < h < 1500 and 2 * h < w < 6 * h
    assert cli.main(args) == 2  # outputs exist: refused
    assert "exists" in capsys.readouterr().err


@pytest.mark.parametrize("extra, match", [
    (["--sampler", "random", "--block", "8"], "need --sampler aligned or sheared"),
    (["--sampler", "aligned", "--spp", "1"], "needs --spp >= 2"),
    (["--sampler", "aligned", "--spp", str(SPP), "--block", "0"], "block_px must be >= 1"),
    (["--sampler", "aligned", "--spp", str(SPP), "--block", "8", "--estimation-samples", "20"],
     "multiple of block_px=8"),
    (["--sampler", "aligned", "--spp", str(SPP), "--direction-map", "m.jpg"], "end in .png"),
])
def test_cli_bad_input(tmp_path, capsys, extra, match):
    args = ["render", str(CORNELL), "--set", "width=16", "--set", "height=16", "-o",
            str(tmp_path / "x.exr"), *extra]
    assert cli.main(args) == 2
    assert match in capsys.readouterr().err

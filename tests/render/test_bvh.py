"""The BVH (render/bvh.py) against brute force: every primitive tested for every ray.

Truth: the brute-force kernel (``Scene.bvh = None``), which tests every planar primitive; the
BVH must report the same hit or miss, the same nearest distance and the same primitive for every
ray (ties to the lowest index, as ``argmin``), and the same shadow-ray answers; a render with
and without it must give the same image.
"""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import anisosample.render as R
from anisosample.render import bvh as B
from anisosample.render.geometry import closest_planar, intersect, occluded


def _soup(n, seed, parallelograms=0, **build):
    """``n`` random triangles (and some parallelograms) in ``[-1, 1]^3``."""
    rng = np.random.default_rng(seed)
    b = R.SceneBuilder()
    m = b.diffuse(0.5)
    c = rng.uniform(-1, 1, (n, 3))
    s = 0.6 * max(n, 1) ** (-1 / 3)
    v = (c[:, None] + rng.normal(0, s, (n, 3, 3))).reshape(-1, 3)
    b.triangles(v, np.arange(3 * n).reshape(-1, 3), m)
    for _ in range(parallelograms):
        t = np.eye(4)
        t[:3, :3] = rng.normal(0, s, (3, 3))
        t[:3, 3] = rng.uniform(-1, 1, 3)
        b.rectangle(t, m)
    b.point_light((0, 0, 5), 1.0)
    b.camera(np.eye(4), width=2, height=2)
    return b.build(**build)


def _rays(seed, n=3000):
    rng = np.random.default_rng(seed)
    o = rng.uniform(-1.6, 1.6, (n, 3))
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    tmin = np.where(rng.random(n) < 0.3, rng.uniform(0, 1, n), 0.0)
    tmax = np.where(rng.random(n) < 0.3, rng.uniform(0.5, 3, n), np.inf)
    f = lambda a: jnp.asarray(a, jnp.float32)  # noqa: E731
    return f(o), f(d), f(tmin), f(tmax)


def _pair(scene):
    assert scene.bvh is not None
    return scene, dataclasses.replace(scene, bvh=None)


_closest = jax.jit(jax.vmap(closest_planar, in_axes=(None, 0, 0, 0, 0)))
_occluded = jax.jit(jax.vmap(occluded, in_axes=(None, 0, 0)))


@pytest.mark.parametrize("n,seed,para", [(1, 0, 0), (7, 1, 2), (300, 2, 20), (3000, 3, 0)])
def test_closest_hit_equals_brute_force(n, seed, para):
    with_bvh, brute = _pair(_soup(n, seed, para, bvh=True))
    o, d, tmin, tmax = _rays(seed + 10)
    tb, ib, b1b, b2b = _closest(with_bvh, o, d, tmin, tmax)
    tn, in_, b1n, b2n = _closest(brute, o, d, tmin, tmax)
    hit = np.isfinite(np.asarray(tn))
    assert hit.sum() > 20 and (~hit).sum() > 20  # both hits and misses are tested
    np.testing.assert_array_equal(np.isfinite(np.asarray(tb)), hit)
    np.testing.assert_array_equal(np.asarray(tb)[hit], np.asarray(tn)[hit])  # nearest distance
    np.testing.assert_array_equal(np.asarray(ib)[hit], np.asarray(in_)[hit])  # primitive
    np.testing.assert_array_equal(np.asarray(b1b)[hit], np.asarray(b1n)[hit])
    np.testing.assert_array_equal(np.asarray(b2b)[hit], np.asarray(b2n)[hit])


def test_ray_queue_gives_each_ray_its_own_traversal(monkeypatch):
    """Vmapped rays run on lanes fed from a queue (bvh._traverse_queue): with more rays than
    lanes (lanes refilled), nested vmaps (flattened into one queue), unbatched distance limits
    and a vmap over scenes, every ray gets the bits of its own traversal, one ray at a time
    (``lax.map``: the plain while loop); the same for shadow rays."""
    monkeypatch.setattr(B, "LANES", 64)
    scene = _soup(300, 5, 10, bvh=True)
    o, d, tmin, tmax = _rays(7, n=1000)
    one = jax.jit(lambda *a: jax.lax.map(lambda r: closest_planar(scene, *r), a))
    flat = jax.jit(jax.vmap(closest_planar, in_axes=(None, 0, 0, 0, 0)))
    nested = jax.jit(jax.vmap(jax.vmap(closest_planar, in_axes=(None, 0, 0, None, None)),
                              in_axes=(None, 0, 0, None, None)))
    want = [np.asarray(x) for x in one(o, d, tmin, tmax)]
    assert np.isfinite(want[0]).sum() > 50 and (~np.isfinite(want[0])).sum() > 50
    for got, w in zip(flat(scene, o, d, tmin, tmax), want, strict=True):
        np.testing.assert_array_equal(np.asarray(got), w)
    limits = [np.asarray(x) for x in one(o, d, jnp.zeros(1000), jnp.full(1000, jnp.inf))]
    got = nested(scene, o.reshape(10, 100, 3), d.reshape(10, 100, 3), 0.0, jnp.inf)
    for g, w in zip(got, limits, strict=True):
        np.testing.assert_array_equal(np.asarray(g).reshape(-1), w)
    # A vmap over scenes (a batched BVH) of the vmap over rays: each copy as one scene.
    pair = jax.tree.map(lambda x: jnp.stack([x, x]), scene)
    over_scenes = jax.jit(jax.vmap(jax.vmap(closest_planar, in_axes=(None, 0, 0, 0, 0)),
                                   in_axes=(0, None, None, None, None)))
    for got, w in zip(over_scenes(pair, o, d, tmin, tmax), want, strict=True):
        np.testing.assert_array_equal(np.asarray(got), np.stack([w, w]))
    target = o + 2.0 * d
    blocked_one = jax.jit(lambda a, b: jax.lax.map(lambda r: occluded(scene, *r), (a, b)))
    blocked = np.asarray(jax.jit(jax.vmap(occluded, in_axes=(None, 0, 0)))(scene, o, target))
    np.testing.assert_array_equal(blocked, np.asarray(blocked_one(o, target)))
    assert 50 < blocked.sum() < 950


def test_ties_go_to_the_lowest_index():
    """Forty copies of one triangle and of one square: every hit is the first copy's."""
    b = R.SceneBuilder()
    m = b.diffuse()
    tri = np.array([[-1, -1, 0], [1, -1, 0], [0, 1, 0.0]])
    b.triangles(np.tile(tri, (40, 1)), np.arange(120).reshape(-1, 3), m)
    sq = np.diag([0.5, 0.5, 1.0, 1.0])
    sq[2, 3] = -0.5
    for _ in range(40):
        b.rectangle(sq, m)
    b.point_light((0, 0, 5), 1.0)
    b.camera(np.eye(4), width=2, height=2)
    with_bvh, brute = _pair(b.build(bvh=True))
    o, d, tmin, tmax = _rays(5)
    tb, ib, _, _ = _closest(with_bvh, o, d, tmin, tmax)
    tn, in_, _, _ = _closest(brute, o, d, tmin, tmax)
    hit = np.isfinite(np.asarray(tn))
    assert hit.mean() > 0.05
    np.testing.assert_array_equal(np.isfinite(np.asarray(tb)), hit)
    np.testing.assert_array_equal(np.asarray(ib)[hit], np.asarray(in_)[hit])
    assert set(np.asarray(in_)[hit].tolist()) <= {0, 40}


@pytest.mark.parametrize("n,seed", [(5, 0), (2000, 1)])
def test_shadow_any_hit_equals_brute_force(n, seed):
    with_bvh, brute = _pair(_soup(n, seed, parallelograms=10, bvh=True))
    o, d, _, _ = _rays(seed + 20)
    length = jnp.asarray(np.random.default_rng(seed).uniform(0.01, 3.0, o.shape[0]), jnp.float32)
    target = o + length[:, None] * d
    ob = np.asarray(_occluded(with_bvh, o, target))
    on = np.asarray(_occluded(brute, o, target))
    assert 0.05 < on.mean() < 0.95
    np.testing.assert_array_equal(ob, on)


def test_intersect_equals_brute_force_with_spheres_and_patches():
    """The full hit record (normal, uv, material, light) in a scene of every shape kind."""
    rng = np.random.default_rng(4)
    b = R.SceneBuilder()
    m1, m2 = b.diffuse(0.5), b.diffuse(0.2)
    v = rng.uniform(-1, 1, (600, 3))
    b.triangles(v, np.arange(600).reshape(-1, 3), m1, uvs=rng.random((600, 2)))
    b.sphere((0.2, 0.1, 0.0), 0.4, m2)
    corners = np.array([[-1, -1, 0.5], [1, -1, 0.8], [-1, 1, 0.6], [1, 1, 0.2]])
    b.bilinear_patch(corners.reshape(2, 2, 3), m2)
    t = np.diag([0.3, 0.3, -1.0, 1.0])
    t[2, 3] = 1.5
    b.rectangle(t, b.diffuse(0.0), radiance=3.0)
    b.camera(np.eye(4), width=2, height=2)
    with_bvh, brute = _pair(b.build(bvh=True))  # 201 planar primitives
    o, d, tmin, tmax = _rays(6)
    f = jax.jit(jax.vmap(intersect, in_axes=(None, 0, 0, 0, 0)))
    hb, hn = f(with_bvh, o, d, tmin, tmax), f(brute, o, d, tmin, tmax)
    ok = np.asarray(hn.valid)
    assert 0.05 < ok.mean() < 0.95
    np.testing.assert_array_equal(np.asarray(hb.valid), ok)
    for name in ("t", "p", "n", "uv", "material", "light"):
        np.testing.assert_array_equal(np.asarray(getattr(hb, name))[ok],
                                      np.asarray(getattr(hn, name))[ok], err_msg=name)


def test_tree_holds_every_primitive_once_inside_its_boxes():
    scene = _soup(500, 7, parallelograms=5, bvh=True)
    bv = scene.bvh
    node = np.asarray(bv.node)
    child, start, count = node[:, :2], node[:, 2], node[:, 3]
    prim = np.asarray(bv.prim)
    leaf = count > 0
    assert np.all(count[leaf] <= B.LEAF_SIZE)
    slots = np.concatenate([np.arange(s, s + c) for s, c in zip(start[leaf], count[leaf],
                                                                  strict=True)])
    np.testing.assert_array_equal(np.sort(prim[slots]), np.arange(505))
    # Every node is reached once from the root.
    seen = np.zeros(len(count), int)
    stack = [0]
    while stack:
        i = stack.pop()
        seen[i] += 1
        if not leaf[i]:
            stack.extend(child[i].tolist())
    assert np.all(seen == 1)


def test_box_contains_the_leaf_vertices():
    rng = np.random.default_rng(8)
    lo = rng.uniform(-1, 1, (1000, 3))
    hi = lo + rng.uniform(0, 0.1, (1000, 3))
    order, bounds, start, count, child, depth = B.build_tree(lo, hi)
    leaf = child[:, 0] < 0
    for i in np.flatnonzero(leaf):
        ids = order[start[i]:start[i] + count[i]]
        assert np.all(lo[ids] >= bounds[i, 0]) and np.all(hi[ids] <= bounds[i, 1])
    for i in np.flatnonzero(~leaf):
        for c in child[i]:
            assert np.all(bounds[c, 0] >= bounds[i, 0]) and np.all(bounds[c, 1] <= bounds[i, 1])
    np.testing.assert_array_equal(np.sort(order), np.arange(1000))
    assert depth <= 30  # SAH on uniform boxes: about log2(1000 / leaf size) levels


def test_render_with_and_without_bvh_agree():
    """A tessellated sphere over a floor under an area light, light sampling and MIS: the same
    image with and without the BVH (float32 rounding: the same primitives are hit)."""
    from anisosample.render.builder import sphere_mesh
    from anisosample.render.xml import look_at

    b = R.SceneBuilder()
    b.rectangle(np.diag([3.0, 3.0, 1.0, 1.0]), b.diffuse(0.6))
    b.triangles(*sphere_mesh((0, 0, 0.6), 0.5, 400), b.roughconductor(0.3, (0.2, 0.9, 1.1),
                                                                      (3.9, 2.4, 2.2)))
    t = np.diag([0.3, 0.3, -1.0, 1.0])
    t[:3, 3] = (0.4, 0.3, 2.0)
    b.rectangle(t, b.diffuse(0.0), radiance=20.0)
    b.camera(look_at(np.array([2.0, -2.5, 1.8]), np.array([0, 0, 0.4]), np.array([0, 0, 1.0])),
             width=12, height=10, fov=45)
    with_bvh, brute = _pair(b.build(bvh=True))
    key = jax.random.key(3)
    for mis in (True,):
        a = R.render(with_bvh, key, spp=8, mis=mis, progress=False).mean
        c = R.render(brute, key, spp=8, mis=mis, progress=False).mean
        assert a.max() > 0.1
        np.testing.assert_allclose(a, c, rtol=1e-5, atol=1e-6)


def test_bad_bvh_option():
    b = R.SceneBuilder()
    b.diffuse()
    b.point_light((0, 0, 1), 1.0)
    b.camera(np.eye(4), width=2, height=2)
    with pytest.raises(TypeError, match="bvh"):
        b.build(bvh="yes")


def test_load_xml_takes_the_bvh_option():
    """``load_xml(..., bvh=...)`` reaches ``build``: blinds (below the threshold) gets a BVH
    only when asked, and the image is the brute-force one to float32 rounding."""
    from .helpers import SCENES

    path = SCENES / "blinds.xml"
    plain = R.load_xml(path, width=8, height=8)
    tree = R.load_xml(path, width=8, height=8, bvh=True)
    assert plain.bvh is None and tree.bvh is not None
    assert R.load_xml(path, width=8, height=8, bvh=False).bvh is None
    key = jax.random.key(1)
    np.testing.assert_allclose(R.render(tree, key, spp=4, progress=False).mean,
                               R.render(plain, key, spp=4, progress=False).mean,
                               rtol=1e-5, atol=1e-6)


@pytest.mark.library_errors
def test_load_xml_refuses_a_bad_bvh_option():
    from .helpers import SCENES

    with pytest.raises(TypeError, match="bvh must be True, False or None"):
        R.load_xml(SCENES / "blinds.xml", bvh="yes")


def test_default_follows_the_threshold():
    """``build()`` gives a BVH from :data:`bvh.THRESHOLD` planar primitives on, not below."""
    for n, want in ((B.THRESHOLD - 1, False), (B.THRESHOLD, True)):
        assert (_soup(n, 9).bvh is not None) == want, n


def test_bad_mesh_shapes():
    b = R.SceneBuilder()
    m = b.diffuse()
    with pytest.raises(ValueError, match="faces must have shape"):
        b.triangles(np.zeros((4, 3)), [[0, 1], [1, 2]], m)
    with pytest.raises(ValueError, match="vertices must have shape"):
        b.triangles(np.zeros((4, 2)), [[0, 1, 2]], m)

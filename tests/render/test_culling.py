"""Per-tile culling (render/culling.py) against brute force.

Truth: the brute-force tests of every planar primitive (``closest_planar`` and the plane test
of ``occluded`` without a subset). Rays drawn inside each tile's pixels and lens, on random
triangle soups seen by pinhole and thin-lens cameras with box and gaussian filters, under area,
point and sphere lights: every nearest hit must be among the tile's primary candidates, and
every primitive that cuts a shadow segment (within occluded's trimmed ends) among its shadow
candidates. Renders with and without culling must give the same image.
"""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import anisosample.render as R
from anisosample import scenes
from anisosample.render import culling as C
from anisosample.render.bvh import plane_test
from anisosample.render.camera import generate_ray
from anisosample.render.geometry import closest_planar, offset_origin
from anisosample.render.scene import LIGHT_POINT, LIGHT_SPHERE


def _soup_scene(seed, *, thin=False, rfilter="box", light="area", size=16, curved=False):
    """Random triangles and rectangles between a floor and a back wall; ``curved``: three
    spheres and a bilinear patch among them."""
    rng = np.random.default_rng(seed)
    b = R.SceneBuilder()
    m = b.diffuse(0.5)
    n = 40
    c = rng.uniform(-1, 1, (n, 3)) * [1.2, 1.2, 0.8]
    v = (c[:, None] + rng.normal(0, 0.25, (n, 3, 3))).reshape(-1, 3)
    b.triangles(v, np.arange(3 * n).reshape(-1, 3), m)
    for _ in range(4):
        t = np.eye(4)
        t[:3, :3] = rng.normal(0, 0.3, (3, 3))
        t[:3, 3] = rng.uniform(-1, 1, 3)
        b.rectangle(t, m)
    floor = np.diag([3.0, 3.0, 1.0, 1.0])
    floor[:3, :3] = floor[:3, :3] @ np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]])
    floor[:3, 3] = (0, -1.5, 0)
    b.rectangle(floor, m)
    back = np.diag([3.0, 3.0, 1.0, 1.0])
    back[:3, 3] = (0, 0, 2.5)
    b.rectangle(back, m, flip_normals=True)
    if light == "area":
        lt = np.diag([0.4, 0.4, 1.0, 1.0])
        lt[:3, :3] = lt[:3, :3] @ np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]]).T
        lt[:3, 3] = (0.3, 2.2, 0.2)
        b.rectangle(lt, m, radiance=5.0)
    elif light == "point":
        b.point_light((0.5, 2.5, -0.5), 3.0)
    else:
        b.sphere((-0.4, 2.4, 0.3), 0.3, m, radiance=4.0)
    if curved:
        for c, r in zip(rng.uniform(-1, 1, (3, 3)) * [1.2, 1.0, 0.6],
                        rng.uniform(0.1, 0.3, 3), strict=True):
            b.sphere(c, r, m)
        b.bilinear_patch(np.array([[[-0.9, 0.6, 0.3], [-0.3, 0.7, 0.2]],
                                   [[-0.8, 1.1, 0.0], [-0.2, 1.2, 0.4]]]), m)
    cam = np.eye(4)
    cam[:3, 3] = (0.2, 0.3, -4.5)
    b.camera(cam, width=size, height=size, fov=50, thinlens=thin, aperture_radius=0.15,
             focus_distance=4.0, rfilter=rfilter, rfilter_stddev=0.5)
    return b.build(bvh=False)


def _tile_rays(scene, tile, rng, per_tile, square):
    """Random rays of every tile: film positions anywhere a sample of its pixels may land
    (the pixels, widened by the filter's support), random lens points."""
    w, h = scene.width, scene.height
    tx = -(-w // tile)
    ty = -(-h // tile)
    sup = 2.0 if scene.camera.rfilter == "gaussian" else 0.0
    ids, films = [], []
    for i in range(ty):
        for j in range(tx):
            x0, x1 = max(j * tile - sup, 0), min((j + 1) * tile + sup, w)
            y0, y1 = max(i * tile - sup, 0), min((i + 1) * tile + sup, h)
            u = rng.random((per_tile, 2))
            films.append(np.stack([(x0 + u[:, 0] * (x1 - x0)) / w,
                                   (y0 + u[:, 1] * (y1 - y0)) / h], 1))
            ids.append(np.full(per_tile, i * tx + j))
    films = jnp.asarray(np.concatenate(films), jnp.float32)
    lens = jnp.asarray(rng.random((films.shape[0], 2)), jnp.float32)
    o, d = jax.vmap(lambda f, a: generate_ray(scene.camera, f, a, square_aperture=square))(
        films, lens)
    return np.concatenate(ids), o, d


@jax.jit
def _shadow_cuts(scene, o, d, targets):
    """Per ray: the primitives cutting its shadow segments to ``targets`` ``(m, 3)`` within
    occluded's trimmed ends (eps = 1e-4), and whether the primary ray hit anything."""

    def one(o, d):
        t, it, _, _ = closest_planar(scene, o, d, 0.0, jnp.inf)
        n = scene.tri_attr[it, :3]
        p = o + jnp.where(jnp.isfinite(t), t, 0.0) * d
        origin = offset_origin(scene, p, n, -d)

        def seg(y):
            v = y - origin
            dist = jnp.linalg.norm(v)
            tt, _, _ = plane_test(scene.tri_soa, origin, v / dist)
            return (tt > dist * 1e-4) & (tt < dist * (1 - 1e-4))

        return it, jnp.isfinite(t), jax.vmap(seg)(targets).any(0)

    return jax.vmap(one)(o, d)


def _light_targets(scene, rng, m=24):
    lt = scene.lights
    shape, p0, e1, e2 = (np.asarray(a) for a in (lt.shape, lt.p0, lt.e1, lt.e2))
    out = []
    for s, a, b, c in zip(shape, p0, e1, e2, strict=True):
        u = rng.random((m, 2))
        if s == LIGHT_POINT:
            out.append(np.repeat(a[None], m, 0))
        elif s == LIGHT_SPHERE:  # points on it
            z = rng.normal(size=(m, 3))
            out.append(a + b[0] * z / np.linalg.norm(z, axis=1, keepdims=True))
        else:
            out.append(a + u[:, :1] * b + u[:, 1:] * c)
    return jnp.asarray(np.concatenate(out), jnp.float32)


@pytest.mark.parametrize("seed,thin,rfilter,light", [
    (0, False, "box", "area"), (1, True, "box", "area"), (2, False, "gaussian", "point"),
    (3, True, "gaussian", "sphere")])
def test_every_hit_is_a_candidate(seed, thin, rfilter, light):
    scene = _soup_scene(seed, thin=thin, rfilter=rfilter, light=light)
    tile = 4
    primary, shadow = C.tile_candidates(scene, tile)
    rng = np.random.default_rng(100 + seed)
    ids, o, d = _tile_rays(scene, tile, rng, 600, square=False)
    it, hit, cuts = (np.asarray(a) for a in _shadow_cuts(scene, o, d, _light_targets(scene, rng)))
    assert hit.mean() > 0.8
    # Every nearest hit among the tile's primary candidates.
    assert primary[ids[hit], it[hit]].all()
    # Every primitive cutting a shadow segment of a hit among the tile's shadow candidates.
    rows, prims = np.nonzero(cuts & hit[:, None])
    assert rows.size > 0
    assert shadow[ids[rows], prims].all()
    # And the lists cull: most tiles test far fewer primitives than the scene holds.
    t = scene.tri_soa.shape[1]
    assert np.median(primary.sum(1)) < t / 2
    assert np.median(shadow.sum(1)) < 0.75 * t


def test_square_aperture_rays_are_candidates_too():
    scene = _soup_scene(5, thin=True)
    primary, _ = C.tile_candidates(scene, 4)
    ids, o, d = _tile_rays(scene, 4, np.random.default_rng(7), 400, square=True)
    it, hit, _ = (np.asarray(a) for a in _shadow_cuts(scene, o, d, jnp.zeros((1, 3))))
    assert primary[ids[hit], it[hit]].all()


@pytest.mark.parametrize("name,options", [
    ("dof", {}), ("blinds", {}),
    ("cornell", dict(mis=True, technique="solid_angle", light_warp="cosine-bilinear"))])
def test_render_with_and_without_culling_agree(name, options):
    scene = R.load_xml(scenes.path(name), width=24, height=16)
    assert C.tile_culling(scene) is not None
    key = jax.random.key(3)
    a, b = (R.render(scene, key, spp=8, sampler="pmj02bn", progress=False, culling=c,
                     **options).mean for c in (True, False))
    np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-7)


def test_pixel_integrand_with_and_without_culling_agree():
    scene = R.load_xml(scenes.path("cornell"), width=32, height=32)
    f = R.pixel_integrand(scene, (20, 25), culling=True)
    assert f.scene.culling is not None
    g = R.pixel_integrand(scene, (20, 25))  # culling off by default
    assert g.scene.culling is None
    x = jax.random.uniform(jax.random.key(0), (5000, 2))
    np.testing.assert_array_equal(np.asarray(f(x)), np.asarray(g(x)))


def test_corners_recovered_from_the_rows():
    b = R.SceneBuilder()
    m = b.diffuse(0.5)
    t = np.array([[0.5, 0.1, 0, 1.0], [0, 0.3, 0.2, -2.0], [0.1, 0, 0.7, 0.5], [0, 0, 0, 1]])
    b.rectangle(t, m)
    b.triangles(np.array([[0, 0, 1.0], [2, 0, 1], [0, 3, 2]]), np.array([[0, 1, 2]]), m)
    b.point_light((0, 0, 5), 1.0)
    b.camera(np.eye(4), width=4, height=4)
    scene = b.build(bvh=False)
    corners, count = C.planar_corners(np.asarray(scene.tri_soa, np.float64))
    p = lambda x, y: t[:3, :3] @ np.array([x, y, 0.0]) + t[:3, 3]  # noqa: E731
    np.testing.assert_allclose(corners[0], [p(-1, -1), p(1, -1), p(1, 1), p(-1, 1)], atol=1e-5)
    np.testing.assert_allclose(corners[1, :3], [[0, 0, 1], [2, 0, 1], [0, 3, 2]], atol=1e-5)
    assert count.tolist() == [4, 3]


def test_clipping_a_square():
    sq = np.zeros((2, 12, 3))
    sq[:, :4] = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]
    # x + y >= 1.5 keeps a corner triangle; x >= 2 keeps nothing.
    out, k = C.clip_polygons(sq, np.array([4, 4]), np.array([[1.0, 1, 0], [1, 0, 0]]),
                             np.array([1.5, 2.0]))
    assert k.tolist() == [3, 0]
    got = sorted(map(tuple, np.round(out[0, :3], 12)))
    assert got == [(0.5, 1.0, 0.0), (1.0, 0.5, 0.0), (1.0, 1.0, 0.0)]


def test_bad_culling_argument():
    scene = R.load_xml(scenes.path("cornell"), width=8, height=8)
    with pytest.raises(TypeError, match="culling"):
        R.render(scene, jax.random.key(0), spp=4, culling="yes", progress=False)
    with pytest.raises(TypeError, match="culling"):
        R.pixel_integrand(scene, (0, 0), culling=1)
    with pytest.raises(ValueError, match="tile"):
        C.tile_candidates(scene, 0)


@pytest.mark.parametrize("seed,thin,light", [(0, False, "area"), (1, True, "point")])
def test_curved_tiles_hold_every_curved_hit_and_blocker(seed, thin, light):
    from anisosample.render.geometry import intersect, occluded

    scene = _soup_scene(seed, thin=thin, light=light, curved=True)
    planar = dataclasses.replace(scene, has_spheres=False, has_patches=False)
    tile = 4
    curved = C.curved_tiles(scene, tile)
    rng = np.random.default_rng(200 + seed)
    ids, o, d = _tile_rays(scene, tile, rng, 400, square=False)
    targets = _light_targets(scene, rng, m=8)

    @jax.jit
    def meets(o, d):
        """Whether a curved surface is the nearest hit, or blocks a shadow segment of a planar
        hit, of each ray."""
        def one(o, d):
            h, hp = intersect(scene, o, d), intersect(planar, o, d)
            seen = h.valid & ~(hp.valid & (hp.t == h.t))
            origin = offset_origin(scene, hp.p, hp.n, -d)
            blocks = jax.vmap(lambda y: occluded(scene, origin, y) != occluded(planar, origin, y))
            return seen, hp.valid & ~seen & blocks(targets).any()
        return jax.vmap(one)(o, d)

    seen, blocks = (np.asarray(a) for a in meets(o, d))
    assert seen.any() and blocks.any()  # the rays meet the curved surfaces both ways
    assert curved[ids[seen | blocks]].all()
    assert not curved.all()  # and some tiles go without them


def test_tile_classes_partition_the_pixels_and_hold_their_candidates():
    scene = R.load_xml(scenes.path("dof"), width=64, height=48)
    scene = C.with_culling(scene)
    classes = C.tile_classes(scene, 64)
    assert classes is not None and len(classes) >= 2
    every = np.concatenate([c.pixels for c in classes])
    assert np.array_equal(np.sort(every), np.arange(64 * 48))
    primary, shadow = C.tile_candidates(scene, scene.culling.tile)
    curved = C.curved_tiles(scene, scene.culling.tile)
    tile, tiles_x = scene.culling.tile, scene.culling.tiles_x
    for c in classes:
        q = c.pixels
        tiles = np.unique((q // 64) // tile * tiles_x + (q % 64) // tile)
        assert c.scene.has_spheres or not curved[tiles].any()
        for mask, lists in ((primary, c.scene.culling.primary), (shadow, c.scene.culling.shadow)):
            if lists is None:  # every primitive
                continue
            index = np.asarray(lists.index)[tiles]
            for tile, row in zip(tiles, index, strict=True):
                assert set(np.nonzero(mask[tile])[0]) <= set(row[row >= 0])
    # MIS: every class tests the sphere (its BSDF rays may meet it anywhere).
    mis = C.tile_classes(scene, 64, curved_everywhere=True)
    assert mis is None or all(c.scene.has_spheres for c in mis)


def test_render_by_tile_classes_agrees_with_brute_force():
    scene = R.load_xml(scenes.path("dof"), width=64, height=48)
    assert C.tile_classes(C.with_culling(scene), 64) is not None
    key = jax.random.key(4)
    a, b = (R.render(scene, key, spp=8, sampler="pmj02bn", progress=False, culling=c, chunk=64)
            .mean for c in (True, False))
    np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-7)


def test_curved_tiles_see_a_sphere_against_the_sky():
    """Nothing planar lies behind the sphere and no shadow ray passes it (the light is under
    the floor): only the primary rays can flag its tiles."""
    from anisosample.render.geometry import intersect

    b = R.SceneBuilder()
    m = b.diffuse(0.5)
    floor = np.diag([3.0, 3.0, 1.0, 1.0])
    floor[:3, :3] = floor[:3, :3] @ np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]])
    floor[:3, 3] = (0, -1.0, 0)
    b.rectangle(floor, m)
    b.sphere((0.3, 0.4, 0.5), 0.4, m)
    b.point_light((0.0, -3.0, 0.0), 1.0)
    cam = np.eye(4)
    cam[:3, 3] = (0.0, 0.0, -4.0)
    b.camera(cam, width=16, height=16, fov=50)
    scene = b.build(bvh=False)
    planar = dataclasses.replace(scene, has_spheres=False)
    curved = C.curved_tiles(scene, 4)
    ids, o, d = _tile_rays(scene, 4, np.random.default_rng(3), 400, square=False)
    hit = np.asarray(jax.vmap(lambda o, d: intersect(scene, o, d).valid)(o, d))
    hit_planar = np.asarray(jax.vmap(lambda o, d: intersect(planar, o, d).valid)(o, d))
    seen = hit & ~hit_planar  # the sphere, with the sky behind it
    assert seen.any() and curved[ids[seen]].all()
    assert not curved.all()

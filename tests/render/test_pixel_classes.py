"""Pixel classes (render.pixel_classes) against exact geometry and synthetic grids."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import assert_pytree_round_trips

from anisosample.metrics import axial_distance_deg
from anisosample.render import SceneBuilder
from anisosample.render import pixel_classes as pc

G = 64
_C = (np.arange(G) + 0.5) / G
X, Y = np.meshgrid(_C, _C, indexing="xy")
SMOOTH = 1.0 + 0.5 * X * Y  # a smooth, positive unoccluded integrand


def _half_plane(normal_deg, through):
    n = np.radians(normal_deg)
    return (X * np.cos(n) + Y * np.sin(n)) < (through[0] * np.cos(n) + through[1] * np.sin(n))


@pytest.mark.parametrize("normal_deg", [0.0, 12.0, 30.0, 67.0, 90.0, 123.4, 145.0, 178.0])
def test_one_edge_direction_is_the_edge_normal(normal_deg):
    r = pc.classify_grid(_half_plane(normal_deg, (0.45, 0.55)) * SMOOTH)
    assert r.name == "one-edge"
    assert axial_distance_deg(r.directions_deg[0], normal_deg, xp=np) < 1.0
    assert r.residual_cells <= 1.0
    # a pytree: the name, the directions and the count are static, the residual a leaf
    assert_pytree_round_trips(r)


def test_random_edges_and_corners():
    rng = np.random.default_rng(7)
    for _ in range(40):
        a = rng.uniform(0, 180)
        r = pc.classify_grid(_half_plane(a, rng.uniform(0.25, 0.75, 2)) * SMOOTH)
        assert r.name == "one-edge" and axial_distance_deg(r.directions_deg[0], a, xp=np) < 1.0
    for _ in range(40):
        a = rng.uniform(0, 180)
        b = (a + rng.uniform(25, 155)) % 180
        q = rng.uniform(0.3, 0.7, 2)
        r = pc.classify_grid((_half_plane(a, q) & _half_plane(b, q)) * SMOOTH)
        assert r.name == "corner", (a, b, q, r)
        d = r.directions_deg
        err = min(axial_distance_deg(d[0], a, xp=np) + axial_distance_deg(d[1], b, xp=np),
                  axial_distance_deg(d[1], a, xp=np) + axial_distance_deg(d[0], b, xp=np))
        assert err < 2.0, (a, b, r)


def test_smooth_dark_curved_and_patterned_grids():
    assert pc.classify_grid(SMOOTH).name == "lit"
    assert pc.classify_grid(np.exp(-4.0 * X)).name == "lit"  # steep but smooth
    assert pc.classify_grid(np.maximum(X - 0.3, 0.0)).name == "lit"  # horizon: continuous
    assert pc.classify_grid(np.zeros((G, G))).name == "occluded"
    assert pc.classify_grid(np.full((G, G), 3.0)).name == "occluded"  # an emitter seen directly
    assert pc.classify_grid(((X - 0.5) ** 2 + (Y - 0.5) ** 2 < 0.09) * 1.0).name == "other"
    assert pc.classify_grid(((X * 8) % 1 < 0.5) * SMOOTH).name == "other"  # a pattern
    # a textured step without occlusion is a jump too
    assert pc.classify_grid(SMOOTH * (1 + (X > 0.4))).name == "one-edge"


def test_bad_input():
    with pytest.raises(ValueError, match="square"):
        pc.classify_grid(np.ones((8, 9)))
    with pytest.raises(ValueError, match="finite"):
        pc.classify_grid(np.full((8, 8), np.nan))
    with pytest.raises(ValueError, match="jump"):
        pc.classify_grid(np.ones((8, 8)), jump=-1.0)


def _occluder_scene(width=24):
    """A floor at y = 0 under a square light at y = 2 and a rotated square occluder at y = 1."""
    b = SceneBuilder()
    white = b.diffuse((0.7, 0.7, 0.7))

    def rect(scale, angle_y, y, flip=False):
        c, s = np.cos(np.radians(angle_y)), np.sin(np.radians(angle_y))
        # [-1,1]^2 at z = 0 -> horizontal square at height y, rotated about +y
        rot_x = np.array([[1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0], [0, 0, 0, 1.0]])
        if flip:
            rot_x = np.array([[1, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1.0]])
        rot_y = np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1.0]])
        m = np.diag([scale, scale, scale, 1.0])
        t = np.eye(4)
        t[1, 3] = y
        return t @ rot_y @ m @ rot_x

    b.rectangle(rect(3.0, 0.0, 0.0), white)  # floor, normal +y
    b.rectangle(rect(0.5, 0.0, 2.0, flip=True), white, radiance=(5, 5, 5))  # light, normal -y
    b.rectangle(rect(0.45, 30.0, 1.0), white)  # occluder
    eye = np.eye(4)
    # looking straight down from y = 6 (Mitsuba look-at: columns left, up, forward, origin)
    eye[:3, :3] = np.array([[-1, 0, 0], [0, 0, -1], [0, -1, 0.0]]).T
    eye[:3, 2] = (0, -1, 0)
    eye[:3, 1] = (0, 0, -1)
    eye[:3, 0] = np.cross(eye[:3, 1], eye[:3, 2])
    eye[:3, 3] = (0, 6, 0)
    b.camera(eye, width=width, height=width, fov=40.0)
    return b.build(), rect(0.45, 30.0, 1.0)


def test_penumbra_directions_match_exact_geometry():
    """Area sampling maps a parallelogram light affinely, so each occluder edge's shadow on it
    is the straight line where the plane through the shading point and the edge meets it;
    its normal in (x0, x1) is (m.e1, m.e2) with m the plane's normal (independent truth)."""
    import jax
    import jax.numpy as jnp

    from anisosample.render.camera import generate_ray
    from anisosample.render.geometry import intersect

    scene, occ = _occluder_scene()
    classes = pc.pixel_classes(scene, grid=G)
    counts = classes.counts()
    assert counts["one-edge"] >= 20 and counts["lit"] >= 20, counts
    light = scene.lights
    p0, e1, e2 = (np.asarray(a[0], np.float64) for a in (light.p0, light.e1, light.e2))
    corners = [occ @ np.array([x, y, 0, 1.0]) for x, y in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    edges = [(corners[i][:3], corners[(i + 1) % 4][:3]) for i in range(4)]
    errs, corner_errs = [], []
    pixels = np.concatenate([classes.pixels("one-edge"), classes.pixels("corner")])

    def primary(film):  # the pixel centre's camera ray and its hit distance
        o, d = generate_ray(scene.camera, film, jnp.full(2, 0.5, jnp.float32))
        return o, d, intersect(scene, o, d).t

    films = (pixels + 0.5) / np.array([scene.width, scene.height])
    rays = jax.jit(jax.vmap(primary))(jnp.asarray(films, jnp.float32))  # all pixels at once
    o_all, d_all, t_all = (np.asarray(a, np.float64) for a in rays)
    for (col, row), o, d, t in zip(pixels, o_all, d_all, t_all, strict=True):
        s = o + t * d
        truth = []
        for a, b in edges:
            m = np.cross(a - s, b - s)
            truth.append(np.degrees(np.arctan2(m @ e2, m @ e1)) % 180.0)
        k = int(classes.num_directions[row, col])
        e = [min(axial_distance_deg(classes.directions_deg[row, col, i], t, xp=np) for t in truth)
             for i in range(k)]
        (errs if k == 1 else corner_errs).extend(e)
    assert np.max(errs) < 1.5, np.max(errs)
    assert np.median(errs) < 0.5, np.median(errs)
    assert len(corner_errs) >= 40 and np.median(corner_errs) < 1.0, np.median(corner_errs)
    assert np.quantile(corner_errs, 0.9) < 3.0


def test_subset_of_pixels_matches_the_full_image():
    scene, _ = _occluder_scene(width=16)
    full = pc.pixel_classes(scene, grid=32)
    pick = np.array([[3, 5], [10, 2], [15, 15], [0, 0]])
    part = pc.pixel_classes(scene, pick, grid=32)
    assert part.evaluated.sum() == 4 and part.evaluated[5, 3] and part.evaluated[15, 15]
    for col, row in pick:
        assert part.classes[row, col] == full.classes[row, col]
        np.testing.assert_array_equal(part.directions_deg[row, col], full.directions_deg[row, col])
    assert sum(full.counts().values()) == 256
    assert_pytree_round_trips(part)  # the grid side and the integrand's names are static
    with pytest.raises(ValueError, match="pixels must lie"):
        pc.pixel_classes(scene, np.array([[16, 0]]))
    with pytest.raises(TypeError, match="integers"):
        pc.pixel_classes(scene, np.array([[1.5, 0.0]]))

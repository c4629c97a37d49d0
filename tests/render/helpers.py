"""Small scenes and references shared by the renderer tests."""


import jax
import numpy as np

import anisosample.render as R
from anisosample import scenes
from anisosample.render.xml import look_at, rotation

SCENES = scenes.FOLDER  # the shipped scenes (anisosample/scenes/)


def plane_under_light(height=1.98, half=0.25, radiance=10.0, albedo=0.5, occluder=None):
    """A diffuse floor (z = 0, normal +z) under a square light of half-width ``half`` facing
    down at ``z = height``, seen straight down by a 9x9 camera; optional occluder (to_world)."""
    b = R.SceneBuilder()
    m = b.diffuse(albedo)
    b.rectangle(np.diag([4.0, 4.0, 1.0, 1.0]), m)
    t = np.eye(4)
    t[:3, :3] = np.diag([half, half, -1.0])
    t[2, 3] = height
    b.rectangle(t, b.diffuse(0.0), radiance=radiance)
    if occluder is not None:
        b.rectangle(occluder, b.diffuse(0.0))
    cam = look_at(np.array([0, 0, 1.0]), np.zeros(3), np.array([0, 1.0, 0]))
    b.camera(cam, width=9, height=9, fov=10)
    return b.build()


def form_factor_parallel(h, a, b):
    """Differential area to a parallel rectangle ``[0, a] x [0, b]`` at height ``h`` whose
    corner is straight above the point (Howell's catalogue, C-11), float64."""
    x, y = a / h, b / h
    return (x / np.sqrt(1 + x * x) * np.arctan(y / np.sqrt(1 + x * x))
            + y / np.sqrt(1 + y * y) * np.arctan(x / np.sqrt(1 + y * y))) / (2 * np.pi)


def lambert_clipped(v):
    """Lambert's projected solid angle of polygon ``v`` (vertices relative to the receiving
    point) about +z, clipped to z >= 0 first (Sutherland-Hodgman), float64."""
    out = []
    for i in range(len(v)):
        a, b = v[i], v[(i + 1) % len(v)]
        if a[2] >= 0:
            out.append(a)
        if a[2] * b[2] < 0:
            out.append(a + a[2] / (a[2] - b[2]) * (b - a))
    if len(out) < 3:
        return 0.0
    w = np.asarray(out) / np.linalg.norm(out, axis=1, keepdims=True)
    phi = 0.0
    for i in range(len(w)):
        a, b = w[i], w[(i + 1) % len(w)]
        cr = np.cross(a, b)
        if np.linalg.norm(cr) > 0:
            phi += np.arctan2(np.linalg.norm(cr), a @ b) * cr[2] / np.linalg.norm(cr)
    return abs(phi) / 2


def mitsuba_render(path, spp, seed=0, **params):
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    scene = mi.load_file(str(path), **{k: v for k, v in params.items()})
    return np.array(mi.render(scene, spp=spp, seed=seed))[..., :3]


LIGHT_Y, LIGHT_HALF = 0.98, 0.25  # cornell.xml: the light spans [-0.25, 0.25]^2 in x, z


def box_edges(scale, angle_deg, translate):
    """The 12 edges (pairs of end points) of the cube ``[-1, 1]^3`` scaled by ``scale``, rotated
    by ``angle_deg`` about +y, then translated by ``translate`` (a box of cornell.xml)."""
    m = rotation(np.array([0.0, 1.0, 0.0]), angle_deg) @ np.diag(np.append(scale, 1.0))
    m[:3, 3] = translate
    c = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    w = c @ m[:3, :3].T + m[:3, 3]
    return [(w[i], w[j]) for i in range(8) for j in range(i + 1, 8) if np.sum(c[i] != c[j]) == 1]


TRIANGLE_ABOVE = np.array([[-0.6, -0.5, 1.0], [0.7, -0.3, 1.0], [0.0, 0.7, 1.0]])  # facing down


def plane_under_triangle(width=16, height=16, albedo=0.5, radiance=4.0):
    """A diffuse floor (z = 0, normal +z) under one triangle light 1 above it, facing down
    (every vertex above every floor point's horizon), seen from above; no occluder."""
    b = R.SceneBuilder()
    b.rectangle(np.diag([4.0, 4.0, 1.0, 1.0]), b.diffuse(albedo))
    b.triangles(TRIANGLE_ABOVE[[0, 2, 1]], [[0, 1, 2]], b.diffuse(0.0), radiance=radiance)
    cam = look_at(np.array([0.3, -2.0, 2.5]), np.array([0.0, 0.0, 0.0]), np.array([0, 0, 1.0]))
    b.camera(cam, width=width, height=height, fov=40)
    return b.build()


def zero_variance(scene, light_warp, min_floor=0.6):
    """Light sampling alone through ``light_warp`` on a diffuse floor under one light: every
    lit pixel's relative variance <= 1e-6 and the lit floor fills more than ``min_floor`` of the
    image; returns the lit-floor mask."""
    res = R.render(scene, jax.random.key(3), spp=4, realizations=16, pixel_center=True,
                   technique="solid_angle", light_warp=light_warp, mis=False, progress=False)
    lum = res.mean @ np.array([0.2126, 0.7152, 0.0722])
    lit = lum > 0  # the lit floor and the light's front (emission, 4)
    rel = res.variance[lit] / np.maximum(res.mean[lit] ** 2, 1e-30)
    assert rel.max() <= 1e-6, rel.max()
    floor = lit & (lum < 3.0)  # rho/pi L Phi <= 2 on the floor
    assert floor.mean() > min_floor  # the lit floor fills much of the image
    return floor

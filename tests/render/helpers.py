"""Small scenes and references shared by the renderer tests."""


import numpy as np

import anisosample.render as R
from anisosample import scenes

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
        b.rectangle(occluder, b.diffuse(0.0), twosided=False)
    from anisosample.render.xml import look_at

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

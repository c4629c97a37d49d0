"""A Cornell-box pixel's light-sample integrand fed to anisosample.directions finds the shadow
edge's direction predicted from the geometry (W Sec. 6.2, Fig. 7)."""

import jax.numpy as jnp
import numpy as np

import anisosample.render as R
from anisosample import directions
from anisosample.metrics import axial_distance_deg, midpoint_grid
from anisosample.render.camera import generate_ray
from anisosample.render.geometry import intersect

from .helpers import LIGHT_HALF, LIGHT_Y, SCENES, box_edges


def _predicted_directions(p):
    """Spectral directions of the box edges whose shadows, seen from ``p``, cross the light.

    The light sample is ``x = ((X + 0.25) / 0.5, (Z + 0.25) / 0.5)``, an isotropic scaling of
    the light plane, so a shadow edge keeps its angle; central projection from ``p`` onto the
    plane ``y = 0.98`` maps each box edge to a segment there.
    """
    out = set()
    for a, b in box_edges([0.3, 0.6, 0.3], 20, [-0.35, -0.4, -0.3]):
        if min(a[1], b[1]) <= p[1] + 1e-9:
            continue
        pa = p + (a - p) * (LIGHT_Y - p[1]) / (a[1] - p[1])
        pb = p + (b - p) * (LIGHT_Y - p[1]) / (b[1] - p[1])
        seg = pa[None] + np.linspace(0, 1, 400)[:, None] * (pb - pa)[None]
        if np.any((np.abs(seg[:, 0]) < LIGHT_HALF) & (np.abs(seg[:, 2]) < LIGHT_HALF)):
            d = pb - pa
            out.add(round(float((np.degrees(np.arctan2(d[2], d[0])) + 90) % 180), 1))
    return sorted(out)


def test_cornell_pixel_shadow_edge_direction():
    scene = R.load_xml(SCENES / "cornell.xml", width=32, height=32)
    pixel = (9, 28)  # floor beside the tall box: its top edge shadows a corner of the light
    o, d = generate_ray(scene.camera, jnp.array([(pixel[0] + 0.5) / 32, (pixel[1] + 0.5) / 32]),
                        jnp.array([0.5, 0.5]))
    p = np.asarray(intersect(scene, o, d).p, np.float64)
    expected = _predicted_directions(p)
    assert len(expected) == 1, expected  # one edge crosses the light from this point
    f = R.pixel_integrand(scene, pixel)
    values = np.asarray(f(jnp.asarray(midpoint_grid(64))))
    assert 0.05 < (values > 0).mean() < 0.99  # a real shadow edge inside [0, 1)^2
    found = directions.estimate(values, k=2)
    assert len(found) >= 1
    assert axial_distance_deg(found[0], expected[0]) < 3.0, (found, expected)

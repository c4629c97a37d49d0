"""Catalogue of warps that the battery parametrizes over (STYLE: optimistix tests/helpers.py).

Each entry: (id, factory, kind) with kind "planar" (output in [0,1]^2) or "spherical" / "surface"
(output a unit direction / a point on a surface in R^3). Factories build the warp lazily so a
failing constructor fails only its own test.
"""

import numpy as np

import anisosample.warps as W


def _n(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


_GENERAL_TRI = np.stack([_n([0.3, 0.1, 1]), _n([-0.5, 0.6, 0.8]), _n([0.2, -0.7, 0.9])])
# Projected-solid-angle cases of references/projected_solid_angle.md Sec. 6 (T3: crossing the
# horizon, P: the parallelogram, seen from a tilted normal); tests/warps/test_polygon.py has more.
_T3 = np.array([(1, -1, 0.8), (1, 1, 0.5), (1, 0.2, -0.7)], float)
_P = np.array([(-0.5, -0.5, 1), (0.7, -0.4, 1), (1, 0.6, 1.2), (-0.2, 0.5, 1.2)], float)
_V3 = np.array([[1, 2, 0.5], [3, 1, 2], [0.2, 4, 1]])
_TABLE = np.abs(np.random.default_rng(0).normal(size=(8, 5)))
_TABLE[2] = 0.0
_TABLE[5, 3] = 0.0

PLANAR = [
    ("bilinear", lambda: W.Bilinear([[1.0, 3.0], [2.0, 4.0]])),
    ("bilinear-equal", lambda: W.Bilinear(np.full((2, 2), 0.7))),
    ("bilinear-tiny", lambda: W.Bilinear([[1e-6, 1.0], [1.0, 1e-6]])),
    ("bilinear-near-equal", lambda: W.Bilinear([[1.0, 1.0 + 1e-6], [1.0, 1.0]])),
    # Issue 24 item 2: some-zero weights and values whose squares leave float32's range.
    ("bilinear-one-corner", lambda: W.Bilinear([[0.0, 0.0], [0.0, 3.0]])),
    ("bilinear-scaled-1e-25", lambda: W.Bilinear(np.array([[1.0, 3.0], [2.0, 4.0]]) * 1e-25)),
    ("bilinear-scaled-1e25", lambda: W.Bilinear(np.array([[1.0, 3.0], [2.0, 4.0]]) * 1e25)),
    ("biquadratic", lambda: W.Biquadratic(_V3)),
    ("biquadratic-zero-row", lambda: W.Biquadratic([[0, 0, 0], [1, 2, 0.5], [3, 1, 2]])),
    ("biquadratic-tiny", lambda: W.Biquadratic([[1e-6, 1, 1e-6], [1, 1e-6, 1], [1e-6, 1, 2]])),
    ("biquadratic-equal", lambda: W.Biquadratic(np.ones((3, 3)))),
    ("tabulated", lambda: W.Tabulated(_TABLE)),
    (
        "compose-bilinear-biquadratic",
        lambda: W.compose(W.Bilinear([[1.0, 3.0], [2.0, 4.0]]), W.Biquadratic(_V3)),
    ),
]

SPHERICAL = [
    ("triangle-octant", lambda: W.SphericalTriangle(np.eye(3), np.zeros(3))),
    ("triangle-general", lambda: W.SphericalTriangle(_GENERAL_TRI, np.zeros(3))),
    (
        "triangle-offset-origin",
        lambda: W.SphericalTriangle(
            [[0.0, 0.0, 2.0], [1.0, 0.0, 2.5], [0.0, 1.5, 1.8]], [0.2, 0.1, 0.3]
        ),
    ),
    (
        "arvo2001-octant",
        lambda: W.CosineSphericalTriangle(np.eye(3), np.zeros(3), [0.0, 0.0, 1.0]),
    ),
    (
        "arvo2001-general",
        lambda: W.CosineSphericalTriangle(_GENERAL_TRI, np.zeros(3), _n([0.5, 0.2, 1.0])),
    ),
    (
        "psa-triangle-horizon",
        lambda: W.ProjectedSphericalPolygon(_T3, np.zeros(3), [0.0, 0.0, 1.0]),
    ),
    (
        "psa-parallelogram-tilted",
        lambda: W.ProjectedSphericalPolygon(_P, np.zeros(3), _n([-0.8, 0.2, 0.5])),
    ),
    (  # a sheared, stretched LTC (Heitz et al. 2016) over a tilted parallelogram
        "ltc-parallelogram",
        lambda: W.LTCPolygon(_P, np.zeros(3), np.eye(3),
                             np.linalg.inv([[0.4, 0.0, 0.3], [0.0, 0.6, 0.0], [-0.2, 0.0, 1.0]])),
    ),
    (
        "rectangle-square",
        lambda: W.SphericalRectangle([-0.5, -0.5, 1.0], [1, 0, 0], [0, 1, 0], [0, 0, 0]),
    ),
    (
        "rectangle-skewed",
        lambda: W.SphericalRectangle(
            [0.3, -0.2, 0.7], [0.8, 0.6, 0.0], [-0.3, 0.4, 0.5], [0, 0, 0]
        ),
    ),
    (
        "compose-bilinear-triangle",
        lambda: W.compose(
            W.Bilinear([[0.2, 1.0], [0.5, 2.0]]), W.SphericalTriangle(_GENERAL_TRI, np.zeros(3))
        ),
    ),
    (
        "compose-biquadratic-rectangle",
        lambda: W.compose(
            W.Biquadratic(_V3),
            W.SphericalRectangle([-0.5, -0.5, 1.0], [1, 0, 0], [0, 1, 0], [0, 0, 0]),
        ),
    ),
]

_EU, _EV = np.array([1.0, 0, 0]), np.array([0.3, 1, 0.2])
_TRI = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.2], [0.3, 0.9, 0.1]])
_TRAPEZOID = np.array([[[0, 0, 0], [0, 1, 0]], [[2, 0, 0], [1, 1, 0]]], float)  # [i, j] = p_ij
_CURVED = np.array([[[0, 0, 0], [0.2, 1, 0.3]], [[1.5, 0, 0.5], [1, 1.2, -0.2]]], float)

HEMISPHERE = [
    ("uniform-hemisphere", W.UniformHemisphere),
    ("angular-hemisphere", W.AngularHemisphere),
    ("cosine-hemisphere", W.CosineHemisphere),
    ("hemi-octahedral", W.HemiOctahedral),
    ("octahedral", W.Octahedral),
]

SURFACE = [
    ("triangle-area", lambda: W.TriangleArea(_TRI)),
    ("parallelogram", lambda: W.Parallelogram([0, 0, 1], _EU, _EV)),
    ("patch-uniform-trapezoid", lambda: W.BilinearPatch(_TRAPEZOID)),
    ("patch-area-trapezoid", lambda: W.patch_area_warp(_TRAPEZOID)),
    ("patch-uniform-curved", lambda: W.BilinearPatch(_CURVED)),
    ("patch-area-curved", lambda: W.patch_area_warp(_CURVED)),
]


def _affine_chart(origin, e1, e2):
    import jax.numpy as jnp

    o, a, b = (jnp.asarray(v, jnp.float32) for v in (origin, e1, e2))
    gram_inv = jnp.linalg.inv(jnp.array([[a @ a, a @ b], [a @ b, b @ b]]))  # normal equations

    def inverse(x):
        d = x - o
        return gram_inv @ jnp.stack([a @ d, b @ d])

    return (lambda s: o + s[0] * a + s[1] * b), inverse


def _patch_chart(corners):
    p = W.BilinearPatch(corners)
    return p.point, p.inverse


CHARTS = {
    "triangle-area": lambda: _affine_chart(_TRI[0], _TRI[1] - _TRI[0], _TRI[2] - _TRI[0]),
    # A chart unrelated to the warp's own map: a rotated, larger bounding parallelogram.
    "parallelogram": lambda: _affine_chart(
        np.array([0, 0, 1.0]) - 0.1 * _EU - 0.15 * _EV,
        1.3 * _EU + 0.2 * _EV,
        -0.1 * _EU + 1.3 * _EV,
    ),
    "patch-uniform-trapezoid": lambda: _affine_chart([0, 0, 0], [2, 0, 0], [0, 1, 0]),
    "patch-area-trapezoid": lambda: _affine_chart([0, 0, 0], [2, 0, 0], [0, 1, 0]),
    "patch-uniform-curved": lambda: _patch_chart(_CURVED),
    "patch-area-curved": lambda: _patch_chart(_CURVED),
}

ALL = [(i, f, "planar") for i, f in PLANAR] + [(i, f, "spherical") for i, f in SPHERICAL]
ALL += [(i, f, "spherical") for i, f in HEMISPHERE] + [
    ("concentric-disk", W.ConcentricDisk, "disk")
]
ALL += [(i, f, "surface") for i, f in SURFACE]

ROUND_TRIP_TOL = {"planar": 1e-5, "disk": 1e-5, "spherical": 1e-3, "surface": 1e-3}

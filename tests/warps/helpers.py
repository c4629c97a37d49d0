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
_V3 = np.array([[1, 2, 0.5], [3, 1, 2], [0.2, 4, 1]])

PLANAR = [
    ("bilinear", lambda: W.Bilinear([[1.0, 3.0], [2.0, 4.0]])),
    ("bilinear-equal", lambda: W.Bilinear(np.full((2, 2), 0.7))),
    ("bilinear-tiny", lambda: W.Bilinear([[1e-6, 1.0], [1.0, 1e-6]])),
    ("bilinear-near-equal", lambda: W.Bilinear([[1.0, 1.0 + 1e-6], [1.0, 1.0]])),
    ("biquadratic", lambda: W.Biquadratic(_V3)),
    ("biquadratic-tiny", lambda: W.Biquadratic([[1e-6, 1, 1e-6], [1, 1e-6, 1], [1e-6, 1, 2]])),
    ("biquadratic-equal", lambda: W.Biquadratic(np.ones((3, 3)))),
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

SURFACE: list = []

ALL = [(i, f, "planar") for i, f in PLANAR] + [(i, f, "spherical") for i, f in SPHERICAL]
ALL += [(i, f, "surface") for i, f in SURFACE]

ROUND_TRIP_TOL = {"planar": 1e-5, "spherical": 1e-3, "surface": 1e-3}

"""Polygon geometry in float64 (NumPy): areas, clipping, simplicity, Fourier sums."""

from __future__ import annotations

import math

import numpy as np

UNIT_SQUARE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])

# --- polygon geometry in float64 (NumPy) -------------------------------------------------------

def polygon_area(vertices) -> float:
    """Signed area (shoelace formula), positive for counter-clockwise vertices."""
    v = np.asarray(vertices, dtype=np.float64)
    if v.shape[0] < 3:
        return 0.0
    x, y = v[:, 0], v[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))

def clip_halfplane(poly: np.ndarray, normal: np.ndarray, offset: float) -> np.ndarray:
    """Sutherland-Hodgman step: keep ``normal . x <= offset`` (a convex clip region)."""
    if poly.shape[0] == 0:
        return poly
    out = []
    d = poly @ normal - offset
    m = poly.shape[0]
    for i in range(m):
        a, b = poly[i], poly[(i + 1) % m]
        da, db = d[i], d[(i + 1) % m]
        if da <= 0:
            out.append(a)
        if (da < 0 < db) or (db < 0 < da):
            t = da / (da - db)
            out.append(a + t * (b - a))
    return np.asarray(out, dtype=np.float64).reshape(-1, 2)

def clip_to_unit_square(vertices) -> np.ndarray:
    """The part of a polygon inside ``[0, 1]^2`` (Sutherland-Hodgman, float64).

    Also right for non-convex polygons as a *chain*: it may contain zero-area bridges along the
    square's border, which cancel in areas and in the Green's-theorem Fourier sums.
    """
    poly = np.asarray(vertices, dtype=np.float64)
    for normal, offset in (((-1.0, 0.0), 0.0), ((1.0, 0.0), 1.0), ((0.0, -1.0), 0.0),
                           ((0.0, 1.0), 1.0)):
        poly = clip_halfplane(poly, np.asarray(normal), offset)
    return poly

def _first_crossing(v: np.ndarray) -> tuple[int, int] | None:
    """The first pair of non-adjacent edges of the closed chain ``v`` that share a point.

    Orientation tests (float64), one edge against all later ones at a time: O(m^2) work,
    O(m) memory.
    """
    m = v.shape[0]
    a, b = v, np.roll(v, -1, axis=0)

    def orient(p, q, r):
        return (q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1]) - (q[..., 1] - p[..., 1]) * (
            r[..., 0] - p[..., 0])

    def within(p, q, r):  # r inside the bounding box of pq (for collinear triples)
        return ((np.minimum(p[..., 0], q[..., 0]) <= r[..., 0])
                & (r[..., 0] <= np.maximum(p[..., 0], q[..., 0]))
                & (np.minimum(p[..., 1], q[..., 1]) <= r[..., 1])
                & (r[..., 1] <= np.maximum(p[..., 1], q[..., 1])))

    for i in range(m - 2):
        j = np.arange(i + 2, m if i > 0 else m - 1)  # skip the neighbours of edge i
        if j.size == 0:
            continue
        p1, p2, q1, q2 = a[i], b[i], a[j], b[j]
        o1, o2 = orient(p1, p2, q1), orient(p1, p2, q2)
        o3, o4 = orient(q1, q2, p1), orient(q1, q2, p2)
        proper = (o1 * o2 < 0) & (o3 * o4 < 0)
        touch = (((o1 == 0) & within(p1, p2, q1)) | ((o2 == 0) & within(p1, p2, q2))
                 | ((o3 == 0) & within(q1, q2, p1)) | ((o4 == 0) & within(q1, q2, p2)))
        hit = np.nonzero(proper | touch)[0]
        if hit.size:
            return i, int(j[hit[0]])
    return None


def check_simple_polygon(name: str, vertices) -> np.ndarray:
    v = np.asarray(vertices, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 2:
        raise ValueError(f"{name} must have shape (m, 2) with m >= 3, got shape {v.shape}")
    if v.shape[0] < 3:
        raise ValueError(f"{name} must have at least 3 vertices, got {v.shape[0]}")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name} contains NaN or Inf")
    if np.any(np.all(v == np.roll(v, -1, axis=0), axis=1)):
        raise ValueError(f"{name} must not repeat a vertex consecutively")
    crossing = _first_crossing(v)
    if crossing is not None:
        raise ValueError(
            f"{name} must be a simple polygon: edges {crossing[0]} and {crossing[1]} intersect "
            "(self-intersecting polygons are not supported)"
        )
    area = polygon_area(v)
    if area == 0.0:
        raise ValueError(f"{name} has zero area")
    return v if area > 0 else v[::-1].copy()  # counter-clockwise

def is_convex(v: np.ndarray) -> bool:
    e = np.roll(v, -1, axis=0) - v
    cross = e[:, 0] * np.roll(e[:, 1], -1) - e[:, 1] * np.roll(e[:, 0], -1)
    return bool(np.all(cross >= 0))

def edge_directions_deg(v: np.ndarray) -> tuple[float, ...]:
    """Spectral directions (normal angles mod 180) of edges not lying on the square's border."""
    out: list[float] = []
    m = v.shape[0]
    for i in range(m):
        a, b = v[i], v[(i + 1) % m]
        e = b - a
        if np.hypot(*e) == 0:
            continue
        on_border = any(
            a[d] == b[d] and a[d] in (0.0, 1.0) for d in range(2)
        )
        if on_border:
            continue
        theta = math.degrees(math.atan2(-e[0], e[1])) % 180.0  # normal (e_y, -e_x)
        theta = round(theta, 9) % 180.0
        if all(abs(theta - t) > 1e-9 for t in out):
            out.append(theta)
    return tuple(sorted(out))

def polygon_fourier(chain: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Fourier coefficients of the indicator of a closed counter-clockwise chain.

    Divergence theorem (fourier_variance.md Sec. 4.2): for ``v != 0``
    ``F(v) = i / (2 pi |v|^2) sum_e (v . n_e) L_e exp(-2 pi i v . m_e) sinc(v . e)``
    with ``(v . n_e) L_e = v_x e_y - v_y e_x`` and ``sinc(z) = sin(pi z) / (pi z)``;
    ``F(0)`` is the area.
    """
    v = np.asarray(v, dtype=np.float64)
    if chain.shape[0] < 3:
        return np.zeros(v.shape[:-1], dtype=np.complex128)
    a = chain
    e = np.roll(chain, -1, axis=0) - a
    mid = a + 0.5 * e
    vx, vy = v[..., 0:1], v[..., 1:2]  # (..., 1) against edges (m,)
    flux = vx * e[:, 1] - vy * e[:, 0]
    phase = np.exp(-2j * np.pi * (vx * mid[:, 0] + vy * mid[:, 1]))
    s = np.sinc(vx * e[:, 0] + vy * e[:, 1])
    total = np.sum(flux * phase * s, axis=-1)
    r2 = v[..., 0] ** 2 + v[..., 1] ** 2
    zero = r2 == 0
    out = 1j * total / (2.0 * np.pi * np.where(zero, 1.0, r2))
    return np.where(zero, polygon_area(chain), out)

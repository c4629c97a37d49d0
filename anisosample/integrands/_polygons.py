"""Polygonal indicators: half-planes, simple polygons, and edges() at chosen directions."""

from __future__ import annotations

import itertools
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._validate import check_directions_deg, check_positive_float
from ._base import Integrand, as_float, check_frequencies_any, check_point2, check_real
from ._geometry import (
    UNIT_SQUARE,
    check_simple_polygon,
    clip_halfplane,
    clip_to_unit_square,
    edge_directions_deg,
    is_convex,
    polygon_area,
    polygon_fourier,
)


class _PolygonalIndicator(Integrand):
    """``value`` times the indicator of a polygonal region; shared by Polygon and HalfPlane."""

    value: float = eqx.field(static=True)
    chain: tuple[tuple[float, float], ...] = eqx.field(static=True)  # clipped, CCW, float64

    @property
    def clipped_vertices(self) -> np.ndarray:
        """The region inside the unit square, counter-clockwise, float64 ``(m, 2)``."""
        return np.asarray(self.chain, dtype=np.float64).reshape(-1, 2)

    @property
    def integral(self) -> float:
        return self.value * polygon_area(self.clipped_vertices)

    def second_moment(self) -> float:
        return self.value * self.integral

    def fourier_coefficients(self, v) -> np.ndarray | np.complexfloating:
        v = check_frequencies_any(v)
        return self.value * polygon_fourier(self.clipped_vertices, v)

class HalfPlane(_PolygonalIndicator):
    """``f(x) = value * 1[x . (cos phi, sin phi) < offset]``, ``phi = normal_deg``.

    The edge runs at ``phi + 90`` degrees; its spectral direction is ``phi mod 180`` (W Sec. 2).
    ``normal_deg`` is any angle (it also says which side is inside). An edge through the point
    ``p`` has ``offset = p . (cos phi, sin phi)``; see :meth:`through`.
    """

    normal_deg: float = eqx.field(static=True)
    offset: float = eqx.field(static=True)
    _normal: jax.Array

    def __init__(self, normal_deg, offset, value=1.0):
        self.normal_deg = check_real("normal_deg", normal_deg)
        self.offset = check_real("offset", offset)
        self.value = check_real("value", value)
        phi = math.radians(self.normal_deg)
        normal = np.array([math.cos(phi), math.sin(phi)])
        clipped = clip_halfplane(UNIT_SQUARE.copy(), normal, self.offset)
        if polygon_area(clipped) <= 0.0:
            clipped = np.zeros((0, 2))
        self.chain = tuple(map(tuple, clipped.tolist()))
        self._normal = jnp.asarray(normal, dtype=jnp.float32)

    @classmethod
    def through(cls, point, normal_deg, value=1.0) -> HalfPlane:
        """The half-plane whose edge passes through ``point``, inside opposite to the normal."""
        px, py = check_point2("point", point)
        phi = math.radians(check_real("normal_deg", normal_deg))
        return cls(normal_deg, px * math.cos(phi) + py * math.sin(phi), value)

    def __call__(self, x):
        x = as_float(x)
        n = self._normal.astype(x.dtype)
        t = x[..., 0] * n[0] + x[..., 1] * n[1]
        return jnp.where(t < jnp.asarray(self.offset, x.dtype), jnp.asarray(self.value, x.dtype),
                         jnp.zeros((), x.dtype))

    @property
    def directions_deg(self) -> tuple[float, ...]:
        theta = round(self.normal_deg % 180.0, 9) % 180.0
        if theta in (0.0, 90.0) or len(self.chain) == 0 or self.integral == self.value:
            return ()
        return (theta,)

class Polygon(_PolygonalIndicator):
    """``value`` times the indicator of a simple polygon (convex or not), clipped to the square.

    ``vertices``: ``(m, 2)``, ``m >= 3``, in either orientation, without self-intersections.
    Evaluation: a half-plane test per edge for convex polygons, the crossing-number rule otherwise.
    The integral is the shoelace area of the clipped polygon; the Fourier coefficients are those
    of fourier_variance.md Sec. 4.2 (divergence theorem) on the clipped polygon.
    ``directions_deg`` defaults to the normal directions of the edges inside the square.
    """

    vertices: tuple[tuple[float, float], ...] = eqx.field(static=True)
    convex: bool = eqx.field(static=True)
    _directions: tuple[float, ...] = eqx.field(static=True)
    _tests: tuple[tuple[float, ...], ...] = eqx.field(static=True)  # per-edge constants

    def __init__(self, vertices, value=1.0, directions_deg=None):
        v = check_simple_polygon("vertices", vertices)
        self.value = check_real("value", value)
        self.vertices = tuple(map(tuple, v.tolist()))
        self.convex = is_convex(v)
        clipped = clip_to_unit_square(v)
        if abs(polygon_area(clipped)) <= 0.0:
            clipped = np.zeros((0, 2))
        self.chain = tuple(map(tuple, clipped.tolist()))
        if directions_deg is None:
            self._directions = edge_directions_deg(clipped) if len(clipped) else ()
            self._directions = tuple(t for t in self._directions if t not in (0.0, 90.0))
        else:
            self._directions = check_directions_deg("directions_deg", directions_deg,
                                                    allow_empty=True)
        if self.convex:
            # x is inside iff n_e . x <= c_e for every edge that cuts the square's interior
            # (the border edges of the clipped polygon hold for every x in [0, 1)^2)
            tests = []
            for a, b in zip(clipped, np.roll(clipped, -1, axis=0), strict=True):
                if any(a[d] == b[d] and a[d] in (0.0, 1.0) for d in range(2)):
                    continue
                nx, ny = b[1] - a[1], a[0] - b[0]  # outward normal of a CCW edge
                scale = 1.0 / math.hypot(nx, ny)
                tests.append((float(nx * scale), float(ny * scale),
                              float((nx * a[0] + ny * a[1]) * scale)))
            self._tests = tuple(tests)
        else:
            # crossing number: per edge (a_y, b_y, a_x, slope dx/dy) of the original polygon
            tests = []
            for a, b in zip(v, np.roll(v, -1, axis=0), strict=True):
                if a[1] == b[1]:
                    continue  # horizontal edges never straddle a horizontal ray
                tests.append((float(a[1]), float(b[1]), float(a[0]),
                              float((b[0] - a[0]) / (b[1] - a[1]))))
            self._tests = tuple(tests)

    @property
    def directions_deg(self) -> tuple[float, ...]:
        return self._directions

    def __call__(self, x):
        x = as_float(x)
        px, py = x[..., 0], x[..., 1]
        dt = x.dtype
        if self.convex:
            # unrolled over the (few) edges: elementwise work that XLA fuses into one loop
            # full shape even when no edge cuts the square (the polygon covers it or misses it)
            inside = jnp.full(px.shape, len(self.chain) > 0)
            for nx, ny, c in self._tests:
                inside = inside & (px * jnp.asarray(nx, dt) + py * jnp.asarray(ny, dt)
                                   <= jnp.asarray(c, dt))
        else:
            # even-odd rule for the ray from x towards +x
            inside = jnp.zeros(px.shape, dtype=bool)
            for ay, by, ax, slope in self._tests:
                straddle = (py < jnp.asarray(ay, dt)) != (py < jnp.asarray(by, dt))
                x_cross = jnp.asarray(ax, dt) + (py - jnp.asarray(ay, dt)) * jnp.asarray(slope, dt)
                inside = inside ^ (straddle & (px < x_cross))
        return jnp.where(inside, jnp.asarray(self.value, dt), jnp.zeros((), dt))


def edges(directions_deg, *, center=(0.5, 0.5), radius=0.25, value=1.0) -> Polygon | HalfPlane:
    """An integrand with one edge perpendicular to each chosen spectral direction (W Fig. 6).

    ``directions_deg``: 1 to 4 distinct spectral directions in ``[0, 180)``. One direction gives
    the half-plane whose edge passes through ``center``; two to four give the convex polygon cut
    from the unit square by the lines tangent to the circle (``center``, ``radius``) with those
    normals, the normals' signs chosen so that the polygon is as round as possible (smallest
    largest angular gap between consecutive normals). Every edge touches that circle, so each
    direction is a visible edge inside the square. The result's ``directions_deg`` are the ones
    asked for apart from 0 and 90 (like every integrand's); the square's border adds 0 and 90
    degrees on the torus.
    """
    dirs = check_directions_deg("directions_deg", directions_deg)
    if len(dirs) > 4:
        raise ValueError(f"directions_deg must hold 1 to 4 directions, got {len(dirs)}")
    cx, cy = check_point2("center", center)
    radius = check_positive_float("radius", radius)
    if not (0.0 < cx < 1.0 and 0.0 < cy < 1.0):
        raise ValueError(f"center must lie inside (0, 1)^2, got {(cx, cy)}")
    if radius >= min(cx, cy, 1.0 - cx, 1.0 - cy):
        raise ValueError(
            f"radius must be smaller than the distance from center to the square's border "
            f"({min(cx, cy, 1 - cx, 1 - cy):g}), got {radius}"
        )
    if len(dirs) == 1:
        return HalfPlane.through((cx, cy), dirs[0], value)
    best, best_gap = None, None
    for signs in itertools.product((0.0, 180.0), repeat=len(dirs) - 1):
        phis = sorted([dirs[0]] + [d + s for d, s in zip(dirs[1:], signs, strict=True)])
        gaps = np.diff(phis + [phis[0] + 360.0])
        if best_gap is None or gaps.max() < best_gap - 1e-12:
            best, best_gap = phis, gaps.max()
    poly = UNIT_SQUARE.copy()
    for phi in best:
        n = np.array([math.cos(math.radians(phi)), math.sin(math.radians(phi))])
        poly = clip_halfplane(poly, n, float(n @ np.array([cx, cy])) + radius)
    # drop vertices repeated by the clipping (a line through a square corner)
    keep = np.any(np.abs(poly - np.roll(poly, 1, axis=0)) > 1e-15, axis=1)
    extra = tuple(d for d in dirs if d not in (0.0, 90.0))  # the axes are implied (W Sec. 5)
    return Polygon(poly[keep], value=value, directions_deg=extra)

"""Analytic 2D integrands on ``[0, 1)^2`` with exact integrals and exact Fourier coefficients.

Every integrand is an immutable ``equinox.Module`` and a pure callable ``f(x)`` over ``x`` of
shape ``(..., 2)`` returning shape ``(...)`` in ``x``'s float dtype. Each carries

* ``integral`` -- the exact value of ``int_{[0,1)^2} f``, computed in float64 (a Python float);
* ``directions_deg`` -- the spectral directions of its discontinuities that are *not* the axes
  (W Sec. 2: an edge running at ``theta + 90`` degrees puts its energy along ``theta``);
* where a closed form exists, ``fourier_coefficients(v)`` for integer ``v`` (complex128),
  ``F_f(v) = int_{[0,1)^2} f(x) exp(-2 pi i v.x) dx``, so ``P_f(v) = |F_f(v)|^2`` is exact
  (W Eq. 3-5; ``shared/references/fourier_variance.md`` Sec. 4).

The integrand lives on the unit square: shapes that reach outside it are clipped to it for the
integral and the spectrum (the torus sees the square's border as extra axis-aligned edges).

Shapes: :class:`HalfPlane`, :class:`Polygon` (simple, convex or not), :func:`edges` (1-4 edges
perpendicular to chosen spectral directions, the integrands of W Fig. 6), :class:`Disk` (curved:
no principal direction), :class:`SmoothedEdge` (a half-plane convolved with a Gaussian, W Fig. 11),
:class:`GaussianBump` (smooth), :class:`Texture` and :class:`Textured` (a smooth texture times a
shape, W Fig. 6's "smooth texture" rows).
"""

from __future__ import annotations

import itertools
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import scipy.integrate
import scipy.special

from ._validate import check_choice, check_directions_deg, check_positive_float

__all__ = [
    "Integrand",
    "HalfPlane",
    "Polygon",
    "edges",
    "Disk",
    "SmoothedEdge",
    "GaussianBump",
    "Texture",
    "smooth_texture",
    "Textured",
    "clip_to_unit_square",
    "polygon_area",
]

_UNIT_SQUARE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])

# --- polygon geometry in float64 (NumPy) -------------------------------------------------------

def polygon_area(vertices) -> float:
    """Signed area (shoelace formula), positive for counter-clockwise vertices."""
    v = np.asarray(vertices, dtype=np.float64)
    if v.shape[0] < 3:
        return 0.0
    x, y = v[:, 0], v[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))

def _clip_halfplane(poly: np.ndarray, normal: np.ndarray, offset: float) -> np.ndarray:
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
        poly = _clip_halfplane(poly, np.asarray(normal), offset)
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


def _check_simple_polygon(name: str, vertices) -> np.ndarray:
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

def _is_convex(v: np.ndarray) -> bool:
    e = np.roll(v, -1, axis=0) - v
    cross = e[:, 0] * np.roll(e[:, 1], -1) - e[:, 1] * np.roll(e[:, 0], -1)
    return bool(np.all(cross >= 0))

def _edge_directions_deg(v: np.ndarray) -> tuple[float, ...]:
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

def _polygon_fourier(chain: np.ndarray, v: np.ndarray) -> np.ndarray:
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

def _check_frequencies_any(v) -> np.ndarray:
    v = np.asarray(v)
    if v.ndim < 1 or v.shape[-1] != 2:
        raise ValueError(f"v must have shape (..., 2), got shape {v.shape}")
    if not np.issubdtype(v.dtype, np.integer):
        if not (np.issubdtype(v.dtype, np.floating) and np.all(v == np.round(v))):
            raise ValueError("v must hold integer frequency vectors")
    return v.astype(np.float64)

def _check_point2(name: str, p) -> tuple[float, float]:
    p = np.asarray(p, dtype=np.float64)
    if p.shape != (2,) or not np.all(np.isfinite(p)):
        raise ValueError(f"{name} must be two finite numbers (x, y), got {p.tolist()}")
    return float(p[0]), float(p[1])

def _check_real(name: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.number):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__} {value!r}")
    if not np.isfinite(float(value)):
        raise ValueError(f"{name} must be finite, got {value}")
    return float(value)

def _as_float(x):
    x = jnp.asarray(x)
    if x.ndim < 1 or x.shape[-1] != 2:
        raise ValueError(f"x must have shape (..., 2), got shape {x.shape}")
    if not jnp.issubdtype(x.dtype, jnp.floating):
        raise TypeError(f"x must be a floating-point array, got dtype {x.dtype}")
    return x

# --- the integrand base ------------------------------------------------------------------------

class Integrand(eqx.Module):
    """Base of the analytic integrands: ``f(x)`` over ``(..., 2)``, ``integral``, directions."""

    def __call__(self, x):
        raise NotImplementedError

    @property
    def integral(self) -> float:
        raise NotImplementedError

    @property
    def directions_deg(self) -> tuple[float, ...]:
        """Spectral directions of the discontinuities, apart from the axes' 0 and 90 degrees."""
        return ()

    def fourier_coefficients(self, v) -> np.ndarray:
        """``F_f(v)`` for integer ``v`` of shape ``(..., 2)``, complex128 (W Eq. 3)."""
        raise NotImplementedError(f"{type(self).__name__} has no closed-form Fourier coefficients")

    def power_spectrum(self, v) -> np.ndarray:
        """``P_f(v) = |F_f(v)|^2`` (W Eq. 4), float64."""
        return np.abs(self.fourier_coefficients(v)) ** 2

    def second_moment(self) -> float:
        """``int f^2`` where known in closed form (for ``Var f = int f^2 - I^2``)."""
        raise NotImplementedError(f"{type(self).__name__} has no closed-form second moment")

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

    def fourier_coefficients(self, v) -> np.ndarray:
        v = _check_frequencies_any(v)
        return self.value * _polygon_fourier(self.clipped_vertices, v)

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
        self.normal_deg = _check_real("normal_deg", normal_deg)
        self.offset = _check_real("offset", offset)
        self.value = _check_real("value", value)
        phi = math.radians(self.normal_deg)
        normal = np.array([math.cos(phi), math.sin(phi)])
        clipped = _clip_halfplane(_UNIT_SQUARE.copy(), normal, self.offset)
        if polygon_area(clipped) <= 0.0:
            clipped = np.zeros((0, 2))
        self.chain = tuple(map(tuple, clipped.tolist()))
        self._normal = jnp.asarray(normal, dtype=jnp.float32)

    @classmethod
    def through(cls, point, normal_deg, value=1.0) -> HalfPlane:
        """The half-plane whose edge passes through ``point``, inside opposite to the normal."""
        px, py = _check_point2("point", point)
        phi = math.radians(_check_real("normal_deg", normal_deg))
        return cls(normal_deg, px * math.cos(phi) + py * math.sin(phi), value)

    def __call__(self, x):
        x = _as_float(x)
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
        v = _check_simple_polygon("vertices", vertices)
        self.value = _check_real("value", value)
        self.vertices = tuple(map(tuple, v.tolist()))
        self.convex = _is_convex(v)
        clipped = clip_to_unit_square(v)
        if abs(polygon_area(clipped)) <= 0.0:
            clipped = np.zeros((0, 2))
        self.chain = tuple(map(tuple, clipped.tolist()))
        if directions_deg is None:
            self._directions = _edge_directions_deg(clipped) if len(clipped) else ()
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
        x = _as_float(x)
        px, py = x[..., 0], x[..., 1]
        dt = x.dtype
        if self.convex:
            # unrolled over the (few) edges: elementwise work that XLA fuses into one loop
            inside = jnp.asarray(len(self.chain) > 0)
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
    asked for; the square's border adds 0 and 90 degrees on the torus.
    """
    dirs = check_directions_deg("directions_deg", directions_deg)
    if len(dirs) > 4:
        raise ValueError(f"directions_deg must hold 1 to 4 directions, got {len(dirs)}")
    cx, cy = _check_point2("center", center)
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
    poly = _UNIT_SQUARE.copy()
    for phi in best:
        n = np.array([math.cos(math.radians(phi)), math.sin(math.radians(phi))])
        poly = _clip_halfplane(poly, n, float(n @ np.array([cx, cy])) + radius)
    # drop vertices repeated by the clipping (a line through a square corner)
    keep = np.any(np.abs(poly - np.roll(poly, 1, axis=0)) > 1e-15, axis=1)
    return Polygon(poly[keep], value=value, directions_deg=dirs)

# --- curved and smooth integrands --------------------------------------------------------------

class Disk(Integrand):
    """``value * 1[|x - center| < radius]``, the disk inside the square: no principal direction.

    The control case of W Sec. 6: its spectrum is isotropic,
    ``F(v) = value * radius * J1(2 pi radius |v|) / |v| * exp(-2 pi i v . center)``.
    """

    center: tuple[float, float] = eqx.field(static=True)
    radius: float = eqx.field(static=True)
    value: float = eqx.field(static=True)

    def __init__(self, center=(0.5, 0.5), radius=0.3, value=1.0):
        self.center = _check_point2("center", center)
        self.radius = check_positive_float("radius", radius)
        self.value = _check_real("value", value)
        cx, cy = self.center
        if min(cx, cy, 1.0 - cx, 1.0 - cy) < self.radius:
            raise ValueError(
                "radius must keep the disk inside [0, 1]^2 (clipped disks are not supported): "
                f"got center {self.center} and radius {self.radius}"
            )

    def __call__(self, x):
        x = _as_float(x)
        dx = x[..., 0] - jnp.asarray(self.center[0], x.dtype)
        dy = x[..., 1] - jnp.asarray(self.center[1], x.dtype)
        inside = dx * dx + dy * dy < jnp.asarray(self.radius**2, x.dtype)
        return jnp.where(inside, jnp.asarray(self.value, x.dtype), jnp.zeros((), x.dtype))

    @property
    def integral(self) -> float:
        return self.value * math.pi * self.radius**2

    def second_moment(self) -> float:
        return self.value * self.integral

    def fourier_coefficients(self, v) -> np.ndarray:
        v = _check_frequencies_any(v)
        rho = np.hypot(v[..., 0], v[..., 1])
        safe = np.where(rho == 0, 1.0, rho)
        amp = np.where(rho == 0, math.pi * self.radius**2,
                       self.radius * scipy.special.j1(2 * math.pi * self.radius * safe) / safe)
        phase = np.exp(-2j * math.pi * (v[..., 0] * self.center[0] + v[..., 1] * self.center[1]))
        return self.value * amp * phase

def _lambda(z):
    """Second antiderivative of the normal CDF: ``Lambda'' = Phi``, ``Lambda(-inf) = 0``."""
    return 0.5 * ((z * z + 1.0) * scipy.special.ndtr(z) + z * np.exp(-0.5 * z * z)
                  / math.sqrt(2 * math.pi))

def _psi(z):
    """First antiderivative of the normal CDF: ``Psi(z) = z Phi(z) + phi(z)``."""
    return z * scipy.special.ndtr(z) + np.exp(-0.5 * z * z) / math.sqrt(2 * math.pi)

class SmoothedEdge(Integrand):
    """A :class:`HalfPlane` convolved with an isotropic Gaussian of std ``sigma`` (W Fig. 11).

    ``f(x) = value * Phi((offset - x . n) / sigma)``, ``n = (cos phi, sin phi)``: the plane's
    half-plane blurred, restricted to the square. W Fig. 11 blurs a 2048^2 grid with sigma = 2.83
    and 8.5 pixels, i.e. ``sigma = 2.83 / 2048`` and ``8.5 / 2048`` here.
    The integral is the closed form ``sigma^2/(n_x n_y) sum_corners +-Lambda(u)`` with
    ``Lambda'' = Phi``; near the axes (``|n_x n_y| < 1e-3``) it switches to adaptive quadrature
    of the exact inner integral. Both are accurate to better than 1e-10.
    The spectral direction is ``phi mod 180``, but the blur cuts that ray off at
    ``|v| ~ 1 / (2 pi sigma)`` (fourier_variance.md Sec. 4.3).
    """

    normal_deg: float = eqx.field(static=True)
    offset: float = eqx.field(static=True)
    sigma: float = eqx.field(static=True)
    value: float = eqx.field(static=True)

    def __init__(self, normal_deg, offset, sigma, value=1.0):
        self.normal_deg = _check_real("normal_deg", normal_deg)
        self.offset = _check_real("offset", offset)
        self.sigma = check_positive_float("sigma", sigma)
        self.value = _check_real("value", value)

    @classmethod
    def through(cls, point, normal_deg, sigma, value=1.0) -> SmoothedEdge:
        px, py = _check_point2("point", point)
        phi = math.radians(_check_real("normal_deg", normal_deg))
        return cls(normal_deg, px * math.cos(phi) + py * math.sin(phi), sigma, value)

    def _n(self):
        phi = math.radians(self.normal_deg)
        return math.cos(phi), math.sin(phi)

    def __call__(self, x):
        x = _as_float(x)
        nx, ny = self._n()
        t = x[..., 0] * jnp.asarray(nx, x.dtype) + x[..., 1] * jnp.asarray(ny, x.dtype)
        u = (jnp.asarray(self.offset, x.dtype) - t) / jnp.asarray(self.sigma, x.dtype)
        return jnp.asarray(self.value, x.dtype) * jax.scipy.special.ndtr(u)

    @property
    def integral(self) -> float:
        nx, ny = self._n()
        s, c = self.sigma, self.offset

        def u(x, y):
            return (c - nx * x - ny * y) / s

        if abs(nx * ny) >= 1e-3:
            total = _lambda(u(1, 1)) - _lambda(u(1, 0)) - _lambda(u(0, 1)) + _lambda(u(0, 0))
            return self.value * float(s * s / (nx * ny) * total)
        # Near an axis: integrate over the coordinate with the larger normal component exactly
        # (Psi) and over the other one by adaptive quadrature.
        if abs(nx) >= abs(ny):
            def inner(y):
                return -(s / nx) * (_psi(u(1, y)) - _psi(u(0, y)))
        else:
            def inner(xv):
                return -(s / ny) * (_psi(u(xv, 1)) - _psi(u(xv, 0)))
        val, _ = scipy.integrate.quad(inner, 0.0, 1.0, epsabs=1e-14, epsrel=1e-13, limit=200)
        return self.value * float(val)

    @property
    def directions_deg(self) -> tuple[float, ...]:
        theta = round(self.normal_deg % 180.0, 9) % 180.0
        return () if theta in (0.0, 90.0) else (theta,)

class GaussianBump(Integrand):
    """``amplitude * exp(-|x - center|^2 / (2 sigma^2))``: a smooth integrand (no edges).

    Exact integral ``2 pi sigma^2 prod_d [Phi((1 - c_d)/sigma) - Phi(-c_d/sigma)]``. Keep the bump
    well inside the square (the defaults leave ``exp(-19.5)`` at the border) so that it is also
    smooth on the torus.
    """

    center: tuple[float, float] = eqx.field(static=True)
    sigma: float = eqx.field(static=True)
    amplitude: float = eqx.field(static=True)

    def __init__(self, center=(0.5, 0.5), sigma=0.08, amplitude=1.0):
        self.center = _check_point2("center", center)
        self.sigma = check_positive_float("sigma", sigma)
        self.amplitude = _check_real("amplitude", amplitude)

    def __call__(self, x):
        x = _as_float(x)
        dx = x[..., 0] - jnp.asarray(self.center[0], x.dtype)
        dy = x[..., 1] - jnp.asarray(self.center[1], x.dtype)
        k = jnp.asarray(-0.5 / self.sigma**2, x.dtype)
        return jnp.asarray(self.amplitude, x.dtype) * jnp.exp(k * (dx * dx + dy * dy))

    def _mass(self, sigma) -> float:
        out = 2 * math.pi * sigma**2
        for c in self.center:
            out *= float(scipy.special.ndtr((1 - c) / sigma) - scipy.special.ndtr(-c / sigma))
        return out

    @property
    def integral(self) -> float:
        return self.amplitude * self._mass(self.sigma)

    def second_moment(self) -> float:
        # f^2 is a bump with sigma / sqrt(2)
        return self.amplitude**2 * self._mass(self.sigma / math.sqrt(2.0))

class Texture(Integrand):
    """A smooth periodic texture ``offset + sum_j a_j cos(2 pi k_j . x + phase_j)``.

    ``freqs``: ``(m, 2)`` nonzero integer frequencies ``k_j``; ``amplitudes``, ``phases``: ``(m,)``.
    A trigonometric polynomial: smooth on the torus, ``integral = offset``, and its spectrum is
    ``m`` pairs of deltas. Multiply a shape by it with :class:`Textured`.
    """

    freqs: tuple[tuple[int, int], ...] = eqx.field(static=True)
    amplitudes: tuple[float, ...] = eqx.field(static=True)
    phases: tuple[float, ...] = eqx.field(static=True)
    offset: float = eqx.field(static=True)

    def __init__(self, freqs, amplitudes, phases=None, offset=1.0):
        k = np.asarray(freqs)
        if k.ndim != 2 or k.shape[1] != 2 or k.shape[0] < 1:
            raise ValueError(f"freqs must have shape (m, 2) with m >= 1, got shape {k.shape}")
        if not np.all(k == np.round(k)):
            raise ValueError("freqs must hold integer frequency vectors")
        if np.any(np.all(k == 0, axis=1)):
            raise ValueError("freqs must not contain the zero frequency (use offset)")
        a = np.asarray(amplitudes, dtype=np.float64).reshape(-1)
        p = np.zeros_like(a) if phases is None else np.asarray(phases, np.float64).reshape(-1)
        if a.shape[0] != k.shape[0] or p.shape[0] != k.shape[0]:
            raise ValueError(
                f"amplitudes and phases must have {k.shape[0]} entries (one per frequency), "
                f"got {a.shape[0]} and {p.shape[0]}"
            )
        if not (np.all(np.isfinite(a)) and np.all(np.isfinite(p))):
            raise ValueError("amplitudes and phases must be finite")
        self.freqs = tuple((int(x), int(y)) for x, y in k)
        self.amplitudes = tuple(float(x) for x in a)
        self.phases = tuple(float(x) for x in p)
        self.offset = _check_real("offset", offset)

    def __call__(self, x):
        x = _as_float(x)
        out = jnp.full(x.shape[:-1], self.offset, dtype=x.dtype)
        for (kx, ky), a, p in zip(self.freqs, self.amplitudes, self.phases, strict=True):
            # reduce the phase modulo one turn before scaling by 2 pi (float32 accuracy)
            t = x[..., 0] * kx + x[..., 1] * ky
            t = t - jnp.floor(t)
            out = out + jnp.asarray(a, x.dtype) * jnp.cos(
                jnp.asarray(2 * math.pi, x.dtype) * t + jnp.asarray(p, x.dtype))
        return out

    @property
    def integral(self) -> float:
        return self.offset

    def second_moment(self) -> float:
        return self.offset**2 + 0.5 * sum(a * a for a in self.amplitudes)  # distinct +-k_j assumed

    def _terms(self):
        """``T(x) = sum_t c_t exp(2 pi i k_t . x)`` as (k_t, c_t) pairs, including the offset."""
        terms = [((0, 0), complex(self.offset))]
        for (kx, ky), a, p in zip(self.freqs, self.amplitudes, self.phases, strict=True):
            terms.append(((kx, ky), 0.5 * a * complex(math.cos(p), math.sin(p))))
            terms.append(((-kx, -ky), 0.5 * a * complex(math.cos(p), -math.sin(p))))
        return terms

    def fourier_coefficients(self, v) -> np.ndarray:
        v = _check_frequencies_any(v)
        out = np.zeros(v.shape[:-1], dtype=np.complex128)
        for (kx, ky), c in self._terms():
            out = out + np.where((v[..., 0] == kx) & (v[..., 1] == ky), c, 0.0)
        return out

def smooth_texture(kind: str = "default") -> Texture:
    """The smooth texture of our W Fig. 6 "with texture" integrands: positive, low frequency.

    ``1 + 0.35 cos(2 pi (x + 2y) + 0.3) + 0.25 cos(2 pi (3x - y) + 1.1) + 0.15 cos(2 pi (2x + 3y))``
    (values in [0.25, 1.75]).
    """
    check_choice("kind", kind, ["default"])
    return Texture([(1, 2), (3, -1), (2, 3)], [0.35, 0.25, 0.15], [0.3, 1.1, 0.0], offset=1.0)

class Textured(Integrand):
    """``texture(x) * shape(x)``: a smooth texture on a discontinuous shape (W Fig. 6).

    Exact integral and Fourier coefficients from the shape's closed-form coefficients:
    ``F_{T s}(v) = sum_t c_t F_s(v - k_t)`` for ``T = sum_t c_t exp(2 pi i k_t . x)``.
    """

    texture: Texture
    shape: Integrand

    def __init__(self, texture: Texture, shape: Integrand):
        if not isinstance(texture, Texture):
            raise TypeError(f"texture must be a Texture, got {type(texture).__name__}")
        if not isinstance(shape, Integrand):
            raise TypeError(f"shape must be an Integrand, got {type(shape).__name__}")
        try:
            shape.fourier_coefficients(np.zeros((1, 2), dtype=np.int64))
        except NotImplementedError:
            raise ValueError(
                f"shape must have closed-form Fourier coefficients (HalfPlane, Polygon, Disk), "
                f"got {type(shape).__name__}"
            ) from None
        self.texture = texture
        self.shape = shape

    def __call__(self, x):
        return self.texture(x) * self.shape(x)

    @property
    def integral(self) -> float:
        return float(np.real(self.fourier_coefficients(np.zeros(2, dtype=np.int64))))

    @property
    def directions_deg(self) -> tuple[float, ...]:
        return self.shape.directions_deg

    def fourier_coefficients(self, v) -> np.ndarray:
        v = _check_frequencies_any(v)
        out = np.zeros(v.shape[:-1], dtype=np.complex128)
        for k, c in self.texture._terms():
            out = out + c * self.shape.fourier_coefficients(v - np.asarray(k, dtype=np.float64))
        return out

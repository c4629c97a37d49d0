"""Analytic integrands against independent computations: slab integration, quadrature, closed-
form Fourier coefficients (W Eqs. 3-5; Durand 2011), a many-sided polygon for the disk."""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.integrate
import scipy.special
from matplotlib.path import Path

from anisosample import integrands as I
from anisosample.integrands._geometry import edge_directions_deg

# --- independent helpers: horizontal slabs -----------------------------------------------------


def _chord_intervals(vertices, y):
    """x-intervals of {x : (x, y) inside polygon} (even-odd rule), clipped to [0, 1]."""
    v = np.asarray(vertices, dtype=np.float64)
    a, b = v, np.roll(v, -1, axis=0)
    xs = []
    for (ax, ay), (bx, by) in zip(a, b, strict=True):
        if (ay > y) != (by > y):
            xs.append(ax + (y - ay) * (bx - ax) / (by - ay))
    xs = sorted(xs)
    out = []
    for lo, hi in zip(xs[::2], xs[1::2], strict=True):
        lo, hi = max(lo, 0.0), min(hi, 1.0)
        if hi > lo:
            out.append((lo, hi))
    return out


def _breakpoints_y(vertices):
    """y values where the chord length stops being linear: vertices and crossings of x = 0, 1."""
    v = np.asarray(vertices, dtype=np.float64)
    ys = [0.0, 1.0, *v[:, 1]]
    for (ax, ay), (bx, by) in zip(v, np.roll(v, -1, axis=0), strict=True):
        for xb in (0.0, 1.0):
            if (ax - xb) * (bx - xb) < 0:
                ys.append(ay + (xb - ax) * (by - ay) / (bx - ax))
    return np.unique(np.clip(ys, 0.0, 1.0))


def _slab_area(vertices):
    """Area inside [0,1]^2: the chord length is linear between breakpoints -> midpoint rule."""
    ys = _breakpoints_y(vertices)
    total = 0.0
    for y0, y1 in zip(ys[:-1], ys[1:], strict=True):
        ym = 0.5 * (y0 + y1)
        total += (y1 - y0) * sum(hi - lo for lo, hi in _chord_intervals(vertices, ym))
    return total


def _slab_fourier(vertices, v):
    """F(v) by exact inner integrals over chords and adaptive quadrature over y."""
    vx, vy = v

    def inner(y, part):
        s = 0.0 + 0.0j
        for lo, hi in _chord_intervals(vertices, y):
            if vx == 0:
                s += (hi - lo)
            else:
                s += (np.exp(-2j * np.pi * vx * hi) - np.exp(-2j * np.pi * vx * lo)) / (
                    -2j * np.pi * vx)
        s *= np.exp(-2j * np.pi * vy * y)
        return s.real if part == 0 else s.imag

    ys = _breakpoints_y(vertices)
    re = sum(scipy.integrate.quad(inner, a, b, args=(0,), epsabs=1e-13, limit=200)[0]
             for a, b in zip(ys[:-1], ys[1:], strict=True))
    im = sum(scipy.integrate.quad(inner, a, b, args=(1,), epsabs=1e-13, limit=200)[0]
             for a, b in zip(ys[:-1], ys[1:], strict=True))
    return re + 1j * im


POLYGONS = {
    "triangle": [(0.1, 0.2), (0.8, 0.3), (0.4, 0.9)],
    "clockwise-quad": [(0.2, 0.1), (0.15, 0.7), (0.9, 0.85), (0.7, 0.2)],
    "concave-arrow": [(0.1, 0.1), (0.9, 0.1), (0.5, 0.5), (0.9, 0.9), (0.1, 0.9)],
    "overhanging": [(-0.3, 0.2), (0.7, -0.4), (1.4, 0.6), (0.5, 1.3), (0.45, 0.5)],
    "concave-outside": [(-0.2, -0.1), (1.2, 0.3), (0.3, 0.45), (1.1, 1.2), (0.1, 0.8)],
}


# --- polygons ----------------------------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(POLYGONS))
def test_polygon_integral_exact(name):
    verts = POLYGONS[name]
    p = I.Polygon(verts, value=2.5)
    assert abs(p.integral - 2.5 * _slab_area(verts)) < 1e-12


@pytest.mark.parametrize("name", sorted(POLYGONS))
def test_polygon_fourier_against_slab_quadrature(name):
    verts = POLYGONS[name]
    p = I.Polygon(verts)
    for v in [(1, 0), (0, 3), (2, -1), (-3, 4), (7, 5)]:
        ref = _slab_fourier(verts, v)
        got = complex(p.fourier_coefficients(np.array(v)))
        assert abs(got - ref) < 1e-10, (v, got, ref)
    assert complex(p.fourier_coefficients(np.zeros(2, np.int64))) == pytest.approx(p.integral)


def test_polygon_fourier_fact_sheet_values():
    p = I.Polygon(POLYGONS["triangle"])
    v = np.array([[1, 0], [2, 3], [-1, 2], [5, -4]])
    want = np.array([-0.13630 - 0.06404j, -0.00332 - 0.00241j, -0.00569 - 0.03011j,
                     0.00049 + 0.00313j])
    np.testing.assert_allclose(p.fourier_coefficients(v), want, atol=1e-5)


def test_triangle_below_diagonal_three_rays():
    """f = 1[y < x]: F = i/(2 pi k) on (k, 0), -i/(2 pi k) on (0, k) and (k, -k), else 0."""
    f = I.Polygon([(0, 0), (1, 0), (1, 1)])
    ks = np.arange(1, 6)
    z = np.zeros_like(ks)
    np.testing.assert_allclose(f.fourier_coefficients(np.stack([ks, z], -1)),
                               1j / (2 * np.pi * ks), atol=1e-15)
    np.testing.assert_allclose(f.fourier_coefficients(np.stack([z, ks], -1)),
                               -1j / (2 * np.pi * ks), atol=1e-15)
    np.testing.assert_allclose(f.fourier_coefficients(np.stack([ks, -ks], -1)),
                               -1j / (2 * np.pi * ks), atol=1e-15)
    off = np.array([[1, 1], [2, 1], [3, -1], [-2, 5]])
    np.testing.assert_allclose(f.fourier_coefficients(off), 0.0, atol=1e-15)
    # Parseval over the three rays: sum P_f = 1/4 = Var f
    k = np.arange(1, 200001, dtype=np.float64)
    total = 3 * 2 * np.sum(1 / (4 * np.pi**2 * k**2))
    assert total == pytest.approx(0.25, abs=1e-6)


@pytest.mark.parametrize("name", sorted(POLYGONS))
def test_polygon_evaluation_matches_float64_point_in_polygon(name, getkey):
    verts = np.asarray(POLYGONS[name], dtype=np.float64)
    p = I.Polygon(verts)
    x = jax.random.uniform(getkey(), (20000, 2), dtype=jnp.float32)
    got = np.asarray(p(x))
    xs = np.asarray(x, dtype=np.float64)
    want = Path(verts).contains_points(xs).astype(np.float32)
    # ignore points within float32 rounding of an edge
    a, b = verts, np.roll(verts, -1, axis=0)
    e, r = (b - a)[None], xs[:, None] - a[None]
    d = np.min(np.abs(e[..., 0] * r[..., 1] - e[..., 1] * r[..., 0])
               / np.linalg.norm(b - a, axis=1)[None], axis=1)
    far = d > 1e-5
    np.testing.assert_array_equal(got[far], want[far])
    assert got.dtype == np.float32


def test_polygon_shapes_jit_vmap():
    p = I.edges([20.0, 70.0, 130.0])
    x = jnp.full((3, 4, 2), 0.5, dtype=jnp.float32)
    assert p(x).shape == (3, 4)
    assert eqx.filter_jit(p)(x).shape == (3, 4)
    assert jax.vmap(p)(x).shape == (3, 4)
    assert float(p(jnp.array([0.5, 0.5], dtype=jnp.float32))) == 1.0


def test_polygon_rejects_bad_input():
    with pytest.raises(ValueError, match="at least 3 vertices"):
        I.Polygon([(0, 0), (1, 1)])
    with pytest.raises(ValueError, match="simple polygon"):
        I.Polygon([(0, 0), (1, 1), (1, 0), (0, 1)])  # bow tie
    with pytest.raises(ValueError, match="zero area"):
        I.Polygon([(0, 0), (0.5, 0.5), (1, 1)])
    with pytest.raises(ValueError, match="NaN"):
        I.Polygon([(0, 0), (np.nan, 0.5), (1, 1)])
    with pytest.raises(ValueError, match=r"shape \(m, 2\)"):
        I.Polygon(np.zeros((4, 3)))
    with pytest.raises(ValueError, match="x must have shape"):
        I.Polygon(POLYGONS["triangle"])(jnp.zeros((4, 3)))


# --- half-planes and edges() -------------------------------------------------------------------


def test_halfplane_integral_and_directions():
    h = I.HalfPlane(0.0, 0.3)  # 1[x < 0.3]
    assert h.integral == pytest.approx(0.3, abs=1e-15)
    assert h.directions_deg == ()
    h = I.HalfPlane.through((0.5, 0.5), 210.0)  # normal at 210: spectral direction 30
    assert h.directions_deg == (30.0,)
    assert abs(h.integral - 0.5) < 1e-12
    for phi, c in [(30.0, 0.4), (115.0, 0.1), (-60.0, -0.2), (45.0, 2.0), (45.0, -1.0)]:
        h = I.HalfPlane(phi, c)
        n = (math.cos(math.radians(phi)), math.sin(math.radians(phi)))
        big = [np.array([0, 0]) + 5 * np.array([-n[1], n[0]]) + c * np.array(n),
               np.array([0, 0]) - 5 * np.array([-n[1], n[0]]) + c * np.array(n)]
        tri = [big[0], big[1], big[1] - 10 * np.array(n), big[0] - 10 * np.array(n)]
        assert abs(h.integral - _slab_area(tri)) < 1e-12
    # F of 1[x < c]: (1 - e^{-2 pi i k c}) / (2 pi i k) on the axis (fact sheet 4.1)
    h = I.HalfPlane(0.0, 0.3)
    k = np.arange(1, 6)
    want = (1 - np.exp(-2j * np.pi * k * 0.3)) / (2j * np.pi * k)
    np.testing.assert_allclose(h.fourier_coefficients(np.stack([k, 0 * k], -1)), want,
                               atol=1e-15)


@pytest.mark.parametrize("dirs", [(30.0,), (30.0, 120.0), (10.0, 70.0, 140.0),
                                  (25.0, 65.0, 115.0, 160.0), (5.0, 10.0, 15.0)])
def test_edges_expose_their_spectral_directions(dirs, getkey):
    f = I.edges(dirs)
    assert f.directions_deg == tuple(sorted(dirs))
    if len(dirs) > 1:
        # the directions of the edges actually cut inside the square are the requested ones
        got = edge_directions_deg(f.clipped_vertices)
        for d in dirs:
            assert any(abs(d - g) < 1e-6 for g in got), (d, got)
        assert abs(f.integral - _slab_area(f.clipped_vertices)) < 1e-12
    # P_f carries a 1/|v|^2 ray along each direction that lies on the integer lattice
    x = jax.random.uniform(getkey(), (100000, 2), dtype=jnp.float32)
    assert float(jnp.mean(f(x))) == pytest.approx(f.integral, abs=0.01)


def test_edges_ray_of_energy_along_direction():
    """W Sec. 2: the 45-degree edge puts ~ L^2 / (4 pi^2 |v|^2) on the (k, k) ray."""
    f = I.edges([45.0, 135.0])
    k = np.arange(20, 40)
    on_ray = f.power_spectrum(np.stack([k, k], -1))
    off_ray = f.power_spectrum(np.stack([k, k // 2], -1))
    assert np.mean(on_ray * (2 * k**2)) > 20 * np.mean(off_ray * (2 * k**2) + 1e-30)


def test_edges_rejects_bad_input():
    with pytest.raises(ValueError, match="1 to 4"):
        I.edges([10.0, 20.0, 30.0, 40.0, 50.0])
    with pytest.raises(ValueError, match="at least one"):
        I.edges([])
    with pytest.raises(ValueError, match=r"\[0, 180\)"):
        I.edges([190.0])
    with pytest.raises(ValueError, match="repeat"):
        I.edges([30.0, 30.0])
    with pytest.raises(ValueError, match="radius"):
        I.edges([30.0, 60.0], radius=0.6)


# --- disk, smoothed edge, bump, texture ----------------------------------------------------------


def test_disk_fourier_against_many_sided_polygon():
    c, r = (0.45, 0.55), 0.3
    d = I.Disk(c, r)
    m = 4000
    t = 2 * np.pi * (np.arange(m) + 0.5) / m
    # a polygon with the disk's area (radius corrected for the lost segments)
    rp = r * np.sqrt(2 * np.pi / (m * np.sin(2 * np.pi / m)))
    poly = I.Polygon(np.stack([c[0] + rp * np.cos(t), c[1] + rp * np.sin(t)], -1))
    v = np.array([[0, 0], [1, 0], [2, 3], [-4, 1], [7, -6]])
    np.testing.assert_allclose(d.fourier_coefficients(v), poly.fourier_coefficients(v), atol=2e-7)
    assert d.integral == pytest.approx(np.pi * r**2, rel=1e-15)
    assert d.directions_deg == ()
    with pytest.raises(ValueError, match="inside"):
        I.Disk((0.2, 0.5), 0.3)


def _smoothed_edge_reference(f):
    """int Phi((c - s)/sigma) L(s) ds, L(s) = length of {n.x = s} in the square."""
    n = np.array([math.cos(math.radians(f.normal_deg)), math.sin(math.radians(f.normal_deg))])
    corners = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], dtype=np.float64) @ n
    lo, hi = corners.min(), corners.max()

    def length(s):  # chord of the square at level s, by clipping a long segment
        t = np.array([-n[1], n[0]])
        p = s * n
        ts = []
        for d in range(2):
            if abs(t[d]) > 1e-15:
                ts += [(0 - p[d]) / t[d], (1 - p[d]) / t[d]]
        ts = sorted(ts)
        a, b = ts[1], ts[2]  # inner pair of the four slab crossings
        return max(0.0, b - a)

    if abs(n[0]) < 1e-12 or abs(n[1]) < 1e-12:
        def length(s):  # noqa: F811  axis-aligned: constant chord
            return 1.0
    pts = sorted({lo, hi, *corners, min(max(f.offset, lo), hi)})
    total = 0.0
    for a, b in zip(pts[:-1], pts[1:], strict=True):
        if b > a:
            total += scipy.integrate.quad(
                lambda s: scipy.special.ndtr((f.offset - s) / f.sigma) * length(s), a, b,
                epsabs=1e-14, epsrel=1e-13, limit=400, points=None)[0]
    return f.value * total


@pytest.mark.parametrize("phi,offset,sigma", [
    (30.0, 0.6, 2.83 / 2048), (30.0, 0.6, 8.5 / 2048), (100.0, 0.2, 0.05), (-135.0, -0.6, 0.1),
    (0.0, 0.3, 0.01), (90.0, 0.7, 0.2), (0.02, 0.5, 0.01), (89.99, 0.45, 0.003)])
def test_smoothed_edge_integral(phi, offset, sigma):
    f = I.SmoothedEdge(phi, offset, sigma, value=1.5)
    assert abs(f.integral - _smoothed_edge_reference(f)) < 1e-10


def test_smoothed_edge_tends_to_halfplane_and_rejects_sigma():
    h = I.HalfPlane.through((0.5, 0.5), 30.0)
    f = I.SmoothedEdge.through((0.5, 0.5), 30.0, 1e-6)
    assert abs(f.integral - h.integral) < 1e-9
    assert f.directions_deg == (30.0,)
    x = jnp.array([[0.1, 0.1], [0.9, 0.9]], dtype=jnp.float32)
    np.testing.assert_array_equal(np.asarray(f(x)), np.asarray(h(x)))
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="sigma"):
            I.SmoothedEdge(30.0, 0.5, bad)


def test_gaussian_bump_integral_and_second_moment():
    g = I.GaussianBump((0.4, 0.55), 0.12, 2.0)

    def f(y, x):
        return 2.0 * np.exp(-((x - 0.4) ** 2 + (y - 0.55) ** 2) / (2 * 0.12**2))

    ref = scipy.integrate.dblquad(f, 0, 1, 0, 1, epsabs=1e-13, epsrel=1e-12)[0]
    assert abs(g.integral - ref) < 1e-11
    ref2 = scipy.integrate.dblquad(lambda y, x: f(y, x) ** 2, 0, 1, 0, 1, epsabs=1e-13,
                                   epsrel=1e-12)[0]
    assert abs(g.second_moment() - ref2) < 1e-11
    with pytest.raises(ValueError, match="sigma"):
        I.GaussianBump(sigma=0.0)


def test_textured_integral_against_quadrature():
    tex = I.smooth_texture()
    verts = POLYGONS["concave-outside"]
    f = I.Textured(tex, I.Polygon(verts))

    def tex64(x, y):
        out = tex.offset
        for (kx, ky), a, p in zip(tex.freqs, tex.amplitudes, tex.phases, strict=True):
            out += a * np.cos(2 * np.pi * (kx * x + ky * y) + p)
        return out

    def inner(y):
        return sum(scipy.integrate.quad(lambda x: tex64(x, y), lo, hi, epsabs=1e-14)[0]
                   for lo, hi in _chord_intervals(verts, y))

    ys = _breakpoints_y(verts)
    ref = sum(scipy.integrate.quad(inner, a, b, epsabs=1e-13, limit=200)[0]
              for a, b in zip(ys[:-1], ys[1:], strict=True))
    assert abs(f.integral - ref) < 1e-10
    assert f.directions_deg == f.shape.directions_deg
    # the texture alone: integral = offset, values positive
    x = jnp.asarray(np.random.default_rng(0).random((1000, 2)), dtype=jnp.float32)
    assert float(jnp.min(tex(x))) > 0.0
    np.testing.assert_allclose(np.asarray(tex(x)), tex64(*np.asarray(x, np.float64).T), atol=2e-6)
    with pytest.raises(ValueError, match="closed-form"):
        I.Textured(tex, I.SmoothedEdge(30.0, 0.5, 0.01))
    with pytest.raises(ValueError, match="zero frequency"):
        I.Texture([(0, 0)], [0.1])


def test_from_spec_builds_each_kind():
    assert I.from_spec("edges:30,75").directions_deg == (30.0, 75.0)
    assert isinstance(I.from_spec("halfplane:30,0.4"), I.HalfPlane)
    assert I.from_spec("polygon:0.1,0.1,0.9,0.2,0.5,0.8").integral == pytest.approx(0.26)
    assert I.from_spec("disk:0.5,0.5,0.2").integral == pytest.approx(np.pi * 0.04)
    assert isinstance(I.from_spec("bump"), I.GaussianBump)
    assert I.from_spec("smoothed:30,0.001").sigma == 0.001
    assert isinstance(I.from_spec("textured-edges:30"), I.Textured)
    for bad in ("", "edges", "edges:1,2,3,4,5", "polygon:0,0,1", "wave:3", "halfplane:x,y"):
        with pytest.raises(ValueError, match="spec|directions"):
            I.from_spec(bad)


def test_directions_never_list_the_axes():
    assert I.edges([0.0]).directions_deg == ()
    assert I.edges([0.0, 30.0, 90.0]).directions_deg == (30.0,)
    assert I.Polygon([(0.2, 0.2), (0.8, 0.2), (0.8, 0.8), (0.2, 0.8)]).directions_deg == ()


def test_gaussian_bump_fourier_against_quadrature():
    g = I.GaussianBump((0.4, 0.55), 0.12, 2.0)

    def axis(c, k):
        def part(fn):
            return scipy.integrate.quad(
                lambda t: fn(np.exp(-(t - c) ** 2 / (2 * 0.12**2)) * np.exp(-2j * np.pi * k * t)),
                0, 1, epsabs=1e-14, limit=200)[0]
        return part(np.real) + 1j * part(np.imag)

    for v in [(0, 0), (1, 0), (0, 2), (3, -1), (5, 4), (40, 30)]:
        ref = 2.0 * axis(0.4, v[0]) * axis(0.55, v[1])
        assert abs(complex(g.fourier_coefficients(np.array(v))) - ref) < 1e-13
    # far out the coefficients underflow to zero instead of overflowing
    far = I.GaussianBump(sigma=0.01).fourier_coefficients(np.array([[1000, 1000]]))
    assert np.all(np.isfinite(far))


@pytest.mark.parametrize(
    "vertices, inside",
    [
        ([[0, 0], [1, 0], [1, 1], [0, 1]], 1.0),  # covers the square: no edge test left
        ([[-1, -1], [2, -1], [2, 2], [-1, 2]], 1.0),
        ([[2, 2], [3, 2], [2, 3]], 0.0),  # misses the square: empty clipped chain
    ],
)
def test_convex_polygon_without_inner_edges_keeps_the_batch_shape(vertices, inside):
    """f(x) over (..., 2) must return (...): it returned a scalar when no edge cut the square."""
    f = I.Polygon(np.asarray(vertices, np.float64), value=2.0)
    x = jnp.asarray(np.random.default_rng(0).random((3, 5, 2)), jnp.float32)
    out = np.asarray(f(x))
    assert out.shape == (3, 5)
    np.testing.assert_array_equal(out, np.full((3, 5), 2.0 * inside, np.float32))
    assert f.integral == pytest.approx(2.0 * inside)


def test_fourier_coefficients_refuse_infinite_frequencies():
    f = I.HalfPlane(30.0, 0.5)
    with pytest.raises(ValueError, match="v must hold integer frequency vectors"):
        f.fourier_coefficients(np.array([[np.inf, 0.0]]))
    with pytest.raises(ValueError, match="v must hold integer frequency vectors"):
        I.GaussianBump().power_spectrum(np.array([[1.0, -np.inf]]))

"""Spherical triangle and rectangle warps against the fact sheet (references/warps.md 5-6)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import anisosample.warps as W


def _n(v):
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v)


OCTANT = W.SphericalTriangle(np.eye(3), np.zeros(3))


@pytest.mark.parametrize(
    "u,w",
    [
        ((0.5, 0.5), (0.61237244, 0.5, 0.61237244)),
        ((0.25, 0.75), (0.89454251, 0.25, 0.37053164)),
        ((0.9, 0.1), (0.06818820, 0.9, 0.43052337)),
        ((0.0, 1.0), (1, 0, 0)),
        ((1.0, 1.0), (0, 0, 1)),
        ((0.37, 0.0), (0, 1, 0)),
    ],
)
def test_triangle_octant_values(u, w):
    got = OCTANT.sample(jnp.asarray(u, jnp.float32))
    np.testing.assert_allclose(np.asarray(got), w, atol=5e-7)
    np.testing.assert_allclose(float(OCTANT.pdf(got)), 2 / np.pi, rtol=1e-6)


def test_triangle_general_solid_angle():
    tri = np.stack([_n([0.3, 0.1, 1]), _n([-0.5, 0.6, 0.8]), _n([0.2, -0.7, 0.9])])
    np.testing.assert_allclose(
        float(W.SphericalTriangle(tri, np.zeros(3)).solid_angle), 0.3629738415, rtol=1e-6
    )


def _lambert_projected_solid_angle(verts, normal):
    """Closed form (Lambert): 1/2 sum_e theta_e n . N(v_i x v_i+1), for a triangle above n."""
    total = 0.0
    for i in range(3):
        a, b = verts[i], verts[(i + 1) % 3]
        cr = np.cross(a, b)
        total += np.arctan2(np.linalg.norm(cr), a @ b) * (normal @ cr) / np.linalg.norm(cr)
    return abs(total) / 2


def test_cosine_integral_solid_angle_vs_area_sampling():
    """∫ cos over a triangle light: solid-angle sampling vs area sampling vs Lambert (2^20)."""
    p = np.array([0.0, 0.0, 0.0])
    verts = np.array([[-0.4, 0.2, 1.0], [0.9, -0.3, 1.3], [0.2, 0.8, 0.6]])
    normal = _n([0.2, -0.1, 1.0])
    dirs = np.stack([_n(v - p) for v in verts])
    exact = _lambert_projected_solid_angle(dirs, normal)
    n = 2**20
    u = jax.random.uniform(jax.random.key(7), (n, 2), dtype=jnp.float32)
    w, pdf = W.sample_batch(W.SphericalTriangle(verts, p), u)
    est_sa = np.asarray(w, np.float64) @ normal / np.asarray(pdf, np.float64)
    # Area sampling (independent second method): uniform barycentrics, cos cos_l / r^2 * area.
    uu = np.asarray(u, np.float64)
    s = np.sqrt(uu[:, 0])
    pts = (
        (1 - s)[:, None] * verts[0]
        + (s * (1 - uu[:, 1]))[:, None] * verts[1]
        + (s * uu[:, 1])[:, None] * verts[2]
    )
    nl = np.cross(verts[1] - verts[0], verts[2] - verts[0])
    area = np.linalg.norm(nl) / 2
    nl = nl / np.linalg.norm(nl)
    d = pts - p
    r2 = np.sum(d * d, 1)
    dn = d / np.sqrt(r2)[:, None]
    est_area = (dn @ normal) * np.abs(dn @ nl) / r2 * area
    m_sa, m_area = est_sa.mean(), est_area.mean()
    se_area = est_area.std() / np.sqrt(n)
    assert abs(m_sa - exact) / exact < 1e-3, (m_sa, exact)
    assert abs(m_sa - m_area) / exact < 1e-3 + 3 * se_area / exact, (m_sa, m_area, se_area)


@pytest.mark.parametrize(
    "u,xy",
    [
        ((0.5, 0.5), (0.0, 0.0)),
        ((0.25, 0.25), (-0.23064532, -0.23033607)),
        ((0.1, 0.9), (-0.38420363, 0.38518138)),
        ((0.0, 0.0), (-0.5, -0.5)),
        ((1.0, 1.0), (0.5, 0.5)),
    ],
)
def test_rectangle_values(u, xy):
    r = W.SphericalRectangle([-0.5, -0.5, 1.0], [1, 0, 0], [0, 1, 0], [0, 0, 0])
    np.testing.assert_allclose(float(r.solid_angle), 0.8054316832, rtol=1e-6)
    pt = r.sample_point(jnp.asarray(u, jnp.float32))
    np.testing.assert_allclose(np.asarray(pt), [*xy, 1.0], atol=5e-7)
    w = r.sample(jnp.asarray(u, jnp.float32))
    np.testing.assert_allclose(np.asarray(w), _n([*xy, 1.0]), atol=5e-7)
    np.testing.assert_allclose(float(r.pdf(w)), 1 / 0.8054316832, rtol=1e-6)


def test_degenerate_triangles_raise():
    with pytest.raises(ValueError, match="positive solid angle"):
        W.SphericalTriangle([[0, 0, 1], [1, 0, 1], [2, 0, 1]], [0, 0, 0])  # collinear
    with pytest.raises(ValueError, match="positive solid angle"):
        W.SphericalTriangle([[0, 0, 1], [1, 0, 1], [0, 1, 1]], [0.2, 0.2, 1.0])  # in its plane
    with pytest.raises(ValueError, match="vertices must have shape"):
        W.SphericalTriangle(np.eye(2), np.zeros(3))
    with pytest.raises(ValueError, match="finite"):
        W.SphericalTriangle(np.full((3, 3), np.nan), np.zeros(3))


def test_degenerate_rectangles_raise():
    with pytest.raises(ValueError, match="perpendicular"):
        W.SphericalRectangle([0, 0, 1], [1, 0, 0], [1, 1, 0], [0, 0, 0])
    with pytest.raises(ValueError, match="positive solid angle"):
        W.SphericalRectangle([0, 0, 1], [1, 0, 0], [0, 1, 0], [0.5, 0.5, 1.0])
    with pytest.raises(ValueError, match="non-zero"):
        W.SphericalRectangle([0, 0, 1], [0, 0, 0], [0, 1, 0], [0, 0, 0])


def test_traced_degenerate_triangle_has_zero_pdf_not_nan():
    @jax.jit
    def run(verts, origin, u):
        t = W.SphericalTriangle(verts, origin)
        w = t.sample(u)
        return w, t.pdf(w), t.inverse(w)

    flat = jnp.asarray([[0, 0, 1], [1, 0, 1], [0, 1, 1]], jnp.float32)
    w, p, back = run(flat, jnp.asarray([0.2, 0.2, 1.0]), jnp.asarray([0.3, 0.4]))
    assert float(p) == 0.0
    assert np.all(np.isfinite(np.asarray(w))) and np.all(np.isfinite(np.asarray(back)))


def test_small_triangle_round_trip():
    """A 1.4e-4 sr triangle (pbrt-v4 switches to area sampling below 3e-4 sr) stays accurate."""
    tri = np.stack([_n([0.01, 0.0, 1]), _n([0.0, 0.012, 1]), _n([-0.01, -0.005, 1])])
    t = W.SphericalTriangle(tri, np.zeros(3))
    u = jax.random.uniform(jax.random.key(4), (20000, 2))
    x, _ = W.sample_batch(t, u)
    err = np.abs(np.asarray(W.inverse_batch(t, x) - u)).max()
    assert err < 1e-4, err


def test_construct_inside_jit_from_constants():
    """Values derived from constants are tracers inside jit: checks must not concretize them."""
    corner = jnp.asarray([-0.5, -0.4, 1.0], jnp.float32)

    @jax.jit
    def run(o):
        r = W.SphericalRectangle(corner, jnp.asarray([1.0, 0, 0]), jnp.asarray([0, 1.0, 0]), o)
        t = W.SphericalTriangle(jnp.eye(3), o)
        c = W.CosineSphericalTriangle(jnp.eye(3), o, jnp.asarray([0.0, 0.0, 1.0]))
        p = W.BilinearPatch(jnp.asarray(np.arange(12.0).reshape(2, 2, 3) ** 1.5))
        a = W.TriangleArea(jnp.eye(3))
        g = W.Parallelogram(corner, jnp.asarray([1.0, 0, 0]), jnp.asarray([0, 1.0, 0]))
        u = jnp.asarray([0.3, 0.6])
        return [w.pdf(w.sample(u)) for w in (r, t, c, p, a, g)]

    assert all(np.isfinite(float(v)) and float(v) > 0 for v in run(jnp.zeros(3)))


@pytest.mark.parametrize(
    "warp",
    [
        W.SphericalTriangle(
            np.array([[0.3, 0.1, 1], [-0.5, 0.6, 0.8], [0.2, -0.7, 0.9]]), np.zeros(3)
        ),
        W.SphericalRectangle([0.3, -0.2, 0.7], [0.8, 0.6, 0.0], [-0.3, 0.4, 0.5], [0, 0, 0]),
    ],
)
def test_corner_images_equal_sampling_at_the_corners(warp):
    """fit_pointwise's shortcut: the images of the PSS corners without sampling."""
    got = np.asarray(warp.corner_images())
    for i in range(2):
        for j in range(2):
            x = warp.sample(jnp.asarray([i, j], jnp.float32))
            np.testing.assert_allclose(got[i, j], np.asarray(x), atol=2e-6)

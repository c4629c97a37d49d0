"""Bilinear patches in the ray caster (render/patch.py): intersection against a float64 Newton
solver, uv round trips, the area pdf against the Jacobian and the true area, irradiance from
planar patches against closed forms, the XML extension and bad input."""


import jax
import jax.numpy as jnp
import numpy as np
import pytest

import anisosample.render as R
from anisosample import scenes, warps
from anisosample.metrics import midpoint_grid
from anisosample.render import patch as P
from anisosample.render.geometry import intersect
from anisosample.render.lights import light_pdf, sample_light

# H Fig. 3's situation (experiments/h_table4.py): twisted, one short edge p00-p01.
TWISTED = np.array(
    [[[-0.9, 0.2, -0.6], [-0.8, 0.35, -0.45]], [[0.9, 0.05, -0.8], [0.6, 0.55, 0.9]]]
)
SCENE_XML = scenes.path("patch_light")


def _point64(c, u, v):
    u, v = np.asarray(u)[..., None], np.asarray(v)[..., None]
    return (1 - u) * ((1 - v) * c[0, 0] + v * c[0, 1]) + u * ((1 - v) * c[1, 0] + v * c[1, 1])


def _newton_hits(c, o, d):
    """All hits of the ray with the patch by float64 Newton on o + t d = p(u, v) from a 4x4 grid
    of starts (a second method: no quadratic, no elimination); nearest ``(t, u, v)`` or None.
    The 16 starts iterate side by side; one whose Jacobian turns singular stops there."""
    u0, v0 = (a.ravel() for a in np.meshgrid(*[np.array([0.05, 0.35, 0.65, 0.95])] * 2,
                                             indexing="ij"))
    x = np.stack([(_point64(c, u0, v0) - o) @ d, u0, v0], axis=1)  # (16, 3): t, u, v
    going = np.ones(len(x), bool)
    for _ in range(40):
        u, v = x[:, 1:2], x[:, 2:3]
        pu = (1 - v) * (c[1, 0] - c[0, 0]) + v * (c[1, 1] - c[0, 1])
        pv = (1 - u) * (c[0, 1] - c[0, 0]) + u * (c[1, 1] - c[1, 0])
        f = o + x[:, :1] * d - _point64(c, x[:, 1], x[:, 2])
        jac = np.stack([np.broadcast_to(d, pu.shape), -pu, -pv], axis=2)  # columns d, -pu, -pv
        going &= np.abs(np.linalg.det(jac)) >= 1e-14
        if not going.any():
            break
        x[going] -= np.linalg.solve(jac[going], f[going][..., None])[..., 0]
    f = o + x[:, :1] * d - _point64(c, x[:, 1], x[:, 2])
    ok = ((np.linalg.norm(f, axis=1) < 1e-10) & (x[:, 0] > 0)
          & np.all((x[:, 1:] >= 0) & (x[:, 1:] <= 1), axis=1))
    if not ok.any():
        return None
    return x[ok][np.argmin(x[ok, 0])]


def _patch_scene(corners, *, flip=False, radiance=None, floor=False):
    b = R.SceneBuilder()
    if floor:
        b.rectangle(np.diag([4.0, 4.0, 1.0, 1.0]), b.diffuse(0.5))
    b.bilinear_patch(corners, b.diffuse(0.0), radiance=radiance, flip_normals=flip)
    if radiance is None:
        b.point_light((0, 0, 5.0), 1.0)
    from anisosample.render.xml import look_at

    b.camera(look_at(np.array([0, 0, 1.0]), np.zeros(3), np.array([0, 1.0, 0])), width=9,
             height=9, fov=10)
    return b.build()


def test_intersection_matches_newton_on_random_rays():
    rng = np.random.default_rng(3)
    scene = _patch_scene(TWISTED)
    flipped = _patch_scene(TWISTED, flip=True)
    n = 160
    o = rng.normal(size=(n, 3)) * 2.5
    aim = _point64(TWISTED, *rng.uniform(-0.25, 1.25, size=(2, n)))  # about 1/3 miss
    d = aim - o
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    f = jax.jit(jax.vmap(lambda s, oo, dd: intersect(s, oo, dd), in_axes=(None, 0, 0)))
    hits = f(scene, jnp.asarray(o, jnp.float32), jnp.asarray(d, jnp.float32))
    hits_f = f(flipped, jnp.asarray(o, jnp.float32), jnp.asarray(d, jnp.float32))
    hits, hits_f = jax.tree.map(np.asarray, (hits, hits_f))  # read per ray below, not eagerly
    compared = hit_count = 0
    for i in range(n):
        truth = _newton_hits(TWISTED, o[i], d[i])
        if truth is not None:
            t, u, v = truth
            pu = (1 - v) * (TWISTED[1, 0] - TWISTED[0, 0]) + v * (TWISTED[1, 1] - TWISTED[0, 1])
            pv = (1 - u) * (TWISTED[0, 1] - TWISTED[0, 0]) + u * (TWISTED[1, 1] - TWISTED[1, 0])
            nn = np.cross(pu, pv)
            nn /= np.linalg.norm(nn)
            near_edge = min(u, 1 - u, v, 1 - v) < 2e-3
            grazing = abs(np.dot(nn, d[i])) < 0.02
            if near_edge or grazing:
                continue
            hit_count += 1
            assert bool(hits.valid[i]), (i, truth)
            assert float(hits.t[i]) == pytest.approx(t, rel=1e-4), (i, truth)
            np.testing.assert_allclose(np.asarray(hits.uv[i]), [u, v], atol=1e-3)
            np.testing.assert_allclose(np.asarray(hits.n[i]), nn, atol=1e-3)
            # flip_normals swaps u and v: the other side is the front, uv reads (v, u)
            np.testing.assert_allclose(np.asarray(hits_f.n[i]), -nn, atol=1e-3)
            np.testing.assert_allclose(np.asarray(hits_f.uv[i]), [v, u], atol=1e-3)
        else:  # a miss, unless the ray passes within 1e-3 of the boundary (ambiguous)
            m = 400
            g = np.linspace(0, 1, m)
            edge = np.concatenate([_point64(TWISTED, g, 0 * g), _point64(TWISTED, g, 1 + 0 * g),
                                   _point64(TWISTED, 0 * g, g), _point64(TWISTED, 1 + 0 * g, g)])
            r = edge - o[i]
            dist = np.linalg.norm(r - np.outer(r @ d[i], d[i]), axis=1)
            if dist.min() < 1e-3:
                continue
            assert not bool(hits.valid[i]), (i, float(hits.t[i]), np.asarray(hits.uv[i]))
        compared += 1
    assert compared > 0.9 * n and 60 < hit_count < n - 20, (compared, hit_count)


METHODS = ("parametric", "area")


def _sample_patch(c, xi, method, ref=None):
    """The renderer's patch light techniques (light_warps.base_warp): ``(p, uv, pdf)``."""
    seen = P.SeenPatch(c, jnp.zeros(3, jnp.float32) if ref is None else ref)
    if method == "area":
        uv, j = warps.Bilinear(seen.corner_area_elements()).sample_and_pdf(xi)
    else:
        uv, j = xi, jnp.ones((), jnp.float32)
    p, pa = seen.sample_and_pdf(uv)
    return p, uv, j * pa


def test_uv_round_trips():
    c = jnp.asarray(TWISTED, jnp.float32)
    x = jax.random.uniform(jax.random.key(0), (256, 2), jnp.float32)
    ref = jnp.asarray([0.1, -1.2, 0.3], jnp.float32)
    bil = warps.Bilinear(warps.BilinearPatch(c).corner_area_elements())

    @jax.jit
    def chain(xi):
        out = {}
        for method in METHODS:
            p, uv, _ = _sample_patch(c, xi, method)
            back, found = P.uv_towards(c, ref, p)
            out[method] = dict(p=p, uv=uv, back=back, found=found, again=P.patch_point(c, uv),
                               gauss_newton=warps.BilinearPatch(c).inverse(p),
                               x_back=bil.inverse(uv))
        return out

    res = jax.vmap(chain)(x)
    for method, r in res.items():
        assert bool(jnp.all(r["found"]))
        np.testing.assert_allclose(np.asarray(r["again"]), np.asarray(r["p"]), atol=1e-6)
        np.testing.assert_allclose(np.asarray(r["back"]), np.asarray(r["uv"]), atol=2e-4)
        # and through the warps module's own inverses (Gauss-Newton, then the bilinear warp)
        np.testing.assert_allclose(np.asarray(r["gauss_newton"]), np.asarray(r["uv"]), atol=2e-4)
        if method == "area":
            np.testing.assert_allclose(np.asarray(r["x_back"]), np.asarray(x), atol=2e-4)


@pytest.mark.parametrize("method", METHODS)
def test_area_pdf_is_the_inverse_jacobian_and_integrates_to_one(method):
    c = jnp.asarray(TWISTED, jnp.float32)
    x = jax.random.uniform(jax.random.key(1), (4096, 2), jnp.float32, 0.01, 0.99)

    def jac_area(xi):  # |dp/dx0 x dp/dx1| of the map x -> p, by autodiff
        jm = jax.jacfwd(lambda a: _sample_patch(c, a, method)[0])(xi)
        return jnp.linalg.norm(jnp.cross(jm[:, 0], jm[:, 1]))

    pdf, ja = jax.jit(jax.vmap(lambda xi: (_sample_patch(c, xi, method)[2], jac_area(xi))))(x)
    np.testing.assert_allclose(np.asarray(pdf * ja), 1.0, rtol=2e-3)
    # E[1 / pdf] = area (Gauss-Legendre, float64); 4.5 standard errors
    inv = 1.0 / np.asarray(pdf, np.float64)
    area = P.patch_area(TWISTED)
    assert abs(inv.mean() - area) < 4.5 * inv.std(ddof=1) / np.sqrt(inv.size) + 1e-5
    # midpoint rule of pdf(p(u, v)) |p_u x p_v| over [0, 1]^2
    m = 256
    uv = jnp.asarray(midpoint_grid(m, indexing="ij").reshape(-1, 2))
    bil = warps.Bilinear(warps.BilinearPatch(c).corner_area_elements())

    def patch_pdf(a):  # the area pdf at the point with parameters a
        j = bil.pdf(a) if method == "area" else 1.0
        _, ae = P.patch_frame(c, a)
        return j / ae

    dens = jax.jit(jax.vmap(lambda a: patch_pdf(a) * P.patch_frame(c, a)[1]))(uv)
    assert float(jnp.mean(dens)) == pytest.approx(1.0, abs=1e-4)


@pytest.mark.parametrize("technique", ["area", "parametric", "solid_angle"])
def test_light_pdf_matches_the_sampled_pdf(technique):
    # What MIS needs: light_pdf at a sampled point equals the pdf sample_light reported.
    scene = _patch_scene(TWISTED, radiance=5.0)
    x = jax.random.uniform(jax.random.key(2), (512, 2), jnp.float32)
    ref = jnp.asarray([0.2, -1.0, 0.1], jnp.float32)

    def one(xi):
        ls = sample_light(scene, xi, ref, technique)
        return ls.pdf, light_pdf(scene, ls.prim, ls.p, ref, technique)

    a, b = jax.jit(jax.vmap(one))(x)
    np.testing.assert_allclose(np.asarray(b), np.asarray(a), rtol=2e-3)
    assert float(jnp.min(a)) > 0


def _lambert_form_factor(x, nx, verts):
    """Point-to-polygon form factor by Lambert's contour formula (float64)."""
    r = np.asarray(verts, np.float64) - x
    total = 0.0
    for i in range(len(r)):
        a, b = r[i], r[(i + 1) % len(r)]
        cr = np.cross(a, b)
        gamma = np.arctan2(np.linalg.norm(cr), np.dot(a, b))
        total += gamma * np.dot(nx, cr / np.linalg.norm(cr))
    return abs(total) / (2 * np.pi)


@pytest.mark.parametrize("technique", ["area", "parametric"])
def test_planar_patch_irradiance_matches_the_closed_form(technique):
    # A planar convex quad (a trapezoid: not a parallelogram) facing down at z = 1.5 over a
    # Lambertian floor; the pixel at the image centre sees the floor at the origin.
    h, L, rho = 1.5, 10.0, 0.5
    p00, p10, p01, p11 = (-0.3, -0.2, h), (0.5, -0.25, h), (-0.2, 0.3, h), (0.25, 0.4, h)
    corners = np.array([[p01, p00], [p11, p10]])  # [i, j]: p_u x p_v points down
    b = R.SceneBuilder()
    b.rectangle(np.diag([4.0, 4.0, 1.0, 1.0]), b.diffuse(rho))
    b.bilinear_patch(corners, b.diffuse(0.0), radiance=L)
    from anisosample.render.xml import look_at

    b.camera(look_at(np.array([0, 0, 1.0]), np.zeros(3), np.array([0, 1.0, 0])), width=9,
             height=9, fov=10)
    scene = b.build()
    exact = rho * L * _lambert_form_factor(np.zeros(3), np.array([0, 0, 1.0]),
                                           [p00, p10, p11, p01])
    f = R.pixel_integrand(scene, (4, 4), channel="r", technique=technique)
    m = 256  # smooth integrand: the midpoint rule errs by O(1/m^2)
    grid = jnp.asarray(midpoint_grid(m).reshape(-1, 2))
    assert float(jnp.mean(f(grid))) == pytest.approx(exact, rel=1e-3)


def test_default_bilinear_shape_is_the_rectangle(tmp_path):
    # <shape type="bilinear"> without points is Mitsuba's rectangle: same hits, same light
    # samples (the equal-area warp of a rectangle is the identity), so the same image.
    tmpl = (SCENE_XML.read_text().rsplit('<shape type="bilinear">', 1)[0]
            + '<shape type="{kind}"><transform name="to_world"><scale x="0.6" y="0.4"/>'
            '<rotate x="1" angle="80"/><translate y="0.3"/></transform>'
            '<emitter type="area"><rgb name="radiance" value="4"/></emitter></shape></scene>')
    imgs = []
    for kind in ("rectangle", "bilinear"):
        path = tmp_path / f"{kind}.xml"
        path.write_text(tmpl.format(kind=kind))
        scene = R.load_xml(path, width=12, height=12)
        imgs.append(R.render(scene, jax.random.key(5), spp=16, progress=False).mean)
    assert float(np.mean(imgs[0])) > 0.01
    np.testing.assert_allclose(imgs[1], imgs[0], rtol=1e-3, atol=1e-5)


def test_shipped_scene_loads_and_all_techniques_agree():
    scene = R.load_xml(SCENE_XML, width=12, height=12)
    assert scene.has_patches and int(scene.lights.shape[0]) == 4
    assert float(scene.lights.area[0]) == pytest.approx(P.patch_area(TWISTED), rel=1e-6)
    f = R.pixel_integrand(scene, (6, 9), channel="r", technique="parametric")
    g = R.pixel_integrand(scene, (6, 9), channel="r", technique="area")
    m = 256
    grid = jnp.asarray(midpoint_grid(m).reshape(-1, 2))
    a, b = float(jnp.mean(f(grid))), float(jnp.mean(g(grid)))
    assert a > 0.05
    assert b == pytest.approx(a, rel=5e-3)


# --- bad input -------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("corners", "match"),
    [
        (np.zeros((4, 3)), "shape"),
        (np.full((2, 2, 3), np.nan), "finite"),
        (np.array([[[0, 0, 0], [0, 0, 0]], [[1, 0, 0], [1, 1, 0]]]), "coincide"),
        (np.array([[[0, 0, 0], [1, 0, 0]], [[2, 0, 0], [3, 0, 0]]]), "zero area"),
    ],
)
def test_degenerate_patches_are_rejected(corners, match):
    b = R.SceneBuilder()
    with pytest.raises(ValueError, match=match):
        b.bilinear_patch(corners, b.diffuse(0.5), radiance=1.0)


XML_BAD = """<scene version="3.0.0"><integrator type="direct"/>
<sensor type="perspective"><float name="fov" value="40"/>
<film type="hdrfilm"><integer name="width" value="4"/><integer name="height" value="4"/>
<rfilter type="box"/></film></sensor>
<shape type="bilinear">{points}
<emitter type="area">{emission}</emitter></shape></scene>"""


@pytest.mark.parametrize(
    ("points", "emission", "match"),
    [
        ('<point name="p00" x="0" y="0" z="0"/><point name="p10" x="1" y="1" z="1"/>'
         '<point name="p01" x="2" y="2" z="2"/><point name="p11" x="3" y="3" z="3"/>',
         '<rgb name="radiance" value="1"/>', r"s\.xml:\d+: <shape type=\"bilinear\">: degenerate"),
        ('<point name="p22" x="0" y="0" z="0"/>', '<rgb name="radiance" value="1"/>',
         "unsupported property 'p22'"),
        ("", '<texture type="bitmap" name="radiance"><string name="filename" value="a.exr"/>'
         "</texture>", "textured emitters"),
    ],
)
def test_bad_bilinear_xml_names_the_problem(tmp_path, points, emission, match):
    p = tmp_path / "s.xml"
    p.write_text(XML_BAD.format(points=points, emission=emission))
    if "texture" in emission:
        from anisosample import io

        io.write_exr(tmp_path / "a.exr", np.ones((2, 2), np.float32))
    with pytest.raises(R.SceneFormatError, match=match):
        R.load_xml(p)


def test_bad_technique_on_a_patch_scene():
    scene = _patch_scene(TWISTED, radiance=5.0)
    with pytest.raises(ValueError, match="technique must be one of"):
        R.render(scene, jax.random.key(0), spp=1, technique="magic", progress=False)

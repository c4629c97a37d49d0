"""anisosample.render.camera.primary_hits against the geometry of a floor seen from above: every
hit lies on the floor (or on an occluder placed between), along the pixel's own ray, with the
normal facing the camera; pixels that see an emitter are not valid."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import library_errors

import anisosample.render as R
from anisosample import scenes
from anisosample.render.camera import generate_ray, primary_hits
from anisosample.render.xml import look_at

DOWN = look_at(np.array([0, 0, 1.0]), np.zeros(3), np.array([0, 1.0, 0]))  # from z = 1, down


def test_primary_hits_of_a_floor_seen_from_above():
    b = R.SceneBuilder()
    b.rectangle(np.diag([4.0, 4.0, 1.0, 1.0]), b.diffuse(0.5))  # the floor z = 0, normal +z
    occluder = np.diag([0.01, 0.01, 1.0, 1.0])
    occluder[2, 3] = 0.4  # a small square at z = 0.4 under the camera's central pixel
    b.rectangle(occluder, b.diffuse(0.2), flip_normals=True)
    light = np.diag([0.1, 0.1, -1.0, 1.0])
    light[:3, 3] = (0.0, 0.0, 2.0)  # behind the camera: never seen
    b.rectangle(light, b.diffuse(0.0), radiance=1.0)
    b.camera(DOWN, width=9, height=9, fov=10)
    scene = b.build()
    hits = primary_hits(scene)
    w, h = scene.width, scene.height
    assert hits.p.shape == (w * h, 3) and hits.material.shape == (w * h,)
    p, n, wi = (np.asarray(a, np.float64) for a in (hits.p, hits.n, hits.wi))
    cam = np.array([0.0, 0.0, 1.0])
    centre = (h // 2) * w + w // 2
    on_occluder = np.abs(p[:, 2] - 0.4) < 1e-5
    assert on_occluder[centre] and on_occluder.sum() < w * h
    np.testing.assert_allclose(p[~on_occluder, 2], 0.0, atol=1e-6)
    np.testing.assert_allclose(n, np.tile([0.0, 0.0, 1.0], (w * h, 1)), atol=1e-6)
    np.testing.assert_allclose(wi, (cam - p) / np.linalg.norm(cam - p, axis=1, keepdims=True),
                               atol=1e-5)
    assert np.all(np.asarray(hits.valid))
    mats = np.asarray(hits.material)
    assert len(set(mats[on_occluder])) == 1 and len(set(mats[~on_occluder])) == 1
    assert mats[centre] != mats[0]
    # row-major, row 0 at the top: pixel (col, row) is the ray through film ((col+.5)/w, ...)
    for q in (0, 7, 40, w * h - 1):
        film = jnp.asarray([(q % w + 0.5) / w, (q // w + 0.5) / h], jnp.float32)
        _, d = generate_ray(scene.camera, film, jnp.full(2, 0.5, jnp.float32))
        np.testing.assert_allclose(-wi[q], np.asarray(d), atol=1e-6)
    # point symmetry of the view straight down: pixel q and its mirror hit mirrored points
    mirror = w * h - 1 - np.arange(w * h)
    np.testing.assert_allclose(p[:, :2], -p[mirror, :2], atol=1e-6)


def test_pixels_that_see_an_emitter_are_not_valid():
    b = R.SceneBuilder()
    b.rectangle(np.diag([4.0, 4.0, 1.0, 1.0]), b.diffuse(0.5), radiance=1.0)  # an emitting floor
    b.camera(DOWN, width=4, height=4, fov=10)
    assert not np.any(np.asarray(primary_hits(b.build()).valid))


# --- crop: a window of the film (Mitsuba's crop_offset / crop_width) ---------------------------

def _hits(scene):
    return np.asarray(primary_hits(scene).p).reshape(scene.height, scene.width, 3)


@pytest.mark.parametrize("xml", ["cornell.xml", "dof.xml"])
def test_a_crop_sees_what_its_pixels_of_the_whole_image_see(xml):
    """Truth: the whole image's own rays. The crop's pixel centres are the whole image's
    (their film position computed through the window: equal here to the last bit), and a
    crop of a crop is the same window of the same film."""
    full = R.load_xml(scenes.FOLDER / xml, width=48, height=40)
    whole = _hits(full)
    part = R.crop(full, (8, 12), (20, 16))
    assert (part.width, part.height) == (20, 16)
    np.testing.assert_allclose(_hits(part), whole[12:28, 8:28], atol=1e-6)
    inner = R.crop(part, (3, 5), (9, 7))
    np.testing.assert_allclose(_hits(inner), whole[17:24, 11:20], atol=1e-6)
    np.testing.assert_array_equal(R.crop(full, (0, 0), (48, 40)).camera.window,
                                  full.camera.window)


def test_a_crop_renders_the_whole_images_pixel_values():
    """The crop's pixel integrands are those of the same pixels of the whole image (thin lens:
    every lens sample's ray too); its render with and without culling gives the same image (the
    culling's tiles follow the window)."""
    full = R.load_xml(scenes.FOLDER / "dof.xml", width=64, height=64)
    part = R.crop(full, (40, 8), (16, 24))
    x = jax.random.uniform(jax.random.key(3), (256, 2))
    for q in ((0, 0), (15, 23), (7, 11)):
        a = R.pixel_integrand(part, q)(x)
        b = R.pixel_integrand(full, (q[0] + 40, q[1] + 8))(x)
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-5, atol=1e-7)
    key = jax.random.key(0)
    box = R.crop(R.load_xml(scenes.FOLDER / "cornell.xml", width=64, height=64), (40, 40),
                 (24, 24))  # the right box and its shadow: other tiles would cull them
    culled = R.render(box, key, spp=16, progress=False, culling=True)
    plain = R.render(box, key, spp=16, progress=False, culling=False)
    assert box.culling is None and culled.mean.std() > 0
    np.testing.assert_array_equal(culled.mean, plain.mean)


def test_crop_from_the_scene_file_and_bad_crops(tmp_path):
    text = (scenes.FOLDER / "cornell.xml").read_text()
    film = '<film type="hdrfilm">'
    assert film in text
    cropped = text.replace(film, film + '<integer name="crop_offset_x" value="4"/>'
                           '<integer name="crop_offset_y" value="6"/>'
                           '<integer name="crop_width" value="10"/>')
    path = tmp_path / "crop.xml"
    path.write_text(cropped)
    scene = R.load_xml(path, width=32, height=32)
    ref = R.crop(R.load_xml(scenes.FOLDER / "cornell.xml", width=32, height=32), (4, 6),
                 (10, 26))  # Mitsuba's default height: to the film's far edge
    assert (scene.width, scene.height) == (10, 26)
    np.testing.assert_array_equal(scene.camera.window, ref.camera.window)
    path.write_text(text.replace(film, film + '<integer name="crop_width" value="40"/>'))
    with pytest.raises(R.SceneFormatError, match="inside the 32 x 32 image"):
        R.load_xml(path, width=32, height=32)
    full = R.load_xml(scenes.FOLDER / "cornell.xml", width=8, height=8)
    for offset, size in (((-1, 0), (2, 2)), ((0, 0), (0, 2)), ((7, 0), (2, 2)), ((0, 7), (1, 2))):
        with pytest.raises(ValueError, match="must lie inside the 8 x 8 image"):
            R.crop(full, offset, size)
    for offset, size in (((0.5, 0), (2, 2)), ("ab", (2, 2)), ((0, 0), None)):
        with pytest.raises(TypeError, match="offset and size must be pairs of integers"):
            R.crop(full, offset, size)
    with library_errors(), pytest.raises(TypeError, match="scene must be"):
        R.crop("cornell", (0, 0), (1, 1))

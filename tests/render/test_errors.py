"""Bad input gives a clear error naming the location; nothing half-written is left behind."""

import jax
import numpy as np
import pytest
from helpers import library_errors

import anisosample.render as R
from anisosample import cli

from .helpers import SCENES

MINIMAL = """<scene version="3.0.0">
  <integrator type="direct"/>
  <sensor type="perspective">
    <float name="fov" value="40"/>
    <film type="hdrfilm"><integer name="width" value="4"/><integer name="height" value="4"/>
      <rfilter type="box"/></film>
  </sensor>
  {body}
</scene>
"""

LIGHT = """<shape type="rectangle"><transform name="to_world"><translate z="-2"/></transform>
    <emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>"""


def _write(tmp_path, text, name="s.xml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_minimal_scene_loads(tmp_path):
    scene = R.load_xml(_write(tmp_path, MINIMAL.format(body=LIGHT)))
    assert (scene.width, scene.height) == (4, 4)


def test_malformed_xml_names_the_line(tmp_path):
    p = _write(tmp_path, MINIMAL.format(body=LIGHT + "\n<shape type='cube'>"))
    with pytest.raises(R.SceneFormatError, match=r"s\.xml:\d+: malformed XML"):
        R.load_xml(p)


def test_missing_scene_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="no such scene file"):
        R.load_xml(tmp_path / "nope.xml")


def test_missing_obj_file_names_the_tag(tmp_path):
    body = LIGHT + '\n  <shape type="obj"><string name="filename" value="gone.obj"/></shape>'
    with pytest.raises(R.SceneFormatError, match=r":10: <shape type=\"obj\">: file not found"):
        R.load_xml(_write(tmp_path, MINIMAL.format(body=body)))


def test_unsupported_plugin_names_tag_and_line(tmp_path):
    body = LIGHT + '\n  <shape type="ply"/>'
    with pytest.raises(R.SceneFormatError, match=r":10: <shape type=\"ply\">: unsupported shape"):
        R.load_xml(_write(tmp_path, MINIMAL.format(body=body)))


def test_unsupported_property_and_beckmann(tmp_path):
    body = LIGHT + """
  <shape type="cube"><bsdf type="roughconductor"><float name="alpha" value="0.2"/></bsdf></shape>"""
    with pytest.raises(R.SceneFormatError, match="ggx"):
        R.load_xml(_write(tmp_path, MINIMAL.format(body=body)))
    body = LIGHT + '\n  <shape type="cube"><float name="wobble" value="1"/></shape>'
    with pytest.raises(R.SceneFormatError, match="unsupported property 'wobble'"):
        R.load_xml(_write(tmp_path, MINIMAL.format(body=body)))


def test_zero_area_light(tmp_path):
    body = """<shape type="rectangle"><transform name="to_world"><scale x="0" y="1" z="1"/>
    </transform><emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>"""
    with pytest.raises(R.SceneFormatError, match="singular|zero area"):
        R.load_xml(_write(tmp_path, MINIMAL.format(body=body)))


def test_undefined_parameter_and_defaults(tmp_path):
    text = MINIMAL.format(body=LIGHT).replace('value="40"', 'value="$fov"')
    with pytest.raises(R.SceneFormatError, match=r"undefined parameter \$fov"):
        R.load_xml(_write(tmp_path, text))
    assert R.load_xml(_write(tmp_path, text), fov=30).width == 4


def test_film_filters_mitsuba_default_gaussian_and_unsupported(tmp_path):
    """No <rfilter>: Mitsuba's default, the gaussian with stddev 0.5; others are refused."""
    text = MINIMAL.format(body=LIGHT).replace('<rfilter type="box"/>', "")
    cam = R.load_xml(_write(tmp_path, text)).camera
    assert (cam.rfilter, cam.rfilter_stddev) == ("gaussian", 0.5)
    assert R.load_xml(_write(tmp_path, MINIMAL.format(body=LIGHT))).camera.rfilter == "box"
    wide = MINIMAL.format(body=LIGHT).replace(
        '<rfilter type="box"/>',
        '<rfilter type="gaussian"><float name="stddev" value="0.8"/></rfilter>')
    assert R.load_xml(_write(tmp_path, wide)).camera.rfilter_stddev == 0.8
    tent = MINIMAL.format(body=LIGHT).replace('type="box"', 'type="tent"')
    with pytest.raises(R.SceneFormatError, match=r"<rfilter type=\"tent\">: .*box, gaussian"):
        R.load_xml(_write(tmp_path, tent))
    bad = wide.replace('value="0.8"', 'value="-1"')
    with pytest.raises(R.SceneFormatError, match="stddev must be > 0"):
        R.load_xml(_write(tmp_path, bad))


def test_negative_spp_and_bad_options():
    scene = R.load_xml(SCENES / "cornell.xml", width=4, height=4)
    with pytest.raises(ValueError, match="spp must be >= 1"):
        R.render(scene, jax.random.key(0), spp=-1)
    with pytest.raises(ValueError, match="technique"):
        R.render(scene, jax.random.key(0), spp=1, technique="magic")
    with pytest.raises(ValueError, match="chunk_samples must be >= 1"):
        R.render(scene, jax.random.key(0), spp=1, chunk_samples=0)
    with pytest.raises(TypeError, match="chunk_samples"):
        R.render(scene, jax.random.key(0), spp=1, chunk_samples=4096.5)
    with pytest.raises(ValueError, match="thinlens"):
        R.pixel_integrand(scene, (0, 0), dimension="lens")
    with pytest.raises(ValueError, match="pixel"):
        R.pixel_integrand(scene, (4, 0))


def test_default_chunk_follows_the_primitive_count():
    """Brute force over many primitives (200) takes small chunks; the BVH and small scenes large
    ones."""
    assert R.default_chunk_samples(R.load_xml(SCENES / "cornell.xml")) == 65536
    b = R.SceneBuilder()
    m = b.diffuse(0.5)
    n = 200
    v = np.random.default_rng(0).normal(size=(3 * n, 3))  # no degenerate triangle
    b.triangles(v, np.arange(3 * n).reshape(-1, 3), m)
    b.point_light((0, 0, 5), 1.0)
    b.camera(np.eye(4), width=2, height=2)
    assert R.default_chunk_samples(b.build(bvh=False)) == 4096
    assert R.default_chunk_samples(b.build(bvh=True)) == 65536


def test_cli_render_writes_outputs_and_refuses_overwrite(tmp_path, capsys):
    out = tmp_path / "img.exr"
    argv = ["render", str(SCENES / "cornell.xml"), "--spp", "4", "--realizations", "2",
            "--set", "width=4", "--set", "height=4", "-o", str(out)]
    assert cli.main(argv) == 0
    assert out.exists() and (tmp_path / "img_variance.exr").exists()
    assert (tmp_path / "img.png").exists()
    from anisosample import io

    img = io.read_exr(out)
    assert img.shape == (4, 4, 3) and np.all(np.isfinite(img))
    assert cli.main(argv) == 2
    assert "exists" in capsys.readouterr().err


def test_cli_render_errors_leave_nothing(tmp_path, capsys):
    bad = _write(tmp_path, MINIMAL.format(body=LIGHT + '\n  <shape type="ply"/>'))
    out = tmp_path / "img.exr"
    assert cli.main(["render", str(bad), "--spp", "4", "-o", str(out)]) == 2
    assert ":10:" in capsys.readouterr().err
    assert cli.main(["render", str(SCENES / "cornell.xml"), "--spp", "-3", "-o", str(out)]) == 2
    assert list(tmp_path.iterdir()) == [bad]


def test_zero_area_mesh_light(tmp_path):
    (tmp_path / "flat.obj").write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n")
    body = """<shape type="obj"><string name="filename" value="flat.obj"/>
    <emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>"""
    with pytest.raises(R.SceneFormatError,
                       match=r":8: <shape type=\"obj\">: triangle light: face 0 .*zero area"):
        R.load_xml(_write(tmp_path, MINIMAL.format(body=body)))


@pytest.mark.parametrize("counts", ['emitter_samples" value="4', 'bsdf_samples" value="2',
                                    'shading_samples" value="8'])
def test_sample_counts_other_than_one_are_refused(tmp_path, counts):
    """More light/BSDF samples per pixel sample would silently hide the sampler under study."""
    text = MINIMAL.format(body=LIGHT).replace(
        '<integrator type="direct"/>',
        f'<integrator type="direct"><integer name="{counts}"/></integrator>')
    with pytest.raises(R.SceneFormatError, match=r"s\.xml:2: .*emitter_samples must be 1"):
        R.load_xml(_write(tmp_path, text))
    ok = MINIMAL.format(body=LIGHT).replace(
        '<integrator type="direct"/>',
        '<integrator type="direct"><integer name="bsdf_samples" value="0"/></integrator>')
    assert R.load_xml_with_settings(_write(tmp_path, ok, "ok.xml"))[1].mis is False


def test_render_settings_are_the_files_not_the_scenes(tmp_path):
    """The sample count and MIS live in RenderSettings (Mitsuba's defaults: 4 samples,
    bsdf_samples = shading_samples = 1), never in the Scene; render() has its own defaults."""
    plain = _write(tmp_path, MINIMAL.format(body=LIGHT))
    scene, settings = R.load_xml_with_settings(plain)
    assert settings == R.RenderSettings(spp=4, mis=True)
    assert not any(hasattr(scene, a) for a in ("spp", "bsdf_samples", "emitter_samples"))
    text = MINIMAL.format(body=LIGHT).replace(
        '<rfilter type="box"/></film>',
        '<rfilter type="box"/></film><sampler type="independent">'
        '<integer name="sample_count" value="$spp"/></sampler>').replace(
        '<integrator type="direct"/>',
        '<default name="spp" value="7"/><integrator type="direct">'
        '<integer name="bsdf_samples" value="0"/></integrator>')
    path = _write(tmp_path, text, "counted.xml")
    assert R.load_xml_with_settings(path)[1] == R.RenderSettings(spp=7, mis=False)
    assert R.load_xml_with_settings(path, spp=3)[1].spp == 3
    res = R.render(R.load_xml(path), jax.random.key(0), pixel_center=True, progress=False)
    assert res.spp == 64 and res.settings["mis"] is False  # render's defaults, not the file's
    with pytest.raises(TypeError, match="mis must be True or False"), library_errors():
        R.render(scene, jax.random.key(0), spp=1, mis=None, progress=False)

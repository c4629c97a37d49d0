"""Mitsuba 3 scenes as people write them (issue 27, item 5): the default gaussian film, the
``path`` integrator at ``max_depth`` 2, no ``<default>`` parameters; and the shipped scenes as
installed package data (``anisosample.scenes``)."""

import fnmatch
import tomllib
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import library_errors

import anisosample.render as R
from anisosample import cli, io, scenes
from anisosample.render import film

from .helpers import mitsuba_render

# What a Mitsuba 3 user writes: the path tracer (max_depth 2 = direct illumination), a film with
# no rfilter (Mitsuba's default gaussian), literal sizes and sample count, no <default>.
STOCK = """<scene version="3.0.0">
    <integrator type="path">
        <integer name="max_depth" value="2"/>
    </integrator>
    <sensor type="perspective">
        <float name="fov" value="45"/>
        <transform name="to_world">
            <lookat origin="0, 2.5, 3" target="0, 0, 0" up="0, 1, 0"/>
        </transform>
        <sampler type="independent">
            <integer name="sample_count" value="64"/>
        </sampler>
        <film type="hdrfilm">
            <integer name="width" value="640"/>
            <integer name="height" value="480"/>
        </film>
    </sensor>
    <bsdf type="twosided" id="gray">
        <bsdf type="diffuse">
            <rgb name="reflectance" value="0.6, 0.6, 0.6"/>
        </bsdf>
    </bsdf>
    <shape type="rectangle">
        <transform name="to_world">
            <scale value="2"/>
            <rotate x="1" angle="-90"/>
        </transform>
        <ref id="gray"/>
    </shape>
    <shape type="cube">
        <transform name="to_world">
            <scale value="0.35"/>
            <rotate y="1" angle="30"/>
            <translate y="0.35"/>
        </transform>
        <bsdf type="diffuse">
            <rgb name="reflectance" value="0.7, 0.2, 0.2"/>
        </bsdf>
    </shape>
    <shape type="rectangle">
        <transform name="to_world">
            <scale value="0.3"/>
            <rotate x="1" angle="90"/>
            <translate x="0.6" y="1.8" z="0.2"/>
        </transform>
        <emitter type="area">
            <rgb name="radiance" value="20, 18, 15"/>
        </emitter>
    </shape>
</scene>
"""
W, H, SPP, REPS = 8, 6, 256, 8  # the CLI render compared with Mitsuba


@pytest.fixture(scope="module")
def stock(tmp_path_factory):
    """The stock scene rendered by the CLI, resized by --set: (folder, mean, variance)."""
    d = tmp_path_factory.mktemp("stock")
    (d / "stock.xml").write_text(STOCK)
    out = d / "out.exr"
    argv = ["render", str(d / "stock.xml"), "--set", f"width={W}", "--set", f"height={H}",
            "--spp", str(SPP), "--realizations", str(REPS), "--seed", "1", "-o", str(out)]
    assert cli.main(argv) == 0
    return d, io.read_exr(out)[..., :3], io.read_exr(d / "out_variance.exr")[..., :3]


def test_stock_scene_renders_from_the_cli(stock):
    _, mean, var = stock
    assert mean.shape == var.shape == (H, W, 3)
    assert np.all(np.isfinite(mean)) and mean.max() > 0
    scene, settings = R.load_xml_with_settings(stock[0] / "stock.xml")
    assert (scene.camera.rfilter, scene.camera.rfilter_stddev) == ("gaussian", 0.5)
    assert (scene.width, scene.height) == (640, 480)
    assert settings == R.RenderSettings(spp=64, mis=True)  # path at depth 2: direct with MIS


def test_stock_scene_matches_mitsuba_within_monte_carlo_error(stock):
    """Our filter-importance-sampled gaussian film against Mitsuba's splatted one (scalar_rgb);
    Mitsuba's box-filtered image of the same scene is far off by the same measure, so the
    comparison does see the filter."""
    pytest.importorskip("mitsuba")
    d, mean, var = stock
    small = STOCK.replace('value="640"', f'value="{W}"').replace('value="480"', f'value="{H}"')
    (d / "mitsuba.xml").write_text(small)
    (d / "mitsuba_box.xml").write_text(small.replace("</film>", '<rfilter type="box"/></film>'))
    m_spp = 4 * SPP * REPS
    ref = mitsuba_render(d / "mitsuba.xml", m_spp, seed=2)
    # Our mean's variance is var / REPS; Mitsuba's, with 4x the samples, about a quarter of it.
    noise = np.sum(var / REPS * 1.25)
    ratio = np.sum((mean - ref) ** 2) / noise
    assert ratio < 2.0, ratio
    box = mitsuba_render(d / "mitsuba_box.xml", m_spp, seed=2)
    assert np.sum((box - ref) ** 2) / noise > 20.0


@pytest.mark.parametrize("depth", ["3", "-1", None])
def test_path_integrator_other_depths_are_refused(tmp_path, depth):
    if depth is None:  # Mitsuba's default: -1, unlimited
        text = STOCK.replace('\n        <integer name="max_depth" value="2"/>', "")
    else:
        text = STOCK.replace('name="max_depth" value="2"', f'name="max_depth" value="{depth}"')
    p = tmp_path / "deep.xml"
    p.write_text(text)
    with pytest.raises(R.SceneFormatError,
                       match=rf'deep\.xml:2: <integrator type="path">: max_depth {depth or -1}'
                             r".* not supported: .*direct illumination.*max_depth 2"):
        R.load_xml(p)
    assert cli.main(["render", str(p), "-o", str(tmp_path / "x.exr")]) == 2
    assert not (tmp_path / "x.exr").exists()


def test_size_and_sample_count_set_without_defaults(tmp_path):
    p = tmp_path / "stock.xml"
    p.write_text(STOCK)
    scene, settings = R.load_xml_with_settings(p, width=5, height="3", spp=7)
    assert (scene.width, scene.height, settings.spp) == (5, 3, 7)
    assert scene.camera.aspect == pytest.approx(5 / 3)
    with pytest.raises(ValueError, match="override width must be an integer >= 1, got 0"):
        R.load_xml(p, width=0)
    with pytest.raises(ValueError, match="override spp must be an integer >= 1, got 'many'"):
        R.load_xml(p, spp="many")
    with pytest.raises(ValueError, match="unknown parameter override 'fov'"):
        R.load_xml(p, fov=30)
    # A declared parameter still goes through <default> substitution: the shipped scenes'.
    assert R.load_xml(scenes.path("cornell"), width=6, height=2).width == 6


def test_gaussian_table_is_mitsubas():
    """The 31-step table against Mitsuba's own ``eval_discretized`` (scalar variants)."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    ref = mi.load_dict({"type": "gaussian"})
    step = 2.0 / film.FILTER_RESOLUTION
    t = np.concatenate([(np.arange(33) + 0.5) * step, (np.arange(33) + 0.1) * step, [2.5]])
    ours = film.gaussian_filter(t)
    theirs = np.array([ref.eval_discretized(float(x)) for x in t])
    # Mitsuba's exp differs from float64's by up to 8e-4 absolute; the steps are 1e-3 to 6e-2.
    np.testing.assert_allclose(ours, theirs, atol=1e-3)
    assert np.all(film.gaussian_filter(-t) == ours)


@pytest.mark.parametrize("lo, hi", [(-2.0, 2.0), (-0.5, 2.0), (-1.5, 0.5)])
def test_gaussian_offsets_follow_the_filter(lo, hi):
    """Chi-square of sampled offsets against the tabulated filter integrated per bin (float64)
    on [lo, hi]: the film truncation of the edge pixels included."""
    n, bins = 200_000, 16
    u = jax.random.uniform(jax.random.key(3), (n,))
    t = np.asarray(film.sample_gaussian_offset(u, jnp.full(n, lo), jnp.full(n, hi)), np.float64)
    assert t.min() >= lo and t.max() <= hi
    edges = np.linspace(lo, hi, bins + 1)
    fine = np.linspace(lo, hi, 64_001)
    mid = 0.5 * (fine[1:] + fine[:-1])
    mass = np.add.reduceat(film.gaussian_filter(mid), np.arange(0, 64_000, 4000))
    expected = n * mass / mass.sum()
    counts, _ = np.histogram(t, edges)
    chi2 = np.sum((counts - expected) ** 2 / expected)
    assert chi2 < 40.0, chi2  # 15 degrees of freedom: p ~ 5e-4


def test_box_film_is_uniform_in_the_pixel():
    u = jax.random.uniform(jax.random.key(0), (64, 2))
    pos = film.film_offsets("box", 0.5, u, jnp.float32(3), jnp.float32(1), 8, 4)
    np.testing.assert_allclose(np.asarray(pos), np.asarray(u) + [3, 1], rtol=1e-6)
    with pytest.raises(ValueError, match="rfilter must be one of"):
        R.SceneBuilder().camera(np.eye(4), width=2, height=2, rfilter="tent")


def test_shipped_scenes_are_package_data():
    names = scenes.names()
    assert {"cornell", "dof", "blinds", "attic", "patch_light"} <= set(names)
    assert scenes.path("cornell").is_file()
    assert scenes.path("cornell").parent == scenes.FOLDER
    with pytest.raises(ValueError, match="shipped scenes attic, blinds, cornell"):
        scenes.path("kitchen")
    with pytest.raises(ValueError, match=r"without \.xml"):
        scenes.path("cornell.xml")
    with pytest.raises(TypeError, match="scene name"), library_errors():
        scenes.path(Path("cornell"))
    # pyproject's package-data globs cover every file of the folder (so installs carry them)
    root = Path(__file__).resolve().parents[2]
    data = tomllib.loads((root / "pyproject.toml").read_text())
    globs = data["tool"]["setuptools"]["package-data"]["anisosample"]
    files = [p for p in scenes.FOLDER.iterdir() if p.is_file() and p.suffix != ".py"]
    assert files
    for p in files:
        assert any(fnmatch.fnmatch(f"scenes/{p.name}", g) for g in globs), p.name
    for name in names:  # every shipped scene loads (each XML with its meshes and textures)
        assert R.load_xml(scenes.path(name), width=2, height=2).width == 2


def test_shipped_scene_renders_by_name_from_the_cli(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # anywhere: the name resolves to the installed file
    argv = ["render", "cornell", "--set", "width=4", "--set", "height=4", "--spp", "2",
            "-o", "c.exr"]
    assert cli.main(argv) == 0
    img = io.read_exr(tmp_path / "c.exr")
    assert img.shape[:2] == (4, 4) and np.all(np.isfinite(img))

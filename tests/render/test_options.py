"""The integrator's options as one record (render.options, issue 23): validated once, immutable,
resolved per scene; MIS on the lens dimension applied (no bit changes); lookup never builds."""

import dataclasses

import jax
import numpy as np
import pytest

import anisosample.render as R
from anisosample import tables
from anisosample.render import aligned, estimation
from anisosample.render.options import IntegratorOptions

from .helpers import SCENES, plane_under_light


@pytest.mark.library_errors
@pytest.mark.parametrize("field, value, error, match", [
    ("dimension", "aperture", ValueError, r"dimension must be one of \['auto', 'lens', 'light'\]"),
    ("dimension", 3, TypeError, "dimension must be one of"),
    ("technique", "cosine", ValueError, r"technique must be one of \['area', 'parametric'"),
    ("technique", None, TypeError, "technique must be one of"),
    ("light_warp", "bilinear", ValueError, r"light_warp must be one of .*'arvo2001'"),
    ("light_warp", 2, TypeError, r"light_warp must be one of .* or a callable"),
    ("mis", 1, TypeError, "mis must be True or False, got 1"),
    ("mis", None, TypeError, "mis must be True or False"),
    ("pixel_center", "yes", TypeError, "pixel_center must be True or False"),
    ("square_aperture", 0.0, TypeError, "square_aperture must be True or False"),
])
def test_each_field_is_checked_when_made(field, value, error, match):
    with pytest.raises(error, match=match):
        IntegratorOptions(**{field: value})
    with pytest.raises(error, match=match):  # replace makes a new, checked record
        IntegratorOptions().replace(**{field: value})


def test_immutable_hashable_and_normalised():
    o = IntegratorOptions(technique="solid_angle", mis=np.bool_(True), dimension=None)
    assert o.mis is True and o.dimension == "auto"
    with pytest.raises(dataclasses.FrozenInstanceError):
        o.mis = False
    assert hash(o) == hash(IntegratorOptions(technique="solid_angle", mis=True))
    assert o.replace(mis=False) == IntegratorOptions(technique="solid_angle")
    assert o.integrand() == o.replace(mis=False, pixel_center=True)
    assert o.settings() == dict(pixel_center=False, dimension="auto", technique="solid_angle",
                                light_warp="none", mis=True, square_aperture=False)


@pytest.mark.library_errors
def test_for_scene_resolves_and_checks_the_scene():
    plane = plane_under_light()
    dof = R.load_xml(SCENES / "dof.xml", width=8, height=8)
    assert IntegratorOptions().for_scene(plane).dimension == "light"
    assert IntegratorOptions().for_scene(dof).dimension == "lens"
    with pytest.raises(ValueError, match="dimension='lens' needs a thinlens sensor"):
        IntegratorOptions(dimension="lens").for_scene(plane)
    with pytest.raises(ValueError, match="only point lights"):
        IntegratorOptions(light_warp="cosine-bilinear").for_scene(dof)
    with pytest.raises(TypeError, match="scene must be an anisosample.render.Scene"):
        IntegratorOptions().for_scene("cornell.xml")


@pytest.mark.library_errors
def test_record_or_keywords_not_both():
    plane = plane_under_light()
    o = IntegratorOptions(technique="solid_angle")
    f = R.pixel_integrand(plane, (4, 4), options=o)
    assert f.options == o.for_scene(plane).integrand()
    assert f.options == R.pixel_integrand(plane, (4, 4), technique="solid_angle").options
    with pytest.raises(ValueError, match=r"give options= or the keywords \['technique'\]"):
        R.pixel_integrand(plane, (4, 4), options=o, technique="parametric")
    with pytest.raises(ValueError, match=r"the keywords \['mis'\], not both"):
        R.render(plane, jax.random.key(0), spp=1, options=o, mis=True, progress=False)
    with pytest.raises(TypeError, match="options must be a render.IntegratorOptions"):
        R.render(plane, jax.random.key(0), spp=1, options={"mis": True}, progress=False)
    with pytest.raises(ValueError, match="give integrand= or options=, not both"):
        estimation.estimation_grid(plane, 3, 6, integrand=f, options=o)


def test_render_with_the_record_is_the_render_with_keywords():
    plane = plane_under_light()
    kw = dict(technique="solid_angle", mis=True, pixel_center=True)
    a = R.render(plane, jax.random.key(2), spp=4, progress=False, **kw)
    b = R.render(plane, jax.random.key(2), spp=4, progress=False, options=IntegratorOptions(**kw))
    np.testing.assert_array_equal(a.mean, b.mean)
    assert a.settings == b.settings and b.settings["mis"] is True


def test_mis_on_the_lens_dimension_is_applied_and_changes_no_bit():
    """Today's rule (``render`` once dropped ``mis`` off the light dimension silently): MIS
    applies on ``dimension="lens"`` too, the record says so, and since a BSDF sample reaches no
    point light the image is the one without MIS, bit for bit."""
    dof = R.load_xml(SCENES / "dof.xml", width=8, height=8)
    off = R.render(dof, jax.random.key(4), spp=4, progress=False)
    on = R.render(dof, jax.random.key(4), spp=4, mis=True, progress=False)
    assert off.settings["dimension"] == on.settings["dimension"] == "lens"
    assert off.settings["mis"] is False and on.settings["mis"] is True
    np.testing.assert_array_equal(off.mean, on.mean)


def test_block_sampler_keeps_the_estimation_options():
    plane = plane_under_light()
    o = IntegratorOptions(technique="solid_angle", light_warp="cosine-bilinear", mis=True)
    s = aligned.block_sampler(plane, "sheared", block_px=3, samples=18, options=o)
    assert s.options == IntegratorOptions(technique="solid_angle", dimension="light",
                                          pixel_center=True)
    R.render(plane, jax.random.key(0), spp=2, sampler=s, options=o, progress=False)
    with pytest.raises(ValueError, match=r"estimated its directions with .* = \('light', "
                                         r"'solid_angle', False\), the render uses \('light', "
                                         r"'area', False\)"):
        R.render(plane, jax.random.key(0), spp=2, sampler=s, progress=False)


def test_lookup_never_builds_and_ensure_does(tmp_path):
    n = 16
    with pytest.raises(FileNotFoundError, match=r"tables.ensure\(\[\[30\]\], 16"):
        tables.lookup((30,), n, table=tmp_path)
    assert not any(tmp_path.iterdir())  # the lookup wrote nothing
    with pytest.raises(TypeError, match="pure lookup"):
        tables.lookup((30,), n, table=tmp_path, build_missing=True)
    built = tables.ensure([(30,)], n, table=tmp_path, build_missing=True, show_progress=False,
                          steps=4)
    assert built == ["psi_030"]
    pts = np.asarray(tables.lookup((30,), n, table=tmp_path))
    assert pts.shape == (n, 2) and pts.dtype == np.float32
    assert tables.ensure([(30,)], n, table=tmp_path, build_missing=True) == []  # nothing to do


def test_samplers_names_no_module_above_it():
    """``samplers`` finds the aligned sampler through the names table and imports it only on
    first use: listing names imports nothing, and its source names no ``selection``."""
    import subprocess
    import sys
    from pathlib import Path

    import anisosample

    src = (Path(anisosample.__file__).parent / "samplers.py").read_text()
    assert "selection" not in src
    code = ("import sys, anisosample.samplers as s; assert 'aligned' in s.names(); "
            "assert 'anisosample.selection' not in sys.modules; "
            "f = s.get('aligned', directions_deg=30); "
            "assert 'anisosample.selection' in sys.modules and f.directions_deg == (30,)")
    subprocess.run([sys.executable, "-c", code], check=True)
    from anisosample import samplers
    with pytest.raises(ValueError, match="'aligned' is already registered"):
        samplers.register("aligned", lambda **o: None)


def test_table_requests_are_the_distinct_rounded_requests():
    from anisosample import selection

    requests, index = selection.table_requests([(30.4,), (), (0.2,), (29.6, 100.0), (30.0,)],
                                               k=2)
    assert requests == [(30,), (30, 100)]
    assert index.tolist() == [0, -1, -1, 1, 0]
    assert selection.FALLBACK == "pmj02bn"


@pytest.mark.parametrize("k,near,snap", [(1, 0.0, False), (2, 12.0, True), (1, 12.0, True)])
def test_table_requests_of_an_array_are_those_of_the_items(k, near, snap):
    """An ``(items, 2)`` array (NaN: none) gives the requests and indices of its items' finite
    directions given one by one, on random directions that crowd the axes and the rounding
    boundaries (half degrees) and repeat."""
    from anisosample import selection

    rng = np.random.default_rng(11)
    pool = np.concatenate([rng.uniform(0, 180, 40), rng.uniform(-1, 1, 20) % 180,
                           90 + rng.uniform(-1, 1, 20), np.arange(0, 180, 7) + 0.5,
                           [179.5, 0.5, 89.5, 90.5, 12.0, 168.0]])
    d = rng.choice(pool, (600, 2))
    d[rng.random(600) < 0.3, 1] = np.nan
    d[rng.random(600) < 0.1] = np.nan
    items = [tuple(row[np.isfinite(row)]) for row in d]
    expect = selection.table_requests(items, k, near_axis_deg=near, axis_snap=snap)
    got = selection.table_requests(d, k, near_axis_deg=near, axis_snap=snap)
    assert got[0] == expect[0] and len(expect[0]) > 20
    np.testing.assert_array_equal(got[1], expect[1])
    assert (expect[1] == -1).sum() > 10
    with pytest.raises(ValueError, match="directions must be finite degrees or NaN"):
        selection.table_requests(np.array([[np.inf, 1.0]]))


def test_near_axis_directions_yield_to_one_off_the_axes():
    """``near_axis_deg`` reorders only: a direction within it of an axis goes behind the
    others, keeps its place among its group, and is still used when it is all there is."""
    from anisosample import selection

    ts = selection.table_directions
    assert ts((2.2, 114.6), 1) == (2,)  # W's rule: strongest first
    assert ts((2.2, 114.6), 1, near_axis_deg=12) == (115,)
    assert ts((178.4, 60.0), 1, near_axis_deg=12) == (60,)  # 2 degrees from 0 (mod 180)
    assert ts((92.0, 60.0), 1, near_axis_deg=12) == (60,)
    assert ts((20.0, 114.0), 1, near_axis_deg=12) == (20,)  # 20 is past the threshold
    assert ts((12.0, 114.0), 1, near_axis_deg=12) == (114,)  # the threshold is inclusive
    assert ts((2.0, 114.0), 2, near_axis_deg=12) == (114, 2)
    assert ts((3.0, 5.0), 1, near_axis_deg=12) == (3,)
    assert ts((3.0,), 1, near_axis_deg=12) == (3,)
    assert ts((0.3, 3.0), 1, near_axis_deg=12) == (3,)  # onto the axis: dropped as before
    requests, index = selection.table_requests([(2.0, 114.0), (114.0, 2.0), (3.0,)], k=1,
                                               near_axis_deg=12)
    assert requests == [(114,), (3,)]
    assert index.tolist() == [0, 0, 1]
    from anisosample.render import pixel_aligned as PA

    dirs = np.array([[2.0, 114.0], [114.0, 2.0], [3.0, np.nan]])
    requests, index, code = PA.choose_sets(dirs, [2, 2, 1], 1, PA.NEAR_AXIS_DEG)
    assert requests == [(114,), (3,)] and index.tolist() == [0, 0, 1]
    assert PA.choose_sets(dirs, [2, 2, 1], 1)[0] == [(2,), (114,), (3,)]  # W's rule
    assert PA.pixel_sampler(R.load_xml(SCENES / "cornell.xml", width=8, height=8)
                            ).near_axis_deg == PA.NEAR_AXIS_DEG


def test_axis_snap_takes_the_set_one_degree_off_the_axis():
    """``axis_snap``: a direction that rounds onto an axis becomes the integer direction one
    degree off it, on its side of the axis, behind every other direction; W's rule (the
    default) drops it. The per-pixel sampler snaps by default."""
    from anisosample import selection
    from anisosample.render import pixel_aligned as PA

    ts = selection.table_directions
    assert ts((0.3,)) == () and ts((0.3,), axis_snap=True) == (1,)
    assert ts((179.8,), axis_snap=True) == (179,)  # -0.2 degrees: the other side of 0
    assert ts((90.2,), axis_snap=True) == (91,) and ts((89.6,), axis_snap=True) == (89,)
    assert ts((-0.4,), axis_snap=True) == (179,)
    assert ts((0.3, 40.0), 2, axis_snap=True) == (40, 1)  # behind, even when stronger
    assert ts((0.3, 40.0), 1, axis_snap=True) == (40,)
    assert ts((0.3, 1.2), 2, axis_snap=True) == (1,)  # no repeat of a kept direction
    assert ts((0.2, 179.9, 89.8), 2, axis_snap=True) == (1, 179)
    requests, index = selection.table_requests([(0.3,), (30.0,), (90.4,), ()], k=1,
                                               axis_snap=True)
    assert requests == [(1,), (30,), (91,)] and index.tolist() == [0, 1, 2, -1]
    dirs = np.array([[0.3, np.nan], [89.7, 60.0]])
    assert PA.choose_sets(dirs, [1, 2], 1, PA.NEAR_AXIS_DEG, True)[0] == [(1,), (60,)]
    assert PA.choose_sets(dirs, [1, 2], 1, PA.NEAR_AXIS_DEG)[2].tolist() == [5, 3]
    assert PA.pixel_sampler(R.load_xml(SCENES / "cornell.xml", width=8, height=8)).axis_snap

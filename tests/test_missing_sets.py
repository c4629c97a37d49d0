"""One rule for aligned sets no table holds (issue 27, item 4), across every entry point:
``tables.lookup``, ``samplers.get("aligned", ...)`` / ``selection``, ``render(sampler=
"aligned")`` and the CLI's ``points``, ``variance`` and ``render``. By default a missing set is
built on demand into the user cache (with progress); ``build_missing=False`` / ``--no-build``
refuses with ``FileNotFoundError`` naming the exact ``anisosample tables build`` command.

Truth: the calls the builder receives (a stand-in writing random points, where only the
plumbing is under test), the files in a temporary user cache, and the message's command run
as written (with ``--steps 2`` so it stays fast): afterwards the refused lookup finds its set.
Any ``n >= 2`` builds (a real tiny build for n = 100, not a table size).
"""

import shlex
from pathlib import Path

import jax
import numpy as np
import pytest
from helpers import library_errors

from anisosample import _table_build, cli, render, samplers, scenes, selection, tables

CORNELL = scenes.path("cornell")


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """An empty user cache and no $ANISOSAMPLE_TABLES: what is built on demand lands here."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.delenv("ANISOSAMPLE_TABLES", raising=False)
    return tables.cache_dir()


@pytest.fixture
def fake_builder(monkeypatch):
    """Replace the on-demand builder by one that writes random points (recording its calls)."""
    calls = []

    def build_set(n, direction_count, extra, *, out, show_progress=True, **options):
        calls.append(dict(n=n, direction_count=direction_count, extra=tuple(extra), out=Path(out),
                          show_progress=show_progress))
        tab = _table_build.create_table(out, n, direction_count, synthesis={"steps": 1})
        pts = np.random.default_rng(len(calls)).random((n, 2), dtype=np.float32)
        _table_build.write_set(tab, extra, pts)

    monkeypatch.setattr(_table_build, "build_set", build_set)
    return calls


def _command(message: str) -> list[str]:
    """The ``anisosample tables build ...`` command quoted in ``message``, as argv for cli."""
    cmd = message.split("`")[1]
    assert cmd.startswith("anisosample tables build ")
    return shlex.split(cmd)[1:]


def test_points_aligned_builds_any_n_by_default_and_no_build_names_the_command(
        cache, fake_builder, tmp_path, capsys):
    out = tmp_path / "p.npy"
    args = ["points", "aligned", "-n", "1000", "--directions", "0,90,30", "-o", str(out)]
    assert cli.main([*args, "--no-build"]) == 2
    err = capsys.readouterr().err
    assert "`anisosample tables build --n 1000 --direction-count 3 --sets 30`" in err, err
    assert "build_missing=True" not in err.split("(")[0]  # no Python hint as the fix
    assert fake_builder == [] and not out.exists()
    assert cli.main(args) == 0  # the default: built on demand, into the user cache
    assert [(c["n"], c["direction_count"], c["extra"]) for c in fake_builder] == [(1000, 3, (30,))]
    assert fake_builder[0]["out"] == tables.cache_table_path(3, 1000)
    assert fake_builder[0]["show_progress"] is True
    assert np.load(out).shape == (1000, 2)
    # a 4-direction request, too (it failed before whatever the size)
    four = ["points", "aligned", "-n", "64", "--directions", "0,90,30,70", "-o",
            str(tmp_path / "q.npy")]
    assert cli.main([*four, "--no-build"]) == 2
    canon = tables.canonicalize([30, 70], direction_count=4).extra
    assert f"--direction-count 4 --sets {canon[0]}:{canon[1]}`" in capsys.readouterr().err
    assert cli.main(four) == 0
    assert fake_builder[-1]["extra"] == canon and fake_builder[-1]["direction_count"] == 4


def test_variance_aligned_builds_by_default_and_refuses_with_no_build(cache, fake_builder,
                                                                      tmp_path, capsys):
    base = ["variance", "--integrand", "halfplane:30,0.1", "--sampler", "aligned", "--directions",
            "0,90,30", "--n", "16,32", "--realizations", "4"]
    assert cli.main([*base, "--no-build", "-o", str(tmp_path / "a.json")]) == 2
    err = capsys.readouterr().err
    assert "`anisosample tables build --n 16 --direction-count 3 --sets 30`" in err
    assert fake_builder == []
    assert cli.main([*base, "-o", str(tmp_path / "b.json")]) == 0
    assert sorted(c["n"] for c in fake_builder) == [16, 32]


def test_the_no_build_command_builds_exactly_the_refused_set(cache):
    """The command in the message, run as written (fewer steps), makes the refused lookup
    succeed: same table, same canonical set, where lookup looks."""
    with pytest.raises(FileNotFoundError) as info:
        selection.aligned_set((40, 110), 16, build_missing=False)
    argv = _command(str(info.value))
    assert argv[:5] == ["tables", "build", "--n", "16", "--direction-count"] and "--sets" in argv
    assert cli.main([*argv, "--steps", "2", "--no-progress"]) == 0
    pts = selection.aligned_set((40, 110), 16, build_missing=False)
    assert pts.shape == (16, 2)
    tab = tables.open_table(tables.cache_table_path(4, 16))
    assert tab.has(tables.canonicalize((40, 110), direction_count=4).extra)
    assert len(tab.missing()) == 4140


def test_api_default_builds_any_n_with_progress_and_refuses_on_request(cache, capfd):
    """samplers.get("aligned") builds by default (a real tiny build: n = 100 is no table's
    size, 2 steps), with the build's progress bar; build_missing=False refuses, naming the
    command; a bad build_missing is a TypeError before anything runs."""
    s = samplers.get("aligned", directions_deg=[0, 90, 25], steps=2)
    pts = np.asarray(s(jax.random.key(0), 100))
    assert pts.shape == (100, 2) and np.all((pts >= 0) & (pts < 1))
    assert "synthesize n=100" in capfd.readouterr().err
    assert tables.open_table(tables.cache_table_path(3, 100)).has((25,))
    with pytest.raises(FileNotFoundError,
                       match=r"tables build --n 100 --direction-count 3 --sets 35"):
        samplers.get("aligned", directions_deg=[35], build_missing=False)(jax.random.key(0), 100)
    quiet = samplers.get("aligned", directions_deg=[45], steps=2, show_progress=False)
    assert quiet(jax.random.key(1), 100).shape == (100, 2)
    assert capfd.readouterr().err == ""
    with pytest.raises(TypeError, match="build_missing must be None, True or False"), \
            library_errors():
        samplers.get("aligned", directions_deg=[35], build_missing="no")


def test_explicit_table_names_its_directory_in_the_command(tmp_path, cache):
    """An explicit table is not written unasked (build_missing=None); the command builds
    into it (--out), and build_missing=True builds there on demand."""
    root = tmp_path / "mine"
    with pytest.raises(FileNotFoundError) as info:
        tables.ensure([[20]], 8, table=root)
    argv = _command(str(info.value))
    assert argv[-2:] == ["--out", str(root / "d3_n8")]
    assert "build_missing=True" in str(info.value)
    assert tables.installed_sizes(3) == [256, 4096]  # the shipped tables; the cache is empty


def test_render_no_build_refuses_after_the_estimate_with_the_commands(cache, tmp_path, capsys):
    """``render --sampler aligned --no-build`` at an spp no table has: one line naming the
    build commands of the sets the blocks need and the installed sizes; nothing written."""
    out = tmp_path / "x.exr"
    args = ["render", str(CORNELL), "--set", "width=16", "--set", "height=16", "--sampler",
            "aligned", "--block", "8", "--estimation-samples", "48", "--spp", "24",
            "--pixel-center", "--no-build", "-o", str(out)]
    assert cli.main(args) == 2
    err = capsys.readouterr().err
    assert "anisosample tables build --n 24 --direction-count 3 --sets " in err, err
    assert "installed tables' sizes (3-direction n = 256, 4096" in err
    assert not out.exists() and not (cache / "d3_n24").exists()
    scene = render.load_xml(CORNELL, width=16, height=16)
    with pytest.raises(FileNotFoundError, match="--n 24 --direction-count 3"):
        render.render(scene, jax.random.key(0), spp=24, sampler="aligned", pixel_center=True,
                      sampler_options=dict(block_px=8, samples=48, build_missing=False),
                      progress=False)

"""Sharded rendering (``render(..., devices=...)``, ``anisosample render --devices/--processes``):
the image's blocks of pixels dealt out to devices and processes (``jax.distributed``) give the
image one device gives, bit for bit, since a pixel's estimate depends only on its index and the
key."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import jax
import numpy as np
import pytest
from helpers import forced_host_devices, free_port

import anisosample.render as R
from anisosample import cli, io, scenes, synthesis

TWO_DEVICES = forced_host_devices(2)

_SCRIPT = textwrap.dedent("""
    import sys, jax, numpy as np
    import anisosample.render as R
    from anisosample import scenes
    assert len(jax.devices()) == 2, jax.devices()
    cases = {
        "pmj02bn": ("cornell", 20, 18, dict(spp=16, sampler="pmj02bn", realizations=2)),
        "aligned": ("cornell", 16, 16, dict(spp=256, sampler="aligned", pixel_center=True,
                                            sampler_options=dict(block_px=8, samples=48, k=1))),
        "light warp": ("triangle_light", 12, 10, dict(spp=8, sampler="random",
                                                      technique="solid_angle",
                                                      light_warp="cosine-bilinear")),
        "aligned-pixel": ("cornell", 12, 12, dict(spp=64, sampler="aligned-pixel",
                                                  pixel_center=True)),
        # two classes of tiles (with and without the sphere), blocks of 4 and of 1 chunk
        "tile classes": ("dof", 64, 48, dict(spp=256, sampler="pmj02bn", culling=True)),
    }
    def variance_case():  # the variance engine's chunks of realizations over the two devices
        from anisosample import samplers, variance as V
        pixel = R.pixel_integrand(R.load_xml(scenes.path("cornell"), width=64, height=64),
                                  (30, 40))
        fixed = np.asarray(samplers.get("pmj02bn")(jax.random.key(1), 256))
        for sampler, kw in (("pmj02bn", dict(randomization="shift", patterns=2)),
                            ("sobol-owen", {}), ("pmj02", {}), (fixed, {})):
            for reals in (40, 6):  # 7 or 14 chunks of 3 (the last padded); one or two
                one = V.realization_estimates(pixel, sampler, 256, jax.random.key(3), reals,
                                              chunk_elements=256 * 3, **kw)
                two = V.realization_estimates(pixel, sampler, 256, jax.random.key(3), reals,
                                              chunk_elements=256 * 3, devices=jax.devices(),
                                              **kw)
                assert np.array_equal(one, two), (sampler, reals)
        print("same variance", float(one.mean()))

    for name in sys.argv[1].split(","):
        if name == "variance":
            variance_case()
            continue
        sc, w, h, opts = cases[name]
        scene = R.load_xml(scenes.path(sc), width=w, height=h)
        # 3: an odd number of blocks; 64: dof's classes (see test_culling)
        chunks = {"pmj02bn": [None, 3], "tile classes": [64]}.get(name, [None])
        for chunk in chunks:
            one = R.render(scene, jax.random.key(5), progress=False, chunk=chunk, **opts)
            two = R.render(scene, jax.random.key(5), progress=False, chunk=chunk,
                           devices=jax.devices(), **opts)
            assert np.array_equal(one.mean, two.mean), name
            assert (one.variance is None) == (two.variance is None), name
            assert one.variance is None or np.array_equal(one.variance, two.variance), name
            for f in ("pixel_sampler", "pixel_directions", "pixel_estimation_samples"):
                a, b = getattr(one, f), getattr(two, f)
                assert (a is None) == (b is None) and (a is None or np.array_equal(a, b, True)), f
        print("same", name, float(one.mean.mean()))
""")


def _two_devices(cases: str):
    env = dict(os.environ, ANISOSAMPLE_PROGRESS="0", **TWO_DEVICES)
    done = subprocess.run([sys.executable, "-c", _SCRIPT, cases], env=env, capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.count("same ") == len(cases.split(",")), done.stdout


def test_two_devices_give_the_same_bits():
    """Two forced host devices: pmj02bn (with realizations, and with 3-pixel chunks), the
    per-block aligned sampler and a light warp, each equal to the one-device render bit for
    bit; and the variance engine's estimates of a pixel integrand
    (``variance.realization_estimates(..., devices=...)``: shifted patterns, fresh jittable
    and NumPy samplers, a fixed set), its chunks of realizations dealt out to both devices."""
    _two_devices("pmj02bn,aligned,light warp,variance")


@pytest.mark.slow
def test_two_devices_give_the_same_bits_with_classes_of_tiles():
    """dof's two classes of tiles (with and without the sphere), in blocks of four chunks and
    of one, on two forced host devices: the one-device image bit for bit (about 13 s; the
    default suite's ``test_render_with_and_without_culling_agree`` checks the classes on one
    device)."""
    _two_devices("tile classes")


@pytest.mark.slow
def test_two_devices_give_the_same_bits_per_pixel_aligned():
    """The per-pixel aligned sampler's two passes on two forced host devices: the one-device
    image, directions, decisions and estimation counts, bit for bit (about 40 s: its kernels
    compile once per device)."""
    _two_devices("aligned-pixel")


def _render_cli(out, *extra, scene="cornell", size=(18, 14), spp=16):
    return [sys.executable, "-m", "anisosample", "render", scene, "--set", f"width={size[0]}",
            "--set", f"height={size[1]}", "--spp", str(spp), "--sampler", "pmj02bn", "-o",
            str(out), *extra]


def test_two_processes_give_the_same_image(tmp_path):
    """Two processes joined by jax.distributed (a localhost coordinator, as two hosts would be,
    each with its own device; CPU collectives gather the image): process 0 writes the one-process
    image, bit for bit; the other writes nothing."""
    env = dict(os.environ, ANISOSAMPLE_PROGRESS="0")
    scene, _ = R.load_xml_with_settings(scenes.path("cornell"), width=18, height=14)
    one = R.render(scene, jax.random.key(0), spp=16, sampler="pmj02bn", progress=False).mean
    two = tmp_path / "two.exr"
    port = free_port()
    procs = [subprocess.Popen(_render_cli(two, "--distributed", "--coordinator",
                                          f"127.0.0.1:{port}", "--num-processes", "2",
                                          "--process-id", str(p)),
                              env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for p in range(2)]
    outs = [p.communicate(timeout=300) for p in procs]
    for p, (_, err) in zip(procs, outs, strict=True):
        assert p.returncode == 0, err[-3000:]
    assert "wrote" in outs[0][0] and "wrote" not in outs[1][0]
    np.testing.assert_array_equal(io.read_exr(two)[..., :3], one)


@pytest.mark.slow
@pytest.mark.parametrize("scene,size,spp", [("cornell", (18, 14), 16), ("dof", (128, 128), 64)])
def test_local_processes_give_the_same_image(tmp_path, scene, size, spp):
    """``--processes 2``: two local workers, each pinned to a core, started and joined by the
    command itself; one ``wrote`` line and the one-process image, bit for bit. dof at 128^2 x
    64 spp renders in two classes of tiles whose passes mix blocks of four chunks and of one
    (the gather must find each block's process)."""
    if len(synthesis.usable_cpus()) < 2:
        pytest.skip("--processes 2 needs two usable cores")
    if scene == "dof":
        from anisosample.render import culling

        dof = culling.with_culling(R.load_xml(scenes.path("dof"), width=128, height=128))
        assert [c.pixels.size % 4096 for c in culling.tile_classes(dof, 1024)] != [0, 0]
    env = dict(os.environ, ANISOSAMPLE_PROGRESS="0")
    one, local = tmp_path / "one.exr", tmp_path / "local.exr"
    for out, extra in ((one, ()), (local, ("--processes", "2"))):
        done = subprocess.run(_render_cli(out, *extra, scene=scene, size=size, spp=spp),
                              env=env, capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr[-3000:]
        assert done.stdout.count("wrote") == 1, done.stdout
    np.testing.assert_array_equal(io.read_exr(one), io.read_exr(local))


@pytest.mark.parametrize("devices, err, match", [
    ([], ValueError, "devices must hold at least one device"),
    ("cpu", TypeError, r"devices\[0\] must be a jax.Device"),
    (3, TypeError, "devices must be None or a sequence"),
    ([None], TypeError, r"devices\[0\] must be a jax.Device"),
])
def test_bad_devices_are_refused(devices, err, match):
    scene = R.load_xml(scenes.path("cornell"), width=4, height=4)
    with pytest.raises(err, match=match):
        R.render(scene, jax.random.key(0), spp=4, devices=devices, progress=False)


def test_one_device_given_alone_is_refused_and_twice_too():
    scene = R.load_xml(scenes.path("cornell"), width=4, height=4)
    d = jax.devices()[0]
    with pytest.raises(TypeError, match=r"one device .*pass \["):
        R.render(scene, jax.random.key(0), spp=4, devices=d, progress=False)
    with pytest.raises(ValueError, match="devices must be distinct"):
        R.render(scene, jax.random.key(0), spp=4, devices=[d, d], progress=False)


def test_a_list_of_the_one_device_is_the_default_image():
    scene = R.load_xml(scenes.path("cornell"), width=6, height=5)
    a = R.render(scene, jax.random.key(2), spp=4, progress=False)
    b = R.render(scene, jax.random.key(2), spp=4, progress=False, devices=jax.devices())
    np.testing.assert_array_equal(a.mean, b.mean)


@pytest.mark.parametrize("flags, match", [
    (["--devices", "0"], "--devices must be a positive integer or 'all', got '0'"),
    (["--devices", "two"], "--devices must be a positive integer or 'all'"),
    (["--devices", "64"], "--devices 64: this process has 1 local device"),
    (["--devices", "2", "--processes", "2"], "--devices N is for one process"),
    (["--processes", "0"], "--processes must be >= 1"),
    (["--processes", "2", "--distributed"], "--processes starts its own local"),
    (["--coordinator", "127.0.0.1:1"], "need --distributed"),
])
def test_cli_refuses_bad_device_flags(tmp_path, capsys, flags, match):
    code = cli.main(["render", "cornell", "--set", "width=4", "--set", "height=4", "--spp", "4",
                     "-o", str(tmp_path / "x.exr"), *flags])
    assert code == 2
    assert match in capsys.readouterr().err
    assert not (tmp_path / "x.exr").exists()


def test_worker_command_line_drops_processes_in_every_spelling():
    class A:
        processes = 2
    for argv in (["render", "c", "--processes", "2", "-o", "x.exr"],
                 ["render", "c", "--processes=2", "-o", "x.exr"],
                 ["render", "c", "--processe", "2", "-o", "x.exr"]):
        A.argv = argv
        got = cli.render_worker_argv(A, 1, 999)
        assert got == ["render", "c", "-o", "x.exr", "--distributed", "--coordinator",
                       "127.0.0.1:999", "--num-processes", "2", "--process-id", "1"], got

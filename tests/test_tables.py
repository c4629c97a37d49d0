"""Tests for aligned point-set tables (W Sec. 5.4): symmetry reduction, store, lookup, build,
resume, and the aligned sampler.

Truths used: brute-force orbit enumeration (counts 46 and 4,141), the Fourier transform of an
orthogonal map of the torus (``P_{M S}(M v) = P_S(v)``, exact on integer frequencies), measured
spectra of a synthesized set along requested lines, and an uninterrupted build as the reference of
a killed-and-resumed one.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import forced_host_devices, free_port

import anisosample as asp
from anisosample import _table_build, selection, tables
from anisosample.diagnostics import band_energy
from anisosample.spectrum import power_spectrum

ROOT = Path(__file__).resolve().parent.parent

# --- symmetry reduction -------------------------------------------------------------------------


def _orbit_count(direction_count):
    """Brute force, independent of tables.py: union-find over the 8 elements of D4 acting on
    direction vectors (rounded back to integer axial angles)."""
    mats = []
    for r in range(4):
        c, s = [(1, 0), (0, 1), (-1, 0), (0, -1)][r]
        rot = np.array([[c, -s], [s, c]])
        mats += [rot, rot @ np.diag([1, -1])]

    def act(m, a):
        v = m @ np.array([np.cos(np.radians(a)), np.sin(np.radians(a))])
        return int(round(np.degrees(np.arctan2(v[1], v[0])))) % 180

    if direction_count == 3:
        items = [(a,) for a in range(180)]
    else:
        items = [(a, b) for a in range(180) for b in range(a, 180)]
    seen, orbits = set(), 0
    for it in items:
        if it in seen:
            continue
        orbits += 1
        for m in mats:
            seen.add(tuple(sorted(act(m, a) for a in it)))
    return orbits


@pytest.mark.parametrize("direction_count, count", [(3, 46), (4, 4141)])
def test_counts(direction_count, count):
    assert len(tables.canonical_sets(direction_count)) == count
    assert _orbit_count(direction_count) == count


def test_three_direction_rows_of_the_fact_sheet():
    # point_synthesis.md Sec. 6: [0,45] identity, (45,90] 90-phi, (90,135] phi-90, (135,180) 180-phi
    for phi in range(180):
        c = tables.canonicalize([0, 90, phi] if phi not in (0, 90) else [phi])
        if phi <= 45:
            want = phi
        elif phi <= 90:
            want = 90 - phi
        elif phi <= 135:
            want = phi - 90
        else:
            want = 180 - phi
        assert c.extra == (want,), phi
        assert 0 <= c.extra[0] <= 45


def test_canonical_is_constant_on_orbits_and_maps_back():
    rng = np.random.default_rng(0)
    maps = tables.ANGLE_MAPS
    for _ in range(200):
        pair = tuple(int(a) for a in rng.integers(0, 180, 2))
        c = tables.canonicalize(list(set(pair)) if pair[0] != pair[1] else [pair[0]],
                                direction_count=4)
        for g in maps.values():
            img = sorted({g(a) for a in pair})
            assert tables.canonicalize(img, direction_count=4).extra == c.extra
        # the transform carries the canonical set's directions back to the request
        back = {maps[c.transform](a) for a in c.extra} | {0, 90}
        assert back == set(pair) | {0, 90}


def _rotation_of(transform):
    return {"identity": np.eye(2), "mirror": np.diag([1, -1]),
            "swap": np.array([[0, 1], [1, 0]]), "rotate90": np.array([[0, -1], [1, 0]])}[transform]


@pytest.mark.parametrize("transform", tables.TRANSFORMS)
def test_point_transform_moves_the_spectrum(getkey, transform):
    # P_{T(S)}(M v) = P_S(v): the spectrum moves with the points (translations drop out of |.|^2)
    pts = jax.random.uniform(getkey(), (257, 2), dtype=jnp.float32)
    moved = tables.apply_symmetry(pts, transform)
    assert moved.dtype == jnp.float32
    assert float(moved.min()) >= 0 and float(moved.max()) < 1
    v = np.stack(np.meshgrid(np.arange(-6, 7), np.arange(-6, 7)), -1).reshape(-1, 2)
    v = v[np.any(v != 0, axis=1)].astype(np.int32)
    mv = (v @ _rotation_of(transform).T).astype(np.int32)
    a = np.asarray(power_spectrum(pts, v, method="direct"))
    b = np.asarray(power_spectrum(moved, mv, method="direct"))
    np.testing.assert_allclose(b, a, rtol=0, atol=2e-5)


def test_mirror_clamps_below_one():
    pts = jnp.asarray([[0.0, 0.0], [2.0**-30, 0.5]], jnp.float32)
    out = np.asarray(tables.apply_symmetry(pts, "rotate90"))
    assert out.max() < 1.0 and out[0, 0] == 0.0


@pytest.mark.parametrize("bad, err, match", [
    ([0, 90, 30.5], ValueError, "integer degrees"),
    ([0, 180], ValueError, r"\[0, 180\)"),
    ([-1], ValueError, r"\[0, 180\)"),
    ([10, 20, 30], ValueError, "at most two"),
    ([float("nan")], ValueError, r"\[0, 180\)"),
    ("abc", TypeError, "integer angles"),
])
def test_canonicalize_bad_input(bad, err, match):
    with pytest.raises(err, match=match):
        tables.canonicalize(bad)


def test_direction_count_bad_input():
    with pytest.raises(ValueError, match="direction_count must be 3 or 4"):
        tables.canonical_sets(5)
    # the old keyword (docs/design.md, Vocabulary) is refused with the new one's name
    for call in (lambda: tables.canonicalize([10], kind=3),
                 lambda: tables.lookup([10], 64, kind=3),
                 lambda: tables.ensure([[10]], 64, kind=3),
                 lambda: tables.canonical_sets(kind=3),
                 lambda: tables.build(64, kind=3),
                 lambda: tables.find_table(kind=3, n=64),
                 lambda: tables.open_table(".", kind=3)):
        with pytest.raises(TypeError, match=r"takes direction_count= where it took kind="):
            call()
    with pytest.raises(ValueError, match="holds 1 extra"):
        tables.canonicalize([10, 20], direction_count=3)


# --- store and lookup (fake tables: random points, no synthesis) ----------------------------------


def _fake_table(root, n=32, direction_count=3, sets=((0,), (30,)), seed=0):
    tab = _table_build.create_table(Path(root) / tables.table_name(direction_count, n), n,
                                    direction_count, seed=seed, synthesis={"steps": 1})
    rng = np.random.default_rng(seed)
    for e in sets:
        _table_build.write_set(tab, e, rng.random((n, 2), dtype=np.float32))
    return tables.open_table(tab.path)


def test_lookup_applies_the_symmetry(tmp_path):
    tab = _fake_table(tmp_path)
    base = tab.load((30,))
    for phi, tr in [(30, "identity"), (60, "swap"), (120, "rotate90"), (150, "mirror")]:
        got = np.asarray(tables.lookup([0, 90, phi], 32, table=tmp_path))
        np.testing.assert_array_equal(got, np.asarray(tables.apply_symmetry(base, tr)))
    # the table directory itself works as table=, and axes only -> the psi = 0 set
    np.testing.assert_array_equal(np.asarray(tables.lookup([0, 90], 32, table=tab.path)),
                                  tab.load((0,)))


def test_four_direction_lookup(tmp_path):
    tab = _fake_table(tmp_path, direction_count=4, sets=[(10, 110), (0, 30)])
    c = tables.canonicalize([0, 90, 20, 100])
    assert (c.direction_count, c.extra, c.transform) == (4, (10, 110), "rotate90")
    got = np.asarray(tables.lookup([100, 20], 32, table=tmp_path))
    np.testing.assert_array_equal(got, np.asarray(tables.apply_symmetry(tab.load((10, 110)),
                                                                        "rotate90")))
    assert tables.set_directions((0, 30)) == (0, 90, 30)
    assert tables.set_directions((0, 0)) == (0, 90)


def test_lookup_many_and_missing_agree_with_one_by_one(tmp_path):
    """lookup_many is lookup of each request, stacked, bit for bit (every symmetry, both
    direction counts in one call of each); missing lists what lookup would not find, in
    order; a missing set raises lookup's FileNotFoundError."""
    _fake_table(tmp_path)
    _fake_table(tmp_path, direction_count=4, sets=[(10, 110), (0, 30)])
    requests = [(30,), (60,), (120,), (150,), (100, 20), (0, 30), (30,)]
    got = np.asarray(tables.lookup_many(requests, 32, table=tmp_path))
    want = np.stack([np.asarray(tables.lookup(r, 32, table=tmp_path)) for r in requests])
    assert got.dtype == np.float32 and got.shape == (7, 32, 2)
    np.testing.assert_array_equal(got, want)
    host = tables.lookup_many(requests, 32, table=tmp_path, as_numpy=True)
    assert isinstance(host, np.ndarray) and host.dtype == np.float32
    np.testing.assert_array_equal(host, want)
    assert tables.missing(requests, 32, table=tmp_path) == []
    assert tables.missing([(40,), (30,), (20, 100), (5,)], 32, table=tmp_path) == [(40,), (5,)]
    assert tables.missing([(30,)], 64, table=tmp_path) == [(30,)]
    with pytest.raises(FileNotFoundError, match="psi_010"):
        tables.lookup_many([(30,), (10,)], 32, table=tmp_path)
    with pytest.raises(ValueError, match="integer degrees"):
        tables.lookup_many([(30.2,)], 32, table=tmp_path)
    assert tables.lookup_many([], 32, table=tmp_path).shape == (0, 32, 2)


def test_lookup_missing_and_incompatible(tmp_path):
    tab = _fake_table(tmp_path)
    with pytest.raises(FileNotFoundError, match="tables build --n 64 --direction-count 3"):
        tables.lookup([0, 90, 30], 64, table=tmp_path)
    with pytest.raises(ValueError, match="holds sets of n=32 points, asked for n=64"):
        tables.lookup([0, 90, 30], 64, table=tab.path)
    with pytest.raises(FileNotFoundError, match="psi_010"):
        tables.lookup([10], 32, table=tmp_path)
    with pytest.raises(ValueError, match="integer degrees"):
        tables.lookup([30.2], 32, table=tmp_path)
    # another format version is refused
    meta = json.loads((tab.path / "table.json").read_text())
    meta["format_version"] = 99
    (tab.path / "table.json").write_text(json.dumps(meta))
    with pytest.raises(ValueError, match="format version 99"):
        tables.lookup([30], 32, table=tab.path)
    (tab.path / "table.json").write_text("{not json")
    with pytest.raises(ValueError, match="damaged"):
        tables.lookup([30], 32, table=tab.path)


def test_damaged_sets_are_refused(tmp_path):
    tab = _fake_table(tmp_path)
    path = tab.set_path((30,))
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])  # truncated
    with pytest.raises(ValueError, match="damaged"):
        tables.lookup([30], 32, table=tmp_path)
    # altered points with the old metadata: the points checksum catches it
    arrays, meta = asp.io.load_npz(tab.set_path((0,)))
    pts = arrays["points"].copy()
    pts[0, 0] = np.float32(0.123)
    asp.io.save_npz(tab.set_path((0,)), {"points": pts}, meta, overwrite=True)
    with pytest.raises(ValueError, match="points checksum"):
        tables.lookup([0, 90], 32, table=tmp_path)
    # a set of another table (other seed) copied in
    other = _fake_table(tmp_path / "other", seed=1)
    (tab.set_path((0,))).write_bytes(other.set_path((0,)).read_bytes())
    with pytest.raises(ValueError, match="another table"):
        tables.lookup([0, 90], 32, table=tmp_path)


def test_complete_table_checks_file_checksums(tmp_path):
    tab = _fake_table(tmp_path, sets=tables.canonical_sets(3))
    assert _table_build._finalize(tab, tables.canonical_sets(3))
    tab = tables.open_table(tab.path)
    assert tab.complete and len(tab.settings["checksums"]) == 46
    tables.lookup([100], 32, table=tmp_path)
    # rewrite a set with valid content but different bytes: the file checksum refuses it
    arrays, meta = asp.io.load_npz(tab.set_path((10,)))
    asp.io.save_npz(tab.set_path((10,)), arrays, dict(meta, note="edited"), overwrite=True)
    with pytest.raises(ValueError, match="file checksum"):
        tables.lookup([10], 32, table=tmp_path)


def test_build_refuses_other_settings(tmp_path):
    _fake_table(tmp_path)
    with pytest.raises(ValueError, match="other settings"):
        tables.build(32, 3, out=tmp_path / "d3_n32", sets=[(0,)], steps=2)
    with pytest.raises(ValueError, match="canonical extra directions"):
        tables.build(32, 3, out=tmp_path / "x", sets=[(60,)], steps=2)
    with pytest.raises(TypeError, match="unexpected keyword"):
        tables.build(32, 3, out=tmp_path / "x", learning_rat=0.1)


# --- the aligned sampler -------------------------------------------------------------------------


def test_aligned_sampler_given_directions(tmp_path, getkey):
    tab = _fake_table(tmp_path)
    s = asp.samplers.get("aligned", directions_deg=[149.6], table=tmp_path)
    assert s.directions_deg == (150,) and s.canonical.extra == (30,)
    key = getkey()
    pts = np.asarray(s(key, 32))
    assert pts.shape == (32, 2) and pts.dtype == np.float32
    # a toroidal shift of the mirrored canonical set: differences mod 1 are constant
    ref = np.asarray(tables.apply_symmetry(tab.load((30,)), "mirror"))
    d = (pts - ref) % 1.0
    assert np.allclose(np.sin(2 * np.pi * (d - d[0])), 0, atol=1e-5)
    assert not np.array_equal(pts, np.asarray(s(getkey(), 32)))  # decorrelated realizations
    np.testing.assert_array_equal(pts, np.asarray(s(key, 32)))  # same key, same bits
    # two directions: the 4-direction set, and no 4-direction table is an error naming its
    # build (never the 3-direction set of the strongest one in its place)
    two = asp.samplers.get("aligned", directions_deg=[30, 100], table=tmp_path)
    assert two.directions_deg == (30, 100) and two.canonical.direction_count == 4
    with pytest.raises(FileNotFoundError, match="--direction-count 4"):
        two(key, 32)
    four = _fake_table(tmp_path, direction_count=4, sets=[two.canonical.extra])
    d = (np.asarray(two(key, 32)) - np.asarray(tables.apply_symmetry(
        four.load(two.canonical.extra), two.canonical.transform))) % 1.0
    assert np.allclose(np.sin(2 * np.pi * (d - d[0])), 0, atol=1e-5)


def test_aligned_sampler_estimates_and_falls_back(tmp_path, getkey):
    _fake_table(tmp_path, sets=tables.canonical_sets(3))
    th = np.radians(30.0)  # an edge whose normal (spectral direction) is at 30 degrees

    def edge(x):
        return (x[..., 0] * np.float32(np.cos(th)) + x[..., 1] * np.float32(np.sin(th))
                > 0.6).astype(jnp.float32)

    s = asp.samplers.get("aligned", integrand=edge, k=1, table=tmp_path)
    assert len(s.directions_deg) == 1 and abs(s.directions_deg[0] - 30) <= 2, s.estimated_deg
    assert s(getkey(), 32).shape == (32, 2)
    smooth = asp.samplers.get("aligned", integrand=lambda x: x[..., 0] * x[..., 1])
    assert smooth.directions_deg == () and "pmj02bn" in smooth.name
    assert smooth(getkey(), 64).shape == (64, 2)
    axis = asp.samplers.get("aligned", directions_deg=[0, 90])
    assert axis.directions_deg == ()
    with pytest.raises(ValueError, match="exactly one of"):
        asp.samplers.get("aligned")
    with pytest.raises(ValueError, match=r"\[0, 180\)"):
        asp.samplers.get("aligned", directions_deg=[190])


# --- synthesized sets: the symmetry moves the low-energy directions -------------------------------


@pytest.fixture(scope="module")
def synthesized_table(tmp_path_factory):
    shipped = tables.shipped_dir() / "d3_n256"
    if shipped in _shipped():  # the shipped table holds this set already
        return shipped
    out = tmp_path_factory.mktemp("tables") / "d3_n256"
    tables.build(256, 3, out=out, sets=[(30,)], steps=120, checkpoint_every=60,
                 show_progress=False)
    return out


def test_symmetry_moves_low_energy_directions(synthesized_table):
    n = 256
    for phi in (30, 60, 120, 150):
        pts = tables.lookup([0, 90, phi], n, table=synthesized_table)
        on = band_energy(pts, phi)
        # the other members of the orbit are not requested (and not dark, except by accident)
        off = [band_energy(pts, q) for q in (30, 60, 120, 150) if q != phi]
        assert on < 0.1, (phi, on)
        assert on < 0.2 * min(off), (phi, on, off)


# --- build: resumable, sharded over devices -------------------------------------------------------


def _cli(args, env_extra=None):
    env = dict(os.environ, ANISOSAMPLE_PROGRESS="0", **(env_extra or {}))
    return [sys.executable, "-m", "anisosample.cli", "tables", "build", *args], env


def test_build_kill_and_resume_on_two_devices(tmp_path):
    """Kill a 2-device build at a random moment, restart it: same sets as an uninterrupted build."""
    common = ["--n", "64", "--direction-count", "3", "--sets", "0,45", "--steps", "10",
              "--checkpoint-every", "5", "--seed", "3"]
    sets = [(0,), (45,)]
    ref_dir, run_dir = tmp_path / "ref", tmp_path / "run"
    two = forced_host_devices(2)
    cmd, env = _cli([*common, "--out", str(run_dir)], two)
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    # random moment after work began: wait for the table index, then a random extra delay
    rng = np.random.default_rng(int(time.time()))
    t0 = time.time()
    while not (run_dir / "table.json").exists() and proc.poll() is None and time.time() - t0 < 120:
        time.sleep(0.1)
    time.sleep(float(rng.uniform(0.5, 4.0)))
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    finished_before_kill = [e for e in sets if (run_dir / f"{tables.set_name(e)}.npz").exists()]
    cmd, env = _cli([*common, "--out", str(run_dir)], two)
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert "complete=False" in done.stdout  # a 2-set subset of the 46
    assert "on 2 device(s)" in done.stdout
    # the uninterrupted reference, in this process on one device
    tables.build(64, 3, out=ref_dir, sets=sets, steps=10, checkpoint_every=5, seed=3,
                 show_progress=False)
    a, b = tables.open_table(ref_dir), tables.open_table(run_dir)
    assert a.settings["fingerprint"] == b.settings["fingerprint"]
    for e in sets:
        np.testing.assert_array_equal(a.load(e), b.load(e))
    devices = {asp.io.load_npz(b.set_path(e))[1]["device"] for e in sets}
    if not finished_before_kill:  # both sets built side by side by the resumed run
        assert len(devices) == 2, devices
    # a rerun builds nothing
    again = tables.build(64, 3, out=run_dir, sets=sets, steps=10, checkpoint_every=5, seed=3,
                         show_progress=False)
    assert again["built"] == [] and len(again["skipped"]) == 2


def test_batched_build_shards_groups_over_two_devices(tmp_path):
    """batch 2 on two (forced CPU) devices: one synthesize_batch loop per group, its sets split
    over the 2 devices (one thread each); the sets equal the one-device batched build bit for
    bit (each set runs the same per-set program wherever it runs)."""
    common = ["--n", "64", "--direction-count", "3", "--sets", "10,20,30", "--steps", "8",
              "--batch", "2", "--seed", "1"]
    run_dir, ref_dir = tmp_path / "two", tmp_path / "one"
    cmd, env = _cli([*common, "--out", str(run_dir)],
                    forced_host_devices(2))
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert "on 2 device(s)" in done.stdout
    tables.build(64, 3, out=ref_dir, sets=[(10,), (20,), (30,)], steps=8, batch=2, seed=1,
                 show_progress=False)
    a, b = tables.open_table(ref_dir), tables.open_table(run_dir)
    assert a.settings["fingerprint"] == b.settings["fingerprint"]
    for e in [(10,), (20,), (30,)]:
        meta = asp.io.load_npz(b.set_path(e))[1]
        assert meta["device"].count("cpu") == 2, meta["device"]  # the group ran on both
        np.testing.assert_array_equal(a.load(e), b.load(e))
    # the group (10, 20) and the padded group (30,) are different sets
    assert not np.array_equal(b.load((10,)), b.load((30,)))


@pytest.mark.parametrize("direction_count", [3, 4])
def test_build_over_two_processes_with_jax_distributed(tmp_path, direction_count):
    """Two processes joined by jax.distributed (a localhost coordinator, as two hosts would be)
    share one --out: process p builds the sets i with i % 2 == p, and every set equals the
    single-process build. 3 directions: two hosts' commands (--distributed ... --process-id p);
    4 directions: the 4,141-set table's one command on one machine, ``--processes 2`` (two
    local workers pinned to a core each, where the machine has two)."""
    sets = "0,10,20,45" if direction_count == 3 else "0:0,10:20,20:50,30:45"
    extras = ([(0,), (10,), (20,), (45,)] if direction_count == 3
              else [(0, 0), (10, 20), (20, 50), (30, 45)])
    run_dir, ref_dir = tmp_path / "two_hosts", tmp_path / "one_host"
    common = ["--n", "32", "--direction-count", str(direction_count), "--sets", sets,
              "--steps", "6", "--seed", "2", "--out", str(run_dir)]
    if direction_count == 3:
        common += ["--distributed", "--coordinator", f"127.0.0.1:{free_port()}",
                   "--num-processes", "2"]
        procs = []
        for pid in range(2):
            cmd, env = _cli([*common, "--process-id", str(pid)])
            procs.append(subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE,
                                          stderr=subprocess.PIPE, text=True))
        outs = [p.communicate(timeout=300) for p in procs]
        for p, (_, err) in zip(procs, outs, strict=True):
            assert p.returncode == 0, err
        built = [o.split("built ")[1].split(" set")[0] for o, _ in outs]
    else:
        if asp.synthesis.usable_cores() < 2:
            pytest.skip("--processes 2 needs two usable cores")
        cmd, env = _cli([*common, "--processes", "2"])
        done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr
        assert "2 local processes done; 4/4141 sets" in done.stdout, done.stdout
        built = [o.split(" set")[0] for o in done.stdout.split("built ")[1:]]
    assert built == ["2", "2"], built  # 4 sets, 2 per process
    tables.build(32, direction_count, out=ref_dir, sets=extras, steps=6, seed=2,
                 show_progress=False)
    a, b = tables.open_table(ref_dir), tables.open_table(run_dir)
    for e in extras:
        np.testing.assert_array_equal(a.load(e), b.load(e))


def _children(pid: int) -> set[int]:
    out = set()
    for task in Path(f"/proc/{pid}/task").glob("*"):
        text = (task / "children").read_text() if (task / "children").exists() else ""
        out |= {int(c) for c in text.split()}
    return out


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
@pytest.mark.parametrize("signal_name", ["SIGTERM", "SIGKILL"])
def test_stopped_build_leaves_no_workers(tmp_path, signal_name):
    """`tables build --processes 2` stopped while its workers synthesize: SIGTERM (the parent
    stops them, SIGKILL where jax.distributed's preemption notice catches SIGTERM) or SIGKILL
    of the parent itself (the kernel kills the workers: PR_SET_PDEATHSIG) leaves no worker."""
    import signal
    import time

    if asp.synthesis.usable_cores() < 2:
        pytest.skip("--processes 2 needs two usable cores")
    cmd, env = _cli(["--n", "256", "--direction-count", "3", "--sets", "10,20,30,40",
                     "--steps", "100000", "--out", str(tmp_path / "t"), "--processes", "2"])
    parent = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.time() + 120
        while len(_children(parent.pid)) < 2 and time.time() < deadline:
            time.sleep(0.2)
        workers = _children(parent.pid)
        assert len(workers) == 2, "the workers did not start"
        time.sleep(3)  # let them reach jax.distributed and the synthesis
        parent.send_signal(getattr(signal, signal_name))
        parent.wait(timeout=60)
        deadline = time.time() + 30
        while any(Path(f"/proc/{w}").exists() and "Z" not in _state(w) for w in workers) \
                and time.time() < deadline:
            time.sleep(0.2)
        alive = [w for w in workers if Path(f"/proc/{w}").exists() and "Z" not in _state(w)]
        assert not alive, f"workers {alive} outlived the stopped build ({signal_name})"
    finally:
        if parent.poll() is None:
            parent.kill()


def _state(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(") ")[1].split()[0]
    except (OSError, IndexError):
        return "Z"


def test_cli_tables_info_and_errors(tmp_path, capsys):
    from anisosample.cli import main

    tab = _fake_table(tmp_path)
    assert main(["tables", "info", str(tab.path)]) == 0
    assert "2/46 sets" in capsys.readouterr().out
    assert main(["tables", "build", "--n", "32", "--out", str(tab.path), "--sets", "7,x"]) == 2
    assert "--sets must look like" in capsys.readouterr().err


# --- the shipped table: W Sec. 5.4's promise on 20 random requests --------------------------------


def _shipped():
    root = tables.shipped_dir()
    found = sorted(root.glob("d3_n*/table.json")) if root.exists() else []
    # a table still being built (make tables) is not shipped yet; prefix and sequence tables
    # (d3_n64_dihedral-16, d3_n4096_seq256) have their own tests
    return [p.parent for p in found if json.loads(p.read_text()).get("complete")
            and re.fullmatch(r"d3_n\d+", p.parent.name)]


@pytest.mark.skipif(not _shipped(), reason="no shipped table")
def test_shipped_table_is_dark_along_requested_directions():
    path = _shipped()[-1]
    tab = tables.open_table(path)
    assert tab.complete
    rng = np.random.default_rng(8)
    ratios = []
    for phi in rng.integers(0, 180, 20):
        pts = tables.lookup([0, 90, int(phi)], tab.n)
        ratios += [band_energy(pts, d) for d in sorted({0, 90, int(phi)})]
    assert np.mean(ratios) < 0.1, ratios
    assert max(ratios) < 0.2, ratios


@pytest.mark.slow  # two compilations of the batched loop: ~45 s on a busy 2-core machine
def test_batched_build_redoes_a_group_identically(tmp_path):
    # batch 2: one synthesize_batch loop for the group [(10,), (20,)]; a lost set redoes the group
    out = tmp_path / "t"
    first = tables.build(64, 3, out=out, sets=[(10,), (20,)], batch=2, steps=10,
                         show_progress=False)
    assert first["built"] == ["psi_010", "psi_020"]
    tab = tables.open_table(out)
    assert tab.settings["synthesis"]["batch"] == 2
    a, b = tab.load((10,)), tab.load((20,))
    assert not np.array_equal(a, b)
    tab.set_path((20,)).unlink()
    again = tables.build(64, 3, out=out, sets=[(10,), (20,)], batch=2, steps=10,
                         show_progress=False)
    assert again["built"] == ["psi_010", "psi_020"]
    np.testing.assert_array_equal(tab.load((10,)), a)
    np.testing.assert_array_equal(tab.load((20,)), b)
    with pytest.raises(ValueError, match="other settings"):  # batch is part of the settings
        tables.build(64, 3, out=out, sets=[(10,)], steps=10, show_progress=False)


def test_aligned_fallback_must_be_an_option_free_baseline():
    """'sheared' and 'aligned' are registered names too, but need options: as a fallback they
    failed only when the sampler was built, with a message about another parameter."""
    for name in ("sheared", "aligned"):
        with pytest.raises(ValueError, match="fallback must be one of"):
            selection.aligned_sampler(directions_deg=[0.0], fallback=name)
    s = selection.aligned_sampler(directions_deg=[0.0], fallback="sobol-owen")
    assert s.directions_deg == () and s(jax.random.key(0), 16).shape == (16, 2)


# --- every set on demand --------------------------------------------------------------------------


@pytest.fixture
def user_cache(tmp_path, monkeypatch):
    """An empty user cache (no $ANISOSAMPLE_TABLES): what lookup builds goes here."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.delenv("ANISOSAMPLE_TABLES", raising=False)
    return tables.cache_dir()


def test_ensure_builds_a_missing_set_into_the_user_cache(user_cache, capsys):
    """A 4-direction set no table holds: the pure lookup refuses, naming ensure; ensure
    synthesizes it (default: build) into the user cache, where lookup finds it; nothing is
    rebuilt next time; build_missing=False and an explicit table refuse."""
    n = 64
    with pytest.raises(FileNotFoundError, match=r"tables\.ensure\(\[\[20, 50\]\], 64\)"):
        tables.lookup([0, 90, 20, 50], n)
    assert tables.ensure([[0, 90, 20, 50]], n, steps=8) == ["psi_020_050"]
    pts = np.asarray(tables.lookup([0, 90, 20, 50], n))
    path = user_cache / "d4_n64"
    tab = tables.open_table(path)
    assert tab.has((20, 50)) and not tab.complete and len(tab.missing()) == 4140
    assert tab.settings["synthesis"]["steps"] == 8
    assert "synthesize n=64" in capsys.readouterr().err  # the progress bar of the one set
    # found in the cache now: same bytes, nothing rebuilt (the set file is not rewritten)
    mtime = tab.set_path((20, 50)).stat().st_mtime_ns
    assert tables.ensure([[50, 20]], n, steps=8) == []
    again = np.asarray(tables.lookup([50, 20], n))
    assert again.tobytes() == pts.tobytes()
    assert tab.set_path((20, 50)).stat().st_mtime_ns == mtime
    # the same points as synthesize with the table's key for that canonical index
    i = tables.canonical_sets(4).index((20, 50))
    want = asp.synthesize(jax.random.fold_in(jax.random.key(0), i), n, (0, 90, 20, 50),
                          steps=8, show_progress=False)
    assert np.asarray(want.points).tobytes() == pts.tobytes()
    with pytest.raises(FileNotFoundError, match="psi_010_070"):
        tables.ensure([[10, 70]], n, build_missing=False)
    with pytest.raises(FileNotFoundError, match="psi_010_070"):
        tables.ensure([[10, 70]], n, table=path)  # an explicit table is not written unasked
    with pytest.raises(TypeError, match="build_missing"):
        tables.ensure([[10, 70]], n, build_missing="yes")
    with pytest.raises(TypeError, match="pure lookup and takes no"):
        tables.lookup([10, 70], n, build_missing=True)


def test_on_demand_four_direction_set_is_warm_started_from_the_shipped_table(user_cache):
    """A new 4-direction table for n = 256 starts each set (a, b) from the shipped 3-direction
    set for a (WARM_STEPS steps at WARM_LEARNING_RATE), recorded in its settings."""
    src = _table_build.warm_source(256)
    if src is None:
        pytest.skip("no complete 3-direction table for n = 256")
    start = _table_build.warm_points(256, (20, 50), src.settings["fingerprint"])
    np.testing.assert_array_equal(start, np.asarray(tables.lookup([20], 256)))
    tables.ensure([[20, 50]], 256, steps=4, show_progress=False)
    pts = np.asarray(tables.lookup([20, 50], 256))
    tab = tables.open_table(user_cache / "d4_n256")
    warm = tab.settings["synthesis"]["warm_start"]
    assert warm["fingerprint"] == src.settings["fingerprint"]
    assert tab.settings["synthesis"]["learning_rate"] == _table_build.WARM_LEARNING_RATE
    # 4 Adam steps of at most lr / sqrt(n) = 0.0125 each from the warm start (on the torus)
    d = np.abs(pts - start)
    assert np.max(np.minimum(d, 1 - d)) <= 4 * 0.2 / 16 + 1e-6
    assert np.asarray(tables.lookup([20, 50], 256)).tobytes() == pts.tobytes()


def test_four_direction_tables_run_single_precision_and_old_tables_keep_theirs(tmp_path):
    """A new 4-direction table records nufft_precision 'single' (FOUR_DIRECTION_PRECISION) in
    its settings; a table made before the option existed (no such field) is finished with its
    own settings, not refused; a 3-direction table stays in double precision."""
    new = tmp_path / "new"
    tables.build(32, 4, out=new, sets=[(0, 0)], steps=2, show_progress=False)
    assert tables.open_table(new).settings["synthesis"]["nufft_precision"] == "single"
    old = tmp_path / "old"
    _table_build.create_table(old, 32, 4, synthesis={"steps": 2})
    tables.build(32, 4, out=old, sets=[(10, 20)], steps=2, show_progress=False)
    tab = tables.open_table(old)
    assert "nufft_precision" not in tab.settings["synthesis"]
    assert tab.has((10, 20))
    three = tmp_path / "three"
    tables.build(32, 3, out=three, sets=[(10,)], steps=2, show_progress=False)
    assert "nufft_precision" not in tables.open_table(three).settings["synthesis"]


def test_deleted_set_makes_a_table_incomplete(tmp_path):
    """issue 17: a complete table with a set file deleted is not reported complete."""
    tab = _fake_table(tmp_path, sets=tables.canonical_sets(3))
    assert _table_build._finalize(tab, tables.canonical_sets(3))
    tab = tables.open_table(tab.path)
    assert tab.complete and tab.missing() == []
    tab.set_path((30,)).unlink()
    assert not tab.complete and tab.missing() == [(30,)]


@pytest.mark.slow  # 20 sets synthesized on demand at n = 4096: minutes on 2 cores
def test_twenty_random_four_direction_sets_on_demand_are_dark(user_cache):
    """issue 16: 20 random 4-direction sets looked up with default arguments have energy
    <= 0.1 of white within one unit of every requested line (axes included) for |v| <= 32."""
    rng = np.random.default_rng(16)
    worst = []
    for _ in range(20):
        a, b = rng.choice([x for x in range(1, 180) if x != 90], 2, replace=False)
        tables.ensure([[0, 90, int(a), int(b)]], 4096, show_progress=False)
        pts = tables.lookup([0, 90, int(a), int(b)], 4096)
        worst.append(max(band_energy(pts, d) for d in (0, 90, int(a), int(b))))
    assert max(worst) <= 0.1, worst


def test_four_direction_tables_below_the_axis_weight_keep_their_fingerprint(tmp_path):
    """The axes' weight (frequencies.AXIS_WEIGHT_4) acts only from ROBUST_MIN_N points, so a
    4-direction table below that size built before it existed (tests/data: the settings of the
    experiments' d4_n256_dihedral-32, 612 sets, built 2026-12-06) is still resumed: its settings
    file alone, in a new folder, is accepted by a build (no set synthesized), where the
    4-direction probe had refused it and so every per-pixel render that needed a new corner
    set at 256 spp. A table from ROBUST_MIN_N points of the design before is still refused (the
    committed experiment table d4_n1024)."""
    from anisosample import frequencies

    four = (0.0, 90.0, 47.0, 148.0)
    below = frequencies.ROBUST_MIN_N // 4
    assert np.array_equal(frequencies.design(below, four).weights,
                          frequencies.design(below, four, axis_weight=1.0).weights)
    here = Path(__file__).resolve().parent
    old = {"d4_n256_dihedral-32": here / "data" / "d4_n256_dihedral-32_table.json",
           "d4_n1024": here.parent / "results" / "w_render_tables" / "d4_n1024" / "table.json"}
    for name, n, refused in (("d4_n256_dihedral-32", 256, False), ("d4_n1024", 1024, True)):
        out = tmp_path / name
        out.mkdir()
        settings = json.loads(old[name].read_text())
        (out / "table.json").write_text(json.dumps(settings))
        call = dict(out=out, sets=[], show_progress=False, **settings["synthesis"])
        if refused:
            with pytest.raises(ValueError, match="frequency_design_at_n1024"):
                tables.build(n, 4, **call)
        else:
            assert tables.build(n, 4, **call)["built"] == []

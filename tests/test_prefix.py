"""Fixed isotropic prefixes (W Sec. 7, issue 22 item 1): the named prefixes, sets that start with
them bit for bit (single, batched, resumed), and tables whose every served set starts with them
whatever its directions' symmetry transform."""

import json

import jax
import numpy as np
import pytest

import anisosample as asp
from anisosample import frequencies, synthesis, tables
from anisosample import prefix as P

SMALL = dict(steps=20, method="direct", show_progress=False)


@pytest.mark.parametrize("m", [8, 16, 32, 64])
def test_dihedral_prefix_is_a_symmetric_dyadic_set(m):
    pts = P.dihedral_points(m)
    assert pts.shape == (m, 2) and pts.dtype == np.float32
    assert len({tuple(p) for p in pts.tolist()}) == m  # m distinct points
    assert np.all((pts >= 0) & (pts < 1))
    # coordinates on the 2^-16 grid: (-t) mod 1 and t + 1/2 mod 1 are exact in float32
    np.testing.assert_array_equal(np.round(pts * 2**16), pts * 2**16)
    assert P.is_symmetric(pts)
    # every table transform, then its shift, maps the set onto itself (checked here directly)
    own = {tuple(p) for p in pts.tolist()}
    for t in tables.TRANSFORMS:
        moved = np.mod(tables.transform_points(pts, t) + np.float32(P.TABLE_SHIFTS[t]), 1)
        assert {tuple(p) for p in moved.astype(np.float32).tolist()} == own
    # glide reflections keep the axis projections apart: m different x and y coordinates
    assert len(set(pts[:, 0].tolist())) == m and len(set(pts[:, 1].tolist())) == m


@pytest.mark.parametrize("m", [8, 16, 32])
def test_shipped_dihedral_prefixes_are_what_the_design_makes(m):
    np.testing.assert_array_equal(P.design_dihedral(m), P.dihedral_points(m))


def test_dihedral_prefix_beats_the_pmj02bn_head_on_edges():
    """The design minimizes W Eq. 5's variance of an edge of any orientation; measured by
    toroidal shifts on edges at orientations it was not designed on, it is below the first 32
    points of pmj02bn (a (0,2)-sequence head, the issue's suggestion)."""
    angles = [7.0 + 15.0 * i for i in range(12)]

    def mean_variance(pts):  # a fixed set: the variance engine randomizes it by shifts
        return np.mean([asp.variance.estimator_variance(
            asp.integrands.edges([t]), pts, 32, jax.random.key(7), 512,
            asp.integrands.edges([t]).integral) for t in angles])

    assert mean_variance(P.dihedral_points(32)) < mean_variance(P.prefix_points("pmj02bn-32"))


def test_pmj_prefix_is_the_head_of_pmj02bn_and_not_symmetric():
    pts = P.prefix_points("pmj02bn-32")
    ref = np.asarray(asp.samplers.get("pmj02bn")(jax.random.key(P.PMJ_KEY), 256))[:32]
    np.testing.assert_array_equal(pts, ref)
    assert not P.is_symmetric(pts)


def test_prefix_specs_are_validated():
    assert P.prefix_size("none") == 0 and P.prefix_size("dihedral-32") == 32
    assert P.prefix_points("none").shape == (0, 2)
    for bad in ("dihedral-12", "dihedral-0", "pmj02bn-0", "pmj02bn-x", "sobol-16", "", "32",
                "pmj02bn-016"):
        with pytest.raises(ValueError, match="prefix"):
            P.check_prefix("prefix", bad)
    with pytest.raises(TypeError, match="prefix"):
        P.check_prefix("prefix", 32)
    with pytest.raises(ValueError, match="explicit"):
        P.prefix_points(P.explicit_prefix_name(np.full((4, 2), 0.5, np.float32)))


def test_place_and_align_prefix():
    rng = np.random.default_rng(0)
    x = rng.uniform(size=(64, 2))
    pre = P.dihedral_points(8).astype(np.float64)
    out = P.place_prefix(x, pre)
    assert out.shape == x.shape
    np.testing.assert_array_equal(out[:8], pre)
    # the removed points are, one per prefix point, the nearest still present
    kept = {tuple(p) for p in out[8:].tolist()}
    assert len(kept) == 56 and kept <= {tuple(p) for p in x.tolist()}
    # a set already starting with the prefix is left alone
    np.testing.assert_array_equal(P.place_prefix(out, pre), out)
    shuffled = np.concatenate([pre[::-1], out[8:]]).astype(np.float32)
    np.testing.assert_array_equal(P.align_prefix(shuffled, pre)[:8], pre.astype(np.float32))
    with pytest.raises(ValueError, match="prefix"):
        P.align_prefix(x.astype(np.float32), pre)


@pytest.mark.parametrize("spec", ["dihedral-16", "pmj02bn-16", "explicit"])
def test_synthesize_keeps_the_prefix_bit_for_bit(getkey, spec):
    n = 64
    if spec == "explicit":
        prefix = np.asarray(jax.random.uniform(jax.random.key(3), (16, 2)), np.float32)
    else:
        prefix = spec
    r = asp.synthesize(getkey(), n, (0, 90, 30), prefix=prefix, **SMALL)
    want = prefix if spec == "explicit" else P.prefix_points(spec)
    assert np.asarray(r.points)[:16].tobytes() == want.tobytes()
    assert r.recipe.prefix.endswith("-16")
    assert r.history[-1] < r.history[0]  # the free points still optimize the whole set
    if spec == "explicit":
        assert r.recipe.prefix == P.explicit_prefix_name(prefix)


def test_prefix_is_part_of_the_record_only_when_there_is_one():
    assert "prefix" not in synthesis.make_recipe().record()
    rec = synthesis.make_recipe(prefix="dihedral-32").record()
    assert rec["prefix"] == "dihedral-32"
    assert rec["prefix_sha256"] == tables.points_checksum(P.dihedral_points(32))


def test_prefix_bad_sizes_are_refused(getkey):
    with pytest.raises(ValueError, match="n/4"):
        asp.synthesize(getkey(), 64, (0, 90, 30), prefix="dihedral-24", **SMALL)
    with pytest.raises(ValueError, match="prefix"):
        asp.synthesize(getkey(), 64, (0, 90, 30), prefix=np.full((4, 3), 0.5), **SMALL)
    with pytest.raises(ValueError, match="prefix"):
        asp.synthesize(getkey(), 64, (0, 90, 30), prefix=np.full((4, 2), 1.5), **SMALL)


def test_batch_with_prefix_equals_single_runs(getkey):
    key, n, dirs = getkey(), 64, [(0, 90, 30), (0, 90, 61)]
    batch = asp.synthesis.synthesize_batch(key, n, dirs, prefix="dihedral-8", **SMALL)
    keys = jax.random.split(key, 2)
    for b in range(2):
        single = asp.synthesize(keys[b], n, dirs[b], prefix="dihedral-8", **SMALL)
        assert np.asarray(batch.points[b]).tobytes() == np.asarray(single.points).tobytes()
        assert np.array_equal(np.asarray(batch.points[b])[:8], P.dihedral_points(8))


class _Killed(Exception):
    pass


def test_killed_prefix_run_resumes_to_the_same_bits(getkey, tmp_path):
    key, n, dirs = getkey(), 64, (0, 90, 30)
    opts = dict(SMALL, checkpoint_every=5, prefix="dihedral-16")
    full = asp.synthesize(key, n, dirs, **opts)
    ck = tmp_path / "ck.npz"

    def kill(step, _):
        if step >= 10:
            raise _Killed

    with pytest.raises(_Killed):
        asp.synthesize(key, n, dirs, checkpoint=ck, callback=kill, **opts)
    resumed = asp.synthesize(key, n, dirs, checkpoint=ck, **opts)
    assert np.asarray(resumed.points).tobytes() == np.asarray(full.points).tobytes()
    # a checkpoint of a run without the prefix is refused, not reused
    with pytest.raises(_Killed):
        asp.synthesize(key, n, dirs, checkpoint=ck, callback=kill, **opts)
    with pytest.raises(ValueError, match="other settings"):
        asp.synthesize(key, n, dirs, checkpoint=ck, **dict(opts, prefix=None))


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.delenv("ANISOSAMPLE_TABLES", raising=False)
    return tmp_path / "cache" / "anisosample" / "tables"


def test_prefixed_table_serves_the_prefix_for_every_transform(cache):
    pre = P.dihedral_points(16)
    seen = set()
    # one request per symmetry transform of the canonical set psi_030
    for dirs in ([0, 90, 30], [0, 90, 150], [0, 90, 60], [0, 90, 120]):
        seen.add(tables.canonicalize(dirs).transform)
        tables.ensure([dirs], 128, prefix="dihedral-16", show_progress=False, steps=10,
                      method="direct")
        pts = np.asarray(tables.lookup(dirs, 128, prefix="dihedral-16"))
        assert pts[:16].tobytes() == pre.tobytes()
        # the rest is the canonical set under that transform: the same multiset of points
        canon = np.asarray(tables.lookup([0, 90, 30], 128, prefix="dihedral-16"))
        t = tables.canonicalize(dirs).transform
        moved = np.mod(tables.transform_points(canon, t) + np.float32(P.TABLE_SHIFTS[t]), 1)
        moved = np.minimum(moved, np.float32(1 - 2**-24)).astype(np.float32)
        assert sorted(map(tuple, moved.tolist())) == sorted(map(tuple, pts.tolist()))
    assert seen == set(tables.TRANSFORMS)
    assert (cache / "d3_n128_dihedral-16" / "psi_030.npz").exists()
    # the table records its prefix; asking it for another prefix is refused
    tab = tables.open_table(cache / "d3_n128_dihedral-16")
    assert tables.table_prefix(tab) == "dihedral-16"
    with pytest.raises(ValueError, match="prefix"):
        tables.lookup([0, 90, 30], 128, table=cache / "d3_n128_dihedral-16",
                      prefix="dihedral-8")


def test_a_second_set_with_build_options_joins_the_prefixed_table(cache):
    # the options given must match the existing table's, its prefix included
    for extra in (30, 40):
        tables.ensure([[0, 90, extra]], 128, prefix="dihedral-16", show_progress=False,
                      steps=10, method="direct")
        pts = np.asarray(tables.lookup([0, 90, extra], 128, prefix="dihedral-16"))
        assert pts[:16].tobytes() == P.dihedral_points(16).tobytes()
    assert {p.name for p in (cache / "d3_n128_dihedral-16").glob("psi_*.npz")} == {
        "psi_030.npz", "psi_040.npz"}
    with pytest.raises(ValueError, match="other settings"):  # options that do not match
        tables.ensure([[0, 90, 20]], 128, prefix="dihedral-16", show_progress=False,
                      steps=11, method="direct")


def test_tables_refuse_an_asymmetric_prefix(cache):
    with pytest.raises(ValueError, match="symmetric"):
        tables.lookup([0, 90, 30], 64, prefix="pmj02bn-16")
    with pytest.raises(ValueError, match="symmetric"):
        tables.build(64, 3, prefix="pmj02bn-16", sets=[(30,)], show_progress=False)
    assert tables.build_command(3, 64, [(30,)], prefix="dihedral-16").endswith(
        "--sets 30 --prefix dihedral-16")


# --- progressive sequences (issue 22 item 2) ---------------------------------------------------


def test_sequence_levels():
    assert synthesis.sequence_levels(4096, 256) == [256, 512, 1024, 2048, 4096]
    assert synthesis.sequence_levels(1000, 256) == [256, 512, 1000]
    assert synthesis.sequence_levels(64, 0) == [64]
    with pytest.raises(ValueError, match="sequence_from"):
        synthesis.make_recipe(sequence_from=48)
    with pytest.raises(ValueError, match="sequence_weights"):
        synthesis.make_recipe(sequence_from=16, sequence_weights="heavy")
    assert "sequence_from" not in synthesis.make_recipe().record()
    rec = synthesis.make_recipe(sequence_from=16).record()
    assert rec["sequence_from"] == 16 and rec["sequence_weights"] == "equal"


def test_sequence_objective_sums_the_nested_prefixes_losses():
    """The sequence's loss is sum_k L_{n_k}(x[:n_k]) (equal weights): each nested prefix scored
    by the plain set loss of its size, computed independently here."""
    from anisosample import frequencies, losses

    x = np.asarray(asp.samplers.get("pmj02bn")(jax.random.key(4), 64), np.float64)
    dirs = (0.0, 90.0, 30.0)
    rec = synthesis.make_recipe(sequence_from=16, method="direct")
    total = synthesis.loss_value(x, frequencies.design(64, dirs, "rate"), dirs, rec)
    with jax.enable_x64(True):
        want = sum(float(losses.linear_spectrum_loss(x[:nk], frequencies.design(nk, dirs, "rate"),
                                                     method="direct"))
                   for nk in (16, 32, 64))
    np.testing.assert_allclose(total, want, rtol=1e-9)


def test_explicit_sequence_weights_weigh_each_nested_prefix():
    """Explicit weights (one per nested prefix, smallest first): all ones is "equal" bit for bit,
    ``n_k / N`` is "size", and any other vector scales each prefix's term by its own weight."""
    from anisosample import frequencies

    dirs, key = (0.0, 90.0, 30.0), jax.random.key(3)
    opts = dict(steps=6, method="direct", show_progress=False)
    equal = synthesis.synthesize_sequence(key, 64, dirs, sequence_from=16, **opts)
    ones = synthesis.synthesize_sequence(key, 64, dirs, sequence_from=16,
                                         sequence_weights=[1, 1, 1], **opts)
    np.testing.assert_array_equal(np.asarray(equal.points), np.asarray(ones.points))
    size = synthesis.synthesize_sequence(key, 64, dirs, sequence_from=16,
                                         sequence_weights="size", **opts)
    quarter = synthesis.synthesize_sequence(key, 64, dirs, sequence_from=16,
                                            sequence_weights=(0.25, 0.5, 1.0), **opts)
    np.testing.assert_array_equal(np.asarray(size.points), np.asarray(quarter.points))
    assert ones.recipe.record()["sequence_weights"] == [1.0, 1.0, 1.0]
    assert equal.recipe.learning_rate == synthesis.SEQUENCE_LEARNING_RATE
    assert equal.recipe.steps == 6

    from anisosample import losses

    x = np.asarray(asp.samplers.get("pmj02bn")(jax.random.key(4), 64), np.float64)
    w = (2.0, 0.5, 3.0)
    rec = synthesis.make_recipe(sequence_from=16, method="direct", sequence_weights=w)
    total = synthesis.loss_value(x, frequencies.design(64, dirs, "rate"), dirs, rec)
    with jax.enable_x64(True):
        want = sum(wk * float(losses.linear_spectrum_loss(
            x[:nk], frequencies.design(nk, dirs, "rate"), method="direct"))
            for wk, nk in zip(w, (16, 32, 64), strict=True))
    np.testing.assert_allclose(total, want, rtol=1e-9)


@pytest.mark.library_errors
@pytest.mark.parametrize(("weights", "error", "match"), [
    ((1.0, 1.0), ValueError, r"one weight per nested prefix \[16, 32, 64\].*got 2"),
    ((1.0, 0.0, 1.0), ValueError, "positive, finite weight per nested prefix"),
    ((1.0, float("nan"), 1.0), ValueError, "positive, finite"),
    (3, TypeError, "sequence_weights must be a name"),
    (("a", "b", "c"), TypeError, "sequence_weights must be a name"),
])
def test_bad_sequence_weights_are_refused(weights, error, match):
    with pytest.raises(error, match=match):
        synthesis.synthesize_sequence(jax.random.key(0), 64, (0, 90, 30), sequence_from=16,
                                      sequence_weights=weights, steps=1, show_progress=False)


def test_sequence_with_prefix_resumes_to_the_same_bits(getkey, tmp_path):
    key = getkey()
    opts = dict(steps=12, method="direct", show_progress=False, checkpoint_every=4,
                prefix="dihedral-8", sequence_from=32)
    full = synthesis.synthesize_sequence(key, 128, (0, 90, 30), **opts)
    pts = np.asarray(full.points)
    assert pts.shape == (128, 2)
    assert pts[:8].tobytes() == P.dihedral_points(8).tobytes()
    ck = tmp_path / "seq.ckpt.npz"

    def kill(step, _):
        if step >= 8:
            raise _Killed

    with pytest.raises(_Killed):
        synthesis.synthesize_sequence(key, 128, (0, 90, 30), checkpoint=ck, callback=kill,
                                      **opts)
    resumed = synthesis.synthesize_sequence(key, 128, (0, 90, 30), checkpoint=ck, **opts)
    assert np.asarray(resumed.points).tobytes() == pts.tobytes()
    with pytest.raises(ValueError, match="sequence_from"):
        synthesis.synthesize_sequence(key, 128, (0, 90, 30), sequence_from=256)


def test_aligned_sequence_sampler_serves_nested_prefixes_of_one_sequence(cache):
    """samplers.get('aligned-sequence'): the first n points of one table sequence (3 and 4
    directions, with a prefix), one toroidal shift per key; n past the length refused."""
    opts = dict(length=64, sequence_from=16, steps=5, method="direct", show_progress=False,
                prefix="dihedral-8")
    for dirs in ([150], [30, 100]):
        s = asp.samplers.get("aligned-sequence", directions_deg=dirs, **opts)
        full = np.asarray(s.fn(None, 64))
        assert np.asarray(s.fn(None, 32)).tobytes() == full[:32].tobytes()
        assert full[:8].tobytes() == P.dihedral_points(8).tobytes()
        key = jax.random.key(3)
        np.testing.assert_array_equal(np.asarray(s(key, 40)),
                                      np.asarray(asp.samplers.toroidal_shift(key, full[:40])))
        with pytest.raises(ValueError, match="length"):
            s(key, 65)
    names = sorted(p.name for p in cache.iterdir())
    assert names == ["d3_n64_seq16_dihedral-8", "d4_n64_seq16_dihedral-8"]
    tab = tables.open_table(cache / names[0])
    assert tables.table_sequence_from(tab) == 16


def test_a_new_sequence_table_takes_the_sequence_defaults_and_an_old_one_keeps_its_own(cache):
    """A sequence table built anew records SEQUENCE_LEARNING_RATE, SEQUENCE_FREQUENCY_OPTIONS
    (and the steps asked for), as the shipped d3_n4096_seq256 does; a table whose settings name
    no learning rate (sequence tables built before the sequence defaults) is finished with the
    recipe's, 0.5: its new sets are those of a table built with learning_rate=0.5."""
    opts = dict(sequence_from=16, steps=3, method="direct", show_progress=False)
    out = cache / "seq"
    tables.build(64, 3, out=out, sets=[(30,)], **opts)
    synth = tables.open_table(out).settings["synthesis"]
    assert synth["learning_rate"] == synthesis.SEQUENCE_LEARNING_RATE and synth["steps"] == 3
    assert synth["frequency_options"] == synthesis.SEQUENCE_FREQUENCY_OPTIONS
    shipped = tables.open_table(tables.shipped_dir() / "d3_n4096_seq256").settings
    assert shipped["synthesis"]["learning_rate"] == synthesis.SEQUENCE_LEARNING_RATE
    assert shipped["synthesis"]["steps"] == synthesis.SEQUENCE_STEPS
    assert shipped["synthesis"]["frequency_options"] == synthesis.SEQUENCE_FREQUENCY_OPTIONS
    # the same table as one built before the sequence defaults: no learning rate in its settings
    old = json.loads((out / "table.json").read_text())
    del old["synthesis"]["learning_rate"]
    old["synthesis_resolved"]["learning_rate"] = 0.5
    old["fingerprint"] = tables.settings_fingerprint(old)
    (cache / "old").mkdir()
    (cache / "old" / "table.json").write_text(json.dumps(old))
    tables.build(64, 3, out=cache / "old", sets=[(40,)], **opts)
    assert "learning_rate" not in tables.open_table(cache / "old").settings["synthesis"]
    tables.build(64, 3, out=cache / "lr05", sets=[(40,)], learning_rate=0.5, **opts)
    np.testing.assert_array_equal(tables.open_table(cache / "old").load((40,)),
                                  tables.open_table(cache / "lr05").load((40,)))


def test_a_sequence_weighs_the_axes_unless_told_otherwise():
    """synthesize_sequence takes SEQUENCE_FREQUENCY_OPTIONS (the axes' weight) unless
    frequency_options is given: the default equals the explicit options bit for bit, and
    frequency_options={} (the sets' 3-direction design, axis weight 1) is another sequence: it
    acts in the prefix of ROBUST_MIN_N points."""
    n = frequencies.ROBUST_MIN_N
    opts = dict(sequence_from=n // 2, steps=2, method="direct", show_progress=False)
    key, dirs = jax.random.key(2), (0.0, 90.0, 30.0)
    default = synthesis.synthesize_sequence(key, n, dirs, **opts).points
    explicit = synthesis.synthesize_sequence(
        key, n, dirs, frequency_options=dict(synthesis.SEQUENCE_FREQUENCY_OPTIONS), **opts).points
    plain = synthesis.synthesize_sequence(key, n, dirs, frequency_options={}, **opts).points
    assert synthesis.SEQUENCE_FREQUENCY_OPTIONS["robust_axis_weight"] != 1.0
    np.testing.assert_array_equal(np.asarray(default), np.asarray(explicit))
    assert not np.array_equal(np.asarray(default), np.asarray(plain))


_SEQUENCE_SCRIPT = """
import hashlib, jax, numpy as np
from anisosample import synthesis
r = synthesis.synthesize_sequence(jax.random.key(5), 512, (0, 90, 30), sequence_from=128,
                                  prefix="dihedral-16", steps=30, method="nufft1",
                                  show_progress=False)
print(hashlib.sha256(np.asarray(r.points).tobytes()).hexdigest())
"""


def test_sequence_with_prefix_same_key_same_bits_in_another_process():
    """A sequence with a prefix on the NUFFT path: a fresh process on one OpenMP thread gives
    the bytes this process gives."""
    import hashlib
    import os
    import subprocess
    import sys

    env = dict(os.environ, OMP_NUM_THREADS="1", ANISOSAMPLE_PROGRESS="0")
    out = subprocess.run([sys.executable, "-c", _SEQUENCE_SCRIPT], env=env, check=True,
                         capture_output=True, text=True, timeout=300)
    here = synthesis.synthesize_sequence(jax.random.key(5), 512, (0, 90, 30), sequence_from=128,
                                         prefix="dihedral-16", steps=30, method="nufft1",
                                         show_progress=False)
    assert out.stdout.strip().splitlines()[-1] == hashlib.sha256(
        np.asarray(here.points).tobytes()).hexdigest()


def test_shipped_per_pixel_prefix_table_is_what_the_library_builds(tmp_path):
    """``d3_n64_dihedral-16`` (the per-pixel sampler's sets at 64 spp) is complete, serves the
    prefix bit for bit, and its set for 30 degrees equals one built by the command it was built
    with (in a process compiling as a user's does: the suite's LLVM level changes float32
    rounding, tests/conftest.py)."""
    import subprocess
    import sys

    from helpers import default_compile_env

    path = tables.shipped_dir() / "d3_n64_dihedral-16"
    tab = tables.open_table(path)
    assert tab.complete and tab.n == 64 and tab.settings["synthesis"]["prefix"] == "dihedral-16"
    assert P.prefix_size("dihedral-16") == 16
    subprocess.run([sys.executable, "-m", "anisosample.cli", "tables", "build", "--n", "64",
                    "--prefix", "dihedral-16", "--sets", "30", "--out", str(tmp_path / "t"),
                    "--no-progress"], env=default_compile_env(), check=True, capture_output=True)
    np.testing.assert_array_equal(tables.open_table(tmp_path / "t").load((30,)), tab.load((30,)))
    for extra in (30, 137):
        pts = np.asarray(tables.lookup([0, 90, extra], 64, prefix="dihedral-16"))
        np.testing.assert_array_equal(pts[:16], P.dihedral_points(16))

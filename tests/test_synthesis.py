"""synthesize(): contract, the losses going down, the spectrum getting dark where asked,
checkpoint/resume giving the same result, bad input, the .npz record."""

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest
from helpers import assert_pytree_round_trips

import anisosample as asp
from anisosample import frequencies as fr
from anisosample import losses as L
from anisosample import synthesis

SMALL = dict(steps=30, method="direct", show_progress=False)


def test_contract_and_suppression(getkey):
    key = getkey()
    n = 64
    result = asp.synthesize(key, n, [0.0, 90.0, 30.0], **SMALL)
    assert isinstance(result, synthesis.SynthesisResult)
    pts = result.points
    assert pts.shape == (n, 2) and pts.dtype == jnp.float32
    assert float(pts.min()) >= 0.0 and float(pts.max()) < 1.0
    np.testing.assert_array_equal(np.asarray(result), np.asarray(pts))
    h = result.history
    assert h.shape == (SMALL["steps"] + 1,) and h[-1] < 0.5 * h[0]
    assert result.final_loss == h[-1]
    assert result.recipe == synthesis.make_recipe("rate", steps=30, method="direct")
    # the weighted spectrum on the design's frequencies is far below the initial jittered set
    fset = fr.design(n, [0.0, 90.0, 30.0])
    before = float(L.linear_spectrum_loss(asp.samplers.get("jittered")(key, n), fset))
    after = float(L.linear_spectrum_loss(pts, fset))
    assert after < 0.5 * before
    again = asp.synthesize(key, n, [0.0, 90.0, 30.0], recipe=result.recipe,
                           show_progress=False)
    np.testing.assert_array_equal(np.asarray(pts), np.asarray(again.points))


@pytest.mark.slow
def test_paper_recipe_stratifies(getkey):
    n = 64
    key = getkey()
    pts = asp.synthesize(key, n, [0.0, 90.0, 45.0], recipe="paper", c=1.0, **SMALL).points
    init = asp.samplers.get("jittered")(key, n)
    sw0 = float(L.sliced_wasserstein_loss(init, [0.0, 90.0, 45.0]))
    sw1 = float(L.sliced_wasserstein_loss(pts, [0.0, 90.0, 45.0]))
    assert sw1 < sw0


def test_checkpoint_resume_same_result(getkey, tmp_path):
    key = getkey()
    n = 32
    opts = dict(steps=20, method="direct", show_progress=False, checkpoint_every=5)
    full = asp.synthesize(key, n, [0.0, 90.0, 60.0], **opts)
    ck = tmp_path / "ck.npz"
    resumed, first_step = _kill_and_resume(key, n, [0.0, 90.0, 60.0], ck, 10, opts)
    assert first_step == 15  # it did not start again from 0
    np.testing.assert_array_equal(np.asarray(full), np.asarray(resumed))
    assert not ck.exists()
    # a checkpoint made with other settings is refused, not silently reused
    with pytest.raises(_Killed):
        asp.synthesize(key, n, [0.0, 90.0, 60.0], checkpoint=ck, callback=_kill_at(10), **opts)
    with pytest.raises(ValueError, match="other settings"):
        asp.synthesize(key, n, [0.0, 90.0, 61.0], checkpoint=ck, **opts)


def test_save_and_load_result(getkey, tmp_path):
    result = asp.synthesize(getkey(), 16, [0.0, 90.0], steps=3, method="direct",
                            show_progress=False)
    path = synthesis.save_result(tmp_path / "set.npz", result)
    back, meta = synthesis.load_result(path)
    np.testing.assert_array_equal(np.asarray(back), np.asarray(result.points))
    assert meta["options"] == result.recipe.record()
    assert meta["n"] == 16 and meta["directions_deg"] == [0.0, 90.0]
    assert meta["frequency_design"]["design"] == "rate"
    assert "anisosample_version" in meta and len(meta["history"]) == 4
    with pytest.raises(FileExistsError):
        synthesis.save_result(path, result)


@pytest.mark.slow
def test_nufft_and_direct_paths_agree(getkey):
    key = getkey()
    a = asp.synthesize(key, 128, [0.0, 90.0, 30.0], steps=5, method="direct",
                       show_progress=False)
    b = asp.synthesize(key, 128, [0.0, 90.0, 30.0], steps=5, method="nufft3",
                       show_progress=False, nufft_eps=1e-12)
    np.testing.assert_allclose(np.asarray(a), np.asarray(b), atol=1e-6)


def test_bad_input(getkey):
    key = getkey()
    with pytest.raises(ValueError, match="n must be >= 2"):
        asp.synthesize(key, 1, [0.0])
    with pytest.raises(ValueError, match="directions_deg"):
        asp.synthesize(key, 16, [0.0, 190.0])
    with pytest.raises(ValueError, match="directions_deg"):
        asp.synthesize(key, 16, [0.0, -5.0])
    with pytest.raises(ValueError, match="directions_deg"):
        asp.synthesize(key, 16, [30.0, 30.0])
    with pytest.raises(ValueError, match="c must"):
        asp.synthesize(key, 16, [0.0], c=-1.0)
    with pytest.raises(ValueError, match="recipe"):
        asp.synthesize(key, 16, [0.0], recipe="magic")
    with pytest.raises(ValueError, match="empty"):
        asp.synthesize(key, 16, [0.0], frequency_options={"length": 0.5, "width": 0.0,
                                                          "disk_radius": 0.0})
    with pytest.raises(TypeError, match="key"):
        asp.synthesize(0, 16, [0.0])
    with pytest.raises(TypeError, match="unexpected"):
        asp.synthesize(key, 16, [0.0], lr=0.1)
    with pytest.raises(ValueError, match="too many for n=64 points: at most 4"):
        asp.synthesize(key, 64, list(range(0, 180, 5)))
    with pytest.raises(ValueError, match="GiB"):
        asp.synthesize(key, 100_000_000, [0.0, 90.0, 30.0])


def _shift_variance(points, f, k=64, seed=0):
    """Brute force: variance of the estimate over a stratified k x k grid of toroidal shifts."""
    rng = np.random.default_rng(seed)
    g = np.stack(np.meshgrid(np.arange(k), np.arange(k), indexing="ij"), -1).reshape(-1, 2)
    t = (g + rng.random(g.shape)) / k
    x = np.asarray(points, np.float64)
    est = np.concatenate([np.asarray(f(jnp.asarray((x[None] + t[i:i + 512, None]) % 1.0,
                                                   jnp.float32))).mean(axis=1)
                          for i in range(0, len(t), 512)])
    return est.var()


def test_variance_decomposition_matches_measured_variance(getkey):
    from anisosample import diagnostics

    n = 256
    pts = asp.samplers.get("jittered")(getkey(), n)
    f = asp.integrands.edges([30.0])
    d = diagnostics.variance_decomposition(pts, f)
    measured = _shift_variance(pts, f)
    assert abs(d["predicted"] - measured) < 0.05 * measured, (d["predicted"], measured)
    parts = sum(r["variance"] for r in d["regions"].values())
    assert parts == pytest.approx(d["total"], rel=1e-12)
    assert set(d["regions"]) == {"line 0 deg", "line 30 deg", "line 90 deg", "elsewhere"}
    # jittered points are not dark along 30 degrees: that line carries most of the variance
    assert d["regions"]["line 30 deg"]["variance"] > 0.3 * d["total"]
    s = diagnostics.summary(d)
    assert "freqs" not in s and len(s["by_radius"]["elsewhere"]) == len(s["radius_edges"]) - 1


@pytest.mark.parametrize("method", ["direct", "nufft1"])
def test_batch_matches_single_runs(getkey, method):
    """One loop: set b of a batch is synthesize(split(key, B)[b]) bit for bit (each set keeps
    its own frequency plan, the lattice type-1 grids included)."""
    key = getkey()
    sets = [[0.0, 90.0, 30.0], [0.0, 90.0, 67.0]]
    opts = dict(steps=10, method=method, show_progress=False, checkpoint_every=4)
    batch = synthesis.synthesize_batch(key, 64, sets, **opts)
    assert batch.points.shape == (2, 64, 2) and batch.points.dtype == jnp.float32
    assert batch.history.shape == (2, 11)
    keys = jax.random.split(key, 2)
    for b, dirs in enumerate(sets):
        single = asp.synthesize(keys[b], 64, dirs, **opts)
        assert np.asarray(batch.points[b]).tobytes() == np.asarray(single.points).tobytes()
        np.testing.assert_array_equal(batch.history[b], single.history)
    with pytest.raises(ValueError, match="same number"):
        synthesis.synthesize_batch(key, 64, [[0.0, 90.0], [0.0, 90.0, 30.0]], **opts)



def test_result_is_a_pytree_with_the_loop_status(getkey):
    """SynthesisResult is an equinox.Module (issue 26): flatten/unflatten, jit and vmap give it
    back; a finished run's status is RESULTS.successful (one per set for a batch)."""
    key = getkey()
    opts = dict(steps=4, method="direct", show_progress=False)
    result = asp.synthesize(key, 32, [0.0, 90.0, 30.0], **opts)
    assert_pytree_round_trips(result)
    assert result.result == optx.RESULTS.successful and bool(result.successful)
    batch = synthesis.synthesize_batch(key, 32, [[0.0, 90.0, 30.0], [0.0, 90.0, 50.0]], **opts)
    assert_pytree_round_trips(batch)
    np.testing.assert_array_equal(np.asarray(batch.successful), [True, True])


def test_loop_status_flags_a_non_finite_history():
    """The status reads the whole history: any non-finite loss is a divergence, per set."""
    ok = np.array([0.5, 0.4, 0.3])
    bad = np.array([0.5, np.nan, 0.3])
    assert synthesis.loop_status(ok) == optx.RESULTS.successful
    assert synthesis.loop_status(bad) == optx.RESULTS.nonlinear_divergence
    assert synthesis.loop_status(np.array([0.5, 0.4, np.inf])) == \
        optx.RESULTS.nonlinear_divergence
    # a finite float64 loss beyond float32's range is still finite
    assert synthesis.loop_status(np.array([1e300, 0.5])) == optx.RESULTS.successful
    assert jax.jit(synthesis.loop_status)(jnp.asarray(ok)) == optx.RESULTS.successful
    both = synthesis.loop_status(np.stack([ok, bad]))
    np.testing.assert_array_equal(np.asarray(both == optx.RESULTS.successful), [True, False])


_SAME_BITS_SCRIPT = """
import sys, hashlib
import jax, numpy as np
import anisosample as asp
x = asp.synthesize(jax.random.key(7), 1024, (0, 90, 30), steps=100, method="nufft1",
                   show_progress=False)
print(hashlib.sha256(np.asarray(x.points).tobytes()).hexdigest())
"""


def test_same_key_same_bits_across_processes_and_thread_counts():
    """DESIGN: same key, same bits. A fresh process at the default thread count and one on a
    single OpenMP thread give the same bytes as this process (FINUFFT's multithreaded spreader
    adds subgrids in a varying order; synthesis runs it on one thread, spectrum.NUFFT_THREADS).
    With the library's threads, 100 steps at n = 1024 differed in 3 of 3 runs."""
    import hashlib
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k != "OMP_NUM_THREADS"}
    env["ANISOSAMPLE_PROGRESS"] = "0"
    digests = []
    for threads in (None, "1"):
        e = dict(env, **({"OMP_NUM_THREADS": threads} if threads else {}))
        out = subprocess.run([sys.executable, "-c", _SAME_BITS_SCRIPT], env=e, check=True,
                             capture_output=True, text=True, timeout=300)
        digests.append(out.stdout.strip().splitlines()[-1])
    here = asp.synthesize(jax.random.key(7), 1024, (0, 90, 30), steps=100, method="nufft1",
                          show_progress=False)
    digests.append(hashlib.sha256(np.asarray(here.points).tobytes()).hexdigest())
    assert len(set(digests)) == 1, digests


def test_killed_run_resumes_to_the_same_bits(tmp_path):
    """Stopped after 48 of 100 steps (a callback raising at a checkpoint: a deterministic kill),
    then resumed from the checkpoint: the same bytes as the uninterrupted run, on the NUFFT
    path (type-1 lattice grids) at the default thread count."""
    key = jax.random.key(11)
    opts = dict(steps=100, method="nufft1", show_progress=False, checkpoint_every=16)
    full = np.asarray(asp.synthesize(key, 1024, (0, 90, 30), **opts).points)
    resumed, first_step = _kill_and_resume(key, 1024, (0, 90, 30), tmp_path / "run.ckpt.npz",
                                           48, opts)
    assert first_step == 64  # resumed at step 48, not from 0
    assert np.asarray(resumed.points).tobytes() == full.tobytes()


class _Killed(Exception):
    pass


def _kill_at(at):
    def kill(step, loss):
        if step == at:
            raise _Killed

    return kill


def _kill_and_resume(key, n, dirs, ck, at, opts):
    """Run until step ``at`` (a callback raises there: the kill), then resume from the
    checkpoint ``ck``; returns the resumed result and the first step it reported."""

    with pytest.raises(_Killed):
        asp.synthesize(key, n, dirs, checkpoint=ck, callback=_kill_at(at), **opts)
    assert ck.exists()
    seen = []
    resumed = asp.synthesize(key, n, dirs, checkpoint=ck, callback=lambda s, v: seen.append(s),
                             **opts)
    return resumed, seen[0]


def test_band_energy_is_one_for_white_noise_and_small_for_an_aligned_set():
    """diagnostics.band_energy: mean n P_S within one unit of a line. White noise has
    E[n P_S(v)] = 1 at every v != 0 (the band holds ~100 frequencies, so 16 sets average to 1
    within +-0.1); a set synthesized for the direction is far darker there. 50 of the rate
    recipe's 200 steps suffice (measured: 0.0073 at 30 degrees after 50 steps, 0.0034 after
    200; 0.57 along 60 degrees, which the set was not made for)."""
    from anisosample import diagnostics

    white = [diagnostics.band_energy(np.asarray(jax.random.uniform(jax.random.key(s), (256, 2))),
                                     30.0) for s in range(16)]
    assert abs(np.mean(white) - 1.0) < 0.1, np.mean(white)
    aligned = asp.synthesize(jax.random.key(0), 256, (0, 90, 30), steps=50, show_progress=False)
    assert diagnostics.band_energy(aligned.points, 30.0, 16.0) < 0.1
    with pytest.raises(ValueError, match="radius"):
        diagnostics.band_energy(aligned.points, 30.0, 0.1)

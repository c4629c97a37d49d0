"""anisosample.diagnostics: a sampler's expected spectrum through its stacked realizations, and
W Eq. 5's decomposition against its own sum."""

import jax
import numpy as np
import pytest

from anisosample import diagnostics, frequencies, integrands, metrics, samplers, spectrum


def test_expected_spectrum_validates_before_sampling():
    f = np.array([[1, 0]])
    with pytest.raises(TypeError, match="key must be a single JAX PRNG key"):
        diagnostics.sampler_power_spectrum("random", 16, 0, f, realizations=2)
    with pytest.raises(TypeError, match="key must be a single JAX PRNG key"):
        diagnostics.sampler_power_spectrum_grid("random", 16, 0, 3, realizations=2)
    with pytest.raises(ValueError, match="radius must be >= 1"):
        diagnostics.sampler_power_spectrum_grid("random", 16, jax.random.key(0), 0)
    with pytest.raises(ValueError, match="method must be one of"):
        diagnostics.sampler_power_spectrum("random", 16, jax.random.key(0), f, method="fft")


def test_sampler_spectrum_is_the_metric_of_its_sets():
    """The sampler-name wrapper: the same sets as :func:`diagnostics.sampler_sets` (each key
    split into the set's and the shift's), the same bits as the metric on them."""
    key = jax.random.key(3)
    f = spectrum.frequency_grid(4)
    sets = diagnostics.sampler_sets("jittered", 32, key, 3)
    assert sets.shape == (3, 32, 2)
    k_pts, k_shift = jax.random.split(jax.random.split(key, 3)[1])
    np.testing.assert_array_equal(
        sets[1], samplers.toroidal_shift(k_shift, samplers.get("jittered")(k_pts, 32)))
    np.testing.assert_array_equal(
        np.asarray(diagnostics.sampler_power_spectrum("jittered", 32, key, f, realizations=3)),
        np.asarray(metrics.expected_power_spectrum(sets, f)))
    plain = diagnostics.sampler_sets(samplers.get("jittered"), 32, key, 3, shift=False)
    np.testing.assert_array_equal(plain[1], samplers.get("jittered")(k_pts, 32))
    np.testing.assert_array_equal(
        np.asarray(diagnostics.sampler_power_spectrum_grid("jittered", 32, key, 4,
                                                           realizations=3, shift=False)),
        np.asarray(metrics.expected_power_spectrum_grid(plain, 4)))


def test_decomposition_frequencies_are_the_disk_and_the_bands():
    """A disk plus a band along each direction, one of each +-v, sorted, nothing twice."""
    v = diagnostics.decomposition_frequencies((0.0, 90.0, 30.0), 8.0, 40.0, 2.0)
    parts = [frequencies.disk(8.0)] + [frequencies.wedge(t, 40.0, 2.0) for t in (0, 90, 30)]
    np.testing.assert_array_equal(v, frequencies.canonical_half(np.concatenate(parts)))
    assert v.dtype == np.int64 and len({tuple(r) for r in v.tolist()}) == len(v)


def test_decomposition_total_is_eq5_over_its_frequencies():
    """The decomposition's total is W Eq. 5 (metrics.predicted_variance) over its frequencies,
    both +-v; its regions add up to it."""
    pts = samplers.get("pmj02bn")(jax.random.key(1), 256)
    edge = integrands.edges([30.0])
    d = diagnostics.variance_decomposition(pts, edge, disk_radius=16, line_length=256)
    assert d["total"] == pytest.approx(2 * metrics.predicted_variance(d["P_S"], d["P_f"]),
                                       rel=1e-12)
    assert sum(r["variance"] for r in d["regions"].values()) == pytest.approx(d["total"],
                                                                              rel=1e-12)

"""Chi-square goodness of fit for every warp of the catalogue (anisosample.testing).

Default run: one seed, 10^6 samples, for every warp; ``slow``: two more seeds. The significance
is 1% corrected (Sidak) for the number of tests in the file.
"""

import jax
import jax.numpy as jnp
import pytest
from helpers import assert_pytree_round_trips

import anisosample.warps as W
from anisosample.testing import chi2_test

from .helpers import ALL, CHARTS

CASES = [(i, f) for i, f, _ in ALL]
N_TESTS = 3 * len(CASES)
# The default run covers one warp of each kind (10^6 samples each); the slow run all of them.
DEFAULT = {
    "bilinear-tiny",
    "bilinear-scaled-1e-25",
    "biquadratic",
    "compose-bilinear-biquadratic",
    "triangle-general",
    "rectangle-skewed",
    "ltc-parallelogram",
    "compose-bilinear-triangle",
    "cosine-hemisphere",
    "octahedral",
    "concentric-disk",
    "triangle-area",
    "patch-area-curved",
}


def _run(name, factory, seed):
    chart = CHARTS[name]() if name in CHARTS else None
    result = chi2_test(factory(), jax.random.key(seed), chart=chart, n_tests=N_TESTS)
    assert result.passed, f"{name}: {result}"
    return result


@pytest.mark.parametrize(
    "name,factory",
    [c for c in CASES if c[0] in DEFAULT],
    ids=[c[0] for c in CASES if c[0] in DEFAULT],
)
def test_chi2(name, factory):
    _run(name, factory, 11)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [11, 12, 13])
@pytest.mark.parametrize("name,factory", CASES, ids=[c[0] for c in CASES])
def test_chi2_more_seeds(name, factory, seed):
    _run(name, factory, seed)


class _WrongPdf(W.Bilinear):
    """Samples the bilinear density but reports a uniform pdf: the test must catch it."""

    def pdf(self, x):
        return jnp.where(jnp.all((x >= 0) & (x <= 1)), 1.0, 0.0)


def test_chi2_detects_a_wrong_pdf(tmp_path):
    warp = _WrongPdf([[1.0, 1.0], [1.0, 1.3]])
    result = chi2_test(warp, jax.random.key(0), figure_path=tmp_path / "fail.png")
    assert not result.passed
    assert (tmp_path / "fail.png").exists() and result.figure == str(tmp_path / "fail.png")


def test_chi2_result_is_a_pytree():
    """Chi2Result is an equinox.Module like the other results (issue 26); the verdict survives
    jit and vmap, its static settings ride in the structure."""
    result = chi2_test(W.Bilinear([[1.0, 2.0], [3.0, 4.0]]), jax.random.key(3), n=20_000, res=11)
    assert result.passed and result.dof > 0
    assert_pytree_round_trips(result)


def test_chi2_arguments():
    with pytest.raises(ValueError, match="res must be odd"):
        chi2_test(W.Bilinear([[1, 1], [1, 1]]), jax.random.key(0), res=50)
    with pytest.raises(ValueError, match="chart="):
        chi2_test(W.TriangleArea([[0, 0, 0], [1, 0, 0], [0, 1, 0]]), jax.random.key(0))

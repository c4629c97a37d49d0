"""The suite runs with jaxtyping's run-time checks on (pyproject's ``--jaxtyping-packages``).

Each test here fails when the import hook is off (``--jaxtyping-packages=`` on the command
line, or the option dropped from ``addopts``): the annotation is what catches the bad value, not
the library's own validation.
"""

import jax
import jax.numpy as jnp
import jaxtyping
import pytest

from anisosample import samplers, warps


def test_the_hook_covers_the_package(request):
    packages = (request.config.getoption("jaxtyping_packages") or "").split(",")
    assert "anisosample" in packages, packages
    assert packages[-1].startswith("beartype.beartype"), packages


def test_a_samplers_output_is_checked_against_points():
    # Sampler.__call__ -> Points (``(n, 2)`` float): the library does not check what a
    # registered construction returns; the return annotation does.
    bad = samplers.Sampler("three_columns", lambda key, n: jnp.zeros((n, 3), jnp.float32))
    with pytest.raises(jaxtyping.TypeCheckError, match="return value"):
        bad(jax.random.key(0), 4)
    ok = samplers.Sampler("two_columns", lambda key, n: jnp.zeros((n, 2), jnp.float32))
    assert ok(jax.random.key(0), 4).shape == (4, 2)


def test_a_batch_of_the_wrong_shape_is_caught_by_its_annotation():
    # sample_batch(warp, u: Float[Array, "n 2"]): without the hook, its own check_points
    # refuses u with a ValueError; with it, the annotation does first.
    with pytest.raises(jaxtyping.TypeCheckError, match="parameter 'u'"):
        warps.sample_batch(warps.ConcentricDisk(), jnp.full((4, 3), 0.5, jnp.float32))


@pytest.mark.library_errors
def test_library_errors_marker_turns_the_checks_off():
    with pytest.raises(ValueError, match="u"):
        warps.sample_batch(warps.ConcentricDisk(), jnp.full((4, 3), 0.5, jnp.float32))

import jax
import pytest

# Strict promotion catches accidental float64/int mixing in the library (STYLE: equinox tests).
jax.config.update("jax_numpy_rank_promotion", "raise")
jax.config.update("jax_numpy_dtype_promotion", "strict")


@pytest.fixture
def getkey():
    """A fresh, deterministic key per call within a test."""
    state = {"key": jax.random.key(20261122)}

    def _next():
        state["key"], sub = jax.random.split(state["key"])
        return sub

    return _next

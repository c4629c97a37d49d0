"""Shared test utilities: independent checks that do not use the library's own code paths."""

import contextlib

import jaxtyping
import numpy as np


def is_net(points, m: int) -> bool:
    """Whether ``2^m`` points form a (0, m, 2)-net in base 2 (every elementary interval of area
    2^-m holds exactly one point). Integer arithmetic on the float32 bits: exact."""
    p = np.asarray(points)
    assert p.shape == (1 << m, 2)
    X = (p.astype(np.float64) * 2**24).astype(np.int64)  # exact for float32 in [0, 1)
    for a in range(m + 1):
        ix = X[:, 0] >> (24 - a)
        iy = X[:, 1] >> (24 - (m - a))
        counts = np.bincount(ix * (1 << (m - a)) + iy, minlength=1 << m)
        if not np.all(counts == 1):
            return False
    return True


def brute_force_spectrum(points, freqs) -> np.ndarray:
    """``P_S(v) = |(1/N) sum exp(-2 pi i v.x)|^2`` in float64 NumPy (W Eq. 6)."""
    p = np.asarray(points, dtype=np.float64)
    f = np.asarray(freqs, dtype=np.float64)
    ph = 2 * np.pi * (f @ p.T)
    n = p.shape[0]
    return (np.cos(ph).sum(1) ** 2 + np.sin(ph).sum(1) ** 2) / n**2


def forced_host_devices(n: int) -> dict:
    """The environment of a subprocess with ``n`` forced host devices, keeping the suite's own
    ``XLA_FLAGS`` (its compile level, tests/conftest.py): the subprocess compiles as this process
    does, so their results can be compared bit for bit."""
    import os

    flags = os.environ.get("XLA_FLAGS", "")
    return {"XLA_FLAGS": f"{flags} --xla_force_host_platform_device_count={n}".strip()}


def default_compile_env() -> dict:
    """This process's environment without the suite's LLVM level (tests/conftest.py): for a
    subprocess that must compile as a user's process does, e.g. to reproduce a shipped fit
    whose end point depends on float32 rounding."""
    import os
    import re

    env = dict(os.environ)
    flags = re.sub(r"\s*--xla_backend_optimization_level=\S+", "", env.get("XLA_FLAGS", ""))
    env["XLA_FLAGS"] = flags.strip()
    return env


def free_port() -> int:
    """A TCP port on localhost that nothing listens on now (for a jax.distributed coordinator)."""
    import socket

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


@contextlib.contextmanager
def library_errors():
    """jaxtyping's run-time checks off inside (the ``library_errors`` marker of conftest, for
    one call): the library's own error is what a user without the import hook sees."""
    before = jaxtyping.config.jaxtyping_disable
    jaxtyping.config.update("jaxtyping_disable", True)
    try:
        yield
    finally:
        jaxtyping.config.update("jaxtyping_disable", before)


def assert_pytree_round_trips(result):
    """A result (an ``equinox.Module``) is a pytree: ``tree_flatten``/``tree_unflatten`` give it
    back equal, and it passes through ``jax.jit`` and ``jax.vmap`` (over a stack of two copies)
    with the same structure and the same leaves (as the traced dtype: NumPy float64 arrives as
    float32 without x64). Static fields (names, counts, settings) ride in the structure."""
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    assert isinstance(result, eqx.Module), type(result)
    leaves, treedef = jax.tree_util.tree_flatten(result)
    again = jax.tree_util.tree_unflatten(treedef, leaves)
    assert type(again) is type(result)
    assert jax.tree_util.tree_structure(again) == treedef
    for a, b in zip(jax.tree_util.tree_leaves(again), leaves, strict=True):
        assert a is b

    def same(out):
        assert type(out) is type(result)
        assert jax.tree_util.tree_structure(out) == treedef
        for a, b in zip(jax.tree_util.tree_leaves(out), leaves, strict=True):
            a = np.asarray(a)
            np.testing.assert_array_equal(a, np.asarray(b).astype(a.dtype))

    same(jax.jit(lambda r: r)(result))
    stacked = jax.tree_util.tree_map(lambda x: jnp.stack([x, x]), result)
    batched = jax.vmap(lambda r: r)(stacked)
    same(jax.tree_util.tree_map(lambda x: x[1], batched))

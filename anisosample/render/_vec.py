"""3-vector helpers written elementwise.

XLA's CPU backend (jaxlib 0.10.2) miscompiles some fused reductions over a trailing axis of
length 3 (``jnp.sum(a * b, axis=-1)`` of a ``jnp.cross``) once a vmapped batch passes a few
thousand rows: rows beyond about 2/3 of the batch come out wrong (regression test:
``test_large_batches_match_small_ones`` in ``tests/render/test_analytic.py``). Spelling dot
products and norms out component by component avoids the reduction entirely.
"""

import jax.numpy as jnp


def dot(a, b):
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def norm(a):
    return jnp.sqrt(dot(a, a))


def normalize(a):
    return a / jnp.maximum(norm(a), 1e-30)[..., None]


def cross(a, b):
    return jnp.stack(
        [
            a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
            a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
            a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0],
        ],
        axis=-1,
    )


def matvec(m, v):
    """``m[:3, :3] @ v`` elementwise."""
    return m[:3, 0] * v[0] + m[:3, 1] * v[1] + m[:3, 2] * v[2]

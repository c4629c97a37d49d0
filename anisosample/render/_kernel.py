"""How the ray caster's kernels are compiled: :func:`kernel`, ``jax.jit`` with
:func:`compiler_options`.

XLA:CPU (jaxlib 0.10.2) hands reductions to YNNPACK fusions by default. In the ray caster those
reductions run over tiny trailing axes (3-vector dot products and norms in the warps, the
primitive axis of the brute-force intersection, per-sample sums), where a YNNPACK call per
reduction costs far more than the loop XLA emits itself. Profiled one-device renders at 128^2 x
64 spp (pmj02bn) spent 12-34 % of their fusions' time in them: cornell 37 of 299 ms, cornell
with ``technique="solid_angle"`` 100 of 546 ms, glossy with MIS 85 of 657 ms. The render kernels
therefore compile with ``xla_cpu_experimental_ynn_fusion_type`` empty (no YNNPACK fusion); the
rest of the library keeps XLA's defaults. A jaxlib that does not know the option compiles the
kernels with its defaults (checked once per process, on the first kernel call).
"""

from __future__ import annotations

import functools

import jax
import numpy as np

_NO_YNN = {"xla_cpu_experimental_ynn_fusion_type": ""}


@functools.cache
def compiler_options() -> dict:
    """The options the render kernels compile with: :data:`_NO_YNN` where this jaxlib knows
    it, else none."""
    try:
        jax.jit(lambda x: x + 1, compiler_options=_NO_YNN).lower(np.float32(0)).compile()
    except Exception:  # noqa: BLE001 - "No such compile option" is a JaxRuntimeError
        return {}
    return dict(_NO_YNN)


def kernel(fun=None, /, *, jit=jax.jit, **jit_kwargs):
    """``jit(fun, compiler_options=compiler_options(), **jit_kwargs)``, made at the first call
    (so that importing starts no XLA backend); called from inside another trace (with traced
    arguments: another kernel, ``jax.eval_shape``), where compiler options are not allowed,
    plain ``jit(fun, **jit_kwargs)``. ``jit``: ``jax.jit`` or ``equinox.filter_jit``. Usable as
    ``@kernel`` or ``@kernel(static_argnames=...)``."""
    if fun is None:
        return functools.partial(kernel, jit=jit, **jit_kwargs)
    nested = jit(fun, **jit_kwargs)
    top = None

    @functools.wraps(fun)
    def call(*args, **kwargs):
        nonlocal top
        if any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree.leaves((args, kwargs))):
            return nested(*args, **kwargs)
        if top is None:
            top = jit(fun, compiler_options=compiler_options(), **jit_kwargs)
        return top(*args, **kwargs)

    return call

"""How the ray caster's kernels are compiled: :func:`kernel`, ``jax.jit`` with
:func:`compiler_options` chosen per scene; and the scene sizes both that choice and the render's
chunk size (:data:`BRUTE_WIDE`, :func:`~anisosample.render.image.default_chunk_samples`) are
read from (:func:`brute_force_primitives`).

XLA:CPU (jaxlib 0.10.2) hands reductions to YNNPACK fusions by default. In the ray caster those
reductions mostly run over tiny trailing axes (3-vector dot products and norms in the warps, the
primitive axis of the brute-force intersection of a small scene, per-sample sums), where a
YNNPACK call per reduction costs far more than the loop XLA emits itself. Profiled one-device
renders at 128^2 x 64 spp (pmj02bn) spent 12-34 % of their fusions' time in them: cornell 37 of
299 ms, cornell with ``technique="solid_angle"`` 100 of 546 ms, glossy with MIS 85 of 657 ms. So
the render kernels compile with ``xla_cpu_experimental_ynn_fusion_type`` empty (no YNNPACK
fusion), except where brute force tests more than :data:`BRUTE_YNN` planar primitives: there
the reduction over them is long enough for YNNPACK to win. One device, light sampling, 64^2 x 16
spp of a sphere mesh on a floor, ns per sample without / with YNNPACK: brute force over 80
triangles 261 / 296, 168: 424-446 / 393-399, 288: 650 / 542, 960: 1631-1633 / 1261-1386; the
BVH over 9,800: 2457 / 2848 (load 1.1-1.4). The rest of the library keeps XLA's defaults. A
jaxlib that does not know the option compiles the kernels with its defaults (checked once per
process, on the first kernel call).
"""

from __future__ import annotations

import functools

import jax
import numpy as np

_NO_YNN = {"xla_cpu_experimental_ynn_fusion_type": ""}


# Brute force over more planar primitives than this: render chunks of 4096 samples instead of
# 65536 (render.image.default_chunk_samples).
BRUTE_WIDE = 64
# Brute force over more planar primitives than this keeps XLA's YNNPACK fusions.
BRUTE_YNN = 128


def brute_force_primitives(scene) -> int:
    """How many planar primitives the scene's rays test one by one (0 with a BVH): with
    per-tile culling (:mod:`~anisosample.render.culling`), the longer candidate list."""
    if scene.bvh is not None:
        return 0
    t = int(scene.tri_soa.shape[1])
    c = scene.culling
    if c is None:
        return t
    return max(t if s is None else int(s.index.shape[-1]) for s in (c.primary, c.shadow))


@functools.cache
def _no_ynn() -> dict:
    """:data:`_NO_YNN` where this jaxlib knows it, else no option."""
    try:
        jax.jit(lambda x: x + 1, compiler_options=_NO_YNN).lower(np.float32(0)).compile()
    except Exception:  # noqa: BLE001 - "No such compile option" is a JaxRuntimeError
        return {}
    return dict(_NO_YNN)


def compiler_options(scene=None) -> dict:
    """The options the render kernels compile with for ``scene`` (a ``Scene``, or anything
    with a ``.scene``; None: a small scene): no YNNPACK fusion, unless brute force tests more
    than :data:`BRUTE_YNN` primitives."""
    scene = getattr(scene, "scene", scene)
    if scene is not None and brute_force_primitives(scene) > BRUTE_YNN:
        return {}
    return _no_ynn()


def kernel(fun=None, /, *, jit=jax.jit, **jit_kwargs):
    """``jit(fun, compiler_options=compiler_options(first argument), **jit_kwargs)``, one per
    set of options, made at the first call that needs it (so that importing starts no XLA
    backend); called from inside another trace (with traced arguments: another kernel,
    ``jax.eval_shape``), where compiler options are not allowed, plain ``jit(fun,
    **jit_kwargs)``. The first argument is the scene (or holds it as ``.scene``). ``jit``:
    ``jax.jit`` or ``equinox.filter_jit``. Usable as ``@kernel`` or
    ``@kernel(static_argnames=...)``."""
    if fun is None:
        return functools.partial(kernel, jit=jit, **jit_kwargs)
    nested = jit(fun, **jit_kwargs)
    compiled = {}

    @functools.wraps(fun)
    def call(*args, **kwargs):
        if any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree.leaves((args, kwargs))):
            return nested(*args, **kwargs)
        options = compiler_options(args[0] if args else None)
        key = tuple(sorted(options.items()))
        if key not in compiled:
            compiled[key] = jit(fun, compiler_options=options, **jit_kwargs)
        return compiled[key](*args, **kwargs)

    return call

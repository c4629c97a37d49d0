"""Names the package's registries start with, importable without JAX.

The command line's ``--help`` lists them before any numerical module is loaded; the modules that
implement them import these tuples from here, so each list is written once.
"""

BASELINES = ("random", "jittered", "cmj", "sobol-owen", "pmj02", "pmj02bn")
"""The baseline samplers, which take no options (``samplers.get(name)(key, n)``)."""

DIRECTIONAL_SAMPLERS = ("aligned", "sheared")
"""Samplers made for chosen spectral directions: ``aligned`` (W Sec. 5.4, from the tables) and
``sheared`` (Singh & Jarosz 2017, a sheared baseline)."""

BUILTIN_SAMPLER_FACTORIES = {
    "aligned": "anisosample.selection:aligned_sampler",
    "aligned-sequence": "anisosample.selection:aligned_sequence_sampler",
}
"""The built-in samplers made above ``samplers`` in the module graph (they look their sets up
in the tables), each as the public function that makes it, ``"module:function"``:
``samplers.get`` imports it on first use. ``samplers`` itself names no module above it (the
module that makes a sampler imports ``samplers``, never the reverse)."""

INTEGRAND_SPEC_HELP = (
    "edges:T1[,T2,..]  |  halfplane:PHI,OFFSET  |  polygon:X0,Y0,X1,Y1,X2,Y2[,..]  |  "
    "disk[:CX,CY,R]  |  bump[:CX,CY,SIGMA]  |  smoothed:PHI,SIGMA (edge through the centre)  |  "
    "textured-<any of these>"
)
"""The grammar of :func:`anisosample.integrands.from_spec`."""

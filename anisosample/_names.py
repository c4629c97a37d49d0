"""Names the package's registries start with, importable without JAX.

The command line's ``--help`` lists them before any numerical module is loaded; the modules that
implement them import these tuples from here, so each list is written once.
"""

BASELINES = ("random", "jittered", "cmj", "sobol-owen", "pmj02", "pmj02bn")
"""The baseline samplers, which take no options (``samplers.get(name)(key, n)``)."""

DIRECTIONAL_SAMPLERS = ("aligned", "sheared")
"""Samplers made for chosen spectral directions: ``aligned`` (W Sec. 5.4, from the tables) and
``sheared`` (Singh & Jarosz 2017, a sheared baseline)."""

INTEGRAND_SPEC_HELP = (
    "edges:T1[,T2,..]  |  halfplane:PHI,OFFSET  |  polygon:X0,Y0,X1,Y1,X2,Y2[,..]  |  "
    "disk[:CX,CY,R]  |  bump[:CX,CY,SIGMA]  |  smoothed:PHI,SIGMA (edge through the centre)  |  "
    "textured-<any of these>"
)
"""The grammar of :func:`anisosample.integrands.from_spec`."""

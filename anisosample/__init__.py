"""anisosample: optimized and aligned anisotropic sampling patterns (Werner et al.) and product
sampling by fitting and composing warps (Hart et al.), as pure JAX functions.

The public API is this list of modules; see ``docs/`` for a guide.
"""

from importlib.metadata import PackageNotFoundError as _PackageNotFoundError
from importlib.metadata import version as _version

from . import diagnostics as diagnostics
from . import directions as directions
from . import frequencies as frequencies
from . import integrands as integrands
from . import io as io
from . import losses as losses
from . import plot as plot
from . import render as render
from . import samplers as samplers
from . import spectrum as spectrum
from . import synthesis as synthesis
from . import tables as tables
from . import testing as testing
from . import variance as variance
from . import vmf as vmf
from . import warps as warps
from .synthesis import synthesize as synthesize

try:
    __version__ = _version("anisosample")
except _PackageNotFoundError:  # a source tree that was not installed
    __version__ = "0+unknown"

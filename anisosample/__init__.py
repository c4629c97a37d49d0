"""anisosample: optimized and aligned anisotropic sampling patterns (Werner et al.) and product
sampling by fitting and composing warps (Hart et al.), as pure JAX functions.

The public API is this list of modules; see ``docs/`` for a guide.

The modules are imported on first use (PEP 562), so ``import anisosample`` and the command
line's ``--help`` start without loading JAX; ``anisosample.samplers`` and the other names below
behave exactly as eager re-exports would.
"""

from importlib import import_module as _import_module
from importlib.util import find_spec as _find_spec
from typing import TYPE_CHECKING as _TYPE_CHECKING

if _TYPE_CHECKING:  # the explicit re-exports, for type checkers and readers
    from . import diagnostics as diagnostics
    from . import directions as directions
    from . import edges as edges
    from . import frequencies as frequencies
    from . import integrands as integrands
    from . import io as io
    from . import losses as losses
    from . import metrics as metrics
    from . import plot as plot
    from . import progress as progress
    from . import render as render
    from . import samplers as samplers
    from . import scenes as scenes
    from . import selection as selection
    from . import spectrum as spectrum
    from . import synthesis as synthesis
    from . import tables as tables
    from . import testing as testing
    from . import variance as variance
    from . import vmf as vmf
    from . import warps as warps
    from .synthesis import synthesize as synthesize

_SUBMODULES = (
    "diagnostics", "directions", "edges", "frequencies", "integrands", "io", "losses", "metrics",
    "plot", "progress", "render", "samplers", "scenes", "selection", "spectrum", "synthesis",
    "tables", "testing", "variance", "vmf", "warps",
)
_FUNCTIONS = {"synthesize": "synthesis"}  # name -> the module that defines it


def _package_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("anisosample")
    except PackageNotFoundError:  # a source tree that was not installed
        return "0+unknown"


def __getattr__(name: str):
    if name in _SUBMODULES:
        return _import_module(f".{name}", __name__)  # the import binds it as an attribute
    if not name.startswith("_") and _find_spec(f"{__name__}.{name}") is not None:
        return _import_module(f".{name}", __name__)  # a module added since this list
    if name in _FUNCTIONS:
        value = getattr(_import_module(f".{_FUNCTIONS[name]}", __name__), name)
    elif name == "__version__":
        value = _package_version()
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_SUBMODULES, *_FUNCTIONS, "__version__"})

"""Shape aliases shared by the package (jaxtyping), in one place.

They document shapes in signatures (``samplers``: ``Key`` in, ``Points`` out; ``directions``,
``vmf``, ``warps``: ``Float[Array, ...]``). An argument that takes NumPy arrays too is
annotated ``ArrayLike``-based (``PointsLike``, ``Float[ArrayLike, ...]``); ``Array`` is a JAX
array only.

The library checks its inputs itself (``_validate``); the annotations are checked at run time
in the test suite only: pyproject's pytest ``addopts`` install jaxtyping's import hook over all
of ``anisosample`` with beartype (``--jaxtyping-packages``), so every call of an annotated
function or dataclass during the tests checks its arguments and result (shapes, dtypes and
the other annotations), and ``tests/test_shape_checks.py`` proves it is on. Tests of the
library's own errors are marked ``library_errors`` (the checks are off for them). Run your own
code with the checks: ``pytest --jaxtyping-packages=anisosample,beartype.beartype``, or
``jaxtyping.install_import_hook("anisosample", "beartype.beartype")`` before importing it.
"""

from jax.typing import ArrayLike
from jaxtyping import Array, Bool, Float, Int, PRNGKeyArray

Points = Float[Array, "n 2"]
"""A point set: ``(n, 2)`` float32 in ``[0, 1)^2``."""

PointsLike = Float[ArrayLike, "n 2"]
"""A point set as an argument: a JAX or NumPy ``(n, 2)`` float array."""

Frequencies = Int[Array, "m 2"]
"""Integer frequency vectors ``v = (v_x, v_y)``."""

Key = PRNGKeyArray

__all__ = [
    "Array", "ArrayLike", "Bool", "Float", "Int", "Key", "Points", "PointsLike", "Frequencies",
]

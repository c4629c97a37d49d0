"""Shape aliases shared by the package (jaxtyping), in one place.

They document shapes in signatures (``samplers``: ``Key`` in, ``Points`` out; ``directions``,
``vmf``, ``warps``: ``Float[Array, ...]``); nothing checks them at run time yet (issue 26: the
suite would need jaxtyping's import hook with beartype, and the annotations of arguments that
accept NumPy arrays too would need ``ArrayLike``-based aliases first).
"""

from jaxtyping import Array, Float, Int, PRNGKeyArray

Points = Float[Array, "n 2"]
"""A point set: ``(n, 2)`` float32 in ``[0, 1)^2``."""

Frequencies = Int[Array, "m 2"]
"""Integer frequency vectors ``v = (v_x, v_y)``."""

Key = PRNGKeyArray

__all__ = ["Array", "Float", "Int", "Key", "Points", "Frequencies"]

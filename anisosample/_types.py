"""Shape aliases shared by the package (jaxtyping), in one place.

They document shapes in signatures; run-time checking happens in the tests, not the library.
"""

from jaxtyping import Array, Float, Int, PRNGKeyArray

Points = Float[Array, "n 2"]
"""A point set: ``(n, 2)`` float32 in ``[0, 1)^2``."""

Frequencies = Int[Array, "m 2"]
"""Integer frequency vectors ``v = (v_x, v_y)``."""

Key = PRNGKeyArray

__all__ = ["Array", "Float", "Int", "Key", "Points", "Frequencies"]

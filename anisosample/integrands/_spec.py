"""Integrands from a short text spec (the command line)."""

from __future__ import annotations

import numpy as np

from .._names import INTEGRAND_SPEC_HELP
from ._base import Integrand
from ._polygons import HalfPlane, Polygon, edges
from ._smooth import Disk, GaussianBump, SmoothedEdge, Textured, smooth_texture

SPEC_HELP = INTEGRAND_SPEC_HELP


def from_spec(spec: str) -> Integrand:
    """Build an integrand from a short spec such as ``"edges:30,75"`` (see ``SPEC_HELP``).

    ``textured-`` in front multiplies the shape by :func:`smooth_texture`.
    """
    if not isinstance(spec, str) or not spec.strip():
        raise ValueError(f"integrand spec must be a non-empty string: {SPEC_HELP}")
    text = spec.strip()
    if text.startswith("textured-"):
        return Textured(smooth_texture(), from_spec(text[len("textured-"):]))
    kind, _, rest = text.partition(":")
    try:
        nums = [float(t) for t in rest.split(",") if t.strip()]
    except ValueError:
        raise ValueError(f"integrand spec {spec!r}: expected numbers after ':'") from None

    def need(count, what):
        if len(nums) not in count:
            raise ValueError(f"integrand spec {spec!r}: {kind} takes {what}")

    if kind == "edges":
        need(range(1, 5), "1 to 4 spectral directions in degrees")
        return edges(nums)
    if kind == "halfplane":
        need((2,), "PHI,OFFSET")
        return HalfPlane(nums[0], nums[1])
    if kind == "polygon":
        if len(nums) < 6 or len(nums) % 2:
            raise ValueError(f"integrand spec {spec!r}: polygon takes x,y pairs of >= 3 vertices")
        return Polygon(np.asarray(nums).reshape(-1, 2))
    if kind == "disk":
        need((0, 3), "nothing or CX,CY,R")
        return Disk((nums[0], nums[1]), nums[2]) if nums else Disk()
    if kind == "bump":
        need((0, 3), "nothing or CX,CY,SIGMA")
        return GaussianBump((nums[0], nums[1]), nums[2]) if nums else GaussianBump()
    if kind == "smoothed":
        need((2,), "PHI,SIGMA")
        return SmoothedEdge.through((0.5, 0.5), nums[0], nums[1])
    raise ValueError(f"unknown integrand kind {kind!r} in spec {spec!r}; known: {SPEC_HELP}")

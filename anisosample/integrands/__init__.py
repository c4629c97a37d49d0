"""Analytic 2D integrands on ``[0, 1)^2`` with exact integrals and exact Fourier coefficients.

Every integrand is an immutable ``equinox.Module`` and a pure callable ``f(x)`` over ``x`` of
shape ``(..., 2)`` returning shape ``(...)`` in ``x``'s float dtype. Each carries

* ``integral`` -- the exact value of ``int_{[0,1)^2} f``, computed in float64 (a Python float);
* ``directions_deg`` -- the spectral directions of its discontinuities that are *not* the axes
  (W Sec. 2: an edge running at ``theta + 90`` degrees puts its energy along ``theta``);
* where a closed form exists, ``fourier_coefficients(v)`` for integer ``v`` (complex128),
  ``F_f(v) = int_{[0,1)^2} f(x) exp(-2 pi i v.x) dx``, so ``P_f(v) = |F_f(v)|^2`` is exact
  (W Eq. 3-5; Durand 2011; Pilleboue et al. 2015).

The integrand lives on the unit square: shapes that reach outside it are clipped to it for the
integral and the spectrum (the torus sees the square's border as extra axis-aligned edges).

Shapes: :class:`HalfPlane`, :class:`Polygon` (simple, convex or not), :func:`edges` (1-4 edges
perpendicular to chosen spectral directions, the integrands of W Fig. 6), :class:`Disk` (curved:
no principal direction), :class:`SmoothedEdge` (a half-plane convolved with a Gaussian, W Fig. 11),
:class:`GaussianBump` (smooth), :class:`Texture` and :class:`Textured` (a smooth texture times a
shape, W Fig. 6's "smooth texture" rows).
"""

from ._base import Integrand as Integrand
from ._geometry import clip_to_unit_square as clip_to_unit_square
from ._geometry import polygon_area as polygon_area
from ._polygons import HalfPlane as HalfPlane
from ._polygons import Polygon as Polygon
from ._polygons import edges as edges
from ._smooth import Disk as Disk
from ._smooth import GaussianBump as GaussianBump
from ._smooth import SmoothedEdge as SmoothedEdge
from ._smooth import Texture as Texture
from ._smooth import Textured as Textured
from ._smooth import smooth_texture as smooth_texture
from ._spec import SPEC_HELP as SPEC_HELP
from ._spec import from_spec as from_spec

"""Primary-sample-space warps: fit, compose, sample, invert (Hart et al. 2020).

Every warp is an ``equinox.Module`` with the triplet ``sample(u) -> x``, ``pdf(x)`` and
``inverse(x) -> u``, each for **one point** (batch with ``jax.vmap`` or :func:`sample_batch`).
The one-point methods are the inner loop: they check shapes, not values, so a NaN ``u`` or
``x`` may give a NaN result; :func:`sample_batch` checks the batch's values too (finite, in
``[0, 1]^2``), eagerly or inside the caller's ``jit``/``vmap``, as warp constructors check their
control values.
See ``_base`` for the contract and ``docs``/``references/warps.md`` for the math.
"""

from ._base import AbstractWarp as AbstractWarp
from ._base import Compose as Compose
from ._base import compose as compose
from ._base import inverse_batch as inverse_batch
from ._base import pdf_batch as pdf_batch
from ._base import sample_batch as sample_batch
from .arvo import CosineSphericalTriangle as CosineSphericalTriangle
from .arvo import projected_solid_angle as projected_solid_angle
from .fit import WarpFit as WarpFit
from .fit import fit_least_squares as fit_least_squares
from .fit import fit_pointwise as fit_pointwise
from .fit import fit_tabulated as fit_tabulated
from .hemisphere import AngularHemisphere as AngularHemisphere
from .hemisphere import ConcentricDisk as ConcentricDisk
from .hemisphere import CosineHemisphere as CosineHemisphere
from .hemisphere import HemiOctahedral as HemiOctahedral
from .hemisphere import Octahedral as Octahedral
from .hemisphere import UniformHemisphere as UniformHemisphere
from .ltc import LTCPolygon as LTCPolygon
from .mis import balance_heuristic as balance_heuristic
from .mis import power_heuristic as power_heuristic
from .patch import BilinearPatch as BilinearPatch
from .patch import Parallelogram as Parallelogram
from .patch import TriangleArea as TriangleArea
from .patch import patch_area_warp as patch_area_warp
from .patch import patch_three_warp as patch_three_warp
from .planar import Bilinear as Bilinear
from .planar import Biquadratic as Biquadratic
from .planar import invert_linear_sample as invert_linear_sample
from .planar import linear_pdf as linear_pdf
from .planar import sample_linear as sample_linear
from .polygon import ProjectedSphericalPolygon as ProjectedSphericalPolygon
from .polygon import clip_to_horizon as clip_to_horizon
from .spherical import SphericalRectangle as SphericalRectangle
from .spherical import SphericalTriangle as SphericalTriangle
from .tabulated import Tabulated as Tabulated
from .tuning import chain_variance as chain_variance
from .tuning import fit_min_variance as fit_min_variance

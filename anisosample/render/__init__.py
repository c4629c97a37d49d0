"""The small JAX ray caster: direct illumination and depth of field, with each pixel's 2D
integrand exposed (W Sec. 6.2, H Sec. 4).

Scenes come from Mitsuba 3's XML format (:func:`load_xml`) or from :class:`SceneBuilder`;
:func:`pixel_integrand` gives ``f_q(x)`` of one pixel for the variance engine and the direction
estimator; :func:`render` renders images over realizations; :func:`save_result` writes EXR/PNG.
Per-block aligned sampling (W Sec. 5.3-5.4, with a per-pixel gate):
:mod:`anisosample.render.aligned` (the sampler), :mod:`anisosample.render.estimation` (the block
estimate and the gate), ``render(scene, key, sampler="aligned")``. Light warps (H Sec. 4):
``render(scene, key, technique=..., light_warp=...)`` with a name of :data:`LIGHT_WARPS`
(:mod:`anisosample.render.light_warps`). The integrator's options are one record,
:class:`IntegratorOptions` (:mod:`anisosample.render.options`). Scenes with many planar
primitives (meshes) are traced through a BVH (:mod:`anisosample.render.bvh`, built by
:meth:`SceneBuilder.build`).
"""

from . import aligned as aligned
from . import bvh as bvh
from . import direction_error as direction_error
from . import estimation as estimation
from . import light_warps as light_warps
from . import mitsuba_compat as mitsuba_compat
from . import options as options
from . import pixel_classes as pixel_classes
from .aligned import BlockSampler as BlockSampler
from .aligned import block_sampler as block_sampler
from .builder import SceneBuilder as SceneBuilder
from .camera import crop as crop
from .image import RenderResult as RenderResult
from .image import default_chunk_samples as default_chunk_samples
from .image import render as render
from .image import save_result as save_result
from .image import tonemap as tonemap
from .integrator import PixelIntegrand as PixelIntegrand
from .integrator import pixel_integrand as pixel_integrand
from .integrator import radiance as radiance
from .light_warps import LIGHT_WARPS as LIGHT_WARPS
from .light_warps import Receiver as Receiver
from .lights import TECHNIQUES as TECHNIQUES
from .options import IntegratorOptions as IntegratorOptions
from .scene import Scene as Scene
from .xml import RenderSettings as RenderSettings
from .xml import SceneFormatError as SceneFormatError
from .xml import load_xml as load_xml
from .xml import load_xml_with_settings as load_xml_with_settings

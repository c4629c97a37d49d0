"""The integrator's options as one record: :class:`IntegratorOptions` (issue 23).

What a render (and each pixel's 2D integrand) is asked to compute, beside the scene and the
sampler: which 2D dimension the sampler drives (``dimension``), the base light technique
(``technique``) and the warp chain in front of it (``light_warp``), whether one BSDF sample joins
the light sample (``mis``), whether the film position is the pixel centre (``pixel_center``) and
the thin lens's aperture shape (``square_aperture``). The record is immutable and checked once,
when it is made (each field's type and allowed values); :meth:`IntegratorOptions.for_scene`
resolves ``dimension="auto"`` and checks what depends on the scene (a lens dimension needs a
thin lens and point lights; a light warp must apply to every area light). Everything below
:func:`anisosample.render.render` and :func:`anisosample.render.pixel_integrand` takes the
resolved record, which is hashable and so a static argument of the jitted kernels.

``mis=True`` applies on either dimension: on ``dimension="lens"`` (point lights only) the BSDF
sample can reach no emitter and a delta light's weight is 1, so the estimate is the one without
MIS, bit for bit, at the cost of the BSDF ray (Mitsuba's ``direct`` integrator with
``bsdf_samples = 1`` does the same); the render records ``mis=True``.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .._validate import check_choice
from .light_warps import LIGHT_WARPS, check_light_warp, light_warp_name
from .lights import TECHNIQUES
from .scene import THINLENS, Scene

__all__ = ["DIMENSIONS", "IntegratorOptions", "default_dimension"]

DIMENSIONS = ("light", "lens")
"""The integrand dimensions a sampler can drive (module docstring of
:mod:`anisosample.render.integrator`)."""

_FLAGS = ("mis", "pixel_center", "square_aperture")


def default_dimension(scene: Scene) -> str:
    """``"lens"`` for a thin-lens scene lit by point lights only, else ``"light"``."""
    if scene.camera.projection == THINLENS and not scene.has_area_lights:
        return "lens"
    return "light"


@dataclasses.dataclass(frozen=True)
class IntegratorOptions:
    """The integrator's options (module docstring): immutable, validated when made.

    ``dimension``: ``"auto"`` (resolved per scene by :meth:`for_scene`), ``"light"`` or
    ``"lens"``; ``technique``: one of :data:`anisosample.render.lights.TECHNIQUES`;
    ``light_warp``: a name of :data:`anisosample.render.light_warps.LIGHT_WARPS` or your own
    ``make(base, receiver)``; ``mis``, ``pixel_center``, ``square_aperture``: ``True`` or
    ``False``. A bad value raises ``ValueError`` (a name not allowed) or ``TypeError`` (not a
    bool, not a name) naming the field and what it allows. Change fields with
    :meth:`replace` (a new, validated record).
    """

    # What the constructor takes; __post_init__ stores a str dimension (None: "auto") and bools.
    dimension: str | None = "auto"
    technique: str = "area"
    light_warp: object = "none"
    mis: bool | np.bool_ = False
    pixel_center: bool | np.bool_ = False
    square_aperture: bool | np.bool_ = False

    def __post_init__(self):
        dim = "auto" if self.dimension is None else self.dimension
        if not isinstance(dim, str):
            raise TypeError(f"dimension must be one of {['auto', *DIMENSIONS]}, got {dim!r}")
        check_choice("dimension", dim, ("auto", *DIMENSIONS))
        object.__setattr__(self, "dimension", dim)
        if not isinstance(self.technique, str):
            raise TypeError(f"technique must be one of {sorted(TECHNIQUES)}, got "
                            f"{self.technique!r}")
        check_choice("technique", self.technique, TECHNIQUES)
        if not callable(self.light_warp):
            if not isinstance(self.light_warp, str):
                raise TypeError(f"light_warp must be one of {sorted(LIGHT_WARPS)} or a callable "
                                f"make(base, receiver), got {self.light_warp!r}")
            check_choice("light_warp", self.light_warp, LIGHT_WARPS)
        for name in _FLAGS:
            value = getattr(self, name)
            if not isinstance(value, bool | np.bool_):
                raise TypeError(f"{name} must be True or False, got {value!r}")
            object.__setattr__(self, name, bool(value))

    def replace(self, **changes) -> IntegratorOptions:
        """A copy with ``changes`` (validated like a new record)."""
        return dataclasses.replace(self, **changes)

    def for_scene(self, scene: Scene) -> IntegratorOptions:
        """The record for ``scene``: ``dimension="auto"`` resolved (:func:`default_dimension`)
        and the scene's rules checked before tracing (``ValueError``): ``"lens"`` needs a
        thinlens sensor and point lights only; ``light_warp`` must apply to every area light
        (:func:`anisosample.render.light_warps.check_light_warp`)."""
        if not isinstance(scene, Scene):
            raise TypeError(f"scene must be an anisosample.render.Scene, got "
                            f"{type(scene).__name__}")
        dimension = default_dimension(scene) if self.dimension == "auto" else self.dimension
        check_light_warp(scene, self.light_warp)
        if dimension == "lens" and scene.camera.projection != THINLENS:
            raise ValueError("dimension='lens' needs a thinlens sensor; this scene's is "
                             "perspective")
        if dimension == "lens" and scene.has_area_lights:
            raise ValueError(
                "dimension='lens' needs a scene lit by point lights only (the light is"
                " connected deterministically, W Sec. 6.2); this one has area lights"
            )
        return self if dimension == self.dimension else self.replace(dimension=dimension)

    def integrand(self) -> IntegratorOptions:
        """The options of a pixel's 2D integrand ``f_q`` (:func:`anisosample.render.
        pixel_integrand`): these, with the film at the pixel centre and no BSDF sample (a 2D
        integrand has one sampling technique)."""
        return self.replace(mis=False, pixel_center=True)

    def settings(self) -> dict:
        """What a render records about them (EXR metadata): the fields, a callable
        ``light_warp`` by its name."""
        return dict(pixel_center=self.pixel_center, dimension=self.dimension,
                    technique=self.technique, light_warp=light_warp_name(self.light_warp),
                    mis=self.mis, square_aperture=self.square_aperture)

"""The scene: a PyTree of arrays that the JAX ray caster traces (intersection, BSDFs, lights).

Geometry is flattened to what the kernels need: planar primitives (OBJ meshes become
triangles; rectangles and cube faces one parallelogram each, where Mitsuba 3 uses two triangles),
analytic spheres, bilinear patches, a table of materials, a
table of light primitives (parallelograms, triangles, spheres, bilinear patches, points) grouped
into emitters, and one camera. How to render it (sample count, MIS) is not part of the scene:
those are keywords of :func:`~anisosample.render.render` (a file's own:
:class:`~anisosample.render.xml.RenderSettings`).
Use :class:`~anisosample.render.builder.SceneBuilder` to assemble a scene from Python, or
:func:`anisosample.render.load_xml` to read Mitsuba 3's XML format.

Conventions (Mitsuba 3): a rectangle is ``[-1, 1]^2 x {0}`` with normal +z before ``to_world``;
BSDFs are one-sided (black seen from the back) unless wrapped in ``twosided``; area emitters emit
from their front side only.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from .bvh import BVH
from .patch import Patches

# Materials (Materials.material).
DIFFUSE, CONDUCTOR, PLASTIC = 0, 1, 2
# Light primitive shapes (Lights.shape).
LIGHT_PARALLELOGRAM, LIGHT_TRIANGLE, LIGHT_SPHERE, LIGHT_POINT = 0, 1, 2, 3
LIGHT_PATCH = 4  # bilinear patch (render/patch.py)
LIGHT_SHAPE_NAMES = {0: "parallelogram", 1: "triangle", 2: "sphere", 3: "point",
                     4: "bilinear patch"}
# Camera projections (Camera.projection).
PERSPECTIVE, THINLENS = 0, 1
LUMINANCE = (0.212671, 0.715160, 0.072169)  # linear sRGB (Rec. 709) luminance weights


class Camera(eqx.Module):
    """Perspective or thin-lens camera (Mitsuba 3 ``perspective`` / ``thinlens``).

    Camera space: +z forward, +y up, +x *left* (Mitsuba's ``lookat``); film position
    ``(s, t)`` in ``[0, 1]^2`` with ``s`` to the right and ``t`` downwards (row 0 on top).
    """

    to_world: Float[Array, "4 4"]
    tan_half_fov_x: Float[Array, ""]
    aspect: Float[Array, ""]  # width / height
    aperture_radius: Float[Array, ""]
    focus_distance: Float[Array, ""]
    projection: int = eqx.field(static=True)  # PERSPECTIVE or THINLENS
    width: int = eqx.field(static=True)
    height: int = eqx.field(static=True)
    # The film's reconstruction filter (render/film.py): "box" or "gaussian" (with its stddev
    # in pixels), which decides where a pixel's samples land on the film.
    rfilter: str = eqx.field(static=True, default="box")
    rfilter_stddev: float = eqx.field(static=True, default=0.5)
    # The image's window of the whole film (Mitsuba's crop): (s0, t0, ds, dt), so that image
    # position (s, t) is film position (s0 + s ds, t0 + t dt); width x height are the window's
    # pixels (render/camera.py's crop). An array, not static: windows of one size share kernels.
    window: Float[Array, "4"] = eqx.field(
        default_factory=lambda: jnp.asarray([0.0, 0.0, 1.0, 1.0], jnp.float32))


class Materials(eqx.Module):
    """Material table, one row per material (H Sec. 4.3 uses GGX conductors and plastics)."""

    material: Int[Array, " m"]  # DIFFUSE, CONDUCTOR or PLASTIC
    reflectance: Float[Array, "m 3"]  # diffuse albedo (diffuse, plastic)
    specular: Float[Array, "m 3"]  # specular reflectance factor (conductor, plastic)
    alpha: Float[Array, " m"]  # GGX roughness (isotropic)
    eta: Float[Array, "m 3"]  # conductor: real IOR; plastic: relative IOR in channel 0
    k: Float[Array, "m 3"]  # conductor: imaginary IOR
    twosided: Int[Array, " m"]
    # roughplastic (Mitsuba 3; see render/plastic.py): the rough interface's external
    # transmittance tabulated over cos theta, internal reflectance, specular sampling weight,
    # flags (plastic.NONLINEAR | plastic.VISIBLE) and distribution (plastic.GGX / BECKMANN).
    transmittance: Float[Array, "m 64"]
    internal: Float[Array, " m"]
    spec_weight: Float[Array, " m"]
    flags: Int[Array, " m"]
    distribution: Int[Array, " m"]
    has_glossy: bool = eqx.field(static=True, default=True)  # any GGX material (else skip it)
    has_plastic: bool = eqx.field(static=True, default=False)  # any roughplastic


class Textures(eqx.Module):
    """Bitmaps used as emitted radiance, stacked and padded to one size (RGB, linear).

    Texel ``(y, x)`` of ``quad`` holds the four texels a bilinear lookup reads from it: its own,
    its right neighbour, the one below and the one below-right (wrapping around the texture's
    own size), so that a lookup is one gather (:func:`~anisosample.render.lights.
    texture_lookup`)."""

    quad: Float[Array, "t h w 12"]
    size: Int[Array, "t 2"]  # (w, h) of each texture's valid region


class Lights(eqx.Module):
    """Light primitives grouped into emitters.

    Every primitive has an origin ``p0``, two edge vectors ``e1``, ``e2`` (parallelogram
    ``p0 + a e1 + b e2``, triangle ``p0 + a e1 + b e2`` with ``a + b <= 1``; sphere: ``p0`` is
    the centre and ``e1[0]`` the radius; point: ``p0`` is the position), its area, the
    emitter it belongs to, its radiance (or intensity, for points) and an optional texture.
    Emitter ``e`` owns primitives ``start[e] .. start[e] + count[e] - 1`` whose selection
    probabilities (proportional to area) are ``prim_prob``.
    """

    shape: Int[Array, " l"]  # LIGHT_PARALLELOGRAM, ... (LIGHT_SHAPE_NAMES)
    p0: Float[Array, "l 3"]
    e1: Float[Array, "l 3"]
    e2: Float[Array, "l 3"]
    normal: Float[Array, "l 3"]
    area: Float[Array, " l"]
    uv0: Float[Array, "l 2"]
    uv1: Float[Array, "l 2"]
    uv2: Float[Array, "l 2"]
    radiance: Float[Array, "l 3"]
    texture: Int[Array, " l"]  # -1: constant radiance
    prim_prob: Float[Array, " l"]
    prim_cdf: Float[Array, " l"]  # inclusive CDF within the emitter
    emitter: Int[Array, " l"]
    start: Int[Array, " e"]
    count: Int[Array, " e"]
    delta: Int[Array, " e"]  # 1 for point emitters
    patch: Int[Array, " l"]  # bilinear patch lights: index into Scene.patches, else -1
    n_prims: int = eqx.field(static=True, default=0)  # static: 1 lets kernels skip selection
    shapes: tuple = eqx.field(static=True, default=(0, 1, 2, 3, 4))  # the shapes present


class Scene(eqx.Module):
    """A scene as a PyTree of arrays (see the module docstring)."""

    # Planar primitives p0 + a e1 + b e2: triangles (a + b <= 1) and parallelograms (a, b <= 1),
    # stored once, in the layouts the intersection kernel reads (builder._plane_rows).
    tri_soa: Float[Array, "13 t"]  # plane test rows: n, n.p0, r1, p0.r1, r2, p0.r2, parallelogram
    tri_attr: Float[Array, "t 9"]  # unit front normal n, uv0, uv1, uv2: one gather per hit
    tri_ids: Int[Array, "t 2"]  # material, light primitive (-1 if not emissive)
    # Spheres.
    sph_center: Float[Array, "s 3"]
    sph_radius: Float[Array, " s"]
    sph_material: Int[Array, " s"]
    sph_light: Int[Array, " s"]
    materials: Materials
    lights: Lights
    textures: Textures
    camera: Camera
    scale: Float[Array, ""]  # scene extent, for ray offsets
    patches: Patches  # bilinear patches (render/patch.py)
    # A BVH over the planar primitives (render/bvh.py), or None: every primitive is tested.
    bvh: BVH | None = None
    # Per-tile candidate primitives of brute force (render/culling.py), or None: render()
    # attaches them (culling.with_culling); every ray of a scene without them tests everything.
    culling: eqx.Module | None = None  # culling.TileCulling (culling imports this module)
    has_spheres: bool = eqx.field(static=True, default=True)
    has_textures: bool = eqx.field(static=True, default=True)
    has_patches: bool = eqx.field(static=True, default=False)

    @property
    def width(self) -> int:
        return self.camera.width

    @property
    def height(self) -> int:
        return self.camera.height

    @property
    def num_emitters(self) -> int:
        return int(self.lights.start.shape[0])

    @property
    def has_area_lights(self) -> bool:
        return bool(np.any(np.asarray(self.lights.delta) == 0))

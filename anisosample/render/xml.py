"""Loader for the subset of Mitsuba 3's XML scene format that the shipped scenes use.

Supported (everything else is an error naming the tag and line):

* ``<default name= value=>`` and ``$name`` substitution in attributes (overridable by keyword
  arguments of :func:`load_xml`, like ``mitsuba.load_file(path, **params)``); ``width``,
  ``height`` and ``spp`` also work on a file that declares no such parameter: they then set the
  film's size and the sampler's ``sample_count`` directly (so any scene can be rendered small);
* shapes ``rectangle``, ``cube``, ``sphere`` (``center``/``radius``; ``to_world`` with translation
  and uniform scale), ``obj`` (triangles; polygons are fanned; per-vertex normals only with
  ``face_normals="true"``); ``to_world`` built from ``translate``, ``rotate``, ``scale``,
  ``matrix`` and ``lookat``; ``flip_normals``; and, as **our extension** (Mitsuba 3 has no such
  shape), ``bilinear``: a bilinear patch with corners ``<point name="p00" .../>``, ``p10``,
  ``p01``, ``p11`` (default: Mitsuba's rectangle ``[-1, 1]^2 x {0}``), see render/patch.py;
* BSDFs ``diffuse``, ``roughconductor`` with ``distribution="ggx"`` and isotropic ``alpha``,
  ``roughplastic`` (``ggx`` or ``beckmann``, isotropic ``alpha``, ``int_ior``/``ext_ior`` as
  numbers or names, ``diffuse_reflectance``, ``specular_reflectance``, ``nonlinear``,
  ``sample_visible``), ``twosided``; declared at top level with ``id`` and used by
  ``<ref id=...>``;
* emitters ``area`` (constant ``radiance`` or an EXR ``bitmap`` texture) and ``point``;
* sensors ``perspective`` and ``thinlens`` with an ``hdrfilm`` (default 768 x 576; its
  ``crop_offset_x/y`` and ``crop_width/height`` render a window of the film:
  :func:`anisosample.render.camera.crop`) and a
  ``box`` or ``gaussian`` (``stddev``) ``rfilter``; a film without one, or a sensor without a
  film, gets Mitsuba's default, the gaussian with stddev 0.5 pixels, rendered by filter
  importance sampling (:mod:`anisosample.render.film`: Mitsuba's image in expectation, each
  pixel still an independent estimator of its own integral); the sampler's ``sample_count``
  becomes :attr:`RenderSettings.spp`;
* integrator ``direct`` (``emitter_samples`` = 1, ``bsdf_samples`` 0 or 1; ``bsdf_samples = 1``
  turns on MIS with one BSDF sample per light sample, :attr:`RenderSettings.mis`; other counts
  are refused: raise spp), or ``path`` with ``max_depth`` 2 (camera ray and one bounce:
  Mitsuba's direct illumination, read as ``direct`` with MIS); other depths, and ``path``'s
  default -1 (unlimited), are refused: there is no indirect light here.

The sample count and the integrator are render settings, not scene data: :func:`load_xml`
returns the :class:`~anisosample.render.scene.Scene` alone, :func:`load_xml_with_settings` the
scene and the file's :class:`RenderSettings`, which ``render(scene, key, **settings._asdict())``
applies (the CLI's ``anisosample render`` does, unless ``--spp`` / ``--mis`` say otherwise).
"""

from __future__ import annotations

import re
import xml.parsers.expat
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np

from .builder import SceneBuilder
from .camera import crop
from .film import GAUSSIAN_STDDEV, RFILTERS
from .obj import read_obj as _read_obj
from .scene import Scene


class RenderSettings(NamedTuple):
    """What a scene file says about *how* to render it (frozen; the scene itself is the
    :class:`~anisosample.render.scene.Scene`): the keywords of
    :func:`~anisosample.render.image.render` that it sets.

    ``spp``: the sensor's ``<sampler>`` ``sample_count`` (Mitsuba 3's default 4 when the
    sampler, or the count, is not given); ``mis``: the ``direct`` integrator's
    ``bsdf_samples = 1`` (one BSDF sample per light sample, combined by the power heuristic;
    Mitsuba's ``bsdf_samples`` defaults to ``shading_samples``, 1).
    """

    spp: int = 4
    mis: bool = True


class SceneFormatError(ValueError):
    """Malformed or unsupported scene description; the message names the file, line and tag."""


@dataclass
class _Node:
    tag: str
    attrs: dict
    line: int
    children: list = field(default_factory=list)


def _parse(path: Path) -> _Node:
    stack: list[_Node] = [_Node("#root", {}, 0)]
    parser = xml.parsers.expat.ParserCreate()

    def start(tag, attrs):
        node = _Node(tag, dict(attrs), parser.CurrentLineNumber)
        stack[-1].children.append(node)
        stack.append(node)

    def end(tag):
        stack.pop()

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    try:
        parser.Parse(path.read_bytes(), True)
    except xml.parsers.expat.ExpatError as exc:
        raise SceneFormatError(
            f"{path}:{exc.lineno}: malformed XML: {xml.parsers.expat.ErrorString(exc.code)}"
        ) from None
    root = stack[0].children
    if len(root) != 1 or root[0].tag != "scene":
        raise SceneFormatError(f"{path}:1: the root element must be <scene>")
    return root[0]


class _Ctx:
    def __init__(self, path: Path, params: dict):
        self.path = path
        self.dir = path.parent
        self.params = dict(params)
        self.bsdfs: dict[str, _Node] = {}
        self.settings = RenderSettings()
        self.size: dict[str, int] = {}  # film width/height set directly (no such parameter)
        self.crop = None  # (film node, its crop_* properties)

    def err(self, node: _Node, msg: str) -> SceneFormatError:
        t = node.attrs.get("type")
        tag = f"<{node.tag}" + (f' type="{t}"' if t else "") + ">"
        return SceneFormatError(f"{self.path}:{node.line}: {tag}: {msg}")

    def attr(self, node: _Node, name: str, default=None, required=False) -> str | None:
        if name not in node.attrs:
            if required:
                raise self.err(node, f"missing attribute {name!r}")
            return default
        value = node.attrs[name]

        def sub(m):
            key = m.group(1)
            if key not in self.params:
                raise self.err(node, f"undefined parameter ${key} (declare it with <default>)")
            return str(self.params[key])

        return re.sub(r"\$([A-Za-z_][A-Za-z0-9_]*)", sub, value)


def _floats(ctx, node, text: str, n: int | tuple) -> np.ndarray:
    try:
        vals = np.array([float(t) for t in re.split(r"[,\s]+", text.strip()) if t], np.float64)
    except ValueError:
        raise ctx.err(node, f"expected numbers, got {text!r}") from None
    ns = (n,) if isinstance(n, int) else n
    if vals.size not in ns:
        raise ctx.err(node, f"expected {' or '.join(map(str, ns))} numbers, got {text!r}")
    return vals


def _xyz(ctx, node, default=0.0) -> np.ndarray:
    if "value" in node.attrs:
        v = _floats(ctx, node, ctx.attr(node, "value"), (1, 3))
        return np.repeat(v, 3) if v.size == 1 else v
    out = []
    for a in "xyz":
        s = ctx.attr(node, a)
        try:
            out.append(default if s is None else float(s))
        except ValueError:
            raise ctx.err(node, f"attribute {a} must be a number, got {s!r}") from None
    return np.array(out)


def rotation(axis, angle_deg) -> np.ndarray:
    """The ``4 x 4`` matrix of Mitsuba's ``<rotate>``: ``angle_deg`` degrees about ``axis`` (a
    NumPy array of shape ``(3,)``, normalised here), counter-clockwise seen from its tip."""
    axis = axis / np.linalg.norm(axis)
    x, y, z = axis
    c, s = np.cos(np.radians(angle_deg)), np.sin(np.radians(angle_deg))
    r = np.array(
        [
            [c + x * x * (1 - c), x * y * (1 - c) - z * s, x * z * (1 - c) + y * s],
            [y * x * (1 - c) + z * s, c + y * y * (1 - c), y * z * (1 - c) - x * s],
            [z * x * (1 - c) - y * s, z * y * (1 - c) + x * s, c + z * z * (1 - c)],
        ]
    )
    m = np.eye(4)
    m[:3, :3] = r
    return m


def look_at(origin, target, up) -> np.ndarray:
    """The ``4 x 4`` matrix of Mitsuba's ``<lookat origin target up>`` (NumPy arrays of shape
    ``(3,)``): columns ``left = up x d``, ``d x left``, the unit view direction ``d`` and
    ``origin``. ``ValueError`` when ``origin`` and ``target`` coincide or ``up`` is parallel to
    the view direction."""
    d = target - origin
    if np.linalg.norm(d) == 0:
        raise ValueError("lookat origin and target coincide")
    d = d / np.linalg.norm(d)
    left = np.cross(up, d)
    if np.linalg.norm(left) == 0:
        raise ValueError("lookat up vector is parallel to the view direction")
    left = left / np.linalg.norm(left)
    new_up = np.cross(d, left)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, new_up, d, origin
    return m


def _transform(ctx: _Ctx, node: _Node) -> np.ndarray:
    m = np.eye(4)
    for c in node.children:
        if c.tag == "translate":
            t = np.eye(4)
            t[:3, 3] = _xyz(ctx, c)
            op = t
        elif c.tag == "scale":
            op = np.diag(np.append(_xyz(ctx, c, default=1.0), 1.0))
        elif c.tag == "rotate":
            angle = float(ctx.attr(c, "angle", required=True))
            axis = _xyz(ctx, c)
            if np.linalg.norm(axis) == 0:
                raise ctx.err(c, "rotation axis must be non-zero")
            op = rotation(axis, angle)
        elif c.tag == "matrix":
            v = _floats(ctx, c, ctx.attr(c, "value", required=True), (9, 16))
            if v.size == 9:
                op = np.eye(4)
                op[:3, :3] = v.reshape(3, 3)
            else:
                op = v.reshape(4, 4)
        elif c.tag == "lookat":
            o = _floats(ctx, c, ctx.attr(c, "origin", required=True), 3)
            t = _floats(ctx, c, ctx.attr(c, "target", required=True), 3)
            up = _floats(ctx, c, ctx.attr(c, "up", "0 1 0"), 3)
            try:
                op = look_at(o, t, up)
            except ValueError as exc:
                raise ctx.err(c, str(exc)) from None
        else:
            raise ctx.err(
                c,
                "unsupported transform operation (translate, rotate, scale, matrix,"
                " lookat are supported)",
            )
        m = op @ m
    if abs(np.linalg.det(m[:3, :3])) < 1e-300:
        raise ctx.err(node, "the transform is singular")
    return m


_VALUE_TAGS = (
    "integer",
    "float",
    "boolean",
    "string",
    "rgb",
    "spectrum",
    "point",
    "vector",
    "transform",
    "ref",
)
_OBJECT_TAGS = ("bsdf", "emitter", "texture", "film", "rfilter", "sampler", "shape")


def _props(ctx: _Ctx, node: _Node, allowed: dict[str, str]):
    """Parse child properties; ``allowed`` maps property name -> expected tag (or 'color')."""
    props: dict = {}
    objects: list[_Node] = []
    for c in node.children:
        if c.tag in _OBJECT_TAGS:
            if c.tag == "texture" and c.attrs.get("name") in allowed:
                props[c.attrs["name"]] = ("texture", c)
            else:
                objects.append(c)
            continue
        if c.tag == "ref":
            objects.append(c)
            continue
        if c.tag not in _VALUE_TAGS:
            raise ctx.err(c, "unsupported element")
        name = ctx.attr(c, "name", required=True)
        if name not in allowed:
            raise ctx.err(
                c,
                f"unsupported property {name!r} of <{node.tag} type="
                f'"{node.attrs.get("type")}"> (supported: {sorted(allowed)})',
            )
        want = allowed[name]
        if want == "ior" and c.tag in ("float", "string"):  # a number or a Mitsuba IOR name
            props[name] = ctx.attr(c, "value", required=True)
        elif want == "ior":
            raise ctx.err(c, f"property {name!r} must be a <float> or a <string> (an IOR name)")
        elif want == "color" and c.tag in ("rgb", "spectrum", "float"):
            v = _floats(ctx, c, ctx.attr(c, "value", required=True), (1, 3))
            props[name] = np.repeat(v, 3) if v.size == 1 else v
        elif want == "ignore":
            props[name] = None
        elif c.tag != want:
            raise ctx.err(c, f"property {name!r} must be a <{want}>, got <{c.tag}>")
        elif want == "transform":
            props[name] = _transform(ctx, c)
        elif want in ("point", "vector"):
            props[name] = _xyz(ctx, c)
        else:
            text = ctx.attr(c, "value", required=True)
            try:
                if want == "integer":
                    props[name] = int(text)
                elif want == "float":
                    props[name] = float(text)
                elif want == "boolean":
                    if text.lower() not in ("true", "false"):
                        raise ValueError
                    props[name] = text.lower() == "true"
                else:
                    props[name] = text
            except ValueError:
                raise ctx.err(c, f"property {name!r}: cannot read {text!r} as {want}") from None
    return props, objects


# --- plugins ------------------------------------------------------------------------------------


def _bsdf(ctx: _Ctx, b: SceneBuilder, node: _Node, twosided=False) -> int:
    if node.tag == "ref":
        rid = ctx.attr(node, "id", required=True)
        if rid not in ctx.bsdfs:
            raise ctx.err(node, f"unknown BSDF id {rid!r}")
        return _bsdf(ctx, b, ctx.bsdfs[rid], twosided)
    kind = ctx.attr(node, "type", required=True)
    if kind == "twosided":
        _, objs = _props(ctx, node, {})
        inner = [o for o in objs if o.tag in ("bsdf", "ref")]
        if len(inner) != 1:
            raise ctx.err(node, "twosided needs exactly one nested BSDF")
        return _bsdf(ctx, b, inner[0], True)
    if kind == "diffuse":
        props, objs = _props(ctx, node, {"reflectance": "color"})
        if isinstance(props.get("reflectance"), tuple):
            raise ctx.err(node, "textured reflectance is not supported")
        _no_objects(ctx, objs)
        return b.diffuse(props.get("reflectance", (0.5, 0.5, 0.5)), twosided=twosided)
    if kind == "roughconductor":
        props, objs = _props(
            ctx,
            node,
            {
                "distribution": "string",
                "alpha": "float",
                "eta": "color",
                "k": "color",
                "material": "string",
                "specular_reflectance": "color",
                "sample_visible": "boolean",
            },
        )
        _no_objects(ctx, objs)
        if props.get("distribution") != "ggx":
            raise ctx.err(
                node,
                'only distribution="ggx" is supported (Mitsuba\'s default is '
                'beckmann: write <string name="distribution" value="ggx"/>)',
            )
        if props.get("material", "none") != "none":
            raise ctx.err(node, "named conductor presets are not supported; give eta and k")
        alpha = props.get("alpha", 0.1)
        if not alpha > 0:
            raise ctx.err(node, f"alpha must be > 0, got {alpha}")
        return b.roughconductor(
            alpha,
            props.get("eta", (0.0, 0.0, 0.0)),
            props.get("k", 1.0),
            props.get("specular_reflectance", (1.0, 1.0, 1.0)),
            twosided=twosided,
        )
    if kind == "roughplastic":
        allowed = {"distribution": "string", "alpha": "float", "int_ior": "ior", "ext_ior": "ior",
                   "nonlinear": "boolean", "sample_visible": "boolean",
                   "diffuse_reflectance": "color", "specular_reflectance": "color"}
        props, objs = _props(ctx, node, allowed)
        _no_objects(ctx, objs)
        if any(isinstance(v, tuple) for v in props.values()):
            raise ctx.err(node, "textured reflectances are not supported")
        props.setdefault("distribution", "beckmann")  # Mitsuba's default (not ggx)
        try:
            return b.roughplastic(twosided=twosided, **props)
        except ValueError as exc:
            raise ctx.err(node, str(exc)) from None
    raise ctx.err(
        node, "unsupported BSDF plugin (diffuse, roughconductor, roughplastic, twosided)"
    )


def _no_objects(ctx, objs):
    if objs:
        raise ctx.err(objs[0], "unexpected nested element here")


def _texture(ctx: _Ctx, b: SceneBuilder, node: _Node) -> int:
    from .. import io

    if ctx.attr(node, "type") != "bitmap":
        raise ctx.err(node, "only bitmap textures are supported")
    props, objs = _props(
        ctx,
        node,
        {"filename": "string", "filter_type": "string", "wrap_mode": "string", "raw": "boolean"},
    )
    _no_objects(ctx, objs)
    if "filename" not in props:
        raise ctx.err(node, "missing filename")
    if (
        props.get("filter_type", "bilinear") != "bilinear"
        or props.get("wrap_mode", "repeat") != "repeat"
    ):
        raise ctx.err(node, "only filter_type=bilinear and wrap_mode=repeat are supported")
    fn = ctx.dir / props["filename"]
    if fn.suffix.lower() != ".exr":
        raise ctx.err(node, f"only EXR bitmaps are supported, got {fn.name}")
    if not fn.exists():
        raise ctx.err(node, f"file not found: {fn}")
    img = io.read_exr(fn)
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=-1)
    return b.texture(img[..., :3])


def _area_emitter(ctx: _Ctx, b: SceneBuilder, node: _Node):
    if ctx.attr(node, "type") != "area":
        raise ctx.err(node, "only area emitters can be attached to shapes")
    props, objs = _props(ctx, node, {"radiance": "color"})
    _no_objects(ctx, objs)
    rad = props.get("radiance", np.ones(3))
    if isinstance(rad, tuple):
        return None, _texture(ctx, b, rad[1])
    if np.any(rad < 0):
        raise ctx.err(node, f"radiance must be >= 0, got {rad.tolist()}")
    return rad, -1


_PATCH_CORNERS = {"p00": np.array([-1.0, -1, 0]), "p10": np.array([1.0, -1, 0]),
                  "p01": np.array([-1.0, 1, 0]), "p11": np.array([1.0, 1, 0])}


def _shape(ctx: _Ctx, b: SceneBuilder, node: _Node):
    kind = ctx.attr(node, "type", required=True)
    allowed = {"to_world": "transform", "flip_normals": "boolean"}
    if kind == "sphere":
        allowed |= {"center": "point", "radius": "float"}
    elif kind == "obj":
        allowed |= {"filename": "string", "face_normals": "boolean"}
    elif kind == "bilinear":  # our extension (render/patch.py)
        allowed |= dict.fromkeys(_PATCH_CORNERS, "point")
    elif kind not in ("rectangle", "cube"):
        raise ctx.err(node, "unsupported shape plugin (rectangle, cube, sphere, obj, bilinear)")
    props, objs = _props(ctx, node, allowed)
    mat, radiance, tex = None, None, -1
    for o in objs:
        if o.tag in ("bsdf", "ref"):
            if mat is not None:
                raise ctx.err(o, "a shape takes one BSDF")
            mat = _bsdf(ctx, b, o)
        elif o.tag == "emitter":
            radiance, tex = _area_emitter(ctx, b, o)
            if radiance is None and tex < 0:
                raise ctx.err(o, "emitter without radiance")
        else:
            raise ctx.err(o, "unexpected nested element in a shape")
    if mat is None:
        mat = b.diffuse((0.5, 0.5, 0.5))  # Mitsuba's default BSDF
    emissive = radiance is not None or tex >= 0
    if emissive and radiance is None:
        radiance = np.ones(3)
    m = props.get("to_world", np.eye(4))
    flip = props.get("flip_normals", False)
    try:
        if kind == "rectangle":
            b.rectangle(
                m, mat, radiance=radiance if emissive else None, texture=tex, flip_normals=flip
            )
        elif kind == "bilinear":
            if tex >= 0:
                raise ValueError("textured emitters are supported on rectangles only")
            c = [m[:3, :3] @ props.get(k, v) + m[:3, 3] for k, v in _PATCH_CORNERS.items()]
            b.bilinear_patch(np.array([[c[0], c[2]], [c[1], c[3]]]), mat,
                             radiance=radiance if emissive else None, flip_normals=flip)
        elif kind == "cube":
            if tex >= 0:
                raise ValueError("textured emitters are supported on rectangles only")
            b.cube(m, mat, radiance=radiance if emissive else None, flip_normals=flip)
        elif kind == "sphere":
            a = m[:3, :3]
            s = np.cbrt(abs(np.linalg.det(a)))
            if not np.allclose(a, s * np.eye(3), atol=1e-9 * max(s, 1)):
                raise ValueError("sphere to_world may only translate and scale uniformly")
            center = m[:3, :3] @ props.get("center", np.zeros(3)) + m[:3, 3]
            if tex >= 0:
                raise ValueError("textured emitters are supported on rectangles only")
            b.sphere(
                center, s * props.get("radius", 1.0), mat, radiance=radiance if emissive else None
            )
        else:
            if "filename" not in props:
                raise ValueError("missing filename")
            v, uv, f, has_vn = _read_obj(ctx.dir / props["filename"])
            if has_vn and not props.get("face_normals", False):
                raise ValueError(
                    "OBJ vertex normals (shading normals) are not supported; set "
                    '<boolean name="face_normals" value="true"/>'
                )
            v = (m[:3, :3] @ v.T).T + m[:3, 3]
            b.triangles(
                v,
                f,
                mat,
                uvs=uv,
                radiance=radiance if emissive else None,
                texture=tex,
                flip_normals=flip,
            )
    except (ValueError, FileNotFoundError) as exc:
        raise ctx.err(node, str(exc)) from None


def _sensor(ctx: _Ctx, b: SceneBuilder, node: _Node):
    kind = ctx.attr(node, "type", required=True)
    allowed = {
        "to_world": "transform",
        "fov": "float",
        "fov_axis": "string",
        "near_clip": "float",
        "far_clip": "float",
    }
    if kind == "thinlens":
        allowed |= {"aperture_radius": "float", "focus_distance": "float"}
    elif kind != "perspective":
        raise ctx.err(node, "unsupported sensor plugin (perspective, thinlens)")
    props, objs = _props(ctx, node, allowed)
    width, height = 768, 576  # Mitsuba's hdrfilm defaults
    rfilter = ("gaussian", GAUSSIAN_STDDEV)  # Mitsuba's default reconstruction filter
    for o in objs:
        if o.tag == "film":
            if ctx.attr(o, "type") != "hdrfilm":
                raise ctx.err(o, "only hdrfilm is supported")
            fp, fo = _props(
                ctx,
                o,
                {
                    "width": "integer",
                    "height": "integer",
                    "pixel_format": "string",
                    "component_format": "string",
                    "file_format": "string",
                    "crop_offset_x": "integer",
                    "crop_offset_y": "integer",
                    "crop_width": "integer",
                    "crop_height": "integer",
                },
            )
            width, height = fp.get("width", width), fp.get("height", height)
            if any(k.startswith("crop_") for k in fp):
                ctx.crop = (o, {k: fp[k] for k in fp if k.startswith("crop_")})
            if width < 1 or height < 1:
                raise ctx.err(o, f"film size must be positive, got {width}x{height}")
            if any(r.tag != "rfilter" for r in fo) or len(fo) > 1:
                raise ctx.err(o, "a film takes one nested <rfilter> and nothing else")
            if fo:
                rfilter = _rfilter(ctx, fo[0])
        elif o.tag == "sampler":
            sp, so = _props(ctx, o, {"sample_count": "integer", "seed": "integer"})
            _no_objects(ctx, so)
            spp = sp.get("sample_count", RenderSettings().spp)
            if spp < 1:
                raise ctx.err(o, f"sample_count must be >= 1, got {spp}")
            ctx.settings = ctx.settings._replace(spp=int(spp))
        else:
            raise ctx.err(o, "unexpected nested element in a sensor")
    if "fov" not in props:
        raise ctx.err(node, "missing fov")
    fov = props["fov"]
    if not 0 < fov < 180:
        raise ctx.err(node, f"fov must lie in (0, 180) degrees, got {fov}")
    ar = props.get("aperture_radius", 0.0)
    fd = props.get("focus_distance", 0.0)
    if kind == "thinlens" and not (ar > 0 and fd > 0):
        raise ctx.err(node, "thinlens needs aperture_radius > 0 and focus_distance > 0")
    width = ctx.size.get("width", width)  # --set width=... on a file without that parameter
    height = ctx.size.get("height", height)
    m = props.get("to_world", np.eye(4))
    try:
        b.camera(
            m,
            width=width,
            height=height,
            rfilter=rfilter[0],
            rfilter_stddev=rfilter[1],
            fov=fov,
            fov_axis=props.get("fov_axis", "x"),
            aperture_radius=ar,
            focus_distance=fd,
            thinlens=kind == "thinlens",
        )
    except ValueError as exc:
        raise ctx.err(node, str(exc)) from None


_SIZE_OVERRIDES = ("width", "height", "spp")


def _positive_int(path: Path, name: str, value) -> int:
    try:
        v = int(str(value).strip())
    except ValueError:
        raise ValueError(f"{path.name}: override {name} must be an integer >= 1, got "
                         f"{value!r}") from None
    if v < 1:
        raise ValueError(f"{path.name}: override {name} must be an integer >= 1, got {v}")
    return v


def _path_integrator(ctx: _Ctx, node: _Node) -> bool:
    """Mitsuba 3's ``path`` integrator at ``max_depth`` 2: the renderer's direct illumination
    with MIS (returned: True). Mitsuba's ``max_depth`` is the longest path depth, -1 unlimited
    (its default): 1 renders only directly visible emitters, 2 "single-bounce (direct-only)
    illumination" (docs of ``src/integrators/path.cpp``). At depth 2 the path tracer takes, at
    the camera ray's hit, one emitter sample and one BSDF sample combined with the power
    heuristic (its ``mis_weight``), and no further vertex: Mitsuba's ``direct`` integrator with
    ``emitter_samples = bsdf_samples = 1``, which is ``mis=True`` here. Russian roulette starts
    after ``rr_depth`` bounces and so never acts at depth 2; ``rr_depth`` is read and unused.
    Other depths (and the default -1) are refused: this renderer has no indirect light."""
    props, objs = _props(ctx, node, {"max_depth": "integer", "rr_depth": "integer",
                                     "hide_emitters": "ignore"})
    _no_objects(ctx, objs)
    depth = props.get("max_depth", -1)
    if depth != 2:
        what = "-1 (unlimited, Mitsuba's default)" if depth == -1 else str(depth)
        raise ctx.err(node, f"max_depth {what} is not supported: this renderer computes direct "
                            "illumination only, which is the path integrator with max_depth 2 "
                            '(write <integer name="max_depth" value="2"/>, or use the direct '
                            "integrator)")
    return True


def _rfilter(ctx: _Ctx, node: _Node) -> tuple[str, float]:
    """``<rfilter type="box"/>`` or ``<rfilter type="gaussian">`` (``stddev``, default 0.5):
    ``(name, stddev)`` for :mod:`anisosample.render.film`."""
    kind = ctx.attr(node, "type", required=True)
    if kind == "box":
        _, objs = _props(ctx, node, {})
        _no_objects(ctx, objs)
        return "box", GAUSSIAN_STDDEV
    if kind == "gaussian":
        props, objs = _props(ctx, node, {"stddev": "float"})
        _no_objects(ctx, objs)
        stddev = props.get("stddev", GAUSSIAN_STDDEV)
        if not (np.isfinite(stddev) and stddev > 0):
            raise ctx.err(node, f"stddev must be > 0 (pixels), got {stddev}")
        return "gaussian", stddev
    raise ctx.err(node, f"unsupported reconstruction filter (supported: {', '.join(RFILTERS)})")


def load_xml(path, *, bvh: bool | None = None, **params) -> Scene:
    """Load a Mitsuba 3 XML scene (see the module docstring for the supported subset).

    Returns the scene alone; :func:`load_xml_with_settings` also returns the file's sample
    count and MIS setting (:class:`RenderSettings`). Keyword arguments override ``<default>``
    parameters (``load_xml(p, spp=16)``); a name the file neither defaults nor references
    (``$name``) is a ``ValueError`` listing the known ones. ``bvh``: as
    :meth:`SceneBuilder.build` (``None``: a BVH from
    :data:`~anisosample.render.bvh.THRESHOLD` planar primitives; ``False``: test every
    primitive, e.g. to time the BVH against brute force).
    Raises :class:`SceneFormatError` (a ``ValueError``) naming the file, line and tag, or
    ``FileNotFoundError``.
    """
    return load_xml_with_settings(path, bvh=bvh, **params)[0]


def load_xml_with_settings(path, *, bvh: bool | None = None,
                           **params) -> tuple[Scene, RenderSettings]:
    """:func:`load_xml`, and the file's :class:`RenderSettings` (sample count, MIS):
    ``scene, settings = load_xml_with_settings(p); render(scene, key, **settings._asdict())``
    renders as the file says (Mitsuba's ``mi.render(mi.load_file(p))``)."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no such scene file: {path}")
    root = _parse(path)
    ctx = _Ctx(path, {})
    for c in root.children:
        if c.tag == "default":
            name = c.attrs.get("name")
            if name is None or "value" not in c.attrs:
                raise ctx.err(c, "<default> needs name and value")
            ctx.params.setdefault(name, c.attrs["value"])
    # An override must name a parameter of the file: a <default> or a $name it references;
    # width, height and spp also resize a file that has no such parameter (_SIZE_OVERRIDES).
    known = set(ctx.params) | set(re.findall(r"\$([A-Za-z_]\w*)", path.read_text(errors="replace")))
    params = dict(params)
    for name in sorted(set(_SIZE_OVERRIDES) & set(params) - known):
        ctx.size[name] = _positive_int(path, name, params.pop(name))
    unknown = sorted(set(params) - known)
    if unknown:
        raise ValueError(
            f"{path.name}: unknown parameter override {', '.join(map(repr, unknown))}; this scene"
            f" has {', '.join(sorted(known)) or 'no parameters'} (and width, height and spp"
            " always set the film size and the sample count)"
        )
    ctx.params.update({k: str(v) for k, v in params.items()})
    b = SceneBuilder()
    sensors = integrators = 0
    for c in root.children:
        if c.tag == "default":
            continue
        if c.tag == "bsdf":
            bid = ctx.attr(c, "id")
            if bid is None:
                raise ctx.err(c, "a top-level BSDF needs an id")
            ctx.bsdfs[bid] = c
        elif c.tag == "shape":
            _shape(ctx, b, c)
        elif c.tag == "emitter":
            kind = ctx.attr(c, "type")
            if kind != "point":
                raise ctx.err(
                    c, "unsupported top-level emitter (point; area emitters go inside a shape)"
                )
            props, objs = _props(
                ctx, c, {"position": "point", "intensity": "color", "to_world": "transform"}
            )
            _no_objects(ctx, objs)
            pos = props.get("position", np.zeros(3))
            if "to_world" in props:
                pos = props["to_world"][:3, :3] @ pos + props["to_world"][:3, 3]
            inten = props.get("intensity", np.ones(3))
            if np.any(inten < 0):
                raise ctx.err(c, "intensity must be >= 0")
            b.point_light(pos, inten)
        elif c.tag == "sensor":
            sensors += 1
            if sensors > 1:
                raise ctx.err(c, "only one sensor is supported")
            _sensor(ctx, b, c)
        elif c.tag == "integrator" and ctx.attr(c, "type") == "path":
            integrators += 1
            ctx.settings = ctx.settings._replace(mis=_path_integrator(ctx, c))
        elif c.tag == "integrator":
            integrators += 1
            if ctx.attr(c, "type") != "direct":
                raise ctx.err(c, "unsupported integrator (direct, or path with max_depth 2)")
            props, objs = _props(
                ctx,
                c,
                {
                    "emitter_samples": "integer",
                    "bsdf_samples": "integer",
                    "shading_samples": "integer",
                    "hide_emitters": "ignore",
                },
            )
            _no_objects(ctx, objs)
            s = props.get("shading_samples", 1)
            emitter_samples = props.get("emitter_samples", s)
            bsdf_samples = props.get("bsdf_samples", s)
            if emitter_samples != 1 or bsdf_samples not in (0, 1):
                # Each pixel sample is one point of the sampler under study (one light sample,
                # W Eq. 8 / H Sec. 4): more emitter or BSDF samples per pixel sample would not
                # change the converged image, only hide the sampler; raise spp instead.
                raise ctx.err(c, "emitter_samples must be 1 and bsdf_samples 0 or 1 here (one "
                                 "light sample and at most one BSDF sample per pixel sample; "
                                 "raise the sample count instead), got "
                                 f"{emitter_samples} and {bsdf_samples}")
            ctx.settings = ctx.settings._replace(mis=bsdf_samples == 1)
        else:
            raise ctx.err(c, "unsupported element")
    if integrators == 0:
        raise SceneFormatError(
            f'{path}: the scene needs <integrator type="direct"> or <integrator type="path"> with'
            ' <integer name="max_depth" value="2"/> (Mitsuba\'s default integrator is the path'
            " tracer with max_depth -1, unlimited; this renderer computes direct illumination)"
        )
    if sensors == 0:
        raise SceneFormatError(f"{path}: the scene has no <sensor>")
    if "spp" in ctx.size:
        ctx.settings = ctx.settings._replace(spp=ctx.size["spp"])
    try:
        scene = b.build(bvh=bvh)
    except ValueError as exc:
        raise SceneFormatError(f"{path}: {exc}") from None
    if ctx.crop is not None:  # Mitsuba's defaults: from the corner to the film's far edges
        node, c = ctx.crop
        x, y = c.get("crop_offset_x", 0), c.get("crop_offset_y", 0)
        size = (c.get("crop_width", scene.width - x), c.get("crop_height", scene.height - y))
        try:
            scene = crop(scene, (x, y), size)
        except ValueError as exc:
            raise ctx.err(node, str(exc)) from None
    return scene, ctx.settings

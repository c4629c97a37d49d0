"""Assembling a :class:`~anisosample.render.scene.Scene` from Python: :class:`SceneBuilder`.

Shapes (rectangles, cubes, triangle meshes, spheres, bilinear patches), materials (``diffuse``,
``roughconductor``, ``roughplastic``), area and point emitters and a camera are collected in
Python lists and flattened by :meth:`SceneBuilder.build` into the scene's arrays. The XML loader
(:func:`anisosample.render.load_xml`) drives the same builder. Conventions as in
:mod:`anisosample.render.scene` (Mitsuba 3's).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from . import bvh as _bvh
from .patch import PatchRecord, build_patches, check_corners
from .scene import (
    CONDUCTOR,
    DIFFUSE,
    LIGHT_PARALLELOGRAM,
    LIGHT_PATCH,
    LIGHT_POINT,
    LIGHT_SPHERE,
    LIGHT_TRIANGLE,
    PERSPECTIVE,
    PLASTIC,
    THINLENS,
    Camera,
    Lights,
    Materials,
    Scene,
    Textures,
)


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v)
    return v / n if n > 0 else v


def _transform_point(m: np.ndarray, p) -> np.ndarray:
    p = np.asarray(p, np.float64)
    h = m @ np.append(p, 1.0)
    return h[:3] / h[3]


def _transform_normal(m: np.ndarray, n) -> np.ndarray:
    return _unit(np.linalg.inv(m[:3, :3]).T @ np.asarray(n, np.float64))


@dataclass
class _Material:
    material: int
    reflectance: tuple = (0.5, 0.5, 0.5)
    specular: tuple = (1.0, 1.0, 1.0)
    alpha: float = 0.1
    eta: tuple = (0.0, 0.0, 0.0)
    k: tuple = (1.0, 1.0, 1.0)
    twosided: bool = False
    transmittance: tuple = (1.0,) * 64  # roughplastic constants (render/plastic.py)
    internal: float = 0.0
    spec_weight: float = 0.5
    flags: int = 0
    distribution: int = 0


class Planar(NamedTuple):
    """A block of ``k`` planar primitives ``p0 + a e1 + b e2`` (``p1 = p0 + e1``, ``p2 = p0 +
    e2``), every field with a leading axis of ``k``: triangles (``a + b <= 1``) or, where
    ``parallelogram``, parallelograms (``a, b <= 1``). A mesh is one block (no per-triangle
    records), so building a million-triangle scene is a few array operations."""

    p0: np.ndarray  # (k, 3)
    p1: np.ndarray
    p2: np.ndarray
    normal: np.ndarray  # (k, 3)
    uv0: np.ndarray  # (k, 2)
    uv1: np.ndarray
    uv2: np.ndarray
    material: np.ndarray  # (k,) int
    light: np.ndarray  # (k,) light primitive, -1 if not emissive
    parallelogram: np.ndarray  # (k,) bool

    @classmethod
    def one(cls, p0, p1, p2, normal, uv0, uv1, uv2, material, light, parallelogram):
        """A block of one primitive."""
        f = lambda a: np.asarray(a, np.float64)[None]  # noqa: E731
        return cls(f(p0), f(p1), f(p2), f(normal), f(uv0), f(uv1), f(uv2),
                   np.array([material]), np.array([light]), np.array([parallelogram], bool))

class SphereRecord(NamedTuple):
    """An analytic sphere of the builder."""

    center: np.ndarray
    radius: float
    material: int
    light: int


class EmitterRecord(NamedTuple):
    """An emitter: its light primitives ``start .. start + count - 1``."""

    start: int  # first light primitive
    count: int
    delta: int  # 1 for point lights


@dataclass
class SceneBuilder:
    """Collects shapes, materials, emitters and a camera, then :meth:`build` s a :class:`Scene`.

    Shapes take a 4x4 ``to_world`` matrix (numpy, float64) as in Mitsuba 3.
    """

    _tris: list = field(default_factory=list)  # Planar blocks
    _spheres: list = field(default_factory=list)  # SphereRecord
    _patches: list = field(default_factory=list)  # PatchRecord
    _materials: list = field(default_factory=list)
    _lights: list = field(default_factory=list)  # blocks of light primitives (_light_block)
    _emitters: list = field(default_factory=list)  # EmitterRecord
    _textures: list = field(default_factory=list)
    _camera: dict | None = None

    # materials ----------------------------------------------------------------------------------
    def diffuse(self, reflectance=(0.5, 0.5, 0.5), *, twosided=False) -> int:
        """Lambertian BSDF ``reflectance / pi`` (Mitsuba ``diffuse``); returns its index."""
        self._materials.append(
            _Material(DIFFUSE, reflectance=tuple(_rgb(reflectance)), twosided=twosided)
        )
        return len(self._materials) - 1

    def roughconductor(self, alpha, eta, k, specular=(1.0, 1.0, 1.0), *, twosided=False) -> int:
        """GGX rough conductor (Mitsuba ``roughconductor``, ``distribution="ggx"``)."""
        self._materials.append(
            _Material(
                CONDUCTOR,
                specular=tuple(_rgb(specular)),
                alpha=float(alpha),
                eta=tuple(_rgb(eta)),
                k=tuple(_rgb(k)),
                twosided=twosided,
            )
        )
        return len(self._materials) - 1

    def roughplastic(
        self,
        alpha=0.1,
        *,
        int_ior=1.49,
        ext_ior=1.000277,
        diffuse_reflectance=(0.5, 0.5, 0.5),
        specular_reflectance=(1.0, 1.0, 1.0),
        distribution="beckmann",
        nonlinear=False,
        sample_visible=True,
        twosided=False,
    ) -> int:
        """Rough plastic (Mitsuba 3 ``roughplastic``; IORs as numbers or Mitsuba's names).

        The defaults are Mitsuba's, including ``distribution="beckmann"`` (pass ``"ggx"``).
        Raises ``ValueError`` naming a bad parameter (see :func:`plastic.make_params`).
        """
        from . import plastic

        p = plastic.make_params(
            alpha=alpha,
            int_ior=int_ior,
            ext_ior=ext_ior,
            diffuse_reflectance=_rgb(diffuse_reflectance),
            specular_reflectance=_rgb(specular_reflectance),
            distribution=distribution,
            nonlinear=bool(nonlinear),
            sample_visible=bool(sample_visible),
        )
        self._materials.append(
            _Material(
                PLASTIC,
                reflectance=tuple(_rgb(diffuse_reflectance)),
                specular=tuple(_rgb(specular_reflectance)),
                alpha=p["alpha"],
                eta=(p["eta"],) * 3,
                twosided=twosided,
                transmittance=p["transmittance"],
                internal=p["internal"],
                spec_weight=p["spec_weight"],
                flags=p["flags"],
                distribution=p["distribution"],
            )
        )
        return len(self._materials) - 1

    # emitters -----------------------------------------------------------------------------------
    def texture(self, rgb_image: np.ndarray) -> int:
        img = np.asarray(rgb_image, np.float32)
        if img.ndim != 3 or img.shape[2] != 3 or img.shape[0] < 1 or img.shape[1] < 1:
            raise ValueError(f"texture must have shape (h, w, 3), got {img.shape}")
        self._textures.append(img)
        return len(self._textures) - 1

    def _add_emitter(self, prims: dict, delta: bool) -> np.ndarray:
        """One emitter of the light primitives ``prims`` (a :func:`_light_block`), picked by
        area (each with probability 1 if ``delta``); returns their indices."""
        start = sum(len(b["shape"]) for b in self._lights)
        areas = np.asarray(prims["area"], np.float64)
        if not delta:
            if not np.all(np.isfinite(areas)) or areas.sum() <= 0:
                raise ValueError(
                    f"an area emitter must have a positive total area, got {areas.sum()}"
                )
            prob = areas / areas.sum()
        else:
            prob = np.ones(len(areas))
        cdf = np.cumsum(prob)
        cdf[-1] = 1.0
        e = len(self._emitters)
        self._lights.append({**prims, "prob": prob, "cdf": cdf,
                             "emitter": np.full(len(areas), e)})
        self._emitters.append(EmitterRecord(start, len(areas), int(delta)))
        return np.arange(start, start + len(areas))

    def point_light(self, position, intensity) -> None:
        """Isotropic point light of radiant intensity ``intensity`` (W/sr, RGB)."""
        self._add_emitter(
            _light_block(LIGHT_POINT, np.asarray(position, np.float64), np.zeros(3), np.zeros(3),
                         np.zeros(3), 0.0, _rgb(intensity), -1),
            delta=True,
        )

    # shapes -------------------------------------------------------------------------------------
    def rectangle(
        self, to_world, material: int, *, radiance=None, texture: int = -1, flip_normals=False
    ) -> None:
        """Mitsuba ``rectangle``: ``[-1,1]^2`` at z = 0, normal +z, uv = ((x+1)/2, (y+1)/2)."""
        m = np.asarray(to_world, np.float64)
        c = _transform_point(m, (-1, -1, 0))
        e1 = _transform_point(m, (1, -1, 0)) - c
        e2 = _transform_point(m, (-1, 1, 0)) - c
        n = _transform_normal(m, (0, 0, 1)) * (-1 if flip_normals else 1)
        light = -1
        if radiance is not None or texture >= 0:
            area = float(np.linalg.norm(np.cross(e1, e2)))
            if not area > 0:
                raise ValueError("rectangle emitter has zero area (degenerate to_world)")
            rad = _rgb(radiance if radiance is not None else (1.0, 1.0, 1.0))
            (light,) = self._add_emitter(
                _light_block(LIGHT_PARALLELOGRAM, c, e1, e2, n, area, rad, texture,
                             uv=((0, 0), (1, 0), (0, 1))),
                delta=False,
            )
        # One parallelogram primitive (Mitsuba splits it into two triangles; one test is cheaper).
        self._tris.append(
            Planar.one(c, c + e1, c + e2, n, (0, 0), (1, 0), (0, 1), material, light, True))

    def triangles(
        self,
        vertices,
        faces,
        material: int,
        *,
        uvs=None,
        radiance=None,
        texture: int = -1,
        flip_normals=False,
    ) -> None:
        """A triangle mesh (world-space ``vertices`` (v, 3), ``faces`` (f, 3)).

        Face normals are ``(p1 - p0) x (p2 - p0)`` normalised (Mitsuba's geometric normal).
        Triangles of zero area (collinear vertices) are dropped; an emissive mesh becomes one
        emitter whose triangles are picked by area, and may have none. Vectorised: one array
        operation per step over all faces. Raises ``ValueError`` for ``vertices`` not ``(v, 3)``
        or ``faces`` not ``(f, 3)``.
        """
        v = np.asarray(vertices, np.float64)
        f = np.asarray(faces, np.int64)
        if f.size == 0:
            f = f.reshape(0, 3)
        if v.ndim != 2 or v.shape[1] != 3:
            raise ValueError(f"vertices must have shape (v, 3), got {v.shape}")
        if f.ndim != 2 or f.shape[1] != 3:
            raise ValueError(f"faces must have shape (f, 3), got {f.shape}")
        if uvs is None:
            uvs = np.zeros((len(v), 2))
        uvs = np.asarray(uvs, np.float64)
        p0, p1, p2 = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
        cr = np.cross(p1 - p0, p2 - p0)
        norm = np.linalg.norm(cr, axis=-1)
        area = 0.5 * norm
        longest = np.maximum(np.maximum(np.sum((p1 - p0) ** 2, -1), np.sum((p2 - p0) ** 2, -1)),
                             np.sum((p2 - p1) ** 2, -1))
        keep = area > 1e-12 * longest  # not collinear (or coincident) vertices
        emissive = radiance is not None or texture >= 0
        if emissive and not keep.all():
            i = int(np.argmin(keep))
            raise ValueError(
                f"triangle light: face {i}"
                f" (vertices {f[i].tolist()}) has zero area (collinear vertices);"
                " an emitter needs triangles of positive area"
            )
        if emissive and not keep.any():
            raise ValueError("mesh emitter has zero area")
        f, p0, p1, p2 = f[keep], p0[keep], p1[keep], p2[keep]  # degenerate ones are never hit
        n = cr[keep] / norm[keep][:, None] * (-1 if flip_normals else 1)
        uv = uvs[f]  # (k, 3 corners, 2)
        lights = np.full(len(f), -1)
        if emissive:
            lights = self._add_emitter(
                _light_block(LIGHT_TRIANGLE, p0, p1 - p0, p2 - p0, n, area[keep],
                             _rgb(radiance if radiance is not None else (1, 1, 1)), texture,
                             uv=uv),
                delta=False,
            )
        if len(f):
            self._tris.append(Planar(p0, p1, p2, n, uv[:, 0], uv[:, 1], uv[:, 2],
                                     np.full(len(f), material), lights, np.zeros(len(f), bool)))

    def cube(self, to_world, material: int, *, radiance=None, flip_normals=False) -> None:
        """Mitsuba ``cube``: ``[-1, 1]^3`` with outward normals.

        Six parallelogram faces; an emissive cube is 12 triangles (one emitter picked by area, as
        Mitsuba's triangle mesh).
        """
        m = np.asarray(to_world, np.float64)
        faces = []  # (p0, e1, e2) with e1 x e2 along the outward normal
        for axis in range(3):
            for sign in (-1.0, 1.0):
                a, b = (axis + 1) % 3, (axis + 2) % 3
                corner = np.zeros(3)
                corner[axis], corner[a], corner[b] = sign, -1.0, -1.0
                p0 = _transform_point(m, corner)
                e1 = _transform_point(m, corner + 2 * np.eye(3)[a]) - p0
                e2 = _transform_point(m, corner + 2 * np.eye(3)[b]) - p0
                if np.dot(np.cross(e1, e2), _transform_normal(m, np.eye(3)[axis] * sign)) < 0:
                    e1, e2 = e2, e1
                faces.append((p0, e1, e2))
        if radiance is None:
            for p0, e1, e2 in faces:
                cr = np.cross(e1, e2)
                if np.linalg.norm(cr) > 0:
                    n = _unit(cr) * (-1 if flip_normals else 1)
                    self._tris.append(Planar.one(p0, p0 + e1, p0 + e2, n, (0, 0), (0, 0),
                                                 (0, 0), material, -1, True))
            return
        verts = [v for p0, e1, e2 in faces for v in (p0, p0 + e1, p0 + e1 + e2, p0 + e2)]
        tris = [(4 * f + i, 4 * f + j, 4 * f + k) for f in range(6) for i, j, k in ((0, 1, 2),
                                                                                     (0, 2, 3))]
        self.triangles(
            np.array(verts), np.array(tris), material, radiance=radiance, flip_normals=flip_normals
        )

    def sphere(self, center, radius, material: int, *, radiance=None) -> None:
        radius = float(radius)
        if not radius > 0:
            raise ValueError(f"sphere radius must be > 0, got {radius}")
        light = -1
        if radiance is not None:
            (light,) = self._add_emitter(
                _light_block(LIGHT_SPHERE, np.asarray(center, np.float64),
                             np.array([radius, 0, 0]), np.zeros(3), np.zeros(3),
                             4 * np.pi * radius**2, _rgb(radiance), -1),
                delta=False,
            )
        self._spheres.append(SphereRecord(np.asarray(center, np.float64), radius, material, light))

    def bilinear_patch(self, corners, material: int, *, radiance=None, flip_normals=False) -> None:
        """A bilinear patch, ``corners[i, j] = p_ij`` (world space, shape (2, 2, 3)), front side
        along ``p_u x p_v``; ``flip_normals`` swaps ``u`` and ``v`` (render/patch.py, H Sec. 4.2).
        An emissive patch is one emitter. Raises ``ValueError`` for a degenerate patch."""
        c, area = check_corners(corners)
        if flip_normals:
            c = c.transpose(1, 0, 2)
        light = -1
        if radiance is not None:
            row = _light_block(LIGHT_PATCH, c[0, 0], c[1, 0] - c[0, 0], c[0, 1] - c[0, 0],
                               np.zeros(3), area, _rgb(radiance), -1, patch=len(self._patches))
            (light,) = self._add_emitter(row, delta=False)
        self._patches.append(PatchRecord(c, material, light))

    # camera -------------------------------------------------------------------------------------
    def camera(
        self,
        to_world,
        *,
        width: int,
        height: int,
        fov: float = 45.0,
        fov_axis: str = "x",
        aperture_radius: float = 0.0,
        focus_distance: float = 1.0,
        thinlens: bool = False,
        rfilter: str = "box",
        rfilter_stddev: float = 0.5,
    ) -> None:
        """Mitsuba ``perspective`` / ``thinlens`` sensor (fov in degrees along ``fov_axis``).

        ``rfilter``: the film's reconstruction filter, ``"box"`` (default here) or
        ``"gaussian"`` with ``rfilter_stddev`` pixels (Mitsuba's default filter and stddev 0.5;
        :mod:`anisosample.render.film`)."""
        from .film import check_rfilter

        rfilter, rfilter_stddev = check_rfilter(rfilter, rfilter_stddev)
        aspect = width / height
        t = np.tan(np.radians(fov) / 2)
        if (
            fov_axis == "y"
            or (fov_axis == "smaller" and aspect > 1)
            or (fov_axis == "larger" and aspect < 1)
        ):
            t = t * aspect
        elif fov_axis not in ("x", "smaller", "larger"):
            raise ValueError(f"fov_axis must be one of x, y, smaller, larger, got {fov_axis!r}")
        self._camera = dict(
            to_world=np.asarray(to_world, np.float64),
            tan=t,
            aspect=aspect,
            aperture_radius=aperture_radius,
            focus_distance=focus_distance,
            projection=THINLENS if thinlens else PERSPECTIVE,
            width=int(width),
            height=int(height),
            rfilter=rfilter,
            rfilter_stddev=rfilter_stddev,
        )

    # build --------------------------------------------------------------------------------------
    def build(self, *, bvh: bool | None = None) -> Scene:
        """The :class:`Scene`. ``bvh``: give it a BVH over the planar primitives
        (:mod:`anisosample.render.bvh`); ``None`` (default): when it has at least
        :data:`~anisosample.render.bvh.THRESHOLD` of them (below that, testing every one is
        faster)."""
        if bvh is not None and not isinstance(bvh, (bool, np.bool_)):
            raise TypeError(f"bvh must be True, False or None, got {bvh!r}")
        if self._camera is None:
            raise ValueError("the scene has no sensor (camera)")
        if not self._emitters:
            raise ValueError("the scene has no emitter")
        f32 = lambda a: jnp.asarray(np.asarray(a, np.float64), jnp.float32)
        i32 = lambda a: jnp.asarray(np.asarray(a, np.int64), jnp.int32)

        far = np.full(3, 1e30)
        n_tris = sum(len(t.material) for t in self._tris)
        tris = self._tris or [
            Planar.one(far, far, far, np.array([0, 0, 1.0]), (0, 0), (0, 0), (0, 0), 0, -1, False)
        ]
        cat = lambda name: np.concatenate([getattr(t, name) for t in tris])  # noqa: E731
        p0 = cat("p0")
        e1 = cat("p1") - p0
        e2 = cat("p2") - p0
        if not self._tris:  # a placeholder that nothing hits
            e1 = np.zeros_like(p0)
            e2 = np.zeros_like(p0)
        sph = self._spheres or [SphereRecord(far, 1.0, 0, -1)]
        sph_r = np.array([s.radius for s in sph])
        if not self._spheres:
            sph_r = np.zeros(1)

        mats = self._materials or [_Material(DIFFUSE)]
        materials = Materials(
            material=i32([m.material for m in mats]),
            reflectance=f32([m.reflectance for m in mats]),
            specular=f32([m.specular for m in mats]),
            alpha=f32([m.alpha for m in mats]),
            eta=f32([m.eta for m in mats]),
            k=f32([m.k for m in mats]),
            twosided=i32([int(m.twosided) for m in mats]),
            transmittance=f32([m.transmittance for m in mats]),
            internal=f32([m.internal for m in mats]),
            spec_weight=f32([m.spec_weight for m in mats]),
            flags=i32([m.flags for m in mats]),
            distribution=i32([m.distribution for m in mats]),
            has_glossy=any(m.material != DIFFUSE for m in mats),
            has_plastic=any(m.material == PLASTIC for m in mats),
        )

        L = lambda name: np.concatenate([b[name] for b in self._lights])  # noqa: E731
        uv = L("uv")
        lights = Lights(
            shape=i32(L("shape")),
            p0=f32(L("p0")),
            e1=f32(L("e1")),
            e2=f32(L("e2")),
            normal=f32(L("normal")),
            area=f32(L("area")),
            uv0=f32(uv[:, 0]),
            uv1=f32(uv[:, 1]),
            uv2=f32(uv[:, 2]),
            radiance=f32(L("radiance")),
            texture=i32(L("texture")),
            prim_prob=f32(L("prob")),
            prim_cdf=f32(L("cdf")),
            emitter=i32(L("emitter")),
            start=i32([e.start for e in self._emitters]),
            count=i32([e.count for e in self._emitters]),
            delta=i32([e.delta for e in self._emitters]),
            patch=i32(L("patch")),
            n_prims=len(uv),
            shapes=tuple(int(k) for k in np.unique(L("shape"))),
        )

        if self._textures:
            hmax = max(t.shape[0] for t in self._textures)
            wmax = max(t.shape[1] for t in self._textures)
            data = np.zeros((len(self._textures), hmax, wmax, 3), np.float32)
            for i, t in enumerate(self._textures):
                data[i, : t.shape[0], : t.shape[1]] = t
            size = [(t.shape[1], t.shape[0]) for t in self._textures]
        else:
            data, size = np.zeros((1, 1, 1, 3), np.float32), [(1, 1)]
        textures = Textures(quad=jnp.asarray(_texel_quads(data, size)), size=i32(size))

        c = self._camera
        camera = Camera(
            to_world=f32(c["to_world"]),
            tan_half_fov_x=f32(c["tan"]),
            aspect=f32(c["aspect"]),
            aperture_radius=f32(c["aperture_radius"]),
            focus_distance=f32(c["focus_distance"]),
            projection=c["projection"],
            width=c["width"],
            height=c["height"],
            rfilter=c["rfilter"],
            rfilter_stddev=c["rfilter_stddev"],
        )

        para = cat("parallelogram")
        pts = [p0[:n_tris], (p0 + e1)[:n_tris], (p0 + e2)[:n_tris]]
        pts += [(p0 + e1 + e2)[:n_tris][para[:n_tris]]]
        pts += [np.array([s.center for s in self._spheres]).reshape(-1, 3)]
        pts += [np.array([q.corners for q in self._patches]).reshape(-1, 3)]
        pts += [np.asarray(c["to_world"][:3, 3])[None]]
        allp = np.concatenate([p.reshape(-1, 3) for p in pts])
        scale = float(np.max(np.abs(allp))) if allp.size else 1.0

        rows = _plane_rows(p0, e1, e2, para)
        if bvh is None:
            bvh = n_tris >= _bvh.THRESHOLD
        accel = None
        if bvh and self._tris:
            corners = [p0, p0 + e1, p0 + e2, np.where(para[:, None], p0 + e1 + e2, p0)]
            accel = _bvh.build_bvh(rows, np.minimum.reduce(corners), np.maximum.reduce(corners),
                              float(np.max(np.abs(np.concatenate(corners)))))
        return Scene(
            bvh=accel,
            tri_soa=f32(rows),
            tri_attr=f32(np.concatenate([cat("normal"), cat("uv0"), cat("uv1"), cat("uv2")], 1)),
            tri_ids=i32(np.stack([cat("material"), cat("light")], 1)),
            sph_center=f32([s.center for s in sph]),
            sph_radius=f32(sph_r),
            sph_material=i32([s.material for s in sph]),
            sph_light=i32([s.light for s in sph]),
            materials=materials,
            lights=lights,
            textures=textures,
            camera=camera,
            scale=f32(max(scale, 1.0)),
            has_spheres=bool(self._spheres),
            has_textures=bool(self._textures),
            patches=build_patches(self._patches),
            has_patches=bool(self._patches),
        )


def _plane_rows(p0, e1, e2, para) -> np.ndarray:
    """Per-primitive rows for the plane-based ray/triangle test, structure of arrays (13, t).

    With ``n = e1 x e2`` and the dual edge vectors ``r1 = (e2 x n) / |n|^2``,
    ``r2 = (n x e1) / |n|^2`` (``r_i . e_j = delta_ij``), a ray meets the plane at
    ``t = (n.p0 - n.o) / (n.d)`` and the hit ``q`` has barycentrics ``b1 = q.r1 - p0.r1``,
    ``b2 = q.r2 - p0.r2`` (the precomputed-transform idea of Baldwin & Weber 2016).
    Row 12 is 1 for a parallelogram (hit: ``0 <= b1, b2 <= 1``), 0 for a triangle
    (``b1 + b2 <= 1``). Degenerate primitives get rows that never report a hit.
    """
    n = np.cross(e1, e2)
    nn = np.sum(n * n, axis=-1)
    good = nn > 0
    inv = np.where(good, 1.0 / np.where(good, nn, 1.0), 0.0)[:, None]
    r1 = np.cross(e2, n) * inv
    r2 = np.cross(n, e1) * inv
    rows = np.concatenate([n, np.sum(n * p0, -1, keepdims=True), r1,
                           np.sum(r1 * p0, -1, keepdims=True), r2,
                           np.sum(r2 * p0, -1, keepdims=True),
                           np.asarray(para, np.float64)[:, None]], axis=1)
    rows[~good] = 0.0
    rows[~good, 7] = 1.0  # b1 = -1: never inside
    return rows.T


def _rgb(v) -> np.ndarray:
    a = np.asarray(v, np.float64).reshape(-1)
    if a.size == 1:
        a = np.repeat(a, 3)
    if a.size != 3 or not np.all(np.isfinite(a)):
        raise ValueError(f"expected one or three finite numbers (RGB), got {v!r}")
    return a


def _texel_quads(data: np.ndarray, size) -> np.ndarray:
    """``(t, h, w, 12)``: each texel with its right, lower and lower-right neighbours, wrapping
    around each texture's own ``(w, h)`` (:class:`~anisosample.render.scene.Textures`)."""
    quad = np.zeros((*data.shape[:3], 12), np.float32)
    for k, (w, h) in enumerate(size):
        img = data[k, :h, :w]
        right, down = (np.arange(w) + 1) % w, (np.arange(h) + 1) % h
        quad[k, :h, :w] = np.concatenate([img, img[:, right], img[down], img[down][:, right]],
                                         -1)
    return quad


def _light_block(shape, p0, e1, e2, n, area, radiance, texture, uv=None, patch=-1) -> dict:
    """Light primitives of one ``shape`` as arrays with a leading axis of ``k``: ``p0, e1, e2,
    n`` ``(k, 3)`` (or ``(3,)`` for one), ``area`` ``(k,)`` or one number, one ``radiance``
    (RGB), ``texture`` and ``patch`` index, corner ``uv`` ``(k, 3, 2)`` (default zeros)."""
    p0 = np.asarray(p0, np.float64).reshape(-1, 3)
    k = len(p0)
    vec = lambda a: np.broadcast_to(np.asarray(a, np.float64), (k, 3))  # noqa: E731
    return {
        "shape": np.full(k, shape),
        "p0": p0,
        "e1": vec(e1),
        "e2": vec(e2),
        "normal": vec(n),
        "area": np.broadcast_to(np.asarray(area, np.float64), (k,)),
        "radiance": vec(radiance),
        "texture": np.full(k, int(texture)),
        "uv": np.zeros((k, 3, 2)) if uv is None else np.asarray(uv, np.float64).reshape(k, 3, 2),
        "patch": np.full(k, int(patch)),
    }


def sphere_mesh(center, radius: float, triangles: int) -> tuple[np.ndarray, np.ndarray]:
    """A latitude-longitude triangulated sphere of about ``triangles`` faces: ``(vertices (v, 3),
    faces (f, 3))`` for :meth:`SceneBuilder.triangles` (outward normals); ``2 m (r - 1)`` faces
    for ``m = 2 r`` segments and ``r`` rings, ``r = max(2, round(sqrt(triangles / 4)))``."""
    rings = max(2, int(round(np.sqrt(max(triangles, 1) / 4))))
    segs = 2 * rings
    theta = np.pi * np.arange(1, rings) / rings
    phi = 2 * np.pi * np.arange(segs) / segs
    st, ct = np.sin(theta)[:, None], np.cos(theta)[:, None]
    ring = np.stack([st * np.cos(phi), st * np.sin(phi), np.broadcast_to(ct, (rings - 1, segs))],
                    -1).reshape(-1, 3)
    v = np.concatenate([[[0, 0, 1.0]], ring, [[0, 0, -1.0]]]) * radius + np.asarray(center)
    idx = 1 + np.arange((rings - 1) * segs).reshape(rings - 1, segs)
    nxt = np.roll(idx, -1, axis=1)
    top = np.stack([np.zeros(segs, np.int64), idx[0], nxt[0]], 1)
    bottom = np.stack([np.full(segs, len(v) - 1), nxt[-1], idx[-1]], 1)
    a, b, c, d = idx[:-1], nxt[:-1], idx[1:], nxt[1:]
    quads = np.concatenate([np.stack([a, c, d], -1).reshape(-1, 3),
                            np.stack([a, d, b], -1).reshape(-1, 3)])
    return v, np.concatenate([top, quads, bottom])

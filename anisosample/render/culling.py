"""Per-tile culling for brute force: which planar primitives, and whether curved surfaces, a
tile's rays can meet.

A scene without a BVH tests every planar primitive with every ray (:mod:`.geometry`); its cost
grows by about 3 ms per primitive per million samples (cornell, one device). The rays of one
image tile are few in kind: primary rays leave the lens through the tile's part of the film,
and shadow rays join those rays' hits to the lights. :func:`tile_culling` finds, on the host
and conservatively, the primitives each can meet, and the render kernels test only those
(:func:`pixel_view`; the BSDF rays of MIS still test everything). The nearest hit, and so the
image, is the brute-force one: the candidate lists keep the primitives' order, so ties break
the same way, and the tests are the same arithmetic (the image may move by float32 rounding
where XLA fuses the smaller loop differently).

* **Primary rays** (camera rays, pinhole or thin lens). A tile's film rectangle ``F`` (its
  pixels, widened by the reconstruction filter's support) placed on the focus plane, and the
  lens' bounding square ``L`` (a point for the pinhole): every ray ``a + s (f - a)``,
  ``a`` in ``L``, ``f`` in ``F``, ``s >= 0``, lies in the convex hull of ``L`` and ``F``
  (``s <= 1``) or in the convex region behind ``F`` bounded by the planes through each edge of
  ``F`` and the opposite edge of ``L`` (``s >= 1``). A primitive is a candidate when clipping
  it (Sutherland & Hodgman 1974) to either region leaves something.
* **Shadow rays.** Their origins lie in the clipped pieces of the primary candidates (moved off
  the surface by :func:`~anisosample.render.geometry.offset_origin`), their ends on a light, so
  each lies in the convex hull ``H`` of those pieces (and the bounding boxes of spheres and
  bilinear patches, whose hits shade too) and the light. A primitive is culled when
  a separating axis (Gottschalk et al. 1996) parts it from ``H``: its normal (where the hull
  lies on the camera's side, the offset points of its own plane counted on that side), the
  coordinate axes, the light's normal, and cross products of the primitive's edges, the
  light's edges, the coordinate axes and the direction from the tile's hits to the light.
* **Curved surfaces** (spheres, bilinear patches: :func:`curved_tiles`). Primary rays meet one
  only where its bounding blob (a sphere, the hull of a patch's corners) is not wholly outside
  one plane of a region; a shadow ray of a tile whose primary rays meet none leaves a piece of
  a planar candidate, so it lies in the hull of that piece and the light, and a separating axis
  parts the blob from each such hull. A render then gives the tiles whose rays meet no curved
  surface a kernel without their tests, and each class of tiles candidate lists as long as its
  own tiles need (:func:`tile_classes`). One-device renders at 128^2 x 64 spp (pmj02bn; the
  smallest of 24 renders in each of three processes per version, median over the processes,
  2026-12-07, load 1.9; this machine's timings switch between a fast and a slow mode, so
  fewer renders mislead): dof 86 -> 64 ms, glossy 100 -> 76, pillars 46 -> 42, attic 84 ->
  85 (cornell and blinds keep one class), every shipped scene's image the same bits.

Every test keeps a margin of ``MARGIN * scene.scale`` (world units), twice the surface offset,
which also covers the float32 rounding of the rays and of the primitives' corners (recovered
here from the intersection rows).

A class of rays keeps the full primitive list where its longest candidate list, rounded up to a
power of two, would not be shorter than it. XLA:CPU vectorizes those sizes: on cornell at
128^2 x 64 spp (one device), lists of 8 took 49 ms, lists of 7, 9, 10 or 12 candidates
116-168 ms (gathered per pixel), all 18 primitives 74 ms. Each tile's rows are stored gathered
(one contiguous read per pixel): lists of 16 took 59.5 ms so, 83.5 ms gathered per pixel.
"""

from __future__ import annotations

import dataclasses
import hashlib
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from .scene import LIGHT_PARALLELOGRAM, LIGHT_PATCH, LIGHT_POINT, LIGHT_SPHERE, THINLENS, Scene

MARGIN = 2e-4  # of scene.scale: geometry.offset_origin moves by 1e-4 scale
TILE_PX = 8  # pixels per tile side, doubled while tiles x primitives exceed MAX_PAIRS
MAX_PAIRS = 2**18  # (tile, primitive) pairs the host tests (54k over 842 triangles: 1.2 s)
MAX_TILE_PX = 128  # beyond: no culling (a scene that large wants its BVH)
MAX_PRIMITIVES = 2048  # above: no culling (the host's lists take seconds; see bvh.THRESHOLD)
# render(culling=None) culls from this many samples per realization: the lists' shapes follow
# the image's tiles, so each image size compiles its own kernel (about 1.5 s on cornell).
AUTO_SAMPLES = 2**18
_HULL_POINTS = 256  # a tile's hit points beyond which its shadow hull takes their bounding box
_SLOTS = 12  # polygon vertex slots: 4 corners + one per clipping plane (6)


class Subset(eqx.Module):
    """Some planar primitives: their intersection rows and their indices (``-1``: padding,
    rows that never report a hit). Stacked per tile in :class:`TileCulling`."""

    soa: Float[Array, "*n 13 k"]
    index: Int[Array, "*n k"]


class TileCulling(eqx.Module):
    """Candidate planar primitives per tile for primary and shadow rays (None: all of them),
    in ascending order, each tile's rows gathered once (one contiguous read per pixel). Tile
    ``(i, j)`` (row, column) is number ``i * tiles_x + j`` and covers pixels
    ``[j tile, (j + 1) tile) x [i tile, (i + 1) tile)``."""

    primary: Subset | None
    shadow: Subset | None
    tile: int = eqx.field(static=True)
    tiles_x: int = eqx.field(static=True)


class View(NamedTuple):
    """The candidates of one pixel's primary and shadow rays (None: every primitive)."""

    primary: Subset | None
    shadow: Subset | None


def pixel_view(scene: Scene, q) -> View | None:
    """The candidates for flat pixel index ``q`` (row-major), or None (no culling)."""
    c = scene.culling
    if c is None:
        return None
    tile = (q // scene.width) // c.tile * c.tiles_x + (q % scene.width) // c.tile
    pick = lambda s: None if s is None else jax.tree.map(lambda a: a[tile], s)  # noqa: E731
    return View(pick(c.primary), pick(c.shadow))


def film_view(scene: Scene, film) -> View | None:
    """The candidates for film position ``film`` in ``[0, 1]^2`` (row 0 on top), or None."""
    c = scene.culling
    if c is None:
        return None
    px = jnp.floor(film * jnp.asarray([scene.width, scene.height], jnp.float32))
    col = jnp.clip(px[0].astype(jnp.int32), 0, scene.width - 1)
    row = jnp.clip(px[1].astype(jnp.int32), 0, scene.height - 1)
    return pixel_view(scene, row * scene.width + col)


def with_culling(scene: Scene, enabled: bool = True) -> Scene:
    """``scene`` carrying its :func:`tile_culling` (or none: ``enabled=False``, or a BVH)."""
    c = tile_culling(scene) if enabled else None
    return eqx.tree_at(lambda s: s.culling, scene, c, is_leaf=lambda x: x is None)


def tile_culling(scene: Scene, tile: int | None = None) -> TileCulling | None:
    """The candidate lists of ``scene`` (:func:`tile_candidates`), or None where a BVH serves
    the scene, it holds more than :data:`MAX_PRIMITIVES` planar primitives, or neither class
    of rays gains (module docstring). Host time (2 cores), once per scene and size (cached by
    contents): cornell at 128^2 0.12-0.25 s, an 842-triangle mesh at 64^2 1.2 s."""
    if scene.bvh is not None or scene.tri_soa.shape[1] > MAX_PRIMITIVES:
        return None
    tile = _tile_px(scene, tile)
    if tile is None:
        return None
    return _cached(_LISTS, (_digest(scene), tile), lambda: _tile_culling(scene, tile))


def _tile_culling(scene: Scene, tile: int, lengths=None) -> TileCulling | None:
    """The lists of every tile, as long as the longest needs, or ``lengths = (primary,
    shadow)`` long (a tile with more candidates keeps the first: :func:`tile_classes` renders
    only the tiles they hold with them)."""
    primary, shadow = tile_candidates(scene, tile)
    t = primary.shape[1]
    if lengths is None:
        lengths = _list_length(primary.sum(1).max(initial=0), t), \
            _list_length(shadow.sum(1).max(initial=0), t)
    lists = _pad_lists(primary, t, lengths[0]), _pad_lists(shadow, t, lengths[1])
    if lists[0] is None and lists[1] is None:
        return None
    soa = np.concatenate([np.asarray(scene.tri_soa), np.zeros((13, 1), np.float32)], 1)
    soa[7, -1] = 1.0  # b1 = -1: never inside (builder._plane_rows' degenerate rows)

    def subset(cols):  # (n, k) indices padded with t
        if cols is None:
            return None
        return Subset(soa=jnp.asarray(np.moveaxis(soa[:, cols], 0, 1)),
                      index=jnp.asarray(np.where(cols < t, cols, -1).astype(np.int32)))

    return TileCulling(primary=subset(lists[0]), shadow=subset(lists[1]), tile=tile,
                       tiles_x=-(-scene.width // tile))


def tile_candidates(scene: Scene, tile: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``(primary, shadow)``: boolean ``(tiles, t)`` masks of the planar primitives that a
    tile's primary rays and shadow rays may meet (module docstring). ``tile``: pixels per
    tile side (default :data:`TILE_PX`, doubled while the tiles times the primitives exceed
    :data:`MAX_PAIRS`). Computed on the host in float64; the last few scenes' are cached by
    their contents."""
    return _masks(scene, _tile_or_raise(scene, tile))[:2]


def curved_tiles(scene: Scene, tile: int | None = None) -> np.ndarray:
    """``(tiles,)`` boolean: whether a tile's primary or shadow rays may meet a sphere or a
    bilinear patch (conservatively, as :func:`tile_candidates`; all false in a scene without
    them). The other tiles' pixels render with a kernel that tests planar primitives only
    (:func:`planar_split`)."""
    return _masks(scene, _tile_or_raise(scene, tile))[2]


class TileClass(NamedTuple):
    """Pixels whose tiles render with one kernel: ``scene`` with candidate lists as long as
    those tiles need (and without spheres and patches where they meet none)."""

    scene: Scene
    pixels: np.ndarray  # flat indices, ascending


# Relative cost per sample of a kernel (tile_classes' model): 1 + COST_ROW x (primary and shadow
# rows tested) + COST_CURVED where it tests the scene's spheres and patches. Fitted to one-device
# renders of every pixel at 128^2 x 64 spp with forced list lengths (2026-12-07, interleaved,
# min of 9, load 2.4 before): blinds 27.3 ms at lists of 2 and 2, 32.3 at 4 and 4, 37.2 at 8
# and 8, 44.9 at 2 and 32; dof without its sphere 44.1 / 45.1 / 51.5 at 2 / 4 / 8 each, with it
# 83.5 at 8 and 8.
COST_ROW = 0.02
COST_CURVED = 0.7
MAX_CLASSES = 3  # kernels per render: each compiles once per image size (about 1.5 s)
# A split of two classes stays only where merging them would cost this part of the image's
# modelled total or more: every class is one more pass (its padding, its dispatches, a sync).
MIN_GAIN = 0.1


def tile_classes(scene: Scene, granule: int, *, curved_everywhere: bool = False,
                 max_classes: int = MAX_CLASSES) -> list[TileClass] | None:
    """The pixels of ``scene`` (which carries its culling) in up to ``max_classes`` classes of
    tiles, each rendered by a kernel whose candidate lists are as long as its own tiles need,
    and without the sphere and patch tests where its tiles meet none (:func:`curved_tiles`).
    One list length for the whole image makes every tile pay for its worst one (attic: one
    tile of 16 primary candidates, most of 1-2); the same samples, fewer rows tested.

    The classes are the tiles' ``(primary length, shadow length, curved)``, merged greedily
    (the pair whose merger costs least, the merged class taking the larger lengths) while
    there are more than ``max_classes`` or a merger costs less than :data:`MIN_GAIN` of the
    image, at the cost ``padded pixels x (1 + COST_ROW rows + COST_CURVED curved)`` where each
    class's pixels are rounded up to ``granule`` (a render's chunk of pixels).
    ``curved_everywhere``: every tile tests the curved surfaces (MIS: its BSDF rays may meet
    anything). None: one class, the scene as it is."""
    from .._validate import check_bool, check_int

    granule = check_int("granule", granule, minimum=1)
    max_classes = check_int("max_classes", max_classes, minimum=1)
    curved_everywhere = check_bool("curved_everywhere", curved_everywhere)
    c = scene.culling
    if c is None:
        return None
    digest = _digest(scene)
    plan = _cached(_CLASSES, (digest, c.tile, granule, curved_everywhere, max_classes),
                   lambda: _class_plan(scene, granule, curved_everywhere, max_classes))
    if plan is None:
        return None
    return [TileClass(dataclasses.replace(
        scene, culling=_cached(_LISTS, (digest, c.tile, key[:2]),
                               lambda key=key: _tile_culling(scene, c.tile, key[:2])),
        has_spheres=scene.has_spheres and bool(key[2]),
        has_patches=scene.has_patches and bool(key[2])), pixels) for key, pixels in plan]


def _class_plan(scene: Scene, granule: int, curved_everywhere: bool, max_classes: int):
    """:func:`tile_classes`' classes: ``[(primary length, shadow length, curved), pixels]``,
    or None for one class."""
    c = scene.culling
    t = scene.tri_soa.shape[1]
    primary, shadow = tile_candidates(scene, c.tile)
    curved = curved_tiles(scene, c.tile) | curved_everywhere
    if not (scene.has_spheres or scene.has_patches):
        curved = np.zeros_like(curved)
    lengths = lambda m: np.array([_list_length(n, t) for n in m.sum(1)])  # noqa: E731
    keys = np.stack([lengths(primary), lengths(shadow), curved], 1)
    q = np.arange(scene.width * scene.height)
    tile_of = (q // scene.width) // c.tile * c.tiles_x + (q % scene.width) // c.tile
    uniq, of_tile = np.unique(keys, axis=0, return_inverse=True)
    inverse = of_tile.ravel()[tile_of]  # each pixel's key
    groups = [(tuple(int(v) for v in k), [i]) for i, k in enumerate(uniq)]
    counts = np.bincount(inverse, minlength=len(uniq))

    def cost(key, n):
        padded = -(-n // granule) * granule
        rows = sum(t if k >= t else k for k in key[:2])
        return padded * (1 + COST_ROW * rows + COST_CURVED * key[2])

    def size(g):
        return int(counts[g[1]].sum())

    total = cost(tuple(int(v) for v in keys.max(0)), q.size)  # one class: the lists of today

    while len(groups) > 1:
        best = None
        for a in range(len(groups)):
            for b in range(a + 1, len(groups)):
                ka, kb = groups[a][0], groups[b][0]
                key = tuple(max(x, y) for x, y in zip(ka, kb, strict=True))
                n = size(groups[a]) + size(groups[b])
                extra = cost(key, n) - cost(ka, size(groups[a])) - cost(kb, size(groups[b]))
                if best is None or extra < best[0]:
                    best = (extra, a, b, key)
        extra, a, b, key = best
        if extra > MIN_GAIN * total and len(groups) <= max_classes:
            break
        merged = (key, groups[a][1] + groups[b][1])
        groups = [g for i, g in enumerate(groups) if i not in (a, b)] + [merged]
    if len(groups) == 1:
        return None
    plan = [(key, q[np.isin(inverse, members)]) for key, members in sorted(groups)]
    for _, pixels in plan:
        pixels.flags.writeable = False
    return plan


def _tile_or_raise(scene: Scene, tile) -> int:
    tile = _tile_px(scene, tile)
    if tile is None:
        raise ValueError(f"{scene.tri_soa.shape[1]} planar primitives at "
                         f"{scene.width}x{scene.height}: more than MAX_PAIRS even with tiles of "
                         f"{MAX_TILE_PX} pixels; pass tile")
    return tile


def _masks(scene: Scene, tile: int):
    return _cached(_MASKS, (_digest(scene), tile),
                   lambda: _read_only(_compute(_Host(scene), tile)))


_MASKS: dict = {}  # (digest, tile) -> tile_candidates' masks, the last few scenes'
_LISTS: dict = {}  # (digest, tile[, lengths]) -> tile_culling's result
_CLASSES: dict = {}  # (digest, tile, granule, curved_everywhere, max_classes) -> _class_plan


def _cached(store: dict, key, make):
    if key not in store:
        if len(store) >= 16:
            store.pop(next(iter(store)))
        store[key] = make()
    return store[key]


def _read_only(masks):
    for m in masks:
        m.flags.writeable = False
    return masks


def _tile_px(scene: Scene, tile) -> int | None:
    """``tile``, validated, or the default (None: no tile size keeps the work bounded)."""
    if tile is not None:
        from .._validate import check_int

        return check_int("tile", tile, minimum=1)
    t = scene.tri_soa.shape[1]
    tile = TILE_PX
    while -(-scene.width // tile) * -(-scene.height // tile) * t > MAX_PAIRS:
        tile *= 2
        if tile > MAX_TILE_PX:
            return None
    return tile


def _digest(scene: Scene) -> str:
    h = hashlib.sha256()
    cam = scene.camera
    for a in (scene.tri_soa, scene.sph_center, scene.sph_radius, scene.patches.corners,
              scene.lights.shape, scene.lights.p0, scene.lights.e1, scene.lights.e2,
              scene.lights.patch, scene.scale, cam.to_world, cam.tan_half_fov_x, cam.aspect,
              cam.aperture_radius, cam.focus_distance, cam.window):
        a = np.asarray(a)
        h.update(str((a.dtype, a.shape)).encode())
        h.update(a.tobytes())
    h.update(repr((cam.projection, cam.width, cam.height, cam.rfilter, cam.rfilter_stddev,
                   scene.has_spheres, scene.has_patches)).encode())
    return h.hexdigest()


class _Host:
    """What the culling reads of a scene, as float64 numpy."""

    def __init__(self, scene: Scene):
        cam = scene.camera
        self.soa = np.asarray(scene.tri_soa, np.float64)
        self.scale = float(scene.scale)
        self.m = np.asarray(cam.to_world, np.float64)
        self.tan = float(cam.tan_half_fov_x)
        self.aspect = float(cam.aspect)
        self.window = np.asarray(cam.window, np.float64)
        thin = cam.projection == THINLENS
        self.radius = float(cam.aperture_radius) if thin else 0.0
        self.focus = float(cam.focus_distance) if thin else 1.0
        self.width, self.height = cam.width, cam.height
        self.support = 4.0 * cam.rfilter_stddev if cam.rfilter == "gaussian" else 0.0
        lights = scene.lights
        self.light_shape = np.asarray(lights.shape)
        self.light_p0 = np.asarray(lights.p0, np.float64)
        self.light_e1 = np.asarray(lights.e1, np.float64)
        self.light_e2 = np.asarray(lights.e2, np.float64)
        self.light_patch = np.asarray(lights.patch)
        corners = np.asarray(scene.patches.corners, np.float64).reshape(-1, 4, 3)
        self.patch_corners = corners
        # Non-planar surfaces whose hits shade: their bounding boxes join every tile's hits.
        extra = []
        if scene.has_spheres:
            c = np.asarray(scene.sph_center, np.float64)
            r = np.asarray(scene.sph_radius, np.float64)[:, None]
            live = r[:, 0] > 0
            extra += [_box_corners(c[live] - r[live], c[live] + r[live]).reshape(-1, 3)]
        if scene.has_patches:
            extra += [corners.reshape(-1, 3)]
        self.extra = np.concatenate(extra) if extra else np.zeros((0, 3))
        # The same surfaces as blobs: 4 points and a radius each, the surface inside the
        # points' hull widened by the radius (a sphere: its centre; a patch: its corners).
        blobs, radii = [], []
        if scene.has_spheres:
            blobs += [np.repeat(c[live][:, None], 4, 1)]
            radii += [r[live, 0]]
        if scene.has_patches:
            blobs += [corners]
            radii += [np.zeros(corners.shape[0])]
        self.blobs = np.concatenate(blobs) if blobs else np.zeros((0, 4, 3))
        self.blob_radius = np.concatenate(radii) if radii else np.zeros(0)


# --- geometry ---------------------------------------------------------------------------------


def _box_corners(lo, hi):
    """The 8 corners of boxes ``[lo, hi]`` (``(..., 3)``): ``(..., 8, 3)``."""
    bits = np.array([[(i >> k) & 1 for k in range(3)] for i in range(8)], np.float64)
    return lo[..., None, :] + bits * (hi - lo)[..., None, :]


def planar_corners(soa: np.ndarray):
    """Corners of the planar primitives from their intersection rows (builder._plane_rows):
    ``(corners (t, 4, 3), count (t,))``, count 3 (triangle), 4 (parallelogram: p0, p0 + e1,
    p0 + e1 + e2, p0 + e2) or 0 (a degenerate primitive, which no ray hits). The rows hold
    ``n, n.p0, r1, p0.r1, r2, p0.r2`` with ``r_i . e_j = delta_ij`` and ``n . e_j = 0``, so
    ``p0``, ``e1`` and ``e2`` solve one 3x3 system each."""
    n, r1, r2 = soa[0:3].T, soa[4:7].T, soa[8:11].T
    a = np.stack([n, r1, r2], axis=1)  # (t, 3, 3)
    good = np.abs(np.linalg.det(a)) > 0
    a = np.where(good[:, None, None], a, np.eye(3))
    rhs = np.stack([soa[3], soa[7], soa[11]], axis=1)
    p0 = np.linalg.solve(a, rhs[..., None])[..., 0]
    inv = np.linalg.inv(a)  # columns: the duals of n, r1, r2
    e1, e2 = inv[:, :, 1], inv[:, :, 2]
    para = soa[12] > 0
    corners = np.stack([p0, p0 + e1, np.where(para[:, None], p0 + e1 + e2, p0 + e2),
                        p0 + e2], axis=1)
    count = np.where(good, np.where(para, 4, 3), 0)
    return corners, count


def _plane(a, b, c, inside):
    """Unit normal ``n`` and offset ``d`` of the plane through ``a, b, c`` (``(..., 3)``),
    oriented so that ``n . inside >= d``."""
    n = np.cross(b - a, c - a)
    n = n / np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-300)
    d = np.sum(n * a, -1)
    flip = np.sum(n * inside, -1) < d
    return np.where(flip[..., None], -n, n), np.where(flip, -d, d)


def clip_polygons(poly, count, n, d):
    """Sutherland & Hodgman: convex polygons ``poly`` ``(N, S, 3)`` with ``count`` corners
    each, clipped to the half-spaces ``n . x >= d`` (``n`` ``(N, 3)``, ``d`` ``(N,)``):
    ``(poly, count)``, count 0 where nothing is left."""
    big, slots = poly.shape[0], poly.shape[1]
    idx = np.arange(slots)[None, :]
    valid = idx < count[:, None]
    nxt = (idx + 1) % np.maximum(count[:, None], 1)
    q = np.take_along_axis(poly, nxt[..., None], 1)
    da = np.einsum("nsk,nk->ns", poly, n) - d[:, None]
    db = np.take_along_axis(da, nxt, 1)
    ina, inb = da >= 0, db >= 0
    t = da / np.where(ina != inb, da - db, 1.0)
    cut = poly + t[..., None] * (q - poly)
    emit_a, emit_x = valid & ina, valid & (ina != inb)
    k = emit_a.astype(np.int64) + emit_x
    off = np.cumsum(k, 1) - k
    out = np.zeros_like(poly)
    rows = np.broadcast_to(np.arange(big)[:, None], (big, slots))
    out[rows[emit_a], off[emit_a]] = poly[emit_a]
    pos = off + emit_a
    out[rows[emit_x], pos[emit_x]] = cut[emit_x]
    return out, k.sum(1)


def _regions(h: _Host, rects):
    """Planes ``(n, d)`` bounding each tile's near region (the hull of lens and focus
    rectangle: 6 planes) and far region (behind the focus rectangle: 5 planes, the sixth
    repeated) in world space, widened by the margin: ``n`` ``(tiles, 2, 6, 3)``."""
    s0, s1, t0, t1 = (rects[:, i] for i in range(4))
    fd, tan, r = h.focus, h.tan, h.radius

    def film(s, t):  # camera-space point of the focus plane (generate_ray)
        s, t = h.window[0] + s * h.window[2], h.window[1] + t * h.window[3]
        return np.stack([(1 - 2 * s) * tan * fd, (1 - 2 * t) * tan / h.aspect * fd,
                         np.full_like(s, fd)], -1)

    def world(p):
        return p @ h.m[:3, :3].T + h.m[:3, 3]

    # Film s grows to camera -x, t to -y: the s0 edge is at F's largest x, the t0 edge at its
    # largest y; the near region pairs each with the lens edge at +r, the far one with -r.
    f = {(i, j): world(film(s, t)) for i, s in enumerate((s0, s1)) for j, t in enumerate((t0, t1))}
    lens = {(i, j): world(np.array([r * (1 - 2 * i), r * (1 - 2 * j), 0.0]))
            for i in range(2) for j in range(2)}
    zero = np.zeros_like(s0)[:, None]
    lens = {k: v + zero for k, v in lens.items()}
    f_mid = sum(f.values()) / 4
    l_mid = sum(lens.values()) / 4
    near_in, far_in = 0.5 * (f_mid + l_mid), 2 * f_mid - l_mid
    edges = [((0, 0), (0, 1), 0, 0), ((1, 0), (1, 1), 0, 1),  # s0, s1 edges: lens x side
             ((0, 0), (1, 0), 1, 0), ((0, 1), (1, 1), 1, 1)]  # t0, t1 edges: lens y side

    def lens_edge(axis, side):
        i = side
        return (lens[(i, 0)], lens[(i, 1)]) if axis == 0 else (lens[(0, i)], lens[(1, i)])

    cam_x, cam_y = world(np.array([1.0, 0, 0])) + zero, world(np.array([0, 1.0, 0])) + zero
    origin = world(np.zeros(3)) + zero
    near = [_plane(origin, cam_x, cam_y, near_in),
            _plane(f[(0, 0)], f[(1, 0)], f[(0, 1)], near_in)]
    far = [_plane(f[(0, 0)], f[(1, 0)], f[(0, 1)], far_in)]
    for a, b, axis, side in edges:
        la, _ = lens_edge(axis, side)
        lo, _ = lens_edge(axis, 1 - side)
        near.append(_plane(f[a], f[b], la, near_in))
        far.append(_plane(f[a], f[b], lo, far_in))
    far.append(far[0])
    n = np.stack([np.stack([p[0] for p in near], 1), np.stack([p[0] for p in far], 1)], 1)
    d = np.stack([np.stack([p[1] for p in near], 1), np.stack([p[1] for p in far], 1)], 1)
    eye = np.stack(list(lens.values()), 1)  # (tiles, 4, 3): the lens corners
    return n, d - MARGIN * h.scale, eye


def _tile_rects(h: _Host, tile: int):
    """Film rectangles ``(s0, s1, t0, t1)`` in ``[0, 1]`` of the tiles, row-major, widened
    by the filter's support (pixels) and a thousandth of a pixel."""
    tx, ty = -(-h.width // tile), -(-h.height // tile)
    j, i = np.meshgrid(np.arange(tx), np.arange(ty), indexing="xy")
    j, i = j.ravel(), i.ravel()
    pad = h.support + 1e-3
    x0 = np.maximum(j * tile - pad, 0.0) / h.width
    x1 = np.minimum((j + 1) * tile + pad, h.width) / h.width
    y0 = np.maximum(i * tile - pad, 0.0) / h.height
    y1 = np.minimum((i + 1) * tile + pad, h.height) / h.height
    return np.stack([x0, x1, y0, y1], 1).astype(np.float64)


def _light_points(h: _Host):
    """Per light primitive, points whose convex hull holds it: ``(l, 8, 3)`` (repeated)."""
    out = []
    for s, p0, e1, e2, k in zip(h.light_shape, h.light_p0, h.light_e1, h.light_e2,
                                h.light_patch, strict=True):
        if s == LIGHT_POINT:
            pts = p0[None]
        elif s == LIGHT_SPHERE:
            pts = _box_corners(p0 - e1[0], p0 + e1[0])
        elif s == LIGHT_PATCH:
            pts = h.patch_corners[k]
        elif s == LIGHT_PARALLELOGRAM:
            pts = np.stack([p0, p0 + e1, p0 + e1 + e2, p0 + e2])
        else:
            pts = np.stack([p0, p0 + e1, p0 + e2])
        out.append(np.concatenate([pts, np.repeat(pts[-1:], 8 - len(pts), 0)]))
    return np.stack(out)


def _list_length(most, t: int) -> int:
    """The list length for at most ``most`` candidates of ``t``: a power of two from 2, or
    ``t`` (no list: every primitive) where that power is not below ``t``."""
    k = max(2, 1 << max(0, int(most) - 1).bit_length())
    return t if k >= t else k


def _pad_lists(mask: np.ndarray, t: int, k: int):
    """Ascending candidate indices per row of ``mask`` ``(n, t)``, the first ``k``, padded with
    ``t`` (None where ``k`` is ``t``: every primitive)."""
    if k >= t:
        return None
    order = np.argsort(~mask, axis=1, kind="stable")[:, :k]
    return np.where(np.take_along_axis(mask, order, 1), order, t).astype(np.int32)


class _Geometry(NamedTuple):
    """The planar primitives as the tests read them (float64, world space)."""

    corners: np.ndarray  # (t, 4, 3), planar_corners
    count: np.ndarray  # (t,)
    cpts: np.ndarray  # (t, 4, 3): corners, a triangle's fourth repeating its first
    normal: np.ndarray  # (t, 3) unit
    offset: np.ndarray  # (t,): normal . p0
    edges: np.ndarray  # (t, 3, 3): unit edge directions (and a diagonal)
    same: np.ndarray  # (t, t): the two primitives lie in one plane
    lights: np.ndarray  # (l, 8, 3): points whose hull holds each light primitive


def _geometry(h: _Host) -> _Geometry:
    corners, count = planar_corners(h.soa)
    normal = _unit(np.cross(corners[:, 1] - corners[:, 0], corners[:, 3] - corners[:, 0]))
    offset = np.sum(normal * corners[:, 0], -1)
    cpts = np.where((np.arange(4) < np.maximum(count, 3)[:, None])[..., None], corners,
                    corners[:, :1])
    edges = _unit(np.stack([corners[:, 1] - corners[:, 0], corners[:, 3] - corners[:, 0],
                            corners[:, 3] - corners[:, 1]], 1))
    # Coplanar within 1.4e-5 rad and 1e-5 scale: a tenth of the surface offset and less.
    dist = normal @ corners[:, 0].T - offset[:, None]  # [p, q]: q's p0 from p's plane
    same = (np.abs(normal @ normal.T) > 1 - 1e-10) & (np.abs(dist) <= 1e-5 * h.scale)
    return _Geometry(corners, count, cpts, normal, offset, edges, same, _light_points(h))


def _compute(h: _Host, tile: int):
    """``(primary, shadow, curved)``: the masks of :func:`tile_candidates` and of
    :func:`curved_tiles`."""
    t = h.soa.shape[1]
    g = _geometry(h)
    rects = _tile_rects(h, tile)
    nt = rects.shape[0]
    primary = np.zeros((nt, t), bool)
    shadow = np.zeros((nt, t), bool)
    curved = np.zeros(nt, bool)
    step = max(1, 500 // t)  # bounds the shadow test's (tiles, t, axes, points) arrays
    for a in range(0, nt, step):
        b = min(nt, a + step)
        primary[a:b], shadow[a:b], curved[a:b] = _tiles(h, g, rects[a:b])
    return primary, shadow, curved


def _unit(v):
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.where(n > 1e-12, v / np.maximum(n, 1e-300), 0.0)


def _tiles(h: _Host, g: _Geometry, rects):
    """``(primary, shadow)`` candidate masks ``(tiles, t)`` of a batch of tiles."""
    nt, t = rects.shape[0], g.count.shape[0]
    n, d, lens = _regions(h, rects)
    # Primary: every primitive clipped to both regions of every tile.
    poly = np.zeros((nt, t, 2, _SLOTS, 3))
    poly[:, :, :, :4] = g.corners[None, :, None]
    flat_p = poly.reshape(-1, _SLOTS, 3)
    flat_c = np.broadcast_to(g.count[None, :, None], (nt, t, 2)).reshape(-1)
    nn = np.broadcast_to(n[:, None], (nt, t, 2, 6, 3)).reshape(-1, 6, 3)
    dd = np.broadcast_to(d[:, None], (nt, t, 2, 6)).reshape(-1, 6)
    for k in range(6):
        flat_p, flat_c = clip_polygons(flat_p, flat_c, nn[:, k], dd[:, k])
    pieces = flat_p.reshape(nt, t, 2, _SLOTS, 3)
    piece_n = flat_c.reshape(nt, t, 2)
    primary = (piece_n > 0).any(2)
    return (primary, _shadow(h, g, primary, pieces, piece_n, lens),
            _curved(h, g, n, d, pieces, piece_n))


def _curved(h: _Host, g: _Geometry, n, d, pieces, piece_n):
    """``(tiles,)``: whether a tile's primary or shadow rays may meet a sphere or a bilinear
    patch (:func:`curved_tiles`). Primary rays: the surface's blob (``_Host.blobs``) is not
    wholly outside one plane of a region. Shadow rays of a tile whose primary rays meet no
    curved surface: each leaves a piece of a planar candidate for a light, so it lies in the
    hull of that piece and the light; a separating axis parts the blob from every such hull:
    the coordinate axes, the piece's normal, the planes through the light's centre and the
    piece's edges (exact for a point light), and the direction across from the light to the
    piece, square to the light's direction to the blob."""
    nt = n.shape[0]
    nb = h.blobs.shape[0]
    if nb == 0:
        return np.zeros(nt, bool)
    m = MARGIN * h.scale
    # Primary: n . x >= d for every plane of a region; the blob leaves it where
    # max(n . points) + radius < d for one plane.
    reach = np.einsum("trpk,bjk->trpbj", n, h.blobs).max(-1) + h.blob_radius  # (nt, 2, 6, b)
    curved = (reach >= d[..., None]).all(2).any(1).any(-1)
    # Shadow: the pieces (nt, P, S, 3) with counts (nt, P).
    poly = pieces.reshape(nt, -1, _SLOTS, 3)
    count = piece_n.reshape(nt, -1)
    slot = np.arange(_SLOTS)
    real = slot < count[..., None]  # (nt, P, S)
    nxt = (slot + 1) % np.maximum(count[..., None], 1)
    edge = np.take_along_axis(poly, nxt[..., None], 2) - poly
    centre = np.where(real[..., None], poly, 0.0).sum(2) / np.maximum(count, 1)[..., None]
    normal = _unit(np.cross(edge[:, :, 0], edge[:, :, 1]))
    fixed = np.broadcast_to(np.eye(3), (*count.shape, 3, 3))
    for light in g.lights:  # (8, 3)
        lc = light.mean(0)
        side = np.where(real[..., None], _unit(np.cross(edge, poly - lc)), 0.0)
        hull = np.concatenate([poly, np.broadcast_to(light, (*count.shape, 8, 3))], 2)
        inner = np.concatenate([real, np.ones((*count.shape, 8), bool)], 2)
        for pts, rad in zip(h.blobs, h.blob_radius, strict=True):
            u = _unit(pts.mean(0) - lc)
            w = centre - lc
            across = _unit(w - (w @ u)[..., None] * u)
            axes = np.concatenate([fixed, normal[..., None, :], across[..., None, :], side], 2)
            proj = np.einsum("tpak,tpxk->tpax", axes, hull)
            p_hi = np.where(inner[:, :, None], proj, -np.inf).max(-1)
            p_lo = np.where(inner[:, :, None], proj, np.inf).min(-1)
            own = np.einsum("tpak,jk->tpaj", axes, pts)
            used = np.linalg.norm(axes, axis=-1) > 0
            apart = used & ((p_hi + m < own.min(-1) - rad) | (p_lo - m > own.max(-1) + rad))
            curved |= ((count > 0) & ~apart.any(-1)).any(1)
    return curved


def _one_side(a, b, delta):
    """Whether segments between points at heights ``>= a`` and ``>= b`` above a plane (float32
    positions good to ``delta``) stay off it but within their trimmed ends (occluded's
    ``eps = 1e-4``; half of it here): both ends clear of the plane, or one within ``delta`` of
    it and the other so high that the crossing falls in the trimmed part."""
    a_clear, b_clear = a > delta, b > delta
    a_near = (a >= -delta) & (2 * delta < 5e-5 * np.maximum(b, 0))
    b_near = (b >= -delta) & (2 * delta < 5e-5 * np.maximum(a, 0))
    return (a_clear | a_near) & (b_clear | b_near)


def _shadow(h: _Host, g: _Geometry, primary, pieces, piece_n, lens):
    """``(tiles, t)``: whether a primitive may block a shadow ray of the tile (module
    docstring): no separating axis parts it from the hull of the tile's hits and a light."""
    nt, t = primary.shape
    m = MARGIN * h.scale
    # The tile's hit points: its primary candidates' pieces, and the non-planar surfaces.
    kp = max(1, int(primary.sum(1).max()))
    order = np.argsort(~primary, axis=1, kind="stable")[:, :kp]  # (nt, kp)
    live = np.take_along_axis(primary, order, 1)
    pts = np.take_along_axis(pieces, order[:, :, None, None, None], 1)  # (nt, kp, 2, S, 3)
    pn = np.take_along_axis(piece_n, order[:, :, None], 1)
    ok = (np.arange(_SLOTS) < pn[..., None]) & live[:, :, None, None]
    src = np.broadcast_to(order[:, :, None, None], ok.shape)
    pts, ok, src = pts.reshape(nt, -1, 3), ok.reshape(nt, -1), src.reshape(nt, -1)
    if h.extra.shape[0]:
        ne = h.extra.shape[0]
        pts = np.concatenate([pts, np.broadcast_to(h.extra, (nt, ne, 3))], 1)
        ok = np.concatenate([ok, np.ones((nt, ne), bool)], 1)
        src = np.concatenate([src, np.full((nt, ne), -1)], 1)
    keep = ok.sum(0) > 0  # drop the slots no tile of the batch uses
    pts, ok, src = pts[:, keep], ok[:, keep], src[:, keep]
    if not keep.any():  # no tile of the batch sees anything: no shadow rays
        return np.zeros((nt, t), bool)
    if pts.shape[1] > _HULL_POINTS:  # bounded work: the hits' bounding box instead
        lo = np.where(ok[..., None], pts, np.inf).min(1)
        hi = np.where(ok[..., None], pts, -np.inf).max(1)
        seen = ok.any(1)
        pts = _box_corners(np.where(seen[:, None], lo, 0.0), np.where(seen[:, None], hi, 0.0))
        ok = np.broadcast_to(seen[:, None], (nt, 8))
        src = np.full((nt, 8), -1)
    any_hit = ok.any(1)
    # Own-normal test: the camera's side of each plane (+1 / -1; 0 where the lens straddles
    # it), the hits' heights above it on that side (those in the plane: their offset), and the
    # lowest of them.
    sd = np.einsum("nck,pk->ncp", lens, g.normal) - g.offset[None, None, :]  # (nt, 4, t)
    side = np.where((sd > 0).all(1), 1.0, np.where((sd < 0).all(1), -1.0, 0.0))
    v = (np.einsum("tk,bxk->btx", g.normal, pts) - g.offset[None, :, None]) * side[:, :, None]
    coplanar = (src >= 0)[:, None, :] & g.same[:, np.maximum(src, 0)].transpose(1, 0, 2)
    v = np.where(coplanar, 1e-4 * h.scale, v)
    low_x = np.where(ok[:, None], v, np.inf).min(-1)  # (nt, t)
    c_x = np.sum(np.where(ok[..., None], pts, 0.0), 1) / np.maximum(ok.sum(1), 1)[:, None]
    fixed = np.eye(3)
    box_lo, box_hi = g.cpts.min(1), g.cpts.max(1)  # (t, 3)
    x_lo = np.where(ok[..., None], pts, np.inf).min(1)
    x_hi = np.where(ok[..., None], pts, -np.inf).max(1)
    blocked = np.zeros((nt, t), bool)
    for light in g.lights:  # (8, 3)
        # Cheap tests first, for every pair: the primitive's own normal, and the boxes.
        low_y = ((light @ g.normal.T - g.offset[None]) * side[:, None, :]).min(1)  # (nt, t)
        own = (side != 0) & _one_side(low_x, low_y, 1e-6 * h.scale)
        lo = np.minimum(x_lo, light.min(0))[:, None]
        hi = np.maximum(x_hi, light.max(0))[:, None]
        boxed = ((hi + m < box_lo[None]) | (lo - m > box_hi[None])).any(-1)
        open_ = ~(own | boxed)
        cols = np.nonzero(open_.any(0))[0]
        if cols.size == 0:
            continue
        # The separating axes for the primitives left.
        ly = _unit(np.stack([light[1] - light[0], light[2] - light[1], light[3] - light[0]]))
        ny = _unit(np.cross(ly[0], ly[1]))
        dirv = _unit(light.mean(0)[None] - c_x)  # (nt, 3)
        e = g.edges[cols]  # (c, 3, 3)
        nc = cols.size

        def each(a, nc=nc):  # axes shared by all tiles -> (nt, c, A, 3)
            return np.broadcast_to(a, (nt, nc, *a.shape[-2:]))

        ax = _unit(np.concatenate([
            each(ny[None, None, None]),
            each(np.cross(e[:, :, None], fixed[None, None]).reshape(1, nc, 9, 3)),
            each(np.cross(e[:, :, None], ly[None, None]).reshape(1, nc, 9, 3)),
            np.cross(e[None], dirv[:, None, None]),
            each(np.cross(dirv[:, None], fixed[None])[:, None]),
            each(np.cross(dirv[:, None], ly[None])[:, None]),
        ], 2))
        hull = np.concatenate([pts, np.broadcast_to(light, (nt, 8, 3))], 1)
        hmask = np.concatenate([ok, np.ones((nt, 8), bool)], 1)
        proj = np.einsum("btak,bxk->btax", ax, hull)
        p_hi = np.where(hmask[:, None, None], proj, -np.inf).max(-1)
        p_lo = np.where(hmask[:, None, None], proj, np.inf).min(-1)
        pp = np.einsum("btak,tck->btac", ax, g.cpts[cols])
        used = np.linalg.norm(ax, axis=-1) > 0
        apart = (used & ((p_hi + m < pp.min(-1)) | (p_lo - m > pp.max(-1)))).any(-1)
        still = open_.copy()
        still[:, cols] &= ~apart
        blocked |= still
    return blocked & any_hit[:, None] & (g.count > 0)[None]

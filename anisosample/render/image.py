"""Rendering whole images: realizations, per-pixel variance, EXR and PNG output.

The image estimator of pixel ``q`` is ``mean_j f_q(shift_q(S)_j)`` with one point set ``S`` per
realization from the chosen sampler and an independent toroidal shift per pixel (W Sec. 5.4).
Over ``R`` realizations the result holds the mean image and the per-pixel sample variance of
the one-realization estimator (its MSE when the estimator is unbiased).
"""

from __future__ import annotations

import collections
import os
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._validate import check_devices, check_int, check_key
from .integrator import options_of, render_chunk
from .options import IntegratorOptions
from .scene import Scene


class RenderResult(eqx.Module):
    """What :func:`render` returns: the images as arrays (pytree leaves), the counts and the
    settings record (what :func:`save_result` writes as metadata) as static fields."""

    mean: np.ndarray  # (h, w, 3) float32, row 0 at the top
    variance: np.ndarray | None  # (h, w, 3) sample variance over realizations (None if R = 1)
    spp: int = eqx.field(static=True)
    realizations: int = eqx.field(static=True)
    settings: dict = eqx.field(static=True)
    # per-block and per-pixel samplers: each pixel's decision (render.aligned.PIXEL_CODES)
    pixel_sampler: np.ndarray | None = None
    # per-pixel aligned sampler (first realization): (h, w, 2) float32 spectral directions in
    # degrees, strongest first, NaN where none; (h, w) int32 samples the estimation took beyond
    # the reused prefix (render.pixel_aligned)
    pixel_directions: np.ndarray | None = None
    pixel_estimation_samples: np.ndarray | None = None


def _get_sampler(sampler) -> tuple[Callable, str]:
    if callable(sampler):
        return sampler, getattr(sampler, "name", getattr(sampler, "__name__", "custom"))
    from .. import samplers

    if not isinstance(sampler, str):
        raise TypeError(f"sampler must be a sampler name or a callable (key, n), got {sampler!r}")
    return samplers.get(sampler), sampler


def render(
    scene: Scene,
    key,
    *,
    spp: int = 64,
    sampler="random",
    realizations: int = 1,
    pixel_center: bool = False,
    dimension: str = "auto",
    technique: str = "area",
    light_warp: str = "none",
    mis: bool = False,
    square_aperture: bool = False,
    chunk: int | None = None,
    chunk_samples: int | None = None,
    progress: bool = True,
    sampler_options: dict | None = None,
    devices=None,
    options: IntegratorOptions | None = None,
    culling: bool | None = None,
) -> RenderResult:
    """Render ``scene`` ``realizations`` times with ``spp`` points per pixel per realization.

    ``sampler``: a name from :func:`anisosample.samplers.names` or a callable ``(key, n)``.
    ``spp`` (default 64) and ``mis`` (default off: light sampling alone; on: one BSDF sample
    per light sample, power heuristic) are the caller's: a scene file's own sample count and
    integrator are :class:`~anisosample.render.xml.RenderSettings`
    (``scene, settings = load_xml_with_settings(p)``; ``render(scene, key,
    **settings._asdict())``). Deterministic for a given ``key``.

    ``options``: the integrator's options as one record,
    :class:`~anisosample.render.options.IntegratorOptions`, instead of the keywords
    ``pixel_center``, ``dimension``, ``technique``, ``light_warp``, ``mis`` and
    ``square_aperture`` (not both); either way it is checked once and resolved for the scene
    here, and everything the render calls takes the record. ``mis=True`` on
    ``dimension="lens"`` (point lights only) is applied and changes no bit: no BSDF sample
    reaches a point light.

    ``technique`` is the base light-sampling technique (``"area"``, ``"solid_angle"``,
    ``"parametric"``) and ``light_warp`` the warp chain fitted at every shading point in front of
    (or instead of) it: a name of :data:`~anisosample.render.light_warps.LIGHT_WARPS`
    (H Sec. 4; ``"none"``: the base technique alone), or your own ``make(base, receiver)``.

    Per-block samplers (W Sec. 5.3-5.4, :mod:`anisosample.render.aligned`): ``sampler="aligned"``
    or ``"sheared"`` estimates each block's direction first (``sampler_options``: the keywords of
    :func:`~anisosample.render.aligned.block_sampler`, e.g. ``block_px``, ``samples``, ``k``,
    ``gate``, ``table``), or pass a finished :class:`~anisosample.render.aligned.BlockSampler`;
    each pixel then uses its block's set (or, gated, pmj02bn) with its own toroidal shift, and
    ``RenderResult.pixel_sampler`` records which. Sets no table holds are built on demand into
    the user cache first (``sampler_options={"build_missing": False}`` refuses instead, naming
    the command that builds them). ``progress=False`` silences everything the call starts: the
    render's bar, the estimation's and those of the sets it builds.

    ``chunk_samples`` (default :func:`default_chunk_samples`: 65536, or 4096 over many
    primitives without a BVH) or ``chunk`` (pixels) sets how many samples one vmapped chunk
    holds: speed and memory. It may move the image's last bit: chunks of 4096 to 262144 samples
    gave the same image on every scene tried, 1024 moved one of cornell's by 8.9e-8.

    ``devices``: split the pixels over these devices, their blocks of ``chunk`` x ``per_call``
    pixels dealt out in turn, e.g. ``jax.local_devices()``; under ``jax.distributed`` every
    process's, ``jax.devices()`` (each process runs the same call, renders its share and gets
    the whole image, gathered with ``multihost_utils.process_allgather``). The same bits as one
    device: each block runs the one-device program, and a pixel's estimate depends only on its
    index and ``key``. ``None``: the default device.

    ``culling``: a scene without a BVH tests, per tile of pixels, only the planar primitives
    the tile's primary and shadow rays can meet (:mod:`anisosample.render.culling`, computed
    here on the host and cached), and the tiles whose rays meet no sphere or bilinear patch
    skip those tests (up to three classes of tiles, each its own kernel:
    :func:`~anisosample.render.culling.tile_classes`); off, every ray tests every primitive.
    The same nearest hits either way (the image may move by float32 rounding). ``None``
    (default): on from :data:`~anisosample.render.culling.AUTO_SAMPLES` samples per
    realization, where it saves more than the kernels it compiles for the image's tiles
    cost.
    """
    key = check_key("key", key)
    spp = check_int("spp", spp, minimum=1)
    if culling is not None and not isinstance(culling, (bool, np.bool_)):
        raise TypeError(f"culling must be True, False or None, got {culling!r}")
    from .culling import AUTO_SAMPLES, tile_classes, with_culling

    if culling is None:
        culling = scene.width * scene.height * spp >= AUTO_SAMPLES
    scene = with_culling(scene, bool(culling))
    realizations = check_int("realizations", realizations, minimum=1)
    options = options_of(options, pixel_center=pixel_center, dimension=dimension,
                         technique=technique, light_warp=light_warp, mis=mis,
                         square_aperture=square_aperture).for_scene(scene)
    split = _PixelSplit.of(check_devices("devices", devices))
    from .aligned import render_chunk_sets, resolve_sampler
    from .pixel_aligned import PIXEL_SAMPLERS, PixelSampler, pixel_sampler

    per_pixel = None
    if isinstance(sampler, str) and sampler in PIXEL_SAMPLERS:
        per_pixel = pixel_sampler(scene, **(sampler_options or {}))
    elif isinstance(sampler, PixelSampler):
        if sampler_options:
            raise ValueError("sampler_options are for samplers given by name, not a finished "
                             "PixelSampler")
        per_pixel = sampler
    blocks = None if per_pixel is not None else resolve_sampler(
        scene, sampler, sampler_options, options=options, progress=progress)
    if per_pixel is not None:
        sampler_name = per_pixel.name
        if (per_pixel.width, per_pixel.height) != (scene.width, scene.height):
            raise ValueError(f"sampler was made for a {per_pixel.width}x{per_pixel.height} "
                             f"image, the scene is {scene.width}x{scene.height}")
        if spp < 64:
            raise ValueError(f"sampler 'aligned-pixel' needs spp >= 64 (a 16-point prefix and "
                             f"its set), got {spp}")
        per_pixel.prefix_for(spp)
    elif blocks is None:
        sample_points, sampler_name = _get_sampler(sampler)
    else:
        sampler_name = blocks.name
        blocks.check_tables(spp, progress=progress)
    w, h = scene.width, scene.height
    npix = w * h
    _check_memory(w, h)
    # A chunk of pixels is vmapped (about ``chunk_samples`` samples); ``per_call`` chunks run
    # per jit call under lax.map (few dispatches, live progress).
    if chunk_samples is None:
        chunk_samples = default_chunk_samples(scene)
    chunk_samples = check_int("chunk_samples", chunk_samples, minimum=1)
    if chunk is not None:
        chunk = check_int("chunk", chunk, minimum=1)

    def sizing(samples: int, pixels: int | None = None) -> tuple[int, int]:
        """``(chunk, per_call)`` of a pass taking ``samples`` per pixel (the per-pixel
        sampler's passes take fewer than ``spp``: its prefix pass ``m``): ``chunk`` if given,
        else ``pixels`` if given, else about ``chunk_samples`` samples per chunk; at most 2^18
        samples per call."""
        c = chunk or pixels or max(1, min(npix, chunk_samples // samples))
        return c, max(1, min(-(-npix // c), 2**18 // (c * samples)))

    # Classes of tiles, each its own kernel: candidate lists as long as its tiles need, and no
    # sphere or patch tests where they meet none (MIS's BSDF rays may meet anything).
    classes = tile_classes(scene, sizing(spp)[0], curved_everywhere=options.mis)
    pixel_class = np.zeros(npix, np.int32)
    for i, c in enumerate(classes or ()):
        pixel_class[c.pixels] = i

    def blocking(size: int, whole: bool, chunk: int, per_call: int) -> list[tuple[int, int]]:
        """The blocks of a pass over ``size`` pixels in chunks of ``chunk`` pixels: ``(first
        position, chunks per jit call)`` each, ``per_call`` chunks but where that pads more
        than a tenth: a pass over
        some pixels (the per-pixel sampler's search and its edge pixels' rest, a class of
        tiles) then runs its whole blocks and the rest one chunk per call (cornell's 1,329
        search pixels at 128^2 x 256 spp had been padded to 2,048). A pass over the whole image
        keeps its blocks: one chunk per call made the smooth pixels' pass slower (109 ->
        122-129 ms, more dispatches)."""
        big = chunk * per_call
        if whole or -size % big <= size // 10:
            return [(c, per_call) for c in range(0, max(size, 1), big)]
        full = size // big * big
        return [(c, per_call) for c in range(0, full, big)] + \
            [(c, 1) for c in range(full, max(size, 1), chunk)]

    # the passes over every pixel: the render's, or the per-pixel sampler's prefix pass
    from ..prefix import prefix_size

    whole_sizing = sizing(spp if per_pixel is None else prefix_size(per_pixel.prefix_for(spp)))
    n_chunks = sum(len(blocking(n, classes is None, *whole_sizing)) for n in
                   ((npix,) if classes is None else (c.pixels.size for c in classes)))
    from ..progress import progress as bar

    total = np.zeros((npix, 3), np.float64)
    total2 = np.zeros((npix, 3), np.float64)
    opts = dict(options=options)
    with bar(
        total=realizations * (n_chunks + 3 if per_pixel is not None else n_chunks),
        desc="render",
        disable=None if progress and jax.process_index() == 0 else True,
        unit="chunk",
    ) as pb:

        def over_pixels(kernel, args, static, pixels=None, samples=spp, chunk_pixels=None):
            """``kernel(*args, idx, **static)`` (a jitted chunk kernel: ``idx`` a
            ``(per_call, chunk)`` block of flat pixel indices, ``args[0]`` the scene) over
            every pixel (or the flat indices ``pixels``): its outputs, each ``(npix, ...)``
            (zero outside ``pixels``). ``samples``: the integrand samples the kernel takes per
            pixel, which size its chunks, or ``chunk_pixels`` pixels per chunk
            (:func:`sizing`). Each class of tiles (``classes``) runs with its own scene."""
            whole = pixels is None
            size = sizing(samples, chunk_pixels)
            todo = np.arange(npix) if whole else np.asarray(pixels, np.int64)
            parts = [(todo, args)]
            if classes is not None and args[0] is scene:
                mine = pixel_class[todo]
                parts = [(todo[mine == i], (c.scene, *args[1:]))
                         for i, c in enumerate(classes)]
                parts = [p for p in parts if p[0].size] or parts[:1]
            outs = None
            for part, run in parts:
                res = one_pass(kernel, run, static, part, whole, whole and len(parts) == 1,
                               *size)
                if outs is None:
                    outs = res
                else:
                    for o, r in zip(outs, res, strict=True):
                        o[part] = r[part]
            if not whole:
                pb.update(1)
            return outs

        def one_pass(kernel, args, static, todo, counted, whole, chunk, per_call):
            """:func:`over_pixels` over ``todo`` with ``args``' scene, in chunks of ``chunk``
            pixels, ``per_call`` per jit call. Block ``c`` runs on process ``c % P`` of the
            ``P`` sharing ``devices``, on its local devices in turn; the next block is
            dispatched before one is read. ``counted``: a part of the pass over every pixel
            (progress per block); ``whole``: that whole pass."""
            blocks = blocking(todo.size, whole, chunk, per_call)
            outs = []  # allocated from the first block's outputs (no trace of the kernel)

            def allocate(results):
                outs.extend(np.zeros((npix, *r.shape[2:]), r.dtype) for r in results)

            def collect(idx, valid, res):
                res = res if isinstance(res, tuple) else (res,)
                if not outs:
                    allocate(res)
                for o, r in zip(outs, res, strict=True):
                    o[idx[valid]] = np.asarray(r).reshape(-1, *r.shape[2:])[valid]
                if counted:
                    pb.update(split.processes)

            pending = collections.deque()
            for turn, (start, calls) in enumerate(blocks[split.rank::split.processes]):
                pos = np.arange(start, start + calls * chunk)
                valid = pos < todo.size
                idx = todo[np.where(valid, pos, max(todo.size - 1, 0))] if todo.size else pos
                idx = idx.astype(np.int32)
                device = split.devices[turn % len(split.devices)]
                block = idx.reshape(calls, chunk)
                block = jnp.asarray(block) if device is None else jax.device_put(block, device)
                pending.append((idx, valid, kernel(*args, block, **static)))
                if len(pending) > len(split.devices):
                    collect(*pending.popleft())
            while pending:
                collect(*pending.popleft())
            if not outs:  # this process rendered no block: the shapes from a trace
                shapes = jax.eval_shape(lambda i: kernel(*args, i, **static),
                                        jax.ShapeDtypeStruct((1, chunk), jnp.int32))
                allocate(shapes if isinstance(shapes, tuple) else (shapes,))
            if split.processes > 1:  # every process gets the blocks the others rendered
                outs = split.gather(outs, todo, [b[0] for b in blocks])
            return outs

        for r in range(realizations):
            k_pts, k_pix = jax.random.split(jax.random.fold_in(key, r))
            if per_pixel is not None:
                est, record = _render_per_pixel(per_pixel, scene, spp, k_pts, k_pix, opts,
                                                over_pixels, progress)
                if r == 0:
                    first = record
            else:
                if blocks is not None:
                    sets, pixel_set = blocks.point_sets(k_pts, spp)
                    pixel_set = jnp.asarray(pixel_set)
                    pts = sets[0]
                else:
                    pts = jnp.asarray(sample_points(k_pts, spp), jnp.float32)
                if pts.shape != (spp, 2):
                    raise ValueError(f"sampler {sampler_name!r} returned shape {pts.shape}, "
                                     f"expected ({spp}, 2)")
                if blocks is None:
                    (est,) = over_pixels(render_chunk, (scene, pts, k_pix), opts)
                else:
                    (est,) = over_pixels(render_chunk_sets,
                                         (scene, sets, pixel_set, k_pix), opts)
                est = est.astype(np.float64)
            if not np.all(np.isfinite(est)):
                raise FloatingPointError("the render produced NaN or Inf (a bug: please report)")
            total += est
            total2 += est * est
    mean = total / realizations
    var = None
    if realizations > 1:
        var = np.maximum(total2 - realizations * mean * mean, 0.0) / (realizations - 1)
        var = var.reshape(h, w, 3).astype(np.float32)
    settings = dict(
        spp=spp,
        sampler=sampler_name,
        realizations=realizations,
        **options.settings(),
        width=w,
        height=h,
    )
    code = dirs = extra = None
    if blocks is not None:
        settings["blocks"] = blocks.settings()
        code = blocks.pixel_sampler
    if per_pixel is not None:
        settings["blocks"] = {**per_pixel.settings(), **first["settings"]}
        code = first["code"].reshape(h, w)
        dirs = first["directions"].reshape(h, w, 2)
        extra = first["extra"].reshape(h, w)
    return RenderResult(
        mean=mean.reshape(h, w, 3).astype(np.float32),
        variance=var,
        spp=spp,
        realizations=realizations,
        settings=settings,
        pixel_sampler=code,
        pixel_directions=dirs,
        pixel_estimation_samples=extra,
    )


def default_chunk_samples(scene: Scene) -> int:
    """Samples per vmapped chunk of :func:`render` (its ``chunk_samples=None``): 65536, or 4096
    where the ray caster tests every one of more than
    :data:`~anisosample.render._kernel.BRUTE_WIDE` planar primitives (its ``(samples x
    primitives)`` arrays then leave the cache). One device, 128^2 x 64 spp, pmj02bn, best of 3
    (load 1-1.8), chunk_samples 4096 / 32768 / 65536 / 131072: cornell 118 / 92 / 84 / - ms,
    blinds 161 / 146 / 137 / -, dof 148 / 112 / 113 / 139, attic 152 / 132 / 126 / 127; the
    same image at every size. Brute force over a sphere mesh, ns per sample at 4096 / 16384 /
    65536: 48 triangles 143 / 134 / 127, 80: 198 / - / 254, 168: 369 / - / 581, 288: 566 / 599
    / 968, 840: 1363 / 1859 / 2656."""
    from ._kernel import BRUTE_WIDE, brute_force_primitives

    return 4096 if brute_force_primitives(scene) > BRUTE_WIDE else 65536


class _PixelSplit(NamedTuple):
    """How :func:`render` spreads its blocks of pixels: over the processes ``owners`` (this one
    is the ``rank``-th of them) and, within this process, over ``devices`` in turn (``[None]``:
    the default device).

    Every block runs the one-device program on one device, so the bits are those of one device.
    (A ``shard_map`` of the block's rows over a mesh, tried first, gives the same bits but on
    two forced CPU devices the per-pixel aligned sampler's edge-search kernel never finished
    (``jax 0.10.2``), while each device alone took 12 s; GSPMD on the chunk axis did the same
    and also changes the vectorised width, and with it the last bit of some pixels.)"""

    devices: list
    owners: tuple = (0,)  # the process indices that share the blocks, in order

    @property
    def processes(self) -> int:
        return len(self.owners)

    @property
    def rank(self) -> int:
        return self.owners.index(jax.process_index())

    @classmethod
    def of(cls, devices) -> _PixelSplit:
        if devices is None:
            return cls([None])
        me = jax.process_index()
        owners = tuple(sorted({d.process_index for d in devices}))
        if me not in owners:
            raise ValueError(f"devices must include one of this process's devices (process "
                             f"{me}), got only those of process(es) {list(owners)}")
        return cls([d for d in devices if d.process_index == me], owners)

    def gather(self, outs: list, todo: np.ndarray, starts: list[int]) -> list:
        """Each pixel's values from the process that rendered its block (block ``c`` of the
        ``todo`` pixels, from position ``starts[c]``: process ``owners[c % processes]``), on
        every process."""
        from jax.experimental import multihost_utils

        every = multihost_utils.process_allgather(outs)  # [(process_count, npix, ...)]
        block = np.searchsorted(np.asarray(starts), np.arange(todo.size), side="right") - 1
        owner = np.asarray(self.owners)[block % self.processes]
        merged = []
        for o, e in zip(outs, every, strict=True):
            o = o.copy()
            o[todo] = np.asarray(e)[owner, todo]
            merged.append(o)
        return merged


def _render_per_pixel(sampler, scene: Scene, spp: int, k_pts, key, opts: dict, over_pixels,
                      progress: bool):
    """One realization with the per-pixel aligned sampler (:mod:`anisosample.render.
    pixel_aligned`): pass 1 renders each pixel's prefix and estimates its directions, the sets
    are chosen (and built where missing), pass 2 renders the rest of each edge pixel's set and
    pmj02bn on the others. ``(estimate, record)``."""
    from .. import samplers
    from ..prefix import prefix_points
    from .aligned import pad_sets
    from .pixel_aligned import (
        FALLBACK,
        SEARCH_CHUNK,
        apart_chunk,
        choose_sets,
        exact_values,
        neighbour_consensus,
        prefix_chunk,
        prefix_weight,
        rest_chunk,
        search_chunk,
    )

    prefix_name = sampler.prefix_for(spp)
    prefix = jnp.asarray(prefix_points(prefix_name), jnp.float32)
    m = prefix.shape[0]
    head, rough = over_pixels(prefix_chunk, (scene, prefix, key),
                              dict(opts, spp=spp, search=sampler.search), samples=m)
    # The search only where it has a candidate (elsewhere it finds nothing and samples nothing):
    # 8 % of cornell's pixels at 128^2 (the search's own test: 30 % of pillars'); run on every
    # pixel, the search was most of the render's time (cornell 128^2 x 256 spp: 2.5 s -> 1.2 s).
    # It evaluates the candidates' prefix values again rather than pass 1 returning every
    # pixel's (npix x m float32: about 420 MB at 1280^2 and 64 points).
    npix = head.shape[0]
    dirs = np.full((npix, 2), np.nan, np.float32)
    count = np.zeros(npix, np.int32)
    extra = np.zeros(npix, np.int32)
    rough = np.flatnonzero(rough)
    if rough.size:
        found = over_pixels(search_chunk, (scene, prefix, key),
                            dict(opts, spp=spp, search=sampler.search), rough,
                            chunk_pixels=SEARCH_CHUNK)
        for out, res in zip((dirs, count, extra), found, strict=True):
            out[rough] = res[rough]
    if not exact_values(scene, opts["options"]):
        extra = extra + m  # the prefix's values re-evaluated for the search
    own = dirs
    if sampler.neighbours:
        shape = (sampler.height, sampler.width)
        dirs, count = neighbour_consensus(dirs.reshape(*shape, 2), count.reshape(shape),
                                          radius=sampler.neighbours)
        dirs, count = dirs.reshape(-1, 2), count.reshape(-1)
    requests, index, code = choose_sets(dirs, count, sampler.k, sampler.near_axis_deg,
                                        sampler.axis_snap)
    edge = np.flatnonzero(index >= 0)
    smooth = np.flatnonzero(index < 0)
    est = np.zeros((index.size, 3), np.float64)
    apart = dict(opts, spp=spp, m=m)
    if edge.size:
        sets = sampler.sets(requests, spp, progress=progress)  # on the host: no compiles
        if sampler.reuse and not np.array_equal(sets[:, :m],
                                                np.broadcast_to(prefix, (len(sets), m, 2))):
            raise ValueError("a prefix set does not start with its prefix (a damaged table)")
        pixel_set = jnp.asarray(np.maximum(index, 0))
        if sampler.reuse:
            (rest,) = over_pixels(rest_chunk, (scene, pad_sets(sets[:, m:]), pixel_set, key),
                                  dict(opts, spp=spp), edge, samples=spp - m)
            est[edge] = (head[edge].astype(np.float64) + rest[edge].astype(np.float64)) / spp
        else:
            (own,) = over_pixels(apart_chunk, (scene, pad_sets(sets), pixel_set, key), apart,
                                 edge)
            est[edge] = own[edge].astype(np.float64)
    if smooth.size:
        base = jnp.asarray(samplers.get(FALLBACK)(k_pts, spp), jnp.float32)
        (fb,) = over_pixels(apart_chunk, (scene, base[None], jnp.zeros(index.size, jnp.int32),
                                          key), apart, smooth)
        w = prefix_weight(m, spp) if sampler.reuse else 0.0
        est[smooth] = (w * head[smooth].astype(np.float64) / m
                       + (1 - w) * fb[smooth].astype(np.float64))
    # beyond spp: the search's samples (and the prefix re-evaluated, or where it is not reused
    # in the set -- on smooth pixels, taken beside pmj02bn's spp and weighted in; with probes
    # apart, every pixel's)
    extra = extra.astype(np.int32) + np.where((index < 0) | (not sampler.reuse), m, 0
                                              ).astype(np.int32)
    found = count > 0
    record = dict(code=code, directions=dirs.astype(np.float32), extra=extra, settings=dict(
        prefix=prefix_name, prefix_points=m, reused_samples_per_pixel=m * sampler.reuse,
        estimation_samples_per_pixel=round(float(extra.mean()), 3),
        estimation_samples_per_edge_pixel=round(float(extra[found].mean()), 3) if found.any()
        else 0.0,
        pixels=int(code.size), pixels_with_3_direction_set=int((code == 3).sum()),
        pixels_with_4_direction_set=int((code == 4).sum()),
        pixels_fallback=int((code == 5).sum()),
        pixels_first_direction_from_neighbours=int(np.sum(
            np.isfinite(own[:, 0]) & ~np.isnan(dirs[:, 0]) & (own[:, 0] != dirs[:, 0]))),
        pixels_second_direction_dropped=int(np.sum(np.isfinite(own[:, 1]) & np.isnan(dirs[:, 1])
                                                   )),
        fallback_prefix_weight=prefix_weight(m, spp) if sampler.reuse else 0.0,
        sets_3_directions_deg=sorted(e[0] for e in requests if len(e) == 1),
        sets_4_directions_deg=sorted(list(e) for e in requests if len(e) == 2)))
    return est, record


_BYTES_PER_PIXEL = 3 * (8 + 8 + 8 + 4 + 4)  # float64 sum, sum of squares, estimate; mean, var


def _check_memory(w: int, h: int) -> None:
    """Refuse, before allocating, an image whose buffers exceed this machine's memory."""
    need = w * h * _BYTES_PER_PIXEL
    try:
        have = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):  # not available on this platform
        return
    if need > have:
        raise ValueError(
            f"a {w}x{h} render needs about {need / 2**30:.1f} GiB for its image buffers"
            f" ({_BYTES_PER_PIXEL} bytes per pixel), more than this machine's"
            f" {have / 2**30:.1f} GiB of memory; render a smaller image (width, height)"
        )


def tonemap(image, *, exposure: float = 0.0) -> np.ndarray:
    """Linear RGB to 8-bit-ready sRGB in ``[0, 1]``: ``2^exposure`` scale, clamp, sRGB curve.

    ``ValueError`` for a non-finite ``exposure`` or an image with NaN (never NaN pixels)."""
    exposure = float(exposure)
    if not np.isfinite(exposure):
        raise ValueError(f"exposure must be finite (stops), got {exposure}")
    x = np.asarray(image, np.float64)
    if np.isnan(x).any():
        raise ValueError(f"image has {int(np.isnan(x).sum())} NaN values; tonemap needs numbers")
    x = np.clip(x * 2.0**exposure, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055).astype(np.float32)


def save_result(
    path,
    result: RenderResult,
    *,
    overwrite: bool = False,
    exposure: float = 0.0,
    reference: np.ndarray | None = None,
    png: bool = True,
    metadata: dict | None = None,
) -> list[Path]:
    """Write ``path`` (EXR, the mean image), ``*_variance.exr`` (when R > 1), ``*_mse.exr``
    (against ``reference``) and ``*.png`` previews. Every file is written atomically and
    nothing is replaced unless ``overwrite``; all targets are checked before the first write.
    """
    from .. import io

    path = Path(path)
    if path.suffix != ".exr":
        raise ValueError(f"output must end in .exr, got {path.name}")
    meta = {**io.provenance(), **result.settings, **(metadata or {})}
    stem = path.with_suffix("")
    jobs: list[tuple[Path, str, np.ndarray]] = [(path, "exr", result.mean)]
    if result.variance is not None:
        jobs.append((Path(f"{stem}_variance.exr"), "exr", result.variance))
    if reference is not None:
        ref = np.asarray(reference, np.float32)
        if ref.shape != result.mean.shape:
            raise ValueError(f"reference must have shape {result.mean.shape}, got {ref.shape}")
        # MSE of one realization's estimate: variance + squared bias of the mean.
        err = (result.mean - ref) ** 2
        if result.variance is not None:
            err = result.variance + err
        jobs.append((Path(f"{stem}_mse.exr"), "exr", err))
    if png:
        jobs.append((path.with_suffix(".png"), "png", tonemap(result.mean, exposure=exposure)))
    if not overwrite:
        for p, _, _ in jobs:
            if p.exists():
                raise FileExistsError(f"{p} exists; pass overwrite=True (CLI: --force)")
    written = []
    for p, kind, img in jobs:
        if kind == "exr":
            io.write_exr(p, img, meta, overwrite=overwrite)
        else:
            io.save_png(p, img, overwrite=overwrite)
        written.append(p)
    return written

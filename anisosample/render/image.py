"""Rendering whole images: realizations, per-pixel variance, EXR and PNG output.

The image estimator of pixel ``q`` is ``mean_j f_q(shift_q(S)_j)`` with one point set ``S`` per
realization from the chosen sampler and an independent toroidal shift per pixel (W Sec. 5.4).
Over ``R`` realizations the result holds the mean image and the per-pixel sample variance of
the one-realization estimator (its MSE when the estimator is unbiased).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._validate import check_int, check_key
from .integrator import check_options, render_chunk
from .light_warps import light_warp_name
from .scene import Scene


class RenderResult(NamedTuple):
    mean: np.ndarray  # (h, w, 3) float32, row 0 at the top
    variance: np.ndarray | None  # (h, w, 3) sample variance over realizations (None if R = 1)
    spp: int
    realizations: int
    settings: dict
    # per-block samplers: each pixel's decision (render.aligned.PIXEL_CODES), else None
    pixel_sampler: np.ndarray | None = None


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
    chunk_samples: int = 4096,
    progress: bool = True,
    sampler_options: dict | None = None,
) -> RenderResult:
    """Render ``scene`` ``realizations`` times with ``spp`` points per pixel per realization.

    ``sampler``: a name from :func:`anisosample.samplers.names` or a callable ``(key, n)``.
    ``spp`` (default 64) and ``mis`` (default off: light sampling alone; on: one BSDF sample
    per light sample, power heuristic) are the caller's: a scene file's own sample count and
    integrator are :class:`~anisosample.render.xml.RenderSettings`
    (``scene, settings = load_xml_with_settings(p)``; ``render(scene, key,
    **settings._asdict())``). ``mis`` applies to light sampling only (``dimension="light"``).
    Deterministic for a given ``key``.

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
    """
    key = check_key("key", key)
    spp = check_int("spp", spp, minimum=1)
    realizations = check_int("realizations", realizations, minimum=1)
    dimension = check_options(scene, dimension, technique, light_warp)
    if not isinstance(mis, (bool, np.bool_)):
        raise TypeError(f"mis must be True or False, got {mis!r}")
    mis = bool(mis) and dimension == "light"
    from .aligned import render_chunk_sets, resolve_sampler

    blocks = resolve_sampler(scene, sampler, sampler_options, dimension=dimension,
                             technique=technique, square_aperture=bool(square_aperture),
                             progress=progress)
    if blocks is None:
        sample_points, sampler_name = _get_sampler(sampler)
    else:
        sampler_name = blocks.name
        blocks.check_tables(spp, progress=progress)
    w, h = scene.width, scene.height
    npix = w * h
    _check_memory(w, h)
    # A chunk of pixels is vmapped (about ``chunk_samples`` samples: small enough to stay in
    # cache); ``per_call`` chunks run per jit call under lax.map (few dispatches, live progress).
    if chunk is None:
        chunk = max(1, min(npix, chunk_samples // spp))
    chunk = check_int("chunk", chunk, minimum=1)
    per_call = max(1, min(-(-npix // chunk), 2**18 // (chunk * spp)))
    n_chunks = -(-npix // (chunk * per_call))
    from ..progress import progress as bar

    total = np.zeros((npix, 3), np.float64)
    total2 = np.zeros((npix, 3), np.float64)
    opts = dict(
        dimension=dimension,
        technique=technique,
        mis=mis,
        pixel_center=bool(pixel_center),
        square_aperture=bool(square_aperture),
        light_warp=light_warp,
    )
    with bar(
        total=realizations * n_chunks,
        desc="render",
        disable=None if progress else True,
        unit="chunk",
    ) as pb:
        for r in range(realizations):
            k_pts, k_pix = jax.random.split(jax.random.fold_in(key, r))
            if blocks is not None:
                sets, pixel_set = blocks.point_sets(k_pts, spp)
                pixel_set = jnp.asarray(pixel_set)
                pts = sets[0]
            else:
                pts = jnp.asarray(sample_points(k_pts, spp), jnp.float32)
            if pts.shape != (spp, 2):
                raise ValueError(
                    f"sampler {sampler_name!r} returned shape {pts.shape}, expected ({spp}, 2)"
                )
            est = np.zeros((npix, 3), np.float64)
            for c in range(n_chunks):
                idx = np.arange(c * chunk * per_call, (c + 1) * chunk * per_call)
                valid = idx < npix
                idx = np.where(valid, idx, npix - 1).astype(np.int32)
                if blocks is None:
                    out = render_chunk(scene, pts, k_pix,
                                        jnp.asarray(idx.reshape(per_call, chunk)), **opts)
                else:
                    out = render_chunk_sets(scene, sets, pixel_set, k_pix,
                                            jnp.asarray(idx.reshape(per_call, chunk)), **opts)
                est[idx[valid]] = np.asarray(out, np.float64).reshape(-1, 3)[valid]
                pb.update(1)
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
        pixel_center=bool(pixel_center),
        dimension=dimension,
        technique=technique,
        light_warp=light_warp_name(light_warp),
        mis=mis,
        square_aperture=bool(square_aperture),
        width=w,
        height=h,
    )
    if blocks is not None:
        settings["blocks"] = blocks.settings()
    return RenderResult(
        mean=mean.reshape(h, w, 3).astype(np.float32),
        variance=var,
        spp=spp,
        realizations=realizations,
        settings=settings,
        pixel_sampler=None if blocks is None else blocks.pixel_sampler,
    )


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

"""The renderer's per-block aligned sampler (W Sec. 5.3-5.4, with a per-pixel gate).

``render(scene, key, sampler="aligned")`` (or ``"sheared"``) resolves to a :class:`BlockSampler`
made by :func:`block_sampler`; the steps live in their own modules:

* **Estimation (W Sec. 5.3)**, :mod:`anisosample.render.estimation`: one tiled ``s x s`` grid of
  integrand samples per block of ``B x B`` pixels and one direction estimate per block (W: 96,
  16); with the gate, each pixel's probe of its own integrand.
* **Selection (W Sec. 5.4)**, :mod:`anisosample.selection`: a block's estimated directions
  (strongest first, at most ``k``) rounded by :func:`anisosample.selection.table_directions`; one
  direction takes the 3-direction set, two the 4-direction set (W's four low-energy directions);
  missing sets are built on demand with progress, before any rendering (the one rule of
  :func:`anisosample.tables.lookup`; ``build_missing=False`` refuses and names the command).
  No direction: the base sampler (pmj02bn, W: "an existing anisotropic sampling pattern").
  ``point_set="sheared"`` gives pmj02bn sheared to the block's strongest direction (Singh & Jarosz
  2017) instead, for comparisons.
* **The gate (beyond W)**: pixels of a block with a set whose probe shows no jump
  (:func:`anisosample.render.estimation.probe_discontinuous`: fully lit, fully occluded) use the
  base sampler; on by default for ``"aligned"``. Each pixel's decision is in the render's record
  (``RenderResult.pixel_sampler``: :data:`PIXEL_CODES`).
* **Decorrelation (W Sec. 5.4)**: every pixel uses its set with its own toroidal shift (Cranley &
  Patterson 1976) from the pixel's key, the key :func:`anisosample.render.render` gives every
  sampler. A uniform shift makes every point uniform on the torus, so each pixel's estimator is
  unbiased whatever set it gets (the choice depends only on the deterministic estimation grid
  and probe). :func:`render_chunk_sets` is the render kernel with per-pixel sets.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from .. import selection
from .._validate import check_choice, check_int, check_key, renamed_keywords
from ..plot import direction_rgb as direction_rgb  # re-exports: see the note below __all__
from ..plot import save_direction_map as save_direction_map
from ._kernel import kernel
from .estimation import BlockEstimate as BlockEstimate
from .estimation import block_grid_values as block_grid_values
from .estimation import estimate_blocks as estimate_blocks
from .estimation import estimation_grid as estimation_grid
from .estimation import estimation_options, gate_estimate
from .estimation import strongest_directions as strongest_directions
from .options import IntegratorOptions
from .scene import Scene

__all__ = [
    "BLOCK_SAMPLERS", "PIXEL_CODES", "POINT_SETS", "BlockSampler", "block_sampler", "block_sets",
    "pad_sets", "render_chunk_sets", "resolve_sampler", "table_direction",
]
# Also importable from here, as before the split (scripts use them): BlockEstimate,
# estimate_blocks, estimation_grid, block_grid_values, strongest_directions (render.estimation),
# aligned_set (selection), direction_rgb, save_direction_map (plot).

POINT_SETS = ("aligned", "sheared", "pmj02bn")
"""Per-block point-set choices: the aligned table set, pmj02bn sheared to the block's strongest
direction (Singh & Jarosz 2017), plain pmj02bn (W Sec. 5.4, Figs. 8-9)."""

BLOCK_SAMPLERS = ("aligned", "sheared")
"""Sampler names :func:`anisosample.render.render` resolves with a per-block estimate."""

PIXEL_CODES = {0: "base: the block has no set", 1: "base: gated (the pixel's probe is smooth)",
               2: "the block's set", 3: "prefix + the 3-direction set of the pixel's direction",
               4: "prefix + the 4-direction set of the pixel's two directions (a corner)",
               5: "pmj02bn, the prefix weighted in (no edge found)"}
"""The per-pixel record ``RenderResult.pixel_sampler``: 0-2 per-block samplers
(``BlockSampler.pixel_sampler``), 3-5 the per-pixel aligned sampler
(:mod:`anisosample.render.pixel_aligned`)."""


# --- selection per block (W Sec. 5.4) -------------------------------------------------------------


def table_direction(direction_deg) -> int | None:
    """The one integer direction the 3-direction table is asked for (or None): the strongest
    direction through :func:`anisosample.selection.table_directions` with ``k = 1``."""
    d = selection.table_directions((direction_deg,), 1)
    return d[0] if d else None


aligned_set = selection.aligned_set


def block_sets(direction_deg: float | None, n: int, key, *, table=None,
               build_missing: bool | None = None) -> dict[str, jax.Array]:
    """The point set of every choice in :data:`POINT_SETS` for a block whose strongest direction
    is ``direction_deg`` (None: no extra direction); ``aligned`` is its 3-direction set.

    ``key`` is split into two: pmj02bn from the first (the fallback, and the set the ``sheared``
    choice shears), the aligned set's toroidal shift from the second. Without a direction (or
    one that rounds onto an axis, for ``aligned``) a choice falls back to the pmj02bn set.
    ``table``, ``build_missing``: the table lookup's (:func:`anisosample.tables.lookup`; a
    missing set is built unless ``build_missing=False``).
    """
    from .. import samplers

    key = check_key("key", key)
    n = check_int("n", n, minimum=2)
    k_pmj, k_al = jax.random.split(key)
    pmj = jnp.asarray(samplers.get(selection.FALLBACK)(k_pmj, n), jnp.float32)
    out = {"pmj02bn": pmj}
    out["sheared"] = pmj if direction_deg is None else samplers.shear(pmj, direction_deg)
    d = selection.table_directions((direction_deg,), 1)
    out["aligned"] = pmj if not d else selection.aligned_set(d, n, k_al, table=table,
                                                             build_missing=build_missing)
    return out


# --- the renderer's per-block sampler -------------------------------------------------------------


@dataclasses.dataclass(frozen=True, eq=False)
class BlockSampler:
    """Per-pixel point sets for :func:`anisosample.render.render` (W Sec. 5.4).

    Made by :func:`block_sampler`. ``directions_deg``/``valid``: each block's strongest extra
    direction that passed the confidence test (``(rows, cols)``; the first valid slot of the
    estimate, the one the block's set is chosen from, so a block marked without a direction
    never gets a set); ``block_extra``: per block (row-major) the integer extra directions of
    its aligned set (empty: the base sampler); ``estimate``: the :class:`BlockEstimate` it came
    from; ``options``: the integrand options the directions were estimated with
    (:func:`~anisosample.render.estimation.estimation_options` of the render's, resolved for
    the scene); ``gate``: whether smooth pixels take the base sampler; ``build_missing``: the
    table lookup's (None: build missing sets into the user cache; False: refuse).
    Per realization, :meth:`point_sets` gives the distinct sets and each pixel's index into
    them; the renderer shifts each pixel's set toroidally with the pixel's own key.
    """

    point_set: str
    block_px: int
    width: int
    height: int
    directions_deg: np.ndarray  # (rows, cols) float64, -1 where there is none
    valid: np.ndarray  # (rows, cols) bool
    estimate: BlockEstimate | None = None
    options: IntegratorOptions = IntegratorOptions(dimension="light").integrand()
    base: str = selection.FALLBACK
    table: object = None
    build_missing: bool | None = None
    k: int = 2
    gate: bool = False
    block_extra: tuple = ()
    build_options: dict = dataclasses.field(default_factory=dict)

    @property
    def name(self) -> str:
        """The sampler's name in render settings: its point set."""
        return self.point_set

    def _set_ids(self) -> list:
        """Per block (row-major) the identity of its set: None (base), a tuple of integer extra
        directions (aligned) or a float direction (sheared)."""
        if self.point_set == "aligned":
            return [e if e else None for e in self.block_extra]
        return [float(d) if v else None for d, v in
                zip(self.directions_deg.reshape(-1), self.valid.reshape(-1), strict=True)]

    @property
    def table_directions(self) -> tuple[tuple[int, ...], ...]:
        """The distinct aligned sets this sampler needs, as extra-direction tuples (one
        direction: a 3-direction set, two: a 4-direction set; empty unless aligned)."""
        if self.point_set != "aligned":
            return ()
        return tuple(sorted({i for i in self._set_ids() if i is not None}))

    @property
    def pixel_sampler(self) -> np.ndarray:
        """``(height, width)`` int8: each pixel's decision, :data:`PIXEL_CODES` (0: its block
        has no set, 1: gated to the base sampler, 2: its block's set)."""
        by, bx = self.valid.shape
        has = np.asarray([i is not None for i in self._set_ids()], bool).reshape(by, bx)
        rows = np.arange(self.height) // self.block_px
        cols = np.arange(self.width) // self.block_px
        code = np.where(has[rows[:, None], cols[None, :]], 2, 0).astype(np.int8)
        if self.gate:
            code[(code == 2) & ~self.estimate.discontinuous] = 1
        return code

    def check_tables(self, n: int, *, progress: bool = True) -> None:
        """Make every aligned set needed for ``n`` points available now, before rendering:
        missing sets are built (the one rule, :func:`anisosample.tables.ensure`:
        into the user cache unless ``build_missing=False``; into an explicit ``table`` only with
        ``build_missing=True``), else one ``FileNotFoundError`` lists them with the commands
        that build them. ``progress=False`` silences the builds' progress bars as well."""
        from pathlib import Path

        from .. import tables
        from ..progress import progress as bar

        n = check_int("n (spp)", n, minimum=2)
        missing = [e for e in self.table_directions
                   if tables.missing([e], n, direction_count=len(e) + 2, table=self.table)]
        if missing and (self.build_missing is False
                        or (self.build_missing is None and self.table is not None)):
            cmds = []
            for kd in sorted({len(e) + 2 for e in missing}):
                sets = sorted({tables.canonicalize(e, direction_count=kd).extra for e in missing
                               if len(e) + 2 == kd})
                out = None
                if self.table is not None:
                    out = (tables.find_table(kd, n, root=self.table)
                           or Path(self.table) / tables.table_name(kd, n))
                cmds.append(f"`{tables.build_command(kd, n, sets, out=out)}`")
            sizes = "; ".join(f"{kd}-direction n = "
                              + (", ".join(map(str, tables.installed_sizes(kd))) or "none")
                              for kd in (3, 4))
            how = ("build_missing=True builds them into the table" if self.table is not None
                   else "without --no-build (build_missing=False) they are built on demand")
            raise FileNotFoundError(
                f"the aligned sampler needs sets for n={n} and extra directions "
                f"{[list(e) for e in missing]} deg that no table holds; build them with "
                + " and ".join(cmds) + f" ({how}), or pick --spp among the installed tables' "
                f"sizes ({sizes})"
            )
        opts = dict(self.build_options)
        opts["show_progress"] = bool(progress) and opts.get("show_progress", True)
        for extra in bar(missing, desc=f"aligned sets n={n}", unit="set",
                         disable=None if progress and missing else True):
            tables.ensure([extra], n, direction_count=len(extra) + 2, table=self.table,
                          build_missing=self.build_missing, **opts)

    def point_sets(self, key, n: int) -> tuple[jax.Array, np.ndarray]:
        """``(sets, pixel_set)``: ``sets`` ``(m, n, 2)`` float32, the distinct sets of one
        realization (``sets[0]`` is the base sampler's set drawn from ``key``, every other set
        derives from it or from the tables), and ``pixel_set`` ``(height * width,)`` int32, each
        pixel's (row-major) index into ``sets`` (0 where :attr:`pixel_sampler` is not 2)."""
        from .. import samplers

        key = check_key("key", key)
        n = check_int("n (spp)", n, minimum=2)
        base = jnp.asarray(samplers.get(self.base)(key, n), jnp.float32)
        ids = self._set_ids()
        distinct = [None] + sorted({i for i in ids if i is not None})
        where = {i: j for j, i in enumerate(distinct)}
        sets = [base]
        for i in distinct[1:]:
            if self.point_set == "aligned":
                sets.append(selection.aligned_set(i, n, table=self.table,
                                                  build_missing=self.build_missing,
                                                  **self.build_options))
            else:
                sets.append(samplers.shear(base, i))
        by, bx = self.valid.shape
        block_set = np.asarray([where[i] for i in ids], np.int32).reshape(by, bx)
        rows = np.arange(self.height) // self.block_px
        cols = np.arange(self.width) // self.block_px
        pixel_set = np.where(self.pixel_sampler == 2, block_set[rows[:, None], cols[None, :]], 0)
        return (pad_sets(np.stack([np.asarray(s) for s in sets])),  # host: no compile per count
                pixel_set.astype(np.int32).reshape(-1))

    def settings(self) -> dict:
        """What a render records about the sampler (EXR metadata)."""
        code = self.pixel_sampler
        s = dict(point_set=self.point_set, base=self.base, block_px=self.block_px, k=self.k,
                 gate=self.gate, blocks_with_direction=int(self.valid.sum()),
                 blocks_with_set=sum(i is not None for i in self._set_ids()),
                 blocks=int(self.valid.size), pixels=int(code.size),
                 pixels_with_block_set=int((code == 2).sum()),
                 pixels_in_blocks_without_set=int((code == 0).sum()),
                 pixels_gated=int((code == 1).sum()))
        if self.point_set == "aligned":
            sets = self.table_directions
            s["sets_3_directions_deg"] = [e[0] for e in sets if len(e) == 1]
            s["sets_4_directions_deg"] = [list(e) for e in sets if len(e) == 2]
            ids = self._set_ids()
            s["blocks_with_3_direction_set"] = sum(i is not None and len(i) == 1 for i in ids)
            s["blocks_with_4_direction_set"] = sum(i is not None and len(i) == 2 for i in ids)
        if self.estimate is not None:
            s.update(estimation_samples=self.estimate.samples,
                     estimation_integrand_samples=self.estimate.integrand_samples,
                     estimation_samples_per_pixel=self.estimate.samples_per_pixel,
                     estimation_seconds=round(self.estimate.seconds, 4))
            if self.gate:
                s.update(gate_probe=self.estimate.probe,
                         gate_seconds=round(self.estimate.probe_seconds, 4))
        return s


@renamed_keywords(method="point_set")
def block_sampler(
    scene: Scene,
    point_set: str = "aligned",
    *,
    block_px: int = 16,
    samples: int = 96,
    k: int = 2,
    gate: bool | None = None,
    probe: int = 6,
    estimate: BlockEstimate | None = None,
    table=None,
    build_missing: bool | None = None,
    build_options: dict | None = None,
    base: str = selection.FALLBACK,
    options: IntegratorOptions | None = None,
    progress: bool = False,
    **estimate_options,
) -> BlockSampler:
    """The per-block sampler of W Sec. 5.4 for ``scene``, to pass as ``render(sampler=...)``.

    ``point_set``: ``"aligned"`` (per block the table set for its estimated directions: one ->
    3 directions, two -> W's 4 directions; ``base`` elsewhere) or ``"sheared"`` (``base``
    sheared to the strongest direction, Singh & Jarosz 2017). Estimates the directions with
    :func:`~anisosample.render.estimation.estimate_blocks` (``block_px``, ``samples``, ``k``,
    ``estimate_options``; W: 16, 96, 2) unless a finished ``estimate`` is given (its ``k``
    slots are used, at most ``k``). ``gate`` (default: on for ``"aligned"``, off for
    ``"sheared"``): pixels whose ``probe x probe`` probe is smooth use ``base``.
    ``options`` (an :class:`~anisosample.render.options.IntegratorOptions`) must be the
    render's: the directions are estimated on its pixel integrands
    (:func:`~anisosample.render.estimation.estimation_options`). Aligned sets come
    from ``table`` (default: the installed tables and the user cache); missing ones are
    synthesized into the user cache (``build_missing=None``, the default; ``True`` also into an
    explicit ``table``; ``False`` refuses, naming the build command), passing ``build_options``
    to the build. Any ``spp >= 2`` works. ``progress``: the estimation's progress bars.
    """
    from .. import samplers

    check_choice("point_set", point_set, BLOCK_SAMPLERS)
    check_choice("base", base, samplers.BASELINES)
    k = check_int("k", k, minimum=1, maximum=2)
    if build_missing is not None and not isinstance(build_missing, bool):
        raise TypeError(f"build_missing must be None, True or False, got {build_missing!r}")
    gate = (point_set == "aligned") if gate is None else bool(gate)
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be an anisosample.render.Scene, got {type(scene).__name__}")
    options = estimation_options(options).for_scene(scene)
    if estimate is None:
        estimate = estimate_blocks(scene, block_px, samples, k, options=options, gate=gate,
                                   probe=probe, progress=progress, **estimate_options)
    elif not isinstance(estimate, BlockEstimate):
        raise TypeError(f"estimate must be a BlockEstimate from estimate_blocks, got "
                        f"{type(estimate).__name__}")
    elif (estimate.width, estimate.height) != (scene.width, scene.height):
        raise ValueError(f"estimate is for a {estimate.width}x{estimate.height} image, the "
                         f"scene is {scene.width}x{scene.height}")
    elif gate and estimate.discontinuous is None:
        estimate = gate_estimate(scene, estimate, probe, options=options, progress=progress)
    dirs = np.asarray(estimate.estimate.directions_deg, np.float64)
    ok = np.asarray(estimate.estimate.valid)
    # The strongest *valid* direction: a block whose first slot fails the confidence test but
    # whose second passes has a direction (and, aligned, a set from it), as the gate agrees.
    first = np.argmax(ok, axis=-1)[..., None]
    v = ok.any(-1)
    d = np.where(v, np.take_along_axis(dirs, first, -1)[..., 0], -1.0)
    extra = tuple(selection.table_directions([x for x, y in zip(dd, vv, strict=True) if y], k)
                  for dd, vv in zip(dirs.reshape(-1, dirs.shape[-1]),
                                    ok.reshape(-1, ok.shape[-1]), strict=True))
    return BlockSampler(point_set, estimate.block_px, scene.width, scene.height, d, v, estimate,
                        options, base, table, build_missing, k, gate, extra,
                        dict(build_options or {}))


def resolve_sampler(scene: Scene, sampler, sampler_options: dict | None, *,
                    options: IntegratorOptions, progress: bool = True) -> BlockSampler | None:
    """The renderer's hook: a :class:`BlockSampler` for ``sampler`` (one, or a name in
    :data:`BLOCK_SAMPLERS` built with ``sampler_options``), None for ordinary samplers.
    ``options``: the render's :class:`~anisosample.render.options.IntegratorOptions`.
    ``progress=False`` (the render's) silences the estimation whatever ``sampler_options``
    say."""
    if isinstance(sampler, str) and sampler in BLOCK_SAMPLERS:
        opts = dict(sampler_options or {})
        if not progress:
            opts["progress"] = False
        if "options" in opts:
            raise ValueError("sampler_options must not hold options: the render's own "
                             "IntegratorOptions are the estimation's")
        return block_sampler(scene, sampler, options=options, **opts)
    if sampler_options:
        what = "a finished BlockSampler" if isinstance(sampler, BlockSampler) else repr(sampler)
        raise ValueError(f"sampler_options are for the per-block samplers given by name "
                         f"{list(BLOCK_SAMPLERS)}, not {what}")
    if not isinstance(sampler, BlockSampler):
        return None
    if (sampler.width, sampler.height) != (scene.width, scene.height):
        raise ValueError(f"sampler was made for a {sampler.width}x{sampler.height} image, the "
                         f"scene is {scene.width}x{scene.height}")
    mine = estimation_options(options).for_scene(scene)
    if sampler.options != mine:
        fields = ("dimension", "technique", "square_aperture")
        raise ValueError(f"sampler estimated its directions with ({', '.join(fields)}) = "
                         f"{tuple(getattr(sampler.options, f) for f in fields)}, the render "
                         f"uses {tuple(getattr(mine, f) for f in fields)}")
    return sampler


def pad_sets(sets: jax.Array | np.ndarray) -> jax.Array:
    """``sets`` ``(m, n, 2)`` with copies of ``sets[0]`` appended up to a power of two rows:
    the render kernels that index per-pixel sets then compile for few shapes (no pixel's
    index reaches the copies, so no bit moves). Without it, each realization of the
    per-pixel sampler, and each window of a cropped image, asked for its own number of sets
    and recompiled: W Fig. 8 on 32^2 windows took about 35 s per window. Padded on the host,
    for the same reason (an eager concatenation compiles once per shape)."""
    sets = np.asarray(sets)
    m = sets.shape[0]
    rows = 1 << max(0, (m - 1).bit_length())
    return jax.device_put(np.concatenate([sets, np.broadcast_to(sets[:1],
                                                                (rows - m, *sets.shape[1:]))]))


@kernel(static_argnames=("options",))
def render_chunk_sets(scene: Scene, sets, pixel_set, key, pixels, *,
                      options: IntegratorOptions):
    """The render kernel with per-pixel point sets:
    :func:`anisosample.render.integrator.render_chunk` where pixel ``q`` uses
    ``sets[pixel_set[q]]`` (and, as there, its own shift from ``fold_in(key, q)``)."""
    from .integrator import render_chunk

    def one(q):
        return render_chunk(scene, sets[pixel_set[q]], key, q[None], options=options)[0]

    if pixels.ndim == 1:
        return jax.vmap(one)(pixels)
    return jax.lax.map(jax.vmap(one), pixels)

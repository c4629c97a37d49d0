"""Aligned point-set tables (W Sec. 5.4): symmetry reduction, storage, lookup, aligned sampler.

Werner et al. precompute one optimized set per combination of integer principal directions: the
axes 0 and 90 degrees are always included, plus one extra direction (the *3-direction* table) or
two (the *4-direction* table). The symmetries of the unit square reduce the 180 (resp. 16,290)
combinations to **46** (resp. **4,141**) canonical sets (W Sec. 5.4).

Symmetry. The dihedral group of the square maps the torus to itself, keeps stratification and
the pair of axes, and acts on axial spectral angles (mod 180) as four maps: identity
(``psi -> psi``), mirror ``(x, y) -> (x, 1 - y)`` (``psi -> -psi``), swap ``(x, y) -> (y, x)``
(``psi -> 90 - psi``) and rotation by 90 degrees ``(x, y) -> (1 - y, x)`` (``psi -> psi + 90``).
Frequency vectors transform like the points (``P_{M S}(M v) = P_S(v)`` for orthogonal ``M``), so
a set optimized for ``{0, 90, psi}`` mirrored is a set for ``{0, 90, -psi}``. Every map is an
involution on angles, so the map ``g`` that carries a request ``R`` to its canonical
representative ``C = g(R)`` also carries the stored set back: ``lookup`` applies the point
transform of ``g`` to the canonical set. The canonical representative of a pair is the
lexicographically smallest sorted image under the four maps (pairs with repetition, as counted
by W).

Store. A table is a directory ``d{direction_count}_n{n}/`` (``d3_n4096/``) holding ``table.json``
(format version, direction count -- stored under the key ``kind`` --, n, seed, synthesis
options, package version and, once complete, the SHA-256 of every set file) and one ``.npz``
per canonical set (``psi_030.npz``, ``psi_010_045.npz``) with the points (float32) and metadata
(canonical directions, the directions synthesized, the SHA-256 of the points, the settings
fingerprint of the table). Every file is written atomically, so an interrupted build leaves only
whole sets. A table whose format, direction count, n or settings do not match, or a
set file that is truncated, altered or from another table, is refused with a ``ValueError``
naming the file.

Where tables are found (:func:`table_dirs`): ``$ANISOSAMPLE_TABLES`` (``os.pathsep``-separated),
the tables shipped in ``anisosample/data/tables``, and the user cache
``$XDG_CACHE_HOME/anisosample/tables`` (default ``~/.cache/anisosample/tables``), where
``anisosample tables build`` writes by default.

Shipped: the 46-set 3-direction tables for ``n = 256`` (380 kB) and the paper's ``n = 4096``
(1.7 MB), and the 46-sequence 3-direction table ``d3_n4096_seq256`` (1.7 MB; progressive
sequences, :func:`anisosample.synthesis.synthesize_sequence`), built with
:data:`~anisosample.synthesis.SEQUENCE_STEPS` = 3000 optimizer steps at
:data:`~anisosample.synthesis.SEQUENCE_LEARNING_RATE` = 1.5 by ``anisosample tables build --n
4096 --sequence-from 256`` with :data:`~anisosample.synthesis.SEQUENCE_FREQUENCY_OPTIONS`
(the axes' weight from 1024 points; rebuilt 2026-12-07/08 on this project's 2-core machine,
niced beside other work: 2-4 min per sequence on both cores, about 12 on one; the table before
had the axes' weight 1, and the first shipped one 200 steps at the rate 0.5).
``n = 4096`` uses the default (robust) weights of :mod:`anisosample.frequencies`
(built with the rotated type-3 NUFFT of the time; ``experiments/bench_tables.py --full`` now
projects 5.1 min for the 46 sets on this project's 2-core machine); ``n = 256``
has the aligned-only weights, the default below
:data:`~anisosample.frequencies.ROBUST_MIN_N` = 1024 points: at 256 points the robust weights
measured worse in the renderer (aligned / pmj02bn variance on the edge pixels of a Cornell crop 1.23
instead of 0.87) and shallower along the requested lines (0.117 of white instead of 0.066), while
the offset lines lie inside the band there anyway. Also shipped: ``d3_n64_dihedral-16``
(196 kB), the 46 sets of 64 points whose first 16 are the ``dihedral-16`` prefix: the per-pixel
sampler's sets at 64 spp (:func:`anisosample.render.pixel_aligned.pixel_prefix`), built by
``anisosample tables build --n 64 --prefix dihedral-16`` in 18 s here with the aligned-only
weights (2026-12-07; the same bits as a set built on demand), so a 64-spp preview with one
direction per pixel synthesizes nothing. Every other set is built on demand: ``ensure``
synthesizes a set no table holds into the user cache (one set, with progress; ``build_missing=
False`` refuses instead) before the pure ``lookup`` reads it, and ``anisosample tables build``
builds whole tables. A 4-direction set
``(a, b)`` for an ``n`` with a complete 3-direction table starts from that table's set for ``a``
(already dark along 0, 90 and ``a``) and runs 150 steps at learning rate 0.2 instead of 200 at
0.5. Measured (``experiments/bench_tables.py --compare-warm``; directions 0/90/16/146 and
0/90/33/43, key 1, 512 shifts per variance): at n = 4096 the rate loss is 0.00430 and 0.00385
warm against 0.00420 and 0.00364 cold, the mean n P_S within one unit of every line for
|v| <= 32 at most 0.013 warm and 0.012 cold, and the variance of an edge at ``a`` 1.67e-7 and
1.24e-7 warm against 1.62e-7 and 1.40e-7 cold; its two-point slope from n = 256 to 4096 is
-1.74 and -1.83 warm, -1.78 and -1.78 cold.

The aligned sampler (W Sec. 5.4): estimate the integrand's extra directions
(:func:`anisosample.directions.estimate`), round them to integer degrees, look the set up, fall
back to ``pmj02bn`` when no extra direction is found, and decorrelate realizations with a
toroidal shift drawn from the sampler's key: ``samplers.get("aligned", integrand=f)``.
"""

from __future__ import annotations

import functools
import os
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from . import _table_build
from ._table_store import ANGLE_MAPS as ANGLE_MAPS
from ._table_store import AXES_DEG as AXES_DEG
from ._table_store import DIRECTION_COUNTS as DIRECTION_COUNTS
from ._table_store import FORMAT as FORMAT
from ._table_store import FORMAT_VERSION as FORMAT_VERSION
from ._table_store import TRANSFORMS as TRANSFORMS
from ._table_store import Canonical as Canonical
from ._table_store import Table as Table
from ._table_store import apply_symmetry as apply_symmetry
from ._table_store import cache_dir as cache_dir
from ._table_store import cache_table_path as cache_table_path
from ._table_store import canonical_sets as canonical_sets
from ._table_store import canonicalize as canonicalize
from ._table_store import find_table as find_table
from ._table_store import open_table as open_table
from ._table_store import points_checksum as points_checksum
from ._table_store import read_set as read_set
from ._table_store import set_directions as set_directions
from ._table_store import set_name as set_name
from ._table_store import settings_fingerprint as settings_fingerprint
from ._table_store import shipped_dir as shipped_dir
from ._table_store import table_dirs as table_dirs
from ._table_store import table_name as table_name
from ._table_store import table_prefix as table_prefix
from ._table_store import table_sequence_from as table_sequence_from
from ._table_store import transform_points as transform_points
from ._validate import check_bool, check_int, renamed_keywords
from .prefix import check_table_prefix, restore_prefix

__all__ = [
    "AXES_DEG",
    "DIRECTION_COUNTS",
    "FORMAT_VERSION",
    "Canonical",
    "canonical_sets",
    "canonicalize",
    "apply_symmetry",
    "set_directions",
    "table_dirs",
    "cache_dir",
    "cache_table_path",
    "find_table",
    "Table",
    "open_table",
    "lookup",
    "lookup_many",
    "missing",
    "ensure",
    "build",
    "build_command",
    "installed_sizes",
]

# --- lookup ---------------------------------------------------------------------------------------


@renamed_keywords(kind="direction_count")
def lookup(directions_deg, n: int, *, direction_count: int | None = None, table=None,
           prefix: str | None = None, sequence_from: int = 0, **unexpected) -> jax.Array:
    """The aligned set of ``n`` points for integer ``directions_deg`` (W Sec. 5.4): a pure
    lookup, it never builds (:func:`ensure` builds what is missing, with progress, before).

    Reduces the request by symmetry (:func:`canonicalize`), loads the canonical set from the
    table for ``n`` (``table``: a table directory, or a folder of tables; default: the search path
    :func:`table_dirs`), and applies the symmetry so the set's low-energy directions are the
    requested ones. Returns float32 ``(n, 2)`` in ``[0, 1)^2``.

    ``prefix`` (W Sec. 7; :mod:`anisosample.prefix`): ``None``/``"none"`` (the tables W
    describes) or a symmetric ``"dihedral-<m>"`` (e.g. :data:`anisosample.prefix.DEFAULT_PREFIX`):
    the set comes from the table ``d{direction_count}_n{n}_{prefix}`` and its first ``m`` points
    are the prefix bit for bit, whatever the directions (the symmetry's shift and reordering of the
    prefix are undone, :func:`anisosample.prefix.restore_prefix`).

    ``sequence_from`` (0: a set): the progressive sequence of ``n`` points whose every nested
    power-of-two prefix from ``sequence_from`` up is aligned
    (:func:`anisosample.synthesis.synthesize_sequence`), from the table
    ``d{direction_count}_n{n}_seq{sequence_from}``; the symmetry keeps the order of the points,
    so every nested prefix of the served sequence is aligned for the requested directions.

    A set no table holds raises ``FileNotFoundError`` naming :func:`ensure` and the command that
    builds it (:func:`build_command`). Damaged or incompatible tables raise ``ValueError``.
    """
    if unexpected:
        raise TypeError(f"tables.lookup is a pure lookup and takes no {sorted(unexpected)}; "
                        "build missing sets first with tables.ensure(requests, n, ...) (its "
                        "build_missing, show_progress and synthesis options)")
    canon = canonicalize(directions_deg, direction_count=direction_count)
    n = check_int("n", n, minimum=2)
    prefix = check_table_prefix(prefix)
    sequence_from = check_int("sequence_from", sequence_from, minimum=0)
    path = find_table(canon.direction_count, n, root=table, prefix=prefix,
                      sequence_from=sequence_from)
    return jnp.asarray(_served(canon, n, path, table, prefix, sequence_from))


@renamed_keywords(kind="direction_count")
def lookup_many(requests, n: int, *, direction_count: int | None = None, table=None,
                prefix: str | None = None, sequence_from: int = 0,
                as_numpy: bool = False) -> jax.Array | np.ndarray:
    """:func:`lookup` of every request in ``requests`` (each a ``directions_deg``), stacked
    ``(len(requests), n, 2)``: the same sets bit for bit, with each table found once per
    direction count and one transfer to the device. A per-pixel render reads hundreds of sets
    per image (dof at 128^2 x 256 spp: 584, with :func:`missing` before): one by one 166 ms,
    together 65 ms (2026-12-07, load about 1.6). ``as_numpy=True`` returns the host array
    (float32) instead, for callers that assemble further on the host."""
    as_numpy = check_bool("as_numpy", as_numpy)
    n = check_int("n", n, minimum=2)
    prefix = check_table_prefix(prefix)
    sequence_from = check_int("sequence_from", sequence_from, minimum=0)
    path_of = _table_finder(n, table, prefix, sequence_from)
    out = np.empty((len(requests), n, 2), np.float32)
    for i, request in enumerate(requests):
        canon = canonicalize(request, direction_count=direction_count)
        out[i] = _served(canon, n, path_of(canon.direction_count), table, prefix, sequence_from)
    if as_numpy:
        return out
    return jax.device_put(out)  # not jnp.asarray: that compiles a staging copy per shape


def _table_finder(n: int, table, prefix: str, sequence_from: int):
    """``direction_count -> find_table(direction_count, n, ...)``, each found once."""
    paths = {}

    def path_of(direction_count: int):
        if direction_count not in paths:
            paths[direction_count] = find_table(direction_count, n, root=table, prefix=prefix,
                                                sequence_from=sequence_from)
        return paths[direction_count]

    return path_of


def _served(canon: Canonical, n: int, path, table, prefix: str, sequence_from: int) -> np.ndarray:
    """The set :func:`lookup` serves for ``canon`` from the table at ``path`` (None: none
    found; ``table``: the caller's root, for the message), as float32 numpy."""
    if path is None or not (path / f"{canon.name}.npz").exists():
        where, command = _where_and_command(canon, n, table, path, prefix, sequence_from)
        raise FileNotFoundError(
            f"no {canon.direction_count}-direction table for n={n} with set {canon.name} in "
            f"{where}; "
            f"build it with tables.ensure([{list(canon.extra)}], {n}"
            + (f", table={str(table)!r}, build_missing=True" if table is not None else "")
            + f") or `{command}`")
    set_file = Path(path) / f"{canon.name}.npz"
    st = set_file.stat()
    return _transformed(str(path), n, canon.direction_count, canon.extra, canon.transform,
                        prefix, sequence_from, st.st_mtime_ns, st.st_size,
                        (Path(path) / "table.json").stat().st_mtime_ns)


@functools.lru_cache(maxsize=2048)  # a per-pixel render serves the same few hundred per call
def _transformed(path: str, n: int, direction_count: int, extra, transform: str, prefix: str,
                 sequence_from: int, mtime_ns: int, size: int,
                 index_mtime_ns: int) -> np.ndarray:
    """:func:`_served`'s set once found: the verified canonical set (:func:`_load_verified`)
    under ``transform``, its prefix in order; cached per file version, read-only."""
    pts, held = _load_verified(path, n, direction_count, extra, mtime_ns, size, index_mtime_ns)
    if held != (prefix, sequence_from):
        raise ValueError(f"table {path} holds sets with (prefix, sequence_from) {held}, not "
                         f"the requested {(prefix, sequence_from)}")
    out = restore_prefix(transform_points(pts, transform), prefix, transform)
    out.setflags(write=False)
    return out


def _where_and_command(canon, n, table, path, prefix, sequence_from) -> tuple[str | Path, str]:
    """Where a missing set was looked for, and the command that builds it there."""
    where = table if table is not None else os.pathsep.join(map(str, table_dirs()))
    into = None if table is None else (
        path if path is not None
        else Path(table) / table_name(canon.direction_count, n, prefix, sequence_from))
    return where, build_command(canon.direction_count, n, [canon.extra], out=into, prefix=prefix,
                                sequence_from=sequence_from)


@renamed_keywords(kind="direction_count")
def missing(requests, n: int, *, direction_count: int | None = None, table=None,
            prefix: str | None = None, sequence_from: int = 0) -> list:
    """The requests (each a ``directions_deg`` of :func:`lookup`) whose sets no table on the
    search path (or in ``table``) holds for ``n`` points: what :func:`ensure` would build (or
    refuse), in order. Each table is found once per direction count."""
    n = check_int("n", n, minimum=2)
    prefix = check_table_prefix(prefix)
    sequence_from = check_int("sequence_from", sequence_from, minimum=0)
    path_of = _table_finder(n, table, prefix, sequence_from)
    out = []
    for request in requests:
        canon = canonicalize(request, direction_count=direction_count)
        path = path_of(canon.direction_count)
        if path is None or not (path / f"{canon.name}.npz").exists():
            out.append(request)
    return out


@renamed_keywords(kind="direction_count")
def ensure(requests, n: int, *, direction_count: int | None = None, table=None,
           build_missing: bool | None = None, show_progress: bool = True,
           prefix: str | None = None, sequence_from: int = 0, **build_options) -> list:
    """Make the sets for ``requests`` (each a ``directions_deg`` of :func:`lookup`) available
    for ``n`` points, building the missing ones now: the one rule for missing sets, used by
    every caller (``samplers.get("aligned", ...)``, :mod:`anisosample.selection`,
    ``render(sampler="aligned" | "aligned-pixel")`` and the CLI, whose ``--no-build`` is
    ``build_missing=False``). Returns the canonical names it built.

    A set no table on the search path holds is synthesized (one set at a time, with a progress
    bar unless ``show_progress=False``) into the user cache's table for ``(direction_count, n)``
    (:func:`cache_dir`), or into the table on the search path that lacks it (finished with its
    own settings). A new 4-direction table is warm-started from the complete 3-direction table
    for ``n`` where one exists (:func:`anisosample._table_build.build_set`). ``build_options``
    (``seed``, synthesis options) go to :func:`build`.

    ``build_missing``: ``None`` (default) builds into the cache as above, but never into an
    explicit ``table=`` (a missing set there raises ``FileNotFoundError``); ``True`` also builds
    into ``table``; ``False`` refuses: ``FileNotFoundError`` with the command that builds the
    set (:func:`build_command`). Any ``n >= 2`` builds.
    """
    n = check_int("n", n, minimum=2)
    if build_missing is not None and not isinstance(build_missing, bool):
        raise TypeError(f"build_missing must be None, True or False, got {build_missing!r}")
    prefix = check_table_prefix(prefix)
    sequence_from = check_int("sequence_from", sequence_from, minimum=0)
    built = []
    for request in missing(requests, n, direction_count=direction_count, table=table,
                           prefix=prefix, sequence_from=sequence_from):
        canon = canonicalize(request, direction_count=direction_count)
        path = find_table(canon.direction_count, n, root=table, prefix=prefix,
                          sequence_from=sequence_from)  # again: a build may have made one
        if path is not None and (path / f"{canon.name}.npz").exists():
            continue  # an earlier request of this call had the same canonical set
        explicit = table is not None and build_missing is None
        if build_missing is False or explicit:
            where, command = _where_and_command(canon, n, table, path, prefix, sequence_from)
            raise FileNotFoundError(
                f"no {canon.direction_count}-direction table for n={n} with set {canon.name} "
                f"in {where}; "
                f"build it with `{command}` "
                + ("(or pass build_missing=True to build it there on demand)" if explicit else
                   "(or build on demand: the default, refused by build_missing=False / "
                   "--no-build)")
            )
        if table is not None:
            out = (path if path is not None
                   else Path(table) / table_name(canon.direction_count, n, prefix, sequence_from))
        elif path is not None and path.parent != shipped_dir():
            out = path  # a table on the search path (the cache, $ANISOSAMPLE_TABLES) lacks it
        else:
            out = cache_table_path(canon.direction_count, n, prefix, sequence_from)
        opts = dict(build_options)
        # An existing table keeps its own settings, unless options are given: then they must
        # match its settings, the prefix and the sequence's included.
        if opts or not (Path(out) / "table.json").exists():
            if prefix != "none":
                opts["prefix"] = prefix
            if sequence_from:
                opts["sequence_from"] = sequence_from
        _table_build.build_set(n, canon.direction_count, canon.extra, out=out,
                               show_progress=show_progress, **opts)
        built.append(canon.name)
    return built


@renamed_keywords(kind="direction_count")
def build_command(direction_count: int, n: int, sets=None, *, out=None, prefix: str = "none",
                  sequence_from: int = 0) -> str:
    """The ``anisosample tables build`` command that builds the canonical ``sets`` (extra
    direction tuples, default: the whole table) of the ``direction_count``-direction table for
    ``n`` into ``out`` (default: the user cache, where :func:`lookup` finds them) -- with the
    settings an on-demand build uses, so the sets are the ones :func:`lookup` would have built."""
    cmd = f"anisosample tables build --n {n} --direction-count {direction_count}"
    if sets:
        cmd += " --sets " + ",".join(":".join(str(int(a)) for a in e) for e in sets)
    if sequence_from:
        cmd += f" --sequence-from {sequence_from}"
    if prefix != "none":
        cmd += f" --prefix {prefix}"
    if out is not None:
        cmd += f" --out {out}"
    return cmd


@renamed_keywords(kind="direction_count")
def installed_sizes(direction_count: int) -> list[int]:
    """The ``n`` of the ``direction_count``-direction tables on the search path
    (:func:`table_dirs`),
    complete or not, ascending. Other sizes are built on demand (any ``n >= 2``)."""
    from ._table_store import check_direction_count

    direction_count = check_direction_count(direction_count)
    out = set()
    for root in table_dirs():
        for d in root.glob(f"d{direction_count}_n*"):
            tail = d.name[len(f"d{direction_count}_n"):]
            if tail.isdigit() and (d / "table.json").exists():
                out.add(int(tail))
    return sorted(out)


@functools.lru_cache(maxsize=512)  # a per-pixel render reads a few hundred sets per call
def _load_verified(path: str, n: int, direction_count: int, extra, mtime_ns: int, size: int,
                   index_mtime_ns: int) -> tuple[np.ndarray, tuple[str, int]]:
    """Verified canonical set and its table's prefix, cached per file version (a renderer looks
    sets up per pixel)."""
    tab = open_table(path, n=n, direction_count=direction_count)
    pts = tab.load(extra)
    pts.setflags(write=False)
    return pts, (table_prefix(tab), table_sequence_from(tab))


@renamed_keywords(kind="direction_count")
def build(n: int, direction_count: int = 3, **options):
    """Build (or finish) the ``direction_count``-direction table for ``n`` points (W Sec. 5.4);
    resumable.

    Keyword options: ``out`` (table directory, default the user cache), ``seed``, ``sets`` (a
    subset of :func:`canonical_sets`), ``batch`` (sets per ``synthesize_batch`` loop; 1 =
    ``synthesize`` per set with checkpoints), ``devices`` (default: all local devices, one worker
    each), ``checkpoint_every``, ``show_progress`` and synthesis options (``recipe``, ``steps``,
    ``learning_rate``, ...). Each finished set is written at once; a rerun verifies and keeps
    them, and a complete table gets the file checksums in ``table.json``. Several hosts: call
    ``jax.distributed.initialize()`` first and share ``out``. Returns a summary dict.
    Details: ``anisosample/_table_build.py``.
    """
    return _table_build.build(n, direction_count, **options)

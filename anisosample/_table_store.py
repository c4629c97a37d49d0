"""Aligned point-set tables, the store (W Sec. 5.4): symmetry reduction, where tables live,
reading and verifying them. :mod:`anisosample.tables` is the public face (it re-exports these
names); :mod:`anisosample._table_build` writes tables with them. See the docstring of
:mod:`anisosample.tables` for the symmetry, the file layout and the checks.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import os
import zipfile
from collections.abc import Callable
from io import BytesIO as _BytesIO
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from . import io as _io
from ._validate import ONE_MINUS_EPSILON, check_choice, check_int, check_points, renamed_keywords

AXES_DEG = (0, 90)
"""The axes every set is optimized for (W Sec. 5.4)."""

DIRECTION_COUNTS = (3, 4)
"""A table's direction counts: the number of directions per set (axes plus one or two extra)."""

FORMAT = "anisosample-aligned-table"
FORMAT_VERSION = 1

TRANSFORMS = ("identity", "mirror", "swap", "rotate90")
"""Point transforms of the square, one per distinct action on axial angles (mod 180)."""

ANGLE_MAPS: dict[str, Callable[[int], int]] = {
    "identity": lambda a: a % 180,
    "mirror": lambda a: (-a) % 180,
    "swap": lambda a: (90 - a) % 180,
    "rotate90": lambda a: (a + 90) % 180,
}


# --- symmetry reduction (W Sec. 5.4) ------------------------------------------------------------


def _images(extra: tuple[int, ...]):
    """``(sorted image, transform)`` of ``extra`` under each of the four angle maps."""
    return [(tuple(sorted(ANGLE_MAPS[t](a) for a in extra)), t) for t in TRANSFORMS]


def _canonical_of(extra: tuple[int, ...]) -> tuple[tuple[int, ...], str]:
    return min(_images(extra))  # ties: the transform name decides; all give the same set


@renamed_keywords(kind="direction_count")
def canonical_sets(direction_count: int) -> list[tuple[int, ...]]:
    """The canonical extra-direction tuples of a table, sorted: 46 for ``direction_count=3``,
    4,141 for 4.

    Found by enumerating every integer combination (with repetition for pairs, W's count) and
    keeping one representative per orbit of the four angle maps.
    """
    return list(_canonical_sets(check_direction_count(direction_count)))


@functools.lru_cache(maxsize=2)
def _canonical_sets(direction_count: int) -> tuple[tuple[int, ...], ...]:
    if direction_count == 3:
        combos = [(a,) for a in range(180)]
    else:
        combos = [(a, b) for a in range(180) for b in range(a, 180)]
    return tuple(sorted({_canonical_of(c)[0] for c in combos}))


@dataclasses.dataclass(frozen=True)
class Canonical:
    """A request reduced by symmetry: the stored set ``extra`` and the ``transform`` that maps it
    to the requested directions (``requested`` = the extra directions asked for, sorted)."""

    direction_count: int
    extra: tuple[int, ...]
    transform: str
    requested: tuple[int, ...]

    @property
    def name(self) -> str:
        return set_name(self.extra)

    @property
    def directions_deg(self) -> tuple[int, ...]:
        """The directions the canonical set is synthesized for (see :func:`set_directions`)."""
        return set_directions(self.extra)


def _integer_directions(name: str, directions_deg) -> tuple[int, ...]:
    if isinstance(directions_deg, tuple) and all(  # a renderer's requests: no numpy round trip
            type(a) is int and 0 <= a < 180 for a in directions_deg):
        return directions_deg
    if isinstance(directions_deg, int | float | np.number) and not isinstance(directions_deg, bool):
        directions_deg = (directions_deg,)
    try:
        d = np.asarray(directions_deg, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise TypeError(
            f"{name} must be a sequence of integer angles in degrees, got {directions_deg!r}"
        ) from None
    if not np.all(np.isfinite(d)) or np.any(d < 0) or np.any(d >= 180):
        raise ValueError(f"{name} must lie in [0, 180) degrees, got {d.tolist()}")
    if np.any(d != np.round(d)):
        raise ValueError(
            f"{name} must be integer degrees (tables hold 1-degree steps, W Sec. 5.4), "
            f"got {d.tolist()}; round them first"
        )
    return tuple(int(x) for x in d)


@renamed_keywords(kind="direction_count")
def canonicalize(directions_deg, *, direction_count: int | None = None) -> Canonical:
    """Reduce a request to its canonical set and the symmetry that maps that set back.

    ``directions_deg``: integer spectral directions in ``[0, 180)``; 0 and 90 (the axes) may be
    included or not -- they are always part of every set. What remains are the extra directions:
    one (3-direction table) or two (4-direction table); none means the axes-only set (``psi = 0``).
    ``direction_count`` forces the table (3 or 4); a single extra direction in a 4-direction
    table is the pair ``(a, a)``.
    """
    d = _integer_directions("directions_deg", directions_deg)
    extra = tuple(sorted({a for a in d if a not in AXES_DEG}))
    if len(extra) > 2:
        raise ValueError(
            f"directions_deg may hold at most two directions besides 0 and 90 (tables of 3 or 4 "
            f"directions, W Sec. 5.4), got {list(d)}"
        )
    if direction_count is None:
        direction_count = 4 if len(extra) == 2 else 3
    direction_count = check_direction_count(direction_count)
    want = direction_count - 2
    if len(extra) > want:
        raise ValueError(
            f"a {direction_count}-direction table holds {want} extra direction(s), "
            f"got {list(extra)}"
        )
    padded = extra if extra else (0,)
    padded = padded + (padded[-1],) * (want - len(padded))
    canon, transform = _canonical_of(padded)
    return Canonical(direction_count=direction_count, extra=canon, transform=transform,
                     requested=extra)


def set_name(extra: tuple[int, ...]) -> str:
    """File stem of a canonical set: ``psi_030`` or ``psi_010_045``."""
    return "psi_" + "_".join(f"{a:03d}" for a in extra)


def set_directions(extra: tuple[int, ...]) -> tuple[int, ...]:
    """The distinct directions a canonical set is synthesized for: 0, 90 and the extra ones
    (repeats and extra directions equal to an axis collapse: ``(0,) -> (0, 90)``)."""
    out = list(AXES_DEG)
    for a in extra:
        if a not in out:
            out.append(int(a))
    return tuple(out)


def transform_points(points: np.ndarray, transform: str) -> np.ndarray:
    x, y = points[:, 0], points[:, 1]

    def flip(t):  # 1 - t on [0, 1): (-t) mod 1, clamped below 1 (1 - tiny rounds to 1.0)
        return np.minimum(np.mod(-t, np.float32(1.0)), ONE_MINUS_EPSILON).astype(np.float32)

    if transform == "identity":
        out = (x, y)
    elif transform == "mirror":
        out = (x, flip(y))
    elif transform == "swap":
        out = (y, x)
    else:  # rotate90: (x, y) -> (1 - y, x)
        out = (flip(y), x)
    return np.stack(out, axis=-1).astype(np.float32)


def table_prefix(table: Table) -> str:
    """The prefix the sets of ``table`` start with (``"none"`` for tables without one)."""
    return table.settings["synthesis"].get("prefix", "none")


def table_sequence_from(table: Table) -> int:
    """The smallest nested prefix of a table of sequences (0: a table of sets)."""
    return int(table.settings["synthesis"].get("sequence_from", 0))


def apply_symmetry(points, transform: str) -> jax.Array:
    """Apply one of :data:`TRANSFORMS` to a point set (float32, stays in ``[0, 1)^2``).

    ``"mirror"`` ``(x, 1 - y)`` maps spectral angle ``psi -> -psi``; ``"swap"`` ``(y, x)`` maps
    ``psi -> 90 - psi``; ``"rotate90"`` ``(1 - y, x)`` maps ``psi -> psi + 90`` (W Sec. 5.4).
    """
    check_choice("transform", transform, TRANSFORMS)
    pts = np.asarray(check_points("points", points), dtype=np.float32)
    return jnp.asarray(transform_points(pts, transform))


def check_direction_count(direction_count) -> int:
    direction_count = check_int("direction_count", direction_count)
    if direction_count not in DIRECTION_COUNTS:
        raise ValueError(f"direction_count must be 3 or 4 (directions per set), "
                         f"got {direction_count}")
    return direction_count


# --- where tables live ----------------------------------------------------------------------------


def cache_dir() -> Path:
    """The user cache for tables built on demand: ``$XDG_CACHE_HOME/anisosample/tables``."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "anisosample" / "tables"


@renamed_keywords(kind="direction_count")
def cache_table_path(direction_count: int, n: int, prefix: str = "none",
                     sequence_from: int = 0) -> Path:
    """Where the user cache keeps the ``direction_count``-direction table for ``n`` points (the
    default
    ``out`` of a build and the target of on-demand lookups)."""
    return cache_dir() / table_name(direction_count, n, prefix, sequence_from)


def shipped_dir() -> Path:
    """The tables installed with the package (``anisosample/data/tables``)."""
    return Path(__file__).parent / "data" / "tables"


def table_dirs() -> list[Path]:
    """Search path for tables: ``$ANISOSAMPLE_TABLES``, the shipped tables, the user cache."""
    env = os.environ.get("ANISOSAMPLE_TABLES", "")
    return [Path(p) for p in env.split(os.pathsep) if p] + [shipped_dir(), cache_dir()]


@renamed_keywords(kind="direction_count")
def table_name(direction_count: int, n: int, prefix: str = "none", sequence_from: int = 0) -> str:
    """``d{direction_count}_n{n}``; ``_seq{sequence_from}`` added for a table of progressive
    sequences
    (:func:`anisosample.synthesis.synthesize_sequence`) and ``_{prefix}`` for sets with a fixed
    prefix (:mod:`anisosample.prefix`): e.g. ``d3_n4096_seq256_dihedral-64``."""
    return (f"d{direction_count}_n{n}" + (f"_seq{sequence_from}" if sequence_from else "")
            + ("" if prefix == "none" else f"_{prefix}"))


@renamed_keywords(kind="direction_count")
def find_table(direction_count: int, n: int, *, root=None, prefix: str = "none",
               sequence_from: int = 0) -> Path | None:
    """The directory of the ``direction_count``-direction table for ``n`` points (and
    ``prefix``), or ``None``.

    ``root``: a table directory itself or a directory holding :func:`table_name`; default: the
    search path :func:`table_dirs`.
    """
    direction_count, n = check_direction_count(direction_count), check_int("n", n, minimum=2)
    name = table_name(direction_count, n, prefix, sequence_from)
    roots = [Path(root)] if root is not None else table_dirs()
    for r in roots:
        if (r / "table.json").exists():
            return r
        if (r / name / "table.json").exists():
            return r / name
    return None


# --- reading a table ------------------------------------------------------------------------------


def _sha256_bytes(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def sha256_file(path: Path) -> str:
    return _sha256_bytes(Path(path).read_bytes())


def points_checksum(points: np.ndarray) -> str:
    """SHA-256 of a point set's float32 little-endian bytes (stored in every set file)."""
    return _sha256_bytes(np.ascontiguousarray(points, dtype="<f4").tobytes())


def settings_fingerprint(settings: dict) -> str:
    """SHA-256 of the settings that determine a table's sets (n, the direction count -- stored
    under its table.json key ``kind`` --, seed, synthesis)."""
    keys = ("n", "kind", "seed", "synthesis", "synthesis_resolved")
    text = json.dumps(_io.to_jsonable({k: settings.get(k) for k in keys}), sort_keys=True)
    return _sha256_bytes(text.encode())


@dataclasses.dataclass(frozen=True)
class Table:
    """An opened table directory: its ``settings`` (``table.json``) and location."""

    path: Path
    settings: dict

    @property
    def n(self) -> int:
        return int(self.settings["n"])

    @property
    def direction_count(self) -> int:
        return int(self.settings["kind"])

    @property
    def complete(self) -> bool:
        """``table.json`` says complete and every canonical set's file is there (a deleted set
        makes a table incomplete again)."""
        return bool(self.settings.get("complete")) and not self.missing()

    def missing(self) -> list[tuple[int, ...]]:
        """The canonical sets (:func:`canonical_sets`) whose files are not in the table."""
        return [e for e in canonical_sets(self.direction_count) if not self.has(e)]

    def set_path(self, extra: tuple[int, ...]) -> Path:
        return self.path / f"{set_name(extra)}.npz"

    def has(self, extra: tuple[int, ...]) -> bool:
        return self.set_path(extra).exists()

    def load(self, extra: tuple[int, ...]) -> np.ndarray:
        """The canonical set ``extra`` as float32 ``(n, 2)``, verified (see :func:`read_set`)."""
        return read_set(self, extra)


@renamed_keywords(kind="direction_count")
def open_table(path, *, n: int | None = None, direction_count: int | None = None) -> Table:
    """Open and check a table directory (refuses other formats, versions, ``n`` or
    ``direction_count``)."""
    path = Path(path)
    meta_path = path / "table.json"
    if not meta_path.exists():
        raise FileNotFoundError(f"no table at {path} (missing table.json)")
    try:
        settings = json.loads(meta_path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"table index {meta_path} is damaged ({exc}); rebuild the table") from None
    if not isinstance(settings, dict) or settings.get("format") != FORMAT:
        raise ValueError(f"{meta_path} is not an anisosample aligned-set table")
    if settings.get("format_version") != FORMAT_VERSION:
        raise ValueError(
            f"table {path} has format version {settings.get('format_version')}, this anisosample "
            f"reads version {FORMAT_VERSION}; rebuild it with `anisosample tables build`"
        )
    for key in ("n", "kind", "seed", "synthesis", "fingerprint"):
        if key not in settings:
            raise ValueError(f"table index {meta_path} lacks {key!r}; rebuild the table")
    if settings["fingerprint"] != settings_fingerprint(settings):
        raise ValueError(f"table index {meta_path} is damaged (settings fingerprint mismatch)")
    table = Table(path, settings)
    if n is not None and table.n != n:
        raise ValueError(f"table {path} holds sets of n={table.n} points, asked for n={n}")
    if direction_count is not None and table.direction_count != direction_count:
        raise ValueError(f"table {path} is a {table.direction_count}-direction table, "
                         f"asked for {direction_count}")
    return table


def read_set(table: Table, extra: tuple[int, ...]) -> np.ndarray:
    """Load one canonical set and check it: file checksum (complete tables), readable archive,
    the points' own checksum, the table fingerprint, directions, shape and range."""
    path = table.set_path(extra)
    if not path.exists():
        raise FileNotFoundError(
            f"table {table.path} has no set for extra directions {list(extra)} (missing "
            f"{path.name}); finish it with `anisosample tables build --n {table.n} "
            f"--direction-count {table.direction_count} --out {table.path}`"
        )
    data = path.read_bytes()  # parsed from memory: np.load leaks the handle of a broken zip
    listed = table.settings.get("checksums", {}).get(path.name)
    if listed is not None and _sha256_bytes(data) != listed:
        raise ValueError(f"table set {path} is damaged (file checksum differs from table.json)")
    try:
        arrays, meta = _io.load_npz(_BytesIO(data))
    except (zipfile.BadZipFile, OSError, ValueError, KeyError, EOFError,
            json.JSONDecodeError) as exc:
        raise ValueError(f"table set {path} is damaged or unreadable ({exc})") from None
    pts = arrays.get("points")
    if pts is None or pts.dtype != np.float32 or pts.shape != (table.n, 2):
        raise ValueError(
            f"table set {path} must hold float32 points of shape ({table.n}, 2), got "
            f"{None if pts is None else (pts.dtype, pts.shape)}"
        )
    if meta.get("points_sha256") != points_checksum(pts):
        raise ValueError(f"table set {path} is damaged (points checksum mismatch)")
    if meta.get("fingerprint") != table.settings["fingerprint"]:
        raise ValueError(
            f"table set {path} belongs to another table (settings fingerprint differs); "
            "rebuild it"
        )
    if tuple(meta.get("extra_deg", ())) != tuple(extra):
        raise ValueError(f"table set {path} holds directions {meta.get('extra_deg')}, "
                         f"expected {list(extra)}")
    if not (np.all(np.isfinite(pts)) and pts.min() >= 0 and pts.max() < 1):
        raise ValueError(f"table set {path} has points outside [0, 1)^2")
    return pts

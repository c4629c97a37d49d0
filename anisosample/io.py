"""Reading and writing results in formats other tools read: .npz, .npy, EXR, PNG, JSON.

Every writer is atomic (a temporary file renamed into place, so an interrupted write leaves
nothing half-written at the destination), creates its file with the permissions the umask
allows (as ``open`` would), refuses a file name whose suffix is not its format's, and refuses to
replace an existing file unless ``overwrite=True``: nothing a user saved is lost without asking.

Every reader refuses a damaged or foreign file (truncated, bit-flipped, another format under the
suffix) with a ``ValueError`` that names the file, and a missing one with ``FileNotFoundError``.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import platform
import secrets
import tempfile
import zipfile
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np

_METADATA_KEY = "__metadata__"


def package_version() -> str:
    """The installed package version (``anisosample.__version__``; ``0+unknown`` from a source
    tree that was not installed)."""
    from . import __version__

    return __version__


def provenance() -> dict[str, Any]:
    """Package version and machine, stored with every result."""
    import jax

    return {
        "anisosample_version": package_version(),
        "jax_version": jax.__version__,
        "backend": jax.default_backend(),
        "devices": [str(d) for d in jax.devices()],
        "machine": platform.machine(),
        "python": platform.python_version(),
        "cpu_count": os.cpu_count(),
    }


def _to_jsonable(obj):
    if isinstance(obj, Mapping):
        return {str(k): _to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_to_jsonable(v) for v in obj]
    if isinstance(obj, np.generic):  # np.float64 is also a float: convert, then handle NaN/Inf
        return _to_jsonable(obj.item())
    if hasattr(obj, "__array__") and not isinstance(obj, str | bytes):
        return _to_jsonable(np.asarray(obj).tolist())
    if isinstance(obj, Path):
        return str(obj)
    if isinstance(obj, float) and not np.isfinite(obj):
        return None if np.isnan(obj) else ("inf" if obj > 0 else "-inf")
    return obj


to_jsonable = _to_jsonable
"""The JSON-able form of a record (dicts, lists, numbers, strings) as the metadata stores it."""


def _check_suffix(path, suffixes: tuple[str, ...], what: str) -> Path:
    path = Path(path)
    if path.suffix.lower() not in suffixes:
        raise ValueError(f"{what} file name must end in {' or '.join(suffixes)}, got {path.name}")
    return path


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, *, overwrite: bool = False) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success rename it onto ``path``.

    The temporary file is created with mode ``0o666`` less the umask, as ``open(path, "w")``
    would (``tempfile.mkstemp`` would make it ``0o600``, unreadable to collaborators).
    Raises ``FileExistsError`` if ``path`` exists and ``overwrite`` is false.
    """
    path = Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists; pass overwrite=True (CLI: --force) to replace it")
    if path.is_dir():
        raise IsADirectoryError(f"{path} is a directory, not a file name")
    path.parent.mkdir(parents=True, exist_ok=True)
    while True:
        tmp = path.parent / f".{path.name}.{secrets.token_hex(4)}{path.suffix}"
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        except FileExistsError:  # another writer drew the same name: draw again
            continue
        os.close(fd)
        break
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def save_json(path, data: Mapping, *, overwrite: bool = False) -> Path:
    """Write ``data`` as strict JSON: arrays become lists, NaN becomes null, +-Inf "inf"/"-inf"."""
    _check_suffix(path, (".json",), "JSON")
    with atomic_path(path, overwrite=overwrite) as tmp:
        tmp.write_text(json.dumps(_to_jsonable(data), indent=2, allow_nan=False) + "\n")
    return Path(path)


def load_json(path) -> dict:
    """Read a JSON file; a damaged one is a ``ValueError`` naming it."""
    path = _existing(path)
    try:
        return json.loads(path.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{path} is not a readable JSON file ({exc})") from None


def _existing(path) -> Path:
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no such file: {path}")
    if path.is_dir():
        raise IsADirectoryError(f"{path} is a directory, not a file")
    return path


_MAGIC = {".npz": b"PK\x03\x04", ".npy": b"\x93NUMPY", ".exr": b"\x76\x2f\x31\x01"}
_FORMAT = {".npz": "NumPy .npz archive", ".npy": "NumPy .npy array", ".exr": "OpenEXR image"}


def _check_magic(path: Path, suffix: str, head: bytes | None = None) -> None:
    """Refuse a file that does not start with its format's signature (a text file named .npz,
    a pickle named .npy) before a library misreads it."""
    if head is None:
        with open(path, "rb") as fh:
            head = fh.read(len(_MAGIC[suffix]))
    head = head[: len(_MAGIC[suffix])]
    if head != _MAGIC[suffix]:
        kind = "empty" if not head else "of another format"
        article = "an" if _FORMAT[suffix][0] in "AEIOU" else "a"
        raise ValueError(f"{path} is not {article} {_FORMAT[suffix]} (the file is {kind})")


# What NumPy's readers raise on a truncated or bit-flipped file (a zip member's CRC, a header
# that does not parse, fewer bytes than the header promises).
_DAMAGED = (zipfile.BadZipFile, EOFError, OSError, ValueError, KeyError, UnicodeDecodeError)


def _damaged(path: Path, suffix: str, exc: BaseException) -> ValueError:
    why = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    return ValueError(f"{path} is a damaged or truncated {_FORMAT[suffix]} ({why})")


def save_npz(
    path, arrays: Mapping[str, Any], metadata: Mapping | None = None, *, overwrite: bool = False
) -> Path:
    """Save arrays and a JSON metadata record (with provenance) into one ``.npz``."""
    _check_suffix(path, (".npz",), ".npz")
    if _METADATA_KEY in arrays:
        raise ValueError(f"arrays must not use the reserved name {_METADATA_KEY!r}")
    meta = {**provenance(), **(dict(metadata) if metadata else {})}
    payload = {k: np.asarray(v) for k, v in arrays.items()}
    payload[_METADATA_KEY] = np.asarray(json.dumps(_to_jsonable(meta), allow_nan=False))
    with atomic_path(path, overwrite=overwrite) as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, **payload)
    return Path(path)


def load_npz(path) -> tuple[dict[str, np.ndarray], dict]:
    """Inverse of :func:`save_npz`: ``(arrays, metadata)``.

    ``path`` may also be an open binary file. A damaged, truncated or foreign file, or one
    holding pickled objects, is a ``ValueError`` naming the file.
    """
    if hasattr(path, "read"):
        source, path = path, Path(getattr(path, "name", None) or "<file object>")
    else:
        path = _existing(path)
        data = path.read_bytes()  # parsed from memory: np.load leaks the handle of a broken zip
        _check_magic(path, ".npz", data)
        source = io.BytesIO(data)
    try:
        with np.load(source, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files if k != _METADATA_KEY}
            meta_text = str(data[_METADATA_KEY]) if _METADATA_KEY in data.files else None
    except _DAMAGED as exc:
        raise _damaged(path, ".npz", exc) from None
    if any(a.dtype == object for a in arrays.values()):  # pragma: no cover - refused by np.load
        raise ValueError(f"{path} holds pickled objects, which are not read")
    try:
        meta = json.loads(meta_text) if meta_text is not None else {}
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: its metadata record is not valid JSON ({exc})") from None
    if not isinstance(meta, dict):
        raise ValueError(f"{path}: its metadata record is not a JSON object")
    return arrays, meta


def load_npy(path) -> np.ndarray:
    """Read one array from a ``.npy`` file; a damaged or foreign file is a ``ValueError`` naming
    it (NumPy alone calls a non-NumPy file "pickled data")."""
    path = _existing(path)
    data = path.read_bytes()
    _check_magic(path, ".npy", data)
    try:
        return np.load(io.BytesIO(data), allow_pickle=False)
    except _DAMAGED as exc:
        raise _damaged(path, ".npy", exc) from None


def save_npy(path, array, *, overwrite: bool = False) -> Path:
    _check_suffix(path, (".npy",), ".npy")
    with atomic_path(path, overwrite=overwrite) as tmp:
        with open(tmp, "wb") as fh:
            np.save(fh, np.asarray(array))
    return Path(path)


POINT_FORMATS = ("npy", "npz", "txt", "csv", "utk", "utk-bin")
"""The formats a point set is read from and written to (``format=`` of :func:`save_points` and
:func:`load_point_sets`):

* ``npy`` -- one ``(n, 2)`` array, or a stack ``(k, n, 2)`` of sets of one size.
  Metadata: in ``NAME.npy.json`` beside it.
* ``npz`` -- the array ``points`` (``(n, 2)`` or ``(k, n, 2)``), or ``points_0``, ``points_1``,
  ... for sets of different sizes, with the JSON metadata record of :func:`save_npz`.
* ``txt`` -- text, one point ``x y`` a line; ``#`` lines are comments, except a line holding only
  ``#``, which ends a set (UTK's separator), and a ``# {...}`` line, the JSON metadata record.
* ``csv`` -- one set, ``x,y`` a line under an ``x,y`` header row (spreadsheets, pandas).
  Metadata: in ``NAME.csv.json`` beside it.
* ``utk`` -- the text format of UTK (the Utk sampling toolkit, github.com/utk-team/utk:
  ``include/utk/utils/PointsetIO.hpp``, ``write_text_pointsets`` / ``read_text_pointset``;
  ``src/io/fileIO_dat.hpp`` in UTK 1): one point a line, its coordinates separated by white
  space, sets separated by a line ``#``. The metadata record goes on one last line ``# {...}``
  after the last set: both of UTK's readers end a set at a line starting with ``#`` and then
  find no further points, so UTK reads the file as the plain sets.
* ``utk-bin`` -- UTK's binary format (UTK 1 ``src/io/fileIO_bin.hpp``, ``PointsetWriter_BIN`` /
  ``PointsetReader_BIN`` for ``Point<2, double>``, the type of UTK's 2D samplers): for each set,
  a 4-byte unsigned count ``s`` and then ``s`` points of two 8-byte floats ``x, y``; no header,
  no separator. UTK writes its machine's byte order (little-endian on x86 and ARM); we read and
  write little-endian. The format has no place for metadata: it goes to a JSON file beside it,
  ``NAME.bin.json`` (read back by :func:`load_point_sets`; UTK ignores it).

Text writers keep every float32 bit (9 significant digits); binary writes float32 values as
float64, exactly.
"""

POINT_SUFFIXES = (".npy", ".npz", ".txt", ".csv", ".dat", ".bin")
"""The file name suffixes of point files: ``.npy``, ``.npz``, ``.txt`` (text), ``.csv``,
``.dat`` (UTK text, UTK 1's name) and ``.bin`` (UTK binary)."""

_FORMAT_SUFFIXES = {"npy": (".npy",), "npz": (".npz",), "txt": (".txt", ".dat"),
                    "csv": (".csv",), "utk": (".txt", ".dat"), "utk-bin": (".bin",)}
_SUFFIX_FORMAT = {".npy": "npy", ".npz": "npz", ".txt": "txt", ".csv": "csv", ".dat": "utk",
                  ".bin": "utk-bin"}


def point_format(path: Path, format: str | None) -> str:
    """The format of a point file: ``format`` (checked against the suffix) or the suffix's."""
    suffix = path.suffix.lower()
    if format is None:
        if suffix not in _SUFFIX_FORMAT:
            raise ValueError(f"points file name must end in {' or '.join(POINT_SUFFIXES)}, got "
                             f"{path.name}")
        return _SUFFIX_FORMAT[suffix]
    if format not in POINT_FORMATS:
        raise ValueError(f"format must be one of {', '.join(POINT_FORMATS)}, got {format!r}")
    if suffix not in _FORMAT_SUFFIXES[format]:
        raise ValueError(f"a {format} points file name must end in "
                         f"{' or '.join(_FORMAT_SUFFIXES[format])}, got {path.name}")
    return format


_SIDECAR_FORMATS = ("npy", "csv", "utk-bin")
"""Formats with no place for metadata: it goes to ``NAME.json`` beside the file."""


def _metadata_sidecar(path: Path) -> Path:
    return path.with_name(path.name + ".json")


def _locator(k: int, many: bool):
    """Where point ``i`` of set ``k`` is, for an error message (``i=None``: the whole set)."""

    def locate(i):
        parts = ([f"set {k}"] if many else []) + ([] if i is None else [f"point {i}"])
        return f" ({', '.join(parts)})" if parts else ""

    return locate


def _check_point_set(pts: np.ndarray, where: str, locate) -> np.ndarray:
    """One set read from a file: ``(n, 2)`` floating point, finite, in ``[0, 1)^2`` once stored
    as float32. ``locate(i)`` says where point ``i`` is in the file (a line, a set)."""
    if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] < 1:
        raise ValueError(f"{where} must have shape (n, 2) with n >= 1, got shape {pts.shape}"
                         f"{locate(None)}")
    if not np.issubdtype(pts.dtype, np.floating):
        raise TypeError(f"{where} must be a floating-point array, got dtype {pts.dtype}")
    bad = ~np.all(np.isfinite(pts), axis=1)
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(f"{where} contains NaN or Inf: point {pts[i].tolist()}{locate(i)}")
    p32 = pts.astype(np.float32)  # 0.999999999 becomes 1 in float32: check what is kept
    out = np.any((p32 < 0) | (p32 >= 1), axis=1)
    if out.any():
        i = int(np.argmax(out))
        raise ValueError(f"{where} must lie in [0, 1)^2 (as float32), got values in "
                         f"[{pts.min()}, {pts.max()}]; the first outside is "
                         f"{pts[i].tolist()}{locate(i)}")
    return p32


def _text_point_sets(path: Path, delimiter: str | None):
    """Parse a text point file: ``(sets, line numbers of their points, metadata)``."""
    raw = path.read_bytes()
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise ValueError(f"{path} is not a text file of points, one 'x y' or 'x,y' a line "
                         "(it is not UTF-8 text)") from None
    sets: list[list[tuple[float, float]]] = []
    lines: list[list[int]] = []
    meta: dict = {}
    cur: list[tuple[float, float]] = []
    cur_lines: list[int] = []
    first = True
    for number, line in enumerate(text.splitlines(), start=1):
        line = line.strip()
        if not line:
            continue
        if line.startswith("#"):
            body = line[1:].strip()
            if not body and cur:  # UTK's separator: the set ends here
                sets.append(cur)
                lines.append(cur_lines)
                cur, cur_lines = [], []
            elif body.startswith("{"):  # the metadata record
                try:
                    record = json.loads(body)
                except json.JSONDecodeError as exc:
                    raise ValueError(f"{path}, line {number}: the metadata record '# {{...}}' "
                                     f"is not valid JSON ({exc})") from None
                if isinstance(record, dict):
                    meta.update(record)
            continue
        parts = line.split(",") if delimiter == "," else line.split()
        try:
            if len(parts) != 2:
                raise ValueError(f"{len(parts)} values")
            point = (float(parts[0]), float(parts[1]))
        except ValueError:
            if first and line[:1].isalpha():  # a column-name row such as "x,y"
                first = False
                continue
            raise ValueError(f"{path} is not a text file of points, one 'x y' or 'x,y' a line "
                             f"(line {number}: {line[:60]!r})") from None
        first = False
        cur.append(point)
        cur_lines.append(number)
    if cur:
        sets.append(cur)
        lines.append(cur_lines)
    arrays = [np.asarray(s, dtype=np.float64).reshape(-1, 2) for s in sets]
    return arrays, lines, meta


def _utk_binary_point_sets(path: Path) -> list[np.ndarray]:
    """Parse UTK's binary format (see :data:`POINT_FORMATS`)."""
    data = path.read_bytes()
    if not data:
        raise ValueError(f"{path} is not a UTK binary point file (the file is empty)")
    sets, offset = [], 0
    while offset < len(data):
        k = len(sets)
        if len(data) - offset < 4:
            raise ValueError(f"{path} is not a UTK binary point file: {len(data) - offset} "
                             f"stray byte(s) after set {k - 1}, too few for a count")
        n = int.from_bytes(data[offset:offset + 4], "little")
        offset += 4
        if n == 0:
            raise ValueError(f"{path}: set {k} of the UTK binary file is empty (0 points)")
        if len(data) - offset < 16 * n:
            raise ValueError(f"{path} is not a UTK binary point file of 2D float64 points, or is "
                             f"truncated: set {k} promises {n} points ({16 * n} bytes) but "
                             f"{len(data) - offset} bytes remain")
        sets.append(np.frombuffer(data, dtype="<f8", count=2 * n, offset=offset).reshape(n, 2))
        offset += 16 * n
    return sets


def load_point_sets(path, *, format: str | None = None, metadata: bool = False):
    """Load every point set in a file: a list of ``(n_i, 2)`` float32 arrays (and the metadata
    record with ``metadata=True``: ``(sets, record)``, ``{}`` where the file has none).

    ``format``: one of :data:`POINT_FORMATS`; by default the suffix's (``.txt`` is read by the
    text reader, which reads UTK text files too). Every set is checked: two columns, finite,
    in ``[0, 1)^2`` once stored as float32; an error names the file and, where the format has
    them, the line (text) or the set and point (binary, stacks).
    """
    path = Path(path)
    fmt = point_format(path, format)
    path = _existing(path)
    meta: dict = {}
    where = f"points in {path}"
    if fmt in ("npy", "npz"):
        if fmt == "npy":
            arrays = {"points": load_npy(path)}
        else:
            arrays, meta = load_npz(path)
        if "points" in arrays:
            stack = arrays["points"]
            if stack.ndim == 3:
                raw = list(stack)
            else:
                raw = [stack]
        else:
            names = [f"points_{i}" for i in range(len(arrays))]
            raw = [arrays[k] for k in names if k in arrays]
            if not raw:
                raise ValueError(f"{path} holds no array named 'points' (has {sorted(arrays)})")
        sets = [_check_point_set(np.asarray(a), where, _locator(k, len(raw) > 1))
                for k, a in enumerate(raw)]
    elif fmt == "utk-bin":
        raw = _utk_binary_point_sets(path)
        sets = [_check_point_set(a, where, _locator(k, True)) for k, a in enumerate(raw)]
    else:
        raw, lines, meta = _text_point_sets(path, "," if fmt == "csv" else None)
        if not raw:
            raise ValueError(f"{where} must have shape (n, 2) with n >= 1: the file holds no "
                             "points")
        many = len(raw) > 1
        sets = [_check_point_set(a, where,
                                 lambda i, k=k: "" if i is None else
                                 f" (line {lines[k][i]}{f', set {k}' if many else ''})")
                for k, a in enumerate(raw)]
    if fmt in _SIDECAR_FORMATS and metadata and _metadata_sidecar(path).exists():
        meta = load_json(_metadata_sidecar(path))
    return (sets, meta) if metadata else sets


def load_points(path, *, format: str | None = None, metadata: bool = False):
    """Load the one point set of a file (any of :data:`POINT_FORMATS`): ``(n, 2)`` float32,
    checked as :func:`load_point_sets` checks it (``(points, record)`` with ``metadata=True``).
    A file holding several sets is a ``ValueError`` (read it with :func:`load_point_sets`)."""
    sets, meta = load_point_sets(path, format=format, metadata=True)
    if len(sets) != 1:
        raise ValueError(f"{path} holds {len(sets)} point sets (n = "
                         f"{', '.join(str(len(s)) for s in sets)}), not one; read them with "
                         "io.load_point_sets")
    return (sets[0], meta) if metadata else sets[0]


def _as_point_sets(points) -> list[np.ndarray]:
    """``(n, 2)``, ``(k, n, 2)`` or a sequence of ``(n_i, 2)`` sets -> checked float32 sets."""
    if isinstance(points, list | tuple):
        raw = [np.asarray(p) for p in points]
        if not raw:
            raise ValueError("points must hold at least one set, got an empty sequence")
    else:
        arr = np.asarray(points)
        raw = list(arr) if arr.ndim == 3 else [arr]
    return [_check_point_set(a, "points", _locator(k, len(raw) > 1)) for k, a in enumerate(raw)]


def _text_of_sets(sets, delimiter: str) -> str:
    blocks = []
    for s in sets:
        buf = io.StringIO()
        np.savetxt(buf, s.astype(np.float64), fmt="%.9g", delimiter=delimiter)
        blocks.append(buf.getvalue())
    return "#\n".join(blocks)


def save_points(path, points, metadata: Mapping | None = None, *, format: str | None = None,
                overwrite: bool = False) -> Path:
    """Write one point set or several to a file in any of :data:`POINT_FORMATS` (by default
    the suffix's: ``.npy``, ``.npz``, ``.txt``, ``.csv``, ``.dat`` UTK text, ``.bin`` UTK
    binary; ``format="utk"`` writes UTK text under ``.txt``).

    ``points``: ``(n, 2)``, a stack ``(k, n, 2)``, or a sequence of ``(n_i, 2)`` sets of any
    sizes (not for ``csv``; ``npy`` takes sets of one size). Each set is checked (finite, in
    ``[0, 1)^2`` as float32). ``metadata`` goes where the format keeps it (see
    :data:`POINT_FORMATS`); ``npy``, ``csv`` and ``utk-bin`` have no place for it and get a
    JSON file beside them, ``NAME.json`` (e.g. ``pts.csv.json``), so nothing is dropped. It
    comes back from ``load_point_sets(..., metadata=True)``. An existing file is replaced only
    with ``overwrite=True``.
    """
    path = Path(path)
    fmt = point_format(path, format)
    sets = _as_point_sets(points)
    sizes = {len(s) for s in sets}
    record = _to_jsonable(dict(metadata)) if metadata else None
    if fmt == "npz":
        if len(sets) == 1:
            arrays = {"points": sets[0]}
        elif len(sizes) == 1:
            arrays = {"points": np.stack(sets)}
        else:
            arrays = {f"points_{k}": s for k, s in enumerate(sets)}
        return save_npz(path, arrays, metadata, overwrite=overwrite)
    if fmt == "npy" and len(sizes) > 1:
        raise ValueError(f"a .npy file holds sets of one size, got sizes {sorted(sizes)}; "
                         "write .npz, .txt or UTK")
    if fmt == "csv" and len(sets) > 1:
        raise ValueError(f"a .csv file holds one point set, got {len(sets)}; write .txt, UTK "
                         "or .npz for several")
    sidecar = _metadata_sidecar(path) if fmt in _SIDECAR_FORMATS else None
    if sidecar is not None and record and sidecar.exists() and not overwrite:
        raise FileExistsError(f"{sidecar} exists; pass overwrite=True (CLI: --force) to "
                              "replace it")
    with atomic_path(path, overwrite=overwrite) as tmp:
        if fmt == "npy":
            with open(tmp, "wb") as fh:
                np.save(fh, sets[0] if len(sets) == 1 else np.stack(sets))
        elif fmt == "utk-bin":
            with open(tmp, "wb") as fh:
                for s in sets:
                    fh.write(np.asarray(len(s), dtype="<u4").tobytes())
                    fh.write(s.astype("<f8").tobytes())
        elif fmt == "csv":  # a plain header row, as spreadsheets and pandas expect
            tmp.write_text("x,y\n" + _text_of_sets(sets, ","))
        elif fmt == "txt":  # the metadata and a column-name comment above the points
            head = f"# {json.dumps(record, allow_nan=False)}\n" if record else ""
            tmp.write_text(head + "# x y\n" + _text_of_sets(sets, " "))
        else:  # utk: nothing before the first point (UTK 1 stops at a leading '#')
            tail = f"# {json.dumps(record, allow_nan=False)}\n" if record else ""
            tmp.write_text(_text_of_sets(sets, " ") + tail)
    if sidecar is not None:
        if record:
            save_json(sidecar, record, overwrite=True)
        elif sidecar.exists() and overwrite:  # a stale record would describe other points
            sidecar.unlink()
    return path


def write_exr(path, image, metadata: Mapping | None = None, *, overwrite: bool = False) -> Path:
    """Write a float32 EXR: ``(h, w)`` as channel Y, ``(h, w, 3)`` as RGB, ``(h, w, 4)`` RGBA.

    Row 0 of ``image`` is the top row of the EXR file. Metadata goes into string attributes.
    """
    import OpenEXR

    _check_suffix(path, (".exr",), "EXR")
    img = np.ascontiguousarray(np.asarray(image, dtype=np.float32))
    if img.ndim == 2:
        channels = {"Y": img}
    elif img.ndim == 3 and img.shape[2] in (3, 4):
        names = "RGBA"[: img.shape[2]]
        channels = {c: np.ascontiguousarray(img[..., i]) for i, c in enumerate(names)}
    else:
        raise ValueError(f"image must have shape (h, w), (h, w, 3) or (h, w, 4), got {img.shape}")
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    for k, v in (metadata or {}).items():
        header[str(k)] = json.dumps(_to_jsonable(v))
    with atomic_path(path, overwrite=overwrite) as tmp:
        with OpenEXR.File(header, channels) as f:
            f.write(str(tmp))
    return Path(path)


def _exr_metadata(header: Mapping) -> dict:
    """The attributes :func:`write_exr` stored (JSON strings), decoded; other strings as they
    are; OpenEXR's own attributes (channels, windows, compression, ...) left out."""
    meta = {}
    for key, value in header.items():
        if not isinstance(value, str):
            continue
        try:
            meta[key] = json.loads(value)
        except json.JSONDecodeError:
            meta[key] = value
    return meta


def read_exr(path, *, metadata: bool = False):
    """Read an EXR as float32: ``(h, w)`` for one channel, else ``(h, w, c)`` in RGBA order.

    Row 0 is the top row of the file, as :func:`write_exr` wrote it (no flip). With
    ``metadata=True``: ``(image, record)``, the record holding what ``write_exr`` stored.
    """
    import OpenEXR

    path = _existing(path)
    _check_magic(path, ".exr")
    try:
        with _c_output_captured() as said, OpenEXR.File(str(path), separate_channels=True) as f:
            ch = f.channels()
            names = list(ch)
            order = [c for c in "RGBA" if c in ch] or names
            if not order:
                raise ValueError("no channels")
            if len(order) == 1:
                img = np.asarray(ch[order[0]].pixels, dtype=np.float32)
            else:
                img = np.stack([np.asarray(ch[c].pixels, dtype=np.float32) for c in order],
                               axis=-1)
            return (img, _exr_metadata(f.header())) if metadata else img
    except (RuntimeError, OSError, ValueError, TypeError) as exc:
        detail = " ".join(said[0].split()) if said and said[0].strip() else str(exc)
        raise _damaged(path, ".exr", RuntimeError(detail)) from None


def _flush_c_streams() -> None:
    import ctypes

    try:
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError):  # no C library to ask (not POSIX)
        pass


@contextlib.contextmanager
def _c_output_captured():
    """Collect what a library writes to file descriptors 1 and 2 and to ``sys.stdout`` /
    ``sys.stderr`` inside the block (OpenEXR reports a damaged chunk there while it raises) into
    the yielded list's first item; a clean read passes it on to ``sys.stderr``, a failed one
    lets the caller fold it into one error message."""
    import sys

    said: list[str] = []
    try:
        sys.stdout.flush()
        sys.stderr.flush()
        saved = [os.dup(1), os.dup(2)]
    except (OSError, ValueError):  # no real descriptors (embedded interpreters)
        yield said
        return
    py_text = io.StringIO()  # what the binding writes through sys.stdout (PySys_WriteStdout)
    with tempfile.TemporaryFile() as buf:
        os.dup2(buf.fileno(), 1)
        os.dup2(buf.fileno(), 2)
        failed = False
        try:
            with contextlib.redirect_stdout(py_text), contextlib.redirect_stderr(py_text):
                yield said
        except BaseException:
            failed = True
            raise
        finally:
            _flush_c_streams()  # C++ writes to stdout go through C's buffer: empty it here
            for fd, old in zip((1, 2), saved, strict=True):
                os.dup2(old, fd)
                os.close(old)
            buf.seek(0)
            said.append(buf.read().decode("utf-8", "replace") + py_text.getvalue())
            if said[0] and not failed:
                sys.stderr.write(said[0])


def save_png(path, image, *, overwrite: bool = False, **imsave_kwargs) -> Path:
    """Save an image array as PNG through matplotlib (``cmap``/``vmin``/``vmax`` allowed).

    Uses ``matplotlib.image.imsave``, which needs no GUI backend and leaves the user's alone.
    """
    from matplotlib.image import imsave

    _check_suffix(path, (".png",), "PNG")
    img = np.asarray(image)
    if np.issubdtype(img.dtype, np.floating) and not np.all(np.isfinite(img)):
        raise ValueError(f"image for {Path(path).name} contains NaN or Inf (PNG pixels must be "
                         "finite)")
    with atomic_path(path, overwrite=overwrite) as tmp:
        imsave(tmp, img, format="png", **imsave_kwargs)
    return Path(path)


def load_grid(path, *, top_down: bool = False) -> np.ndarray:
    """Load a ``(h, w)`` grid of integrand samples from ``.npy`` or ``.exr`` (RGB is averaged).

    DESIGN's grid convention: ``values[i, j] = f((j + 0.5) / w, (i + 0.5) / h)``, row 0 at the
    smallest y. Images stored top-down (as renderers write them) need ``top_down=True``, which
    flips the rows.
    """
    path = _check_suffix(path, (".npy", ".exr"), "grid")
    if path.suffix.lower() == ".exr":
        img = read_exr(path)
        if img.ndim == 3:
            img = img[..., :3].mean(axis=-1)
    else:
        img = load_npy(path)
    if img.ndim != 2 or min(img.shape) < 1:
        raise ValueError(f"grid in {path} must be 2D (h, w) and not empty, got shape {img.shape}")
    if not (np.issubdtype(img.dtype, np.floating) or np.issubdtype(img.dtype, np.integer)):
        raise ValueError(f"grid in {path} must hold real numbers, got dtype {img.dtype}")
    if not np.all(np.isfinite(img)):
        raise ValueError(f"grid in {path} contains NaN or Inf")
    return np.ascontiguousarray(img[::-1] if top_down else img)

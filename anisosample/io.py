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


POINT_SUFFIXES = (".npy", ".npz", ".txt", ".csv")
"""The files a point set is read from and written to: ``.npy``, the ``points`` array of an
``.npz`` (with metadata), or text with one point ``x y`` (``.txt``) or ``x,y`` (``.csv``) a line."""


def load_points(path) -> np.ndarray:
    """Load a point set from any of :data:`POINT_SUFFIXES` and check it: shape ``(n, 2)``,
    floating point, finite, in ``[0, 1)^2`` (a ``ValueError`` naming the file otherwise)."""
    from ._validate import check_points

    path = _check_suffix(path, POINT_SUFFIXES, "points")
    path = _existing(path)
    suffix = path.suffix.lower()
    if suffix == ".npz":
        arrays, _ = load_npz(path)
        if "points" not in arrays:
            raise ValueError(f"{path} holds no array named 'points' (has {sorted(arrays)})")
        pts = arrays["points"]
    elif suffix == ".npy":
        pts = load_npy(path)
    else:
        with open(path, "rb") as fh:
            first = fh.readline().strip()
        header = first[:1].isalpha()  # a column-name row such as "x,y"
        try:
            pts = np.loadtxt(path, delimiter="," if suffix == ".csv" else None, comments="#",
                             dtype=np.float64, ndmin=2, skiprows=int(header))
        except (ValueError, UnicodeDecodeError) as exc:
            why = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise ValueError(f"{path} is not a text file of points, one 'x y' or 'x,y' a line "
                             f"({why})") from None
        pts = pts.astype(np.float32)
    return np.asarray(check_points(f"points in {path}", pts))


def save_points(path, points, metadata: Mapping | None = None, *,
                overwrite: bool = False) -> Path:
    """Write a point set to any of :data:`POINT_SUFFIXES` (chosen by the suffix): ``.npy``,
    ``.npz`` (``points`` and ``metadata``), ``.txt`` (``x y`` a line) or ``.csv`` (``x,y`` a
    line, with a header). Text keeps every float32 bit (9 significant digits)."""
    path = _check_suffix(path, POINT_SUFFIXES, "points")
    pts = np.asarray(points)
    suffix = path.suffix.lower()
    if suffix == ".npy":
        return save_npy(path, pts, overwrite=overwrite)
    if suffix == ".npz":
        return save_npz(path, {"points": pts}, metadata, overwrite=overwrite)
    if suffix == ".csv":  # a plain header row, as spreadsheets and pandas expect
        header, comments = "x,y", ""
    else:  # the metadata as a comment line above the points
        header, comments = "x y", "# "
        if metadata:
            header = f"{json.dumps(_to_jsonable(dict(metadata)), allow_nan=False)}\n{header}"
    with atomic_path(path, overwrite=overwrite) as tmp:
        np.savetxt(tmp, pts.astype(np.float64), fmt="%.9g",
                   delimiter="," if suffix == ".csv" else " ", header=header, comments=comments)
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


def read_exr(path) -> np.ndarray:
    """Read an EXR as float32: ``(h, w)`` for one channel, else ``(h, w, c)`` in RGBA order."""
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
                return np.asarray(ch[order[0]].pixels, dtype=np.float32)
            return np.stack([np.asarray(ch[c].pixels, dtype=np.float32) for c in order], axis=-1)
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

"""Reading and writing results in formats other tools read: .npz, .npy, EXR, PNG, JSON.

Every writer is atomic (a temporary file renamed into place, so an interrupted write leaves
nothing half-written at the destination) and refuses to replace an existing file unless
``overwrite=True``: nothing a user saved is lost without asking.
"""

from __future__ import annotations

import contextlib
import json
import os
import platform
import tempfile
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


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, *, overwrite: bool = False) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success rename it onto ``path``.

    Raises ``FileExistsError`` if ``path`` exists and ``overwrite`` is false.
    """
    path = Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists; pass overwrite=True (CLI: --force) to replace it")
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    tmp = Path(tmp)
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def save_json(path, data: Mapping, *, overwrite: bool = False) -> Path:
    """Write ``data`` as strict JSON: arrays become lists, NaN becomes null, +-Inf "inf"/"-inf"."""
    with atomic_path(path, overwrite=overwrite) as tmp:
        tmp.write_text(json.dumps(_to_jsonable(data), indent=2, allow_nan=False) + "\n")
    return Path(path)


def load_json(path) -> dict:
    return json.loads(Path(path).read_text())


def save_npz(
    path, arrays: Mapping[str, Any], metadata: Mapping | None = None, *, overwrite: bool = False
) -> Path:
    """Save arrays and a JSON metadata record (with provenance) into one ``.npz``."""
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
    """Inverse of :func:`save_npz`: ``(arrays, metadata)``."""
    with np.load(path, allow_pickle=False) as data:
        arrays = {k: data[k] for k in data.files if k != _METADATA_KEY}
        meta = json.loads(str(data[_METADATA_KEY])) if _METADATA_KEY in data.files else {}
    return arrays, meta


def save_npy(path, array, *, overwrite: bool = False) -> Path:
    with atomic_path(path, overwrite=overwrite) as tmp:
        with open(tmp, "wb") as fh:
            np.save(fh, np.asarray(array))
    return Path(path)


def load_points(path) -> np.ndarray:
    """Load a point set from ``.npy`` or from the ``points`` array of an ``.npz``."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no such file: {path}")
    if path.suffix == ".npz":
        arrays, _ = load_npz(path)
        if "points" not in arrays:
            raise ValueError(f"{path} holds no array named 'points' (has {sorted(arrays)})")
        return arrays["points"]
    if path.suffix == ".npy":
        return np.load(path, allow_pickle=False)
    raise ValueError(f"points file must be .npy or .npz, got {path.name}")


def write_exr(path, image, metadata: Mapping | None = None, *, overwrite: bool = False) -> Path:
    """Write a float32 EXR: ``(h, w)`` as channel Y, ``(h, w, 3)`` as RGB, ``(h, w, 4)`` RGBA.

    Row 0 of ``image`` is the top row of the EXR file. Metadata goes into string attributes.
    """
    import OpenEXR

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

    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no such file: {path}")
    with OpenEXR.File(str(path), separate_channels=True) as f:
        ch = f.channels()
        names = list(ch)
        order = [c for c in "RGBA" if c in ch] or names
        if len(order) == 1:
            return np.asarray(ch[order[0]].pixels, dtype=np.float32)
        return np.stack([np.asarray(ch[c].pixels, dtype=np.float32) for c in order], axis=-1)


def save_png(path, image, *, overwrite: bool = False, **imsave_kwargs) -> Path:
    """Save an image array as PNG through matplotlib (``cmap``/``vmin``/``vmax`` allowed).

    Uses ``matplotlib.image.imsave``, which needs no GUI backend and leaves the user's alone.
    """
    from matplotlib.image import imsave

    with atomic_path(path, overwrite=overwrite) as tmp:
        imsave(tmp, np.asarray(image), format="png", **imsave_kwargs)
    return Path(path)


def load_grid(path, *, top_down: bool = False) -> np.ndarray:
    """Load a ``(h, w)`` grid of integrand samples from ``.npy`` or ``.exr`` (RGB is averaged).

    DESIGN's grid convention: ``values[i, j] = f((j + 0.5) / w, (i + 0.5) / h)``, row 0 at the
    smallest y. Images stored top-down (as renderers write them) need ``top_down=True``, which
    flips the rows.
    """
    path = Path(path)
    if path.suffix == ".exr":
        img = read_exr(path)
        if img.ndim == 3:
            img = img[..., :3].mean(axis=-1)
    elif path.suffix == ".npy":
        img = np.load(path, allow_pickle=False)
    else:
        raise ValueError(f"grid file must be .npy or .exr, got {path.name}")
    if img.ndim != 2:
        raise ValueError(f"grid in {path} must be 2D (h, w), got shape {img.shape}")
    return np.ascontiguousarray(img[::-1] if top_down else img)
